"""What one replicate of the second locked set costs (issue 55, point 5), per task and processor.

Reads only what the landing script wrote: each `report/r<R>/time-<task>.txt` (`/usr/bin/time
-v` of the replicate's `pipeline run`, `--jobs 2`) and each archive's stage stamps
(`started_unix`, `ended_unix`, `wall_s`), never a metric:

    python analysis/locked2_cost.py [analysis/results/locked2/report]

A run resumed after a session break has a time file that covers its last part only; it is
recognised by its stages' stamps spanning more than its measured wall time and left out of
the medians (its stage time still counts). The processor is not in the archives (the frozen
binary records the kernel variant, `avx512` on both machines), so it is taken from the landing
notes: the Intel Xeon (family 6, model 167) ran replicates 0-5 and replicate 6's HalfCheetah,
the AMD EPYC Zen 4 (family 25, model 17) everything after.
"""
import json
import re
import statistics
import subprocess
import sys
from pathlib import Path

TASKS = ["halfcheetah", "hopper", "walker2d", "ant"]
INTEL = "Intel Xeon (6/167)"
ZEN4 = "AMD EPYC Zen 4 (25/17)"
# Stage stamps may start a little before the timed process (the plan) or end after it: a span
# this much longer than the measured wall time means the run was resumed.
RESUMED_SLACK_S = 120


def processor(replicate, task):
    if replicate < 6 or (replicate == 6 and task == "halfcheetah"):
        return INTEL
    return ZEN4


def timed(path):
    """(wall s, CPU s) from a `/usr/bin/time -v` file."""
    text = path.read_text()
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", text).group(1)
    seconds = 0.0
    for part in wall.split(":"):
        seconds = seconds * 60 + float(part)
    user = float(re.search(r"User time \(seconds\): (\S+)", text).group(1))
    system = float(re.search(r"System time \(seconds\): (\S+)", text).group(1))
    return seconds, user + system


def stamps(path):
    """(span of the stages' stamps in s, sum of their wall times in s, stage count)."""
    lines = subprocess.run(["zstdcat", str(path)], capture_output=True, check=True).stdout
    starts, ends, total, count = [], [], 0.0, 0
    for line in lines.decode().splitlines():
        entry = json.loads(line)
        if "wall_s" not in entry:
            continue
        starts.append(entry["started_unix"])
        ends.append(entry["ended_unix"])
        total += entry["wall_s"]
        count += 1
    return max(ends) - min(starts), total, count


def main():
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "analysis/results/locked2/report")
    rows = []
    for replicate in range(10):
        for task in TASKS:
            archive = root / f"r{replicate}" / f"{task}.ndjson.zst"
            timing = root / f"r{replicate}" / f"time-{task}.txt"
            if not archive.exists() or not timing.exists():
                continue
            wall, cpu = timed(timing)
            span, stage_time, count = stamps(archive)
            resumed = span > wall + RESUMED_SLACK_S
            rows.append((replicate, task, processor(replicate, task), wall, cpu, stage_time, count, resumed))

    print("| replicate | task | processor | wall min | CPU min | stage time min | note |")
    print("|---|---|---|---|---|---|---|")
    for r, task, proc, wall, cpu, stage_time, count, resumed in rows:
        note = "resumed: time covers the last part" if resumed else ""
        print(f"| r{r} | {task} | {proc} | {wall / 60:.1f} | {cpu / 60:.1f} | {stage_time / 60:.1f} | {note} |")

    print()
    print("Medians over the runs not resumed (wall and CPU of `pipeline run --jobs 2`):")
    print()
    print("| processor | task | runs | wall min | CPU min |")
    print("|---|---|---|---|---|")
    whole = {}
    for proc in (INTEL, ZEN4):
        for task in TASKS:
            kept = [(w, c) for r, t, p, w, c, _, _, res in rows if p == proc and t == task and not res]
            if not kept:
                continue
            wall = statistics.median(w for w, _ in kept)
            cpu = statistics.median(c for _, c in kept)
            whole.setdefault(proc, []).append((wall, cpu))
            print(f"| {proc} | {task} | {len(kept)} | {wall / 60:.1f} | {cpu / 60:.1f} |")
    for proc, parts in whole.items():
        if len(parts) == len(TASKS):
            wall = sum(w for w, _ in parts)
            cpu = sum(c for _, c in parts)
            print(f"| {proc} | one replicate, four tasks | | {wall / 60:.1f} | {cpu / 60:.1f} |")


if __name__ == "__main__":
    main()
