#!/usr/bin/env bash
# Prints the path of the idrex binary built from COMMIT, building it once per machine (in a
# worktree beside the shared build, copied out under the cache): the frozen binary a locked
# test set runs every replicate with.
#   frozen="$(scripts/frozen-idrex.sh 10fbc61)"
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
[ $# -eq 1 ] || { echo "usage: $0 COMMIT" >&2; exit 2; }
commit="$1"
cache="${IDREX_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/idrex}"
frozen="$cache/idrex-$commit"
if [ ! -x "$frozen" ]; then
  src="$cache/locked-src-$commit"
  [ -d "$src" ] || git worktree add --detach "$src" "$commit" >&2
  (cd "$src" && ./scripts/bootstrap.sh && cargo build --release --quiet --bin idrex) >&2
  target="$(sed -n 's/^target-dir = "\(.*\)"$/\1/p' "$src/.cargo/config.toml")"
  cp "$target/release/idrex" "$frozen.partial" && mv "$frozen.partial" "$frozen"
fi
echo "$frozen"
