#!/usr/bin/env bash
# The small Python environment in which tests/rliable.rs runs rliable 1.2.0 itself
# (requirements.txt here; not the 5 GB environment of scripts/bootstrap.sh). Created once per
# machine under the idrex cache, trusted only once its `.complete` marker exists, shared by
# concurrent callers through a lock. Prints the environment's Python.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cache="${IDREX_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/idrex}"
python="${IDREX_PYTHON:-python3}"
pyver="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
dir="$cache/rliable-$( (cat "$here/requirements.txt"; echo "rliable==1.2.0 $pyver") | sha256sum | cut -c1-12)"
mkdir -p "$cache"
exec 9>"$cache/rliable.lock"
flock 9
if [ ! -f "$dir/.complete" ]; then
  rm -rf "$dir"
  {
    "$python" -m venv "$dir" &&
      "$dir/bin/pip" install --quiet --disable-pip-version-check -r "$here/requirements.txt" &&
      "$dir/bin/pip" install --quiet --disable-pip-version-check --no-deps rliable==1.2.0
  } >"$dir.install.log" 2>&1 || { rm -rf "$dir"; echo "rliable env: pip install failed (see $dir.install.log)" >&2; exit 1; }
  touch "$dir/.complete"
fi
echo "$dir/bin/python"
