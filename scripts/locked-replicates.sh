#!/usr/bin/env bash
# Lands replicates of the locked test set (analysis/results/locked/test.yaml), one after
# another, with the frozen binary that ran all of them (built from commit 8e58d64 once per
# machine by scripts/frozen-idrex.sh). After each replicate it writes, under
# analysis/results/locked/report/r<R>/:
#   manifests.ndjson.zst   the replicate's stage manifests (`idrex export`), to commit;
#   time.txt           /usr/bin/time -v of the run (time-recomputed.txt where the replicate
#                      had landed before, on a machine whose store is gone: its report stays
#                      as it landed, and the archive test compares the two);
#   the report's tables (CSV) of every replicate stored or archived so far (new replicates
#                      only; its words and figures are rebuilt from the archives, not committed).
# Committing is left to the caller. Start it detached, it runs for hours:
#   setsid nohup scripts/locked-replicates.sh 8 9 > locked.log 2>&1 < /dev/null &
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
[ $# -gt 0 ] || { echo "usage: $0 R [R...] (replicates of analysis/results/locked/test.yaml, 0-9)" >&2; exit 2; }
./scripts/bootstrap.sh
frozen="$(./scripts/frozen-idrex.sh 8e58d64)"
./dev --version >/dev/null  # the current binary, for export and report
locked=analysis/results/locked
for r in "$@"; do
  out="$locked/report/r$r"
  time_file=time.txt
  [ -f "$out/returns.csv" ] && time_file=time-recomputed.txt
  mkdir -p "$out"
  echo "$(date -u +%FT%TZ) replicate $r: start"
  /usr/bin/time -v -o "$out/$time_file" "$frozen" pipeline run "$locked/test.yaml" --only-replicate "$r" --store artifacts --jobs 2
  ./dev export "$locked/test.yaml" --only-replicate "$r" --store artifacts --out "$out/manifests.ndjson.zst"
  if [ "$time_file" = time.txt ]; then
    archives=()
    for a in "$locked"/report/r*/manifests.ndjson.zst; do archives+=(--archive "$a"); done
    ./dev report --store artifacts "${archives[@]}" --out "$out" --format csv
  fi
  echo "$(date -u +%FT%TZ) replicate $r: landed in $out"
done
