#!/usr/bin/env bash
# The GPU checks of idrex's CUDA path, as one command on a machine with an NVIDIA GPU and
# idrex built against a CUDA libtorch (the README's install: torch 2.13.0 from PyPI is a CUDA
# 13.0 build). A few minutes. Writes JSON and logs into $OUT (default analysis/gpu/out) and
# exits non-zero at the first failed check.
#
#   [POLICY=DIR] analysis/gpu/check.sh [IDREX_BINARY]
#
# DEVICE=cpu runs the same checks on the CPU: how the script itself was tested.
set -euo pipefail
device="${DEVICE:-cuda}"
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
idrex="${1:-${IDREX:-$(sed -n 's/^target-dir = "\(.*\)"$/\1/p' .cargo/config.toml)/release/idrex}}"
out="${OUT:-analysis/gpu/out}"
mkdir -p "$out"
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu.csv"

# 1. `auto` must choose the GPU, and the plan must carry it in the keys.
"$idrex" pipeline plan pipelines/smoke.yaml --store "$scratch/a" --device auto > "$out/plan-auto.txt"
"$idrex" pipeline plan pipelines/smoke.yaml --store "$scratch/a" --device "$device" > "$out/plan-$device.txt"
cmp "$out/plan-auto.txt" "$out/plan-$device.txt" || { echo "FAIL: auto did not choose $device"; exit 1; }

# 2. Reproducible on the device: the smoke pipeline twice, byte-identical artifacts.
digest() { (cd "$1" && find . -type f ! -name 'manifest*' ! -name '*.lock' | sort | xargs sha256sum | sha256sum); }
for run in a b; do
  "$idrex" pipeline run pipelines/smoke.yaml --store "$scratch/$run" --device "$device" --jobs 4 \
    --recording "$scratch/$run.rrd" > "$out/smoke-$run.log" 2>&1
done
[ "$(digest "$scratch/a")" = "$(digest "$scratch/b")" ] || { echo "FAIL: two runs on $device differ"; exit 1; }
echo "smoke on $device: two runs identical ($(digest "$scratch/a" | cut -c1-12))" | tee "$out/determinism.txt"

# 3. Speed at the report's shapes: idrex on the GPU against PyTorch on the GPU and idrex's
#    CPU learners (the same command measures all three).
"$idrex" bench learners --device "$device" --threads 2 --trex-iterations 300 --bc-iterations 3000 | tee "$out/learners-$device.json"

# 4. Ranking quality on the GPU against the CPU: T-REX on noise-injected rollouts of $POLICY
#    (a policy directory; give a trained one, e.g. a HalfCheetah BC policy from a paper-settings
#    store: the smoke run's BC policy, the default, barely acts, and both devices then rank
#    at chance).
policy="${POLICY:-$(dirname "$(grep -l '"kind": "bc"' "$scratch"/a/*/manifest.json | head -1)")/policy}"
for d in "$device" cpu; do
  "$idrex" bench trex --policy "$policy" --iterations 1000 --device "$d" | tee "$out/trex-$d.json"
done
echo "all GPU checks passed; results in $out"
