#!/usr/bin/env bash
# The GPU checks of idrex's CUDA path, as one command on a machine with an NVIDIA GPU and
# idrex built against a CUDA libtorch (the README's install: torch 2.13.0 from PyPI is a CUDA
# 13.0 build). About 5 minutes on one GPU. Writes JSON and logs into $OUT (default
# analysis/gpu/out) and exits non-zero at the first failed check.
#
#   analysis/gpu/check.sh [IDREX_BINARY]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
idrex="${1:-${IDREX:-$(sed -n 's/^target-dir = "\(.*\)"$/\1/p' .cargo/config.toml)/release/idrex}}"
out="${OUT:-analysis/gpu/out}"
mkdir -p "$out"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu.csv"

# 1. `auto` must choose the GPU, and the plan must carry it in the keys.
"$idrex" pipeline plan pipelines/smoke.yaml --store "$scratch/a" --device auto > "$out/plan-auto.txt"
"$idrex" pipeline plan pipelines/smoke.yaml --store "$scratch/a" --device cuda > "$out/plan-cuda.txt"
cmp "$out/plan-auto.txt" "$out/plan-cuda.txt" || { echo "FAIL: auto did not choose cuda"; exit 1; }

# 2. Reproducible on the device: the smoke pipeline twice, byte-identical artifacts.
digest() { (cd "$1" && find . -type f ! -name 'manifest*' ! -name '*.lock' | sort | xargs sha256sum | sha256sum); }
for run in a b; do
  "$idrex" pipeline run pipelines/smoke.yaml --store "$scratch/$run" --device cuda --jobs 4 > "$out/smoke-$run.log" 2>&1
done
[ "$(digest "$scratch/a")" = "$(digest "$scratch/b")" ] || { echo "FAIL: two CUDA runs differ"; exit 1; }
echo "smoke on cuda: two runs identical ($(digest "$scratch/a" | cut -c1-12))" | tee "$out/determinism.txt"

# 3. Speed at the report's shapes: idrex on the GPU against PyTorch on the GPU and idrex's
#    CPU learners (the same command measures all three).
"$idrex" bench learners --device cuda --threads 2 --trex-iterations 300 --bc-iterations 3000 | tee "$out/learners-cuda.json"

# 4. Ranking quality on the GPU against the CPU: T-REX on rollouts of the smoke run's BC policy.
policy="$(dirname "$(find "$scratch/a" -name policy.json | sort | head -1)")"
for device in cuda cpu; do
  "$idrex" bench trex --policy "$policy" --iterations 1000 --device "$device" | tee "$out/trex-$device.json"
done
echo "all GPU checks passed; results in $out"
