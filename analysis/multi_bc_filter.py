"""How multi-BC's clone filters decide, judged with the ground truth (which no stage reads).

For every multi-BC rollout stage in a store (stage version 4: fidelity recorded), each
clone's noise-free true return is compared with the true return of the set the filter
compares it with (the newest earlier set's least noisy rollouts). A rule that measures what it
claims keeps the clones above that return and rejects those below. The three rules:
`none` keeps every clone; `previous-reward` keeps a clone whose per-step score under the
reward its source was trained on is >= 0; `held-out-reward` (the default) the same under the
judge, a reward trained on the same sets from independent seeds.

    python3 analysis/multi_bc_filter.py [STORE] [--nodes SUBSTRING ...]
"""
import glob
import json
import os
import sys


def mean(v):
    return sum(v) / len(v) if v else float("nan")


def main():
    args = sys.argv[1:]
    store = args[0] if args and not args[0].startswith("--") else "artifacts"
    only = args[args.index("--nodes") + 1:] if "--nodes" in args else []
    manifests = {}
    for f in glob.glob(os.path.join(store, "*", "manifest.json")):
        m = json.load(open(f))
        manifests[m["key"]] = m
    rules = {"none": lambda c: True, "previous-reward": lambda c: (c.get("previous_reward_score") or 0) >= 0,
             "held-out-reward": lambda c: (c.get("score") if c.get("score") is not None else 0) >= 0}
    tally = {}
    print("| stage | clone | source return | clone return | baseline return | fidelity | judge score | previous-reward score | kept |")
    print("|---|---|---|---|---|---|---|---|---|")
    for m in sorted(manifests.values(), key=lambda m: m["node"]):
        if m["kind"] != "multi-bc-rollouts" or m["version"] < 4 or (only and not any(s in m["node"] for s in only)):
            continue
        x = m["metrics"]
        base_key = m["inputs"].get("baseline%d" % (x["baseline_set"] or 0))
        levels = manifests[base_key]["metrics"]["degradation"] if base_key in manifests else []
        base = min(levels, key=lambda l: l["noise"])["mean"] if levels else float("nan")
        env = m["node"].split("/")[0]
        for c in x["clones"]:
            f = c["fidelity"]
            above = mean(f["clone_returns"]) >= base
            fid = f["normalised"]
            print("| %s | %d | %.1f | %.1f | %.1f | %s | %s | %s | %s |" % (
                m["node"], c["clone"], mean(f["source_returns"]), mean(f["clone_returns"]), base,
                "-" if fid is None else "%.2f" % fid,
                "-" if c["score"] is None else "%.2f" % c["score"],
                "-" if c.get("previous_reward_score") is None else "%.2f" % c["previous_reward_score"],
                "yes" if c["kept"] else "no"))
            for name, keep in rules.items():
                t = tally.setdefault((env, name), [0, 0, 0, 0])
                t[(0 if keep(c) else 2) + (0 if above else 1)] += 1
    print()
    print("| env | rule | kept above | kept below | rejected above | rejected below |")
    print("|---|---|---|---|---|---|")
    for (env, name), t in sorted(tally.items()):
        print("| %s | %s | %d | %d | %d | %d |" % (env, name, *t))


if __name__ == "__main__":
    main()
