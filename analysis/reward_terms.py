"""What a store's policies are paid for: each method's evaluation episodes (final policies)
and demonstrations split into the environment's reward terms (forward, survive, control and
contact cost), with episode length, net forward displacement (forward reward x dt, for a
forward weight of 1) and the learned return; and, pooled
over the final policies' episodes, what the learned return correlates with.

Read with Python's `mcap` reader from the stored rollouts.mcap files, as a user would.

    python analysis/reward_terms.py runs/ant-store [--pipeline NAME] [--csv OUT.csv]
"""
import argparse
import csv
import glob
import json
import os
import re
import sys
from collections import defaultdict

from mcap.reader import make_reader

from checkpoints import pearson  # this folder's, one definition

TERMS = ["reward_forward", "reward_survive", "reward_ctrl", "reward_contact"]


def episodes(path):
    """Per episode: the sum of every reward term, the learned return where the file has one,
    and the length."""
    dt = None
    eps = defaultdict(lambda: defaultdict(float))
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(topics=["/step"]):
            s = json.loads(message.data)
            e = eps[s["episode"]]
            e["length"] += 1
            e["reward"] += s["reward"]
            for t in TERMS:
                e[t] += s.get(t, 0.0)
            if s.get("truncated"):
                e["truncated"] = 1
            if "learned_reward" in s:
                e["learned"] += s["learned_reward"]
                e["has_learned"] = 1
        for meta in reader.iter_metadata():
            if meta.name == "idrex.rollout":
                dt = float(meta.metadata["dt"])
    if dt is None:
        raise SystemExit(f"{path}: no idrex.rollout metadata with dt")
    out = []
    for k in sorted(eps):
        e = dict(eps[k])
        e["displacement"] = e["reward_forward"] * dt
        out.append(e)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store")
    ap.add_argument("--pipeline")
    ap.add_argument("--csv")
    args = ap.parse_args()

    groups = defaultdict(list)  # (pipeline, method) -> episodes
    for m in sorted(glob.glob(os.path.join(args.store, "*", "manifest.json"))):
        j = json.load(open(m))
        node = j["node"]
        rep = re.match(r"r(\d+)/", node)
        pipeline = j["params"].get("pipeline")
        if j["kind"] == "eval":
            method = j["params"]["method"]
            it = j["params"].get("iteration", 1)
            label = method if method in ("bc", "drex") else f"{method} K={it}"
        elif j["kind"] == "demos":
            # Demos carry no pipeline name; the eval manifests that read them do.
            label, pipeline = "demos", None
        else:
            continue
        path = os.path.join(os.path.dirname(m), "rollouts.mcap")
        if os.path.exists(path):
            eps = episodes(path)
            for e in eps:
                e["replicate"] = int(rep.group(1)) if rep else 0
            groups[(pipeline, label, j["key"])] = eps

    # Attribute demos to the pipeline whose evaluations read them.
    demos_of = {}
    for m in glob.glob(os.path.join(args.store, "*", "manifest.json")):
        j = json.load(open(m))
        if j["kind"] == "eval" and "demos" in j["inputs"]:
            demos_of[j["inputs"]["demos"]] = j["params"].get("pipeline")
    merged = defaultdict(list)
    for (pipeline, label, key), eps in groups.items():
        if label == "demos":
            pipeline = demos_of.get(key)
            if pipeline is None:
                continue
        if args.pipeline and pipeline != args.pipeline:
            continue
        merged[(pipeline, label)].extend(eps)

    cols = ["length", "reward", "reward_forward", "reward_survive", "reward_ctrl", "reward_contact", "displacement", "learned"]
    rows = []
    for (pipeline, label), eps in sorted(merged.items(), key=lambda kv: (str(kv[0][0]), kv[0][1])):
        n = len(eps)
        row = {"pipeline": pipeline, "source": label, "episodes": n}
        for c in cols:
            vals = [e.get(c, 0.0) for e in eps]
            row[c] = sum(vals) / n if (c != "learned" or all(e.get("has_learned") for e in eps)) else None
        row["time_limit"] = sum(e.get("truncated", 0) for e in eps) / n
        rows.append(row)

    hdr = ["pipeline", "source", "episodes", "length", "time_limit", "reward", "reward_forward", "reward_survive",
           "reward_ctrl", "reward_contact", "displacement", "learned"]
    print("| " + " | ".join(hdr) + " |")
    print("|" + "---|" * len(hdr))
    for r in rows:
        print("| " + " | ".join(
            "-" if r[h] is None else (f"{r[h]:.2f}" if isinstance(r[h], float) else str(r[h])) for h in hdr) + " |")

    # What the learned return tracks, over the final policies' evaluation episodes (unseen by
    # T-REX), pooled per pipeline and method.
    print()
    print("| pipeline | method | episodes | learned vs true return | vs forward | vs survive (length) | vs displacement |")
    print("|---|---|---|---|---|---|---|")
    for (pipeline, label), eps in sorted(merged.items(), key=lambda kv: (str(kv[0][0]), kv[0][1])):
        if not all(e.get("has_learned") for e in eps) or len(eps) < 3:
            continue
        le = [e["learned"] for e in eps]
        print(f"| {pipeline} | {label} | {len(eps)} | "
              + " | ".join(f"{pearson(le, [e[c] for e in eps]):.3f}" for c in ["reward", "reward_forward", "reward_survive", "displacement"])
              + " |")

    # Per replicate (the unit of replication: a replicate's runs share its seeds and reward),
    # each method's mean forward reward per episode, and against BC paired by replicate.
    print()
    print("| pipeline | source | forward reward per episode, replicates 0.. | above BC's (paired) |")
    print("|---|---|---|---|")
    for (pipeline, label), eps in sorted(merged.items(), key=lambda kv: (str(kv[0][0]), kv[0][1])):
        reps = sorted({e["replicate"] for e in eps})
        fwd = {r: sum(e["reward_forward"] for e in eps if e["replicate"] == r) / sum(e["replicate"] == r for e in eps) for r in reps}
        bc = merged.get((pipeline, "bc"), [])
        vs = "-"
        if label not in ("bc", "demos") and bc:
            bc_reps = sorted({e["replicate"] for e in bc} & set(reps))
            bc_fwd = {r: sum(e["reward_forward"] for e in bc if e["replicate"] == r) / sum(e["replicate"] == r for e in bc) for r in bc_reps}
            ties = sum(fwd[r] == bc_fwd[r] for r in bc_reps)
            vs = f"{sum(fwd[r] > bc_fwd[r] for r in bc_reps)} of {len(bc_reps) - ties}" + (f", {ties} ties" if ties else "")
        print(f"| {pipeline} | {label} | " + ", ".join(f"{fwd[r]:.1f}" for r in reps) + f" | {vs} |")

    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=hdr)
            w.writeheader()
            for r in rows:
                w.writerow({h: r[h] for h in hdr})


if __name__ == "__main__":
    sys.exit(main())
