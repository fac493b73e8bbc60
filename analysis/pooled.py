"""Final-policy returns pooled over several pipelines of one environment (seed sets of the
same file): per method, each run's mean true return over its evaluation episodes, the mean
over all runs with two 95 % percentile-bootstrap intervals of that mean, how many runs end
above a threshold (the demonstration's return), and each seed set's mean.

The runs of one seed set share its BC policy and learned rewards, so they are not
independent: the first interval resamples runs, the second (hierarchical) resamples seed
sets and then runs within each, and is the one to read.

A run's final policy is its last iteration's (iD-REX: iteration K-1; BC and D-REX: 0). Only
eval stages are read; the store's manifests are JSON, so no idrex is needed.

    python analysis/pooled.py STORE --pipeline NAME [--pipeline NAME]... [--above 187.7] [--markdown]
"""
import argparse
import json
import os
import random
from collections import defaultdict

METHODS = ["bc", "drex", "idrex-interpolation", "idrex-action-noise", "idrex-multi-bc"]


def bootstrap_ci(values, resamples=10_000, seed=0):
    rng = random.Random(seed)
    n = len(values)
    means = sorted(sum(rng.choice(values) for _ in range(n)) / n for _ in range(resamples))
    return means[int(0.025 * resamples)], means[int(0.975 * resamples) - 1]


def hierarchical_ci(groups, resamples=10_000, seed=0):
    """Resamples the groups, then the runs within each resampled group."""
    rng = random.Random(seed)
    means = []
    for _ in range(resamples):
        picked = [rng.choice(groups) for _ in groups]
        values = [rng.choice(g) for g in picked for _ in g]
        means.append(sum(values) / len(values))
    means.sort()
    return means[int(0.025 * resamples)], means[int(0.975 * resamples) - 1]


def final_runs(store, pipelines):
    """{method: {pipeline: [run means]}} of the final iteration's evaluations."""
    found = defaultdict(dict)  # (method, pipeline, run) -> (iteration, mean)
    for key in sorted(os.listdir(store)):
        path = os.path.join(store, key, "manifest.json")
        if not os.path.isfile(path):
            continue
        with open(path) as f:
            m = json.load(f)
        if m.get("kind") != "eval" or m["params"].get("pipeline") not in pipelines:
            continue
        p = m["params"]
        slot = (p["method"], p["pipeline"], p["run"])
        if slot not in found or p["iteration"] > found[slot][0]:
            found[slot] = (p["iteration"], m["metrics"]["mean"])
    runs = defaultdict(lambda: defaultdict(list))
    for (method, pipeline, run), (_, mean) in sorted(found.items()):
        runs[method][pipeline].append(mean)
    return runs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("store")
    ap.add_argument("--pipeline", action="append", required=True)
    ap.add_argument("--above", type=float, default=None, help="count runs ending above this return")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    runs = final_runs(args.store, set(args.pipeline))
    header = ["method", "runs", "mean [95 % CI, runs resampled]", "[95 % CI, seed sets then runs]"]
    if args.above is not None:
        header.append(f"runs above {args.above}")
    header += [f"{p} mean" for p in args.pipeline]
    rows = []
    for method in METHODS:
        if method not in runs:
            continue
        per = runs[method]
        pooled = [v for p in args.pipeline for v in per.get(p, [])]
        lo, hi = bootstrap_ci(pooled)
        hlo, hhi = hierarchical_ci([per[p] for p in args.pipeline if per.get(p)])
        row = [method, str(len(pooled)), f"{sum(pooled) / len(pooled):.1f} [{lo:.1f}, {hi:.1f}]", f"[{hlo:.1f}, {hhi:.1f}]"]
        if args.above is not None:
            row.append(f"{sum(v > args.above for v in pooled)} of {len(pooled)}")
        row += [f"{sum(per[p]) / len(per[p]):.1f}" if per.get(p) else "-" for p in args.pipeline]
        rows.append(row)
    if args.markdown:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for r in rows:
            print("| " + " | ".join(r) + " |")
    else:
        print(json.dumps([dict(zip(header, r)) for r in rows], indent=1))


if __name__ == "__main__":
    main()
