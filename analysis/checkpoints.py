"""Per-checkpoint table of a store's evaluations: for each method, the true return (pooled
over runs and episodes), the ensemble-mean learned return, the pessimistic member's return
and the members' spread, and how each learned signal correlates with the true return over
the checkpoints (Spearman, per run then averaged).

    python analysis/checkpoints.py artifacts [--pipeline NAME]
"""
import argparse
import json
import os
from collections import defaultdict


def ranks(v):
    order = sorted(range(len(v)), key=lambda i: v[i])
    r = [0.0] * len(v)
    i = 0
    while i < len(order):
        j = i
        while j + 1 < len(order) and v[order[j + 1]] == v[order[i]]:
            j += 1
        for k in order[i : j + 1]:
            r[k] = (i + j) / 2
        i = j + 1
    return r


def pearson(x, y):
    n = len(x)
    mx, my = sum(x) / n, sum(y) / n
    cov = sum((a - mx) * (b - my) for a, b in zip(x, y))
    vx = sum((a - mx) ** 2 for a in x)
    vy = sum((b - my) ** 2 for b in y)
    return cov / (vx * vy) ** 0.5 if vx > 0 and vy > 0 else float("nan")


def spearman(x, y):
    return pearson(ranks(x), ranks(y))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("store")
    ap.add_argument("--pipeline")
    args = ap.parse_args()
    groups = defaultdict(list)
    for d in sorted(os.listdir(args.store)):
        path = os.path.join(args.store, d, "manifest.json")
        if d.startswith(".") or not os.path.isfile(path):
            continue
        m = json.load(open(path))
        if m["kind"] != "eval" or not m["metrics"].get("checkpoints"):
            continue
        p = m["params"]
        if args.pipeline and p["pipeline"] != args.pipeline:
            continue
        groups[(p["pipeline"], p["method"], p["iteration"])].append((p["run"], m["metrics"]["checkpoints"]))
    mean = lambda v: sum(v) / len(v)
    for (pipeline, method, k), runs in sorted(groups.items()):
        runs.sort()
        steps = [c["step"] for c in runs[0][1]]
        print(f"\n{pipeline} {method} (iteration {k}, {len(runs)} runs)")
        print(f"{'step':>8} {'true':>8} {'learned':>9} {'pessim.':>8} {'spread':>7}   true per run")
        for s in steps:
            cs = [next(c for c in r if c["step"] == s) for _, r in runs]
            true = mean([x for c in cs for x in c["returns"]])
            learned = mean([c["learned"]["mean"] for c in cs])
            pess = mean([c["learned"]["pessimistic"] for c in cs])
            spread = mean([c["learned"]["spread"] for c in cs])
            per_run = " ".join(f"{mean(c['returns']):8.1f}" for c in cs)
            print(f"{s:>8} {true:8.1f} {learned:9.1f} {pess:8.1f} {spread:7.1f}   {per_run}")
        for signal in ["mean", "pessimistic", "spread"]:
            rhos = []
            for _, r in runs:
                t = [mean(c["returns"]) for c in r]
                x = [c["learned"][signal] for c in r]
                rhos.append(spearman(x, t))
            print(f"  Spearman(true, {signal}) over checkpoints, per run: " + ", ".join(f"{x:.2f}" for x in rhos))


if __name__ == "__main__":
    main()
