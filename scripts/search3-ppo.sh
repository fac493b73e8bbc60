#!/usr/bin/env bash
# Lands replicates of one of issue 77's PPO phases (analysis/results/reward-search3/
# ppo-PHASE.yaml: a tuning file with its variants cut to `shipped` and those going to PPO,
# committed before this runs), one after another, each with one job; run two side by side
# (even and odd replicates). For each replicate R it writes, under
# analysis/results/reward-search3/report/ppo-PHASE/:
#   rR.ndjson.zst     the manifests of the replicate's stages that no earlier archive of that
#                     replicate (report/screen/rR.ndjson.zst, report/ppo-*/rR.ndjson.zst)
#                     holds (`idrex export --except`), so each manifest is committed once;
#   time-rR[-T].txt   /usr/bin/time -v of each run of it (a resumed replicate has several).
# A landed replicate is skipped. Nothing is read here: `idrex report` reads the phase once,
# after the tenth replicate (README.md beside the files). Start both detached:
#   setsid nohup scripts/search3-ppo.sh halfcheetah 0 2 4 6 8 > ppo-even.log 2>&1 < /dev/null &
#   setsid nohup scripts/search3-ppo.sh halfcheetah 1 3 5 7 9 > ppo-odd.log 2>&1 < /dev/null &
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
[ $# -gt 1 ] || { echo "usage: $0 PHASE R [R...] (PHASE: ppo-PHASE.yaml's, e.g. halfcheetah or ant; replicates 0-9)" >&2; exit 2; }
phase="$1"
shift
study=analysis/results/reward-search3
file="$study/ppo-$phase.yaml"
[ -f "$file" ] || { echo "$file: not there; write the phase's file and commit it first" >&2; exit 2; }
# Declared before it runs: committed, and unchanged since.
git ls-files --error-unmatch "$file" >/dev/null 2>&1 && git diff --quiet HEAD -- "$file" ||
  { echo "$file: not committed as it is; commit it before it runs (declared before any result)" >&2; exit 2; }
out="$study/report/ppo-$phase"
mkdir -p "$out"
bin="$(scripts/private-idrex.sh)"
tmp="$(dirname "$bin")"
for r in "$@"; do
  if [ -f "$out/r$r.ndjson.zst" ]; then echo "replicate $r: landed before"; continue; fi
  time="$out/time-r$r.txt"
  [ -e "$time" ] && time="$out/time-r$r-$(date -u +%s).txt"
  echo "$(date -u +%FT%TZ) replicate $r: start"
  /usr/bin/time -v -o "$time" "$bin" pipeline run "$file" --only-replicate "$r" --jobs 1 \
    --store artifacts --recording "$tmp/r$r.rrd"
  except=()
  for earlier in "$study"/report/{screen,ppo-*}/"r$r.ndjson.zst"; do
    [ -f "$earlier" ] && [ "$earlier" != "$out/r$r.ndjson.zst" ] && except+=(--except "$earlier")
  done
  "$bin" export "$file" --only-replicate "$r" --store artifacts "${except[@]}" --out "$out/r$r.ndjson.zst"
  echo "$(date -u +%FT%TZ) replicate $r: landed"
done
