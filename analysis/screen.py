"""Issue 77's screen: every sweep variant's probe against the `shipped` baseline's, paired by
replicate (the variants of one replicate share its demonstrations and BC), by the rule
`results/reward-search3/README.md` declares: a variant passes when its probe is above the
baseline's on at least 7 of the 10 replicates; the two or three passing variants with the
highest median paired difference go to PPO.

Reads `idrex pipeline plan FILE` (node names and keys) and the manifests of stores and of
archives (`idrex export`, `.ndjson` or `.ndjson.zst`: the committed replicates, so that the
screen is read on any machine):

    idrex pipeline plan FILE | python analysis/screen.py [--score SCORE] SOURCE... > screen.csv

SCORE is a probe metric: `true_return` (the last quarter's training episodes; the default) or
`final_forward` (the final policy's forward term). Beside each variant, the wall time of its
own stages (ranked set, T-REX, probe) per replicate, from their manifests, so the next search
can be planned from it; and the median paired difference's distribution-free interval (order
statistics; for 10 replicates d(2) to d(9), coverage 97.9 %), which the rule does not use. Only
the standard library.
"""
import csv
import json
import math
import os
import re
import statistics
import subprocess
import sys

BASELINE = "shipped"
PASS_AT = 7
TO_PPO = 3
LINE = re.compile(r"^(stored|missing)\s+([0-9a-f]{12})\s+(\S+)\s+(\S+)")
NODE = re.compile(r"^(?:(?P<variant>[^/]+)/)?r(?P<replicate>\d+)/drex/(?P<stage>noise|trex|trex/probe)$")


def sign_test(above, n):
    """One-sided p of at least `above` successes in `n` fair coin flips."""
    return sum(math.comb(n, k) for k in range(above, n + 1)) / 2**n if n else float("nan")


def median_interval(diffs, level=0.95):
    """The distribution-free interval for the median of `diffs`: order statistics d(k) and
    d(n+1-k) with the largest k whose coverage, 1 - 2 P(Binomial(n, 1/2) <= k - 1), is at least
    `level` (for n = 10, d(2) to d(9), 97.9 %). None where n is too small for any."""
    d, n = sorted(diffs), len(diffs)
    best = None
    for k in range(1, n // 2 + 1):
        coverage = 1 - 2 * sum(math.comb(n, j) for j in range(k)) / 2**n
        if coverage >= level:
            best = (d[k - 1], d[n - k], coverage)
    return best


def plan_nodes(lines):
    """(variant, replicate, stage) -> key prefix, for the ranked set, T-REX and the probe."""
    nodes = {}
    for line in lines:
        m = LINE.match(line)
        if not m:
            continue
        n = NODE.match(m.group(3))
        if n:
            variant = n.group("variant") or BASELINE
            nodes[(variant, int(n.group("replicate")), n.group("stage"))] = m.group(2)
    return nodes


def manifests_by_prefix(source):
    """A store directory's manifests, or an archive's lines (zstd through the `zstd` command)."""
    out = {}
    if os.path.isdir(source):
        for d in os.listdir(source):
            path = os.path.join(source, d, "manifest.json")
            if os.path.isfile(path):
                with open(path) as f:
                    out[d[:12]] = json.load(f)
        return out
    if source.endswith(".zst"):
        text = subprocess.run(["zstd", "-dc", source], check=True, capture_output=True, text=True).stdout
    else:
        with open(source) as f:
            text = f.read()
    for line in text.splitlines():
        if line.strip():
            m = json.loads(line)
            out[m["key"][:12]] = m
    return out


def screen(nodes, stored, score):
    probes, cost = {}, {}
    for (variant, r, stage), key in nodes.items():
        m = stored.get(key)
        if m is None:
            continue
        if stage == "trex/probe":
            probes[(variant, r)] = m["metrics"][score]
        # A variant's own stages only: where its key is the baseline's, the stage is shared.
        if variant == BASELINE or nodes.get((BASELINE, r, stage)) != key:
            cost.setdefault(variant, {}).setdefault(r, 0.0)
            cost[variant][r] += m["wall_s"]
    variants = sorted({k[0] for k in nodes}, key=lambda v: (v != BASELINE, v))
    rows = []
    for v in variants:
        reps = sorted(r for (vv, r) in probes if vv == v)
        paired = [(r, probes[(v, r)] - probes[(BASELINE, r)]) for r in reps if (BASELINE, r) in probes]
        diffs = [d for _, d in paired]
        nonzero = [d for d in diffs if d != 0]
        above = sum(d > 0 for d in diffs)
        walls = list(cost.get(v, {}).values())
        interval = median_interval(diffs) if v != BASELINE else None
        rows.append({
            "variant": v,
            "probed": len(reps),
            "paired": len(paired),
            "above_baseline": above if v != BASELINE else "",
            "median_paired_diff": f"{statistics.median(diffs):.1f}" if diffs and v != BASELINE else "",
            "sign_test_p": f"{sign_test(sum(d > 0 for d in nonzero), len(nonzero)):.4f}" if nonzero else "",
            "median_probe": f"{statistics.median(probes[(v, r)] for r in reps):.1f}" if reps else "",
            "passes": (above >= PASS_AT) if v != BASELINE and len(paired) >= 10 else "",
            "own_wall_s_per_replicate": f"{statistics.median(walls):.0f}" if walls else "",
            "median_diff_lo": f"{interval[0]:.1f}" if interval else "",
            "median_diff_hi": f"{interval[1]:.1f}" if interval else "",
            "interval_coverage": f"{interval[2]:.3f}" if interval else "",
        })
    passing = sorted((r for r in rows if r["passes"] is True), key=lambda r: -float(r["median_paired_diff"]))
    for i, r in enumerate(passing):
        r["to_ppo"] = i < TO_PPO
    return rows


def main(args):
    score = "true_return"
    if args[:1] == ["--score"]:
        score, args = args[1], args[2:]
    if not args:
        sys.exit("usage: idrex pipeline plan FILE | python analysis/screen.py [--score SCORE] STORE_OR_ARCHIVE...")
    stored = {}
    for source in args:
        stored.update(manifests_by_prefix(source))
    rows = screen(plan_nodes(sys.stdin), stored, score)
    fields = ["variant", "probed", "paired", "above_baseline", "median_paired_diff", "sign_test_p",
              "median_probe", "passes", "to_ppo", "own_wall_s_per_replicate",
              "median_diff_lo", "median_diff_hi", "interval_coverage"]
    w = csv.DictWriter(sys.stdout, fieldnames=fields, restval="")
    w.writeheader()
    w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1:])
