#!/usr/bin/env bash
# Lands replicates of the second locked test set (analysis/results/locked2/, four files), one
# replicate after another, each task in turn, with the frozen binary that runs all of them
# (built from commit 10fbc61 once per machine, beside the shared build). For each replicate R
# and task T it writes, under analysis/results/locked2/report/r<R>/:
#   T.ndjson.zst  the replicate's stage manifests (`idrex export`), to commit;
#   time-T.txt    /usr/bin/time -v of the run.
# It prints whether every stage is stored, never a result: the set is reported once, after
# the tenth replicate. Committing is left to the caller. Start it detached, it runs for hours:
#   setsid nohup scripts/locked2-replicates.sh 0 1 > locked2.log 2>&1 < /dev/null &
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
[ $# -gt 0 ] || { echo "usage: $0 R [R...] (replicates of analysis/results/locked2/*.yaml, 0-9)" >&2; exit 2; }
./scripts/bootstrap.sh
frozen="$(./scripts/frozen-idrex.sh 10fbc61)"
set2=analysis/results/locked2
for r in "$@"; do
  out="$set2/report/r$r"
  mkdir -p "$out"
  for task in halfcheetah hopper walker2d ant; do
    # A landed task (its archive is there) is not run again: its time file stays the one
    # that measured it.
    if [ -f "$out/$task.ndjson.zst" ]; then echo "replicate $r $task: landed before"; continue; fi
    echo "$(date -u +%FT%TZ) replicate $r $task: start"
    /usr/bin/time -v -o "$out/time-$task.txt" "$frozen" pipeline run "$set2/$task.yaml" --only-replicate "$r" --store artifacts --jobs 2
    "$frozen" export "$set2/$task.yaml" --only-replicate "$r" --store artifacts --out "$out/$task.ndjson"
    # Committed compressed (the frozen binary writes plain NDJSON; idrex reads either).
    zstd -19 -q -f --rm "$out/$task.ndjson"
    states="$("$frozen" pipeline plan "$set2/$task.yaml" --store artifacts | awk -v r="r$r/" 'index($3, r) == 1 {print $1}' | sort | uniq -c | tr -s ' \n' ' ')"
    echo "$(date -u +%FT%TZ) replicate $r $task: stages$states"
  done
  echo "$(date -u +%FT%TZ) replicate $r: landed in $out"
done
