"""Does the start of PPO's own run on a learned reward predict its end? (issue 76, the second
question in `results/reward-bench/README.md`, declared there before any curve was read.)

Reads the locked sets' committed manifest archives (each PPO stage's learning curve: the true
return of the training episodes that ended in each update) and the committed outcomes
(`results/reward-bench/report/outcomes.csv`); runs nothing:

    python analysis/probe_curves.py OUT.csv

The probe of a replicate: D-REX's PPO run 0, the mean true return of the curve's points in
(15 %, 20 %] of its steps, minus BC's evaluation mean. Against it: D-REX minus BC at the end
(3 runs x 20 episodes), by the true return and the forward term. Beside it, not used to choose
anything: the same window ending at 10 %, 30 % and 50 %, and the mean over the 3 runs.
"""
import csv
import glob
import io
import json
import os
import re
import subprocess
import sys

import numpy as np

from reward_bench import OUTCOMES, bootstrap, spearman

HERE = os.path.dirname(os.path.abspath(__file__))
# Each archive set: the pipeline file as outcomes.csv names it, and its archives.
ARCHIVES = [
    ("analysis/results/locked/test.yaml", "results/locked/report/r*/manifests.ndjson.zst"),
    ("analysis/results/locked2/{task}.yaml", "results/locked2/report/r*/*.ndjson.zst"),
    ("analysis/results/ant/test.yaml", "results/ant/report/test/manifests.ndjson.zst"),
]
TASKS = {"HalfCheetah-v5": "halfcheetah", "Hopper-v5": "hopper", "Walker2d-v5": "walker2d", "Ant-v5": "ant"}
WINDOW = 0.05
ENDS = [0.10, 0.20, 0.30, 0.50]
PRIMARY = 0.20


def read_archive(path):
    text = subprocess.run(["zstd", "-dc", path], check=True, capture_output=True).stdout.decode()
    return [json.loads(line) for line in io.StringIO(text) if line.strip()]


def window_mean(curve, total, end):
    lo, hi = (end - WINDOW) * total, end * total
    vals = [p["true_return"] for p in curve if lo < p["step"] <= hi and p.get("true_return") is not None]
    return float(np.mean(vals)) if vals else float("nan")


def curves():
    """(pipeline file, env, replicate) -> [run 0's curve, run 1's, run 2's] with total steps."""
    out = {}
    for file, pattern in ARCHIVES:
        for path in sorted(glob.glob(os.path.join(HERE, pattern))):
            folder = os.path.basename(os.path.dirname(path))
            for m in read_archive(path):
                node, env = m["node"], m["params"].get("env")
                if m["kind"] != "ppo" or env not in TASKS:
                    continue
                # A node reads `[ENV/][rN/]drex/ppo/K` (either prefix first, or none); without
                # `rN/` the archive's folder is the replicate.
                parts = node.split("/")
                rep = int(folder[1:]) if re.fullmatch(r"r\d+", folder) else 0
                while parts[0] == env or re.fullmatch(r"r\d+", parts[0]):
                    if parts[0] != env:
                        rep = int(parts[0][1:])
                    parts = parts[1:]
                if parts[:2] != ["drex", "ppo"]:
                    continue
                key = (file.format(task=TASKS[env]), env, rep)
                out.setdefault(key, {})[int(parts[2])] = (m["metrics"]["curve"], m["params"]["ppo"]["total_steps"])
    return out


def number(s):
    try:
        return float(s)
    except ValueError:
        return float("nan")


def main(out):
    outcomes = {}
    with open(OUTCOMES) as f:
        for r in csv.DictReader(f):
            outcomes[(r["pipeline_file"], r["env"], int(r["replicate"]))] = r
    rows = []
    for key, runs in sorted(curves().items()):
        o = outcomes.get(key)
        if o is None or sorted(runs) != [0, 1, 2]:
            print(f"no outcome or not 3 runs for {key}", file=sys.stderr)
            continue
        bc = number(o["bc_return"])
        row = {
            "pipeline_file": key[0], "env": key[1], "seed_set": o["seed_set"], "replicate": key[2], "bc_return": bc,
            "drex_minus_bc": number(o["drex_return"]) - bc,
            "drex_minus_bc_forward": number(o["drex_forward"]) - number(o["bc_forward"]),
        }
        for end in ENDS:
            tag = int(round(end * 100))
            row[f"probe_{tag}"] = window_mean(*runs[0], end) - bc
            row[f"probe_{tag}_3runs"] = float(np.mean([window_mean(*runs[i], end) for i in range(3)])) - bc
        rows.append(row)
    with open(out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| task | replicates | probe | outcome | Spearman [95 % CI] | probe < 0 on D-REX < BC |")
    print("|---|---|---|---|---|---|")
    for env in TASKS:
        sel = [r for r in rows if r["env"] == env]
        if not sel:
            continue
        for outcome in ["drex_minus_bc", "drex_minus_bc_forward"]:
            got = [r for r in sel if np.isfinite(r[outcome])]
            if len(got) < 4:
                continue
            for probe in [f"probe_{int(e * 100)}" for e in ENDS] + [f"probe_{int(PRIMARY * 100)}_3runs"]:
                x = [r[probe] for r in got]
                y = [r[outcome] for r in got]
                lo, hi = bootstrap(x, y)
                fails = [r for r in got if r[outcome] < 0]
                flagged = sum(r[probe] < 0 for r in fails)
                false = sum(r[probe] < 0 and r[outcome] >= 0 for r in got)
                print(f"| {env} | {len(got)} | {probe} | {outcome} | {spearman(x, y):.2f} [{lo:.2f}, {hi:.2f}] | "
                      f"{flagged} of {len(fails)} (and {false} of {len(got) - len(fails)} good ones) |")
            # Controls: probe and outcome share "minus BC", so BC's return alone predicts
            # D-REX minus BC wherever BC varies; the probe is worth something only above that.
            for name, x in [("BC alone (-BC)", [-r["bc_return"] for r in got]),
                            ("probe_20 without BC", [r["probe_20"] + r["bc_return"] for r in got])]:
                lo, hi = bootstrap(x, y)
                print(f"| {env} | {len(got)} | {name} | {outcome} | {spearman(x, y):.2f} [{lo:.2f}, {hi:.2f}] | |")


if __name__ == "__main__":
    main(sys.argv[1])
