"""The reward bench's validation (issue 76, point 3): every D-REX reward the store scored on a
bank, paired with what PPO made of that reward as committed (`results/reward-bench/report/
outcomes.csv`), and the rank correlation of each bank score with D-REX minus BC (true return
and forward term), with a 95 % bootstrap interval over replicates.

Reads the store's manifests only (JSON; no idrex code), numpy for the statistics:

    python analysis/reward_bench.py STORE OUT.csv PIPELINE_FILE... > correlations.csv

(and flags.csv beside OUT.csv: which failures each flag sees.)

The pipeline files are the committed ones whose rewards the store regenerated (as
`outcomes.csv` names them): an outcome is paired with a reward when its file is one of them
and its task, seed set, replicate and learner are the reward's (a file's other variants, or
another file on the same seeds, are other rewards).

A T-REX artifact's seed gives its seed set and replicate (the replicate stride of
`pipeline::config::replicate_seed`); its loss, the learner. Each bank-score names its bank,
whose parameters say the design (1: evenly spaced checkpoints; 2: `first` and `mean`). Where the
store holds a probe of the reward (`bank.probe`), its true return minus BC's is scored too.
"""
import csv
import json
import os
import sys

import numpy as np

STRIDE = 1_000_000_007
OUTCOMES = os.path.join(os.path.dirname(__file__), "results/reward-bench/report/outcomes.csv")


def manifests(store):
    for d in os.listdir(store):
        path = os.path.join(store, d, "manifest.json")
        if os.path.isfile(path):
            with open(path) as f:
                yield json.load(f)


def rank(x):
    order = np.argsort(x, kind="stable")
    r = np.empty(len(x))
    r[order] = np.arange(len(x))
    # Ties share their mean rank.
    for v in np.unique(x):
        at = x == v
        r[at] = r[at].mean()
    return r


def spearman(x, y):
    x, y = rank(np.asarray(x, float)), rank(np.asarray(y, float))
    if x.std() == 0 or y.std() == 0:
        return float("nan")
    return float(np.corrcoef(x, y)[0, 1])


def bootstrap(x, y, resamples=2000, seed=0):
    rng = np.random.default_rng(seed)
    x, y = np.asarray(x, float), np.asarray(y, float)
    stats = []
    for _ in range(resamples):
        i = rng.integers(0, len(x), len(x))
        s = spearman(x[i], y[i])
        if np.isfinite(s):
            stats.append(s)
    return (float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))) if stats else (float("nan"),) * 2


def learner(trex, by_key):
    """The learner as `outcomes.csv` writes it: T-REX's loss and observation, then the ranked
    set's settings that a variant changed (absent from the noise stage's parameters unless set)."""
    t = trex["params"]["trex"]
    parts = [t.get("loss", "ranking")]
    if t.get("observation", "all") != "all":
        parts.append("trex.observation=" + t["observation"])
    noise = by_key.get(trex["inputs"].get("set0"), {}).get("params", {})
    for field in ("horizon", "still"):
        if field in noise:
            parts.append(f"noise.{field}={noise[field]}")
    return "; ".join(parts)


