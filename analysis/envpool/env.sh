#!/usr/bin/env bash
# The small Python environment in which `idrex bench env --envpool` runs EnvPool 1.2.5
# (requirements.txt here, every package pinned; not the 5 GB environment of
# scripts/bootstrap.sh). Created
# once per machine under the idrex cache, trusted only once its `.complete` marker exists,
# shared by concurrent callers through a lock. Prints the environment's Python:
#   idrex bench env --envpool "$(analysis/envpool/env.sh)"
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cache="${IDREX_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/idrex}"
python="${IDREX_PYTHON:-python3}"
pyver="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
dir="$cache/envpool-$( (cat "$here/requirements.txt"; echo "$pyver") | sha256sum | cut -c1-12)"
mkdir -p "$cache"
exec 9>"$cache/envpool.lock"
flock 9
if [ ! -f "$dir/.complete" ]; then
  rm -rf "$dir"
  {
    "$python" -m venv "$dir" &&
      "$dir/bin/pip" install --quiet --disable-pip-version-check -r "$here/requirements.txt" &&
      "$dir/bin/python" -c "import envpool; envpool.make('Ant-v5', env_type='gymnasium', num_envs=1).reset()"
  } >"$dir.install.log" 2>&1 || { rm -rf "$dir"; echo "envpool env: install failed (see $dir.install.log)" >&2; exit 1; }
  touch "$dir/.complete"
fi
echo "$dir/bin/python"
