#!/usr/bin/env bash
# Lands replicates of issue 77's HalfCheetah screen (analysis/results/reward-search3/), one
# after another, each with one job: run two of these side by side (even and odd replicates),
# which keeps both cores busy through each replicate's long tail. For each replicate R it
# writes, under analysis/results/reward-search3/report/screen/:
#   rR.ndjson.zst     the replicate's stored stages' manifests (`idrex export`: the probes'
#                     metrics, the stages' wall times), to commit, so that the screen is read
#                     on any machine and a new machine's store need not redo it;
#   time-rR[-T].txt   /usr/bin/time -v of each run of it (a resumed replicate has several).
# A landed replicate (its archive is there) is skipped. It prints no probe: the screen is read
# once, after the tenth replicate (README.md beside the files). Start both detached:
#   setsid nohup scripts/search3-screen.sh 0 2 4 6 8 > screen-even.log 2>&1 < /dev/null &
#   setsid nohup scripts/search3-screen.sh 1 3 5 7 9 > screen-odd.log 2>&1 < /dev/null &
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
[ $# -gt 0 ] || { echo "usage: $0 R [R...] (replicates 0-9)" >&2; exit 2; }
file=analysis/results/reward-search3/tuning-halfcheetah.yaml
out=analysis/results/reward-search3/report/screen
mkdir -p "$out"
bin="$(scripts/private-idrex.sh)"
tmp="$(dirname "$bin")"
for r in "$@"; do
  if [ -f "$out/r$r.ndjson.zst" ]; then echo "replicate $r: landed before"; continue; fi
  time="$out/time-r$r.txt"
  [ -e "$time" ] && time="$out/time-r$r-$(date -u +%s).txt"
  echo "$(date -u +%FT%TZ) replicate $r: start"
  /usr/bin/time -v -o "$time" "$bin" pipeline run "$file" --target drex/trex/probe --only-replicate "$r" --jobs 1 \
    --store artifacts --recording "$tmp/r$r.rrd"
  "$bin" export "$file" --only-replicate "$r" --store artifacts --out "$out/r$r.ndjson.zst"
  echo "$(date -u +%FT%TZ) replicate $r: landed"
done