def main(store, out, files):
    by_key = {m["key"]: m for m in manifests(store)}
    # The probe of each reward (`bank.probe`): a short PPO run's true return, last quarter.
    # With the final policy's forward term per episode, for a task that ends (moving or living).
    # Probes made by earlier versions of the stage may share the store: the newest version wins
    # (before it rolled its final policy out, a probe had no final_forward).
    probed = sorted((m for m in by_key.values() if m["kind"] == "probe"), key=lambda m: (m["version"], "final_forward" in m["metrics"]))
    probes = {m["inputs"]["reward"]: m["metrics"] for m in probed}
    outcomes = list(csv.DictReader(open(OUTCOMES)))
    rows = []
    for m in by_key.values():
        if m["kind"] != "bank-score" or not m["node"].endswith("drex/trex/bank-score"):
            continue
        trex, bank = by_key.get(m["inputs"]["reward"]), by_key.get(m["inputs"]["bank"])
        if trex is None or bank is None:
            continue
        env = trex["params"]["env"]
        seed = trex["seed"]
        base, r = seed % STRIDE, seed // STRIDE
        design = 2 if bank["params"].get("mean", 0) > 0 else 1
        loss = learner(trex, by_key)
        # The committed outcomes of this reward: same task, seed set, replicate and learner.
        matches = [
            o for o in outcomes
            if o["env"] == env and o["seed_set"].split("-")[0] == str(base) and int(o["replicate"]) == r
            and o["learner"] == loss and o["pipeline_file"] in files
        ]
        s = m["metrics"]
        overpaid = sum(s["overpaid"])
        for o in matches:
            bc, dr = float(o["bc_return"] or "nan"), float(o["drex_return"] or "nan")
            bf, df = float(o["bc_forward"] or "nan"), float(o["drex_forward"] or "nan")
            rows.append({
                "env": env, "seed_set": o["seed_set"], "replicate": r, "learner": o["learner"], "design": design,
                "reward": trex["key"][:12], "spearman": s["spearman"], "forward_spearman": s["forward_spearman"],
                "overpaid": overpaid, "misordered": s["misordered"], "flags": int(overpaid > 0 or s["forward_spearman"] < 0.5),
                "probe_minus_bc": probes.get(trex["key"], {}).get("true_return", float("nan")) - bc, "minus_bc": -bc,
                "probe_forward_minus_bc": probes.get(trex["key"], {}).get("final_forward", float("nan")) - bf,
                "minus_bc_forward": -bf,
                "probe_return": probes.get(trex["key"], {}).get("true_return", float("nan")),
                "probe_forward": probes.get(trex["key"], {}).get("final_forward", float("nan")),
                "drex_return": dr, "drex_forward": df,
                "drex_minus_bc": dr - bc, "forward_minus_bc": df - bf, "pipeline_file": o["pipeline_file"],
                "notes": o["notes"][:120],
            })
    # One row per (reward, design, outcome): an outcome row repeated in two committed files is kept once.
    seen, unique = set(), []
    for r in rows:
        k = (r["reward"], r["design"], r["pipeline_file"], round(r["drex_minus_bc"], 6))
        if k not in seen:
            seen.add(k)
            unique.append(r)
    unique.sort(key=lambda r: (r["design"], r["env"], r["seed_set"], r["replicate"], r["learner"]))
    if unique:
        with open(out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(unique[0].keys()) if unique else ["env"])
            w.writeheader()
            w.writerows(unique)
    print("design,env,n,score,outcome,spearman,ci_low,ci_high")
    for design in (1, 2):
        for env in sorted({r["env"] for r in unique}):
            sub = [r for r in unique if r["design"] == design and r["env"] == env and np.isfinite(r["drex_minus_bc"])]
            if len(sub) < 3:
                continue
            # minus_bc and minus_bc_forward, BC's return and forward term alone: the controls for
            # probe_minus_bc and probe_forward_minus_bc (a score and its outcome share "minus BC").
            scores = ("spearman", "forward_spearman", "misordered", "probe_minus_bc", "probe_forward_minus_bc", "minus_bc", "minus_bc_forward", "probe_return", "probe_forward")
            for score in scores:
                # The raw pairs (a probe's return against D-REX's own, no BC subtracted from either)
                # ask whether the probe sees the gait PPO will find, free of the shared BC term.
                raw = {"probe_return": ("drex_return",), "probe_forward": ("drex_forward",)}
                for outcome in raw.get(score, ("drex_minus_bc", "forward_minus_bc")):
                    pairs = [(r[score], r[outcome]) for r in sub if np.isfinite(r[outcome]) and np.isfinite(r[score])]
                    if len(pairs) < 3:
                        continue
                    x, y = zip(*pairs)
                    lo, hi = bootstrap(x, y)
                    print(f"{design},{env},{len(pairs)},{score},{outcome},{spearman(x, y):.3f},{lo:.3f},{hi:.3f}")

    # Which failures each flag sees (design 1's bank; the probe is the same on both designs):
    # a failure is D-REX below BC at the end, by the true return or by the forward term.
    # Written beside OUT as flags.csv (stdout keeps the correlations).
    lines = ["env,flag,outcome,failures_flagged,failures,false_alarms,others"]
    flags = {
        "bank": lambda r: r["flags"] == 1,
        "probe": lambda r: r["probe_minus_bc"] < 0,
        "probe_forward": lambda r: r["probe_forward_minus_bc"] < 0,
    }
    for env in sorted({r["env"] for r in unique}):
        for name, flag in flags.items():
            for outcome in ("drex_minus_bc", "forward_minus_bc"):
                sub = [r for r in unique if r["design"] == 1 and r["env"] == env and np.isfinite(r[outcome])]
                if name != "bank":
                    sub = [r for r in sub if np.isfinite(r[name + "_minus_bc"])]
                if not sub:
                    continue
                fails = [r for r in sub if r[outcome] < 0]
                hit = sum(flag(r) for r in fails)
                false = sum(flag(r) for r in sub if r[outcome] >= 0)
                lines.append(f"{env},{name},{outcome},{hit},{len(fails)},{false},{len(sub) - len(fails)}")
    with open(os.path.join(os.path.dirname(out), "flags.csv"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
