#!/usr/bin/env bash
# Sets up and builds where needed (`./dev --version`), then prints the path of a private copy
# of the release binary in a fresh temporary folder: a chain of long runs holds it, so that a
# rebuild meanwhile does not change the binary under it, and writes its own files (recordings)
# beside it, since two chains would write one file at once.
#   bin="$(scripts/private-idrex.sh)"; tmp="$(dirname "$bin")"
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
./dev --version >/dev/null
target="$(sed -n 's/^target-dir = "\(.*\)"$/\1/p' .cargo/config.toml)"
tmp="$(mktemp -d)"
cp "$target/release/idrex" "$tmp/idrex"
echo "$tmp/idrex"
