#!/usr/bin/env bash
# PPO on the ground-truth reward, CleanRL's settings: 1M steps, seeds 0-2, HalfCheetah-v5 and
# Hopper-v5 (or the tasks named in ENVS); then the final stochastic policy's mean return over
# 20 episodes (idrex eval). Two runs at a time (one core each).
# Usage: [ENVS="Ant-v5"] analysis/ppo_quality.sh [OUT_DIR] [STEPS]
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-runs/ppo-quality}"
steps="${2:-1000000}"
bin="$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')/release/idrex"
mkdir -p "$out"
jobs=()
for env in ${ENVS:-HalfCheetah-v5 Hopper-v5}; do
  for seed in 0 1 2; do
    jobs+=("$env $seed")
  done
done
run() {
  set -- $1
  "$bin" train ppo --env "$1" --steps "$steps" --seed "$2" --out "$out/$1-$2" --eval-every 100000 >"$out/$1-$2.log" 2>&1
}
printf '%s\n' "${jobs[@]}" | while read -r j; do echo "$j"; done | xargs -P 2 -I{} bash -c "$(declare -f run); bin='$bin' out='$out' steps='$steps' run '{}'"
echo "| env | seed | return (20 episodes, stochastic) | train wall s | steps/s |"
echo "|---|---|---|---|---|"
for j in "${jobs[@]}"; do
  set -- $j
  r=$("$bin" eval --policy "$out/$1-$2" --episodes 20 --seed 100 --json)
  line=$(grep '^trained' "$out/$1-$2.log")
  wall=$(echo "$line" | sed -E 's/.* in ([0-9.]+) s .*/\1/')
  sps=$(echo "$line" | sed -E 's/.*\(([0-9]+) steps\/s\).*/\1/')
  echo "| $1 | $2 | $(echo "$r" | python3 -c 'import json,sys; d=json.load(sys.stdin); print("%.1f +- %.1f" % (d["mean"], d["std"]))') | $wall | $sps |"
done
