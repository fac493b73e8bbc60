"""Why BC does or does not clone its demonstrations (issue 53's diagnosis), per BC in a store:

- the demonstrations' and BC's final-policy evaluation episodes split into the task's reward
  terms (forward, control, healthy, contact) with episode length;
- the demonstrations' action statistics (mean |a|, the fraction of values outside the box);
- BC's action error on the demonstration's own states (RMS over steps and dimensions) against
  the recorded actions and, where the demonstrator is in the store, against the
  demonstrator's mean action (the noise-free label), beside the noise floor (recorded against
  mean) and BC's error against that mean on the states BC itself visits;
- drift: each state BC visits, its distance to the nearest demonstration state (observation
  dimensions scaled by the demonstrations' standard deviation), over the same distance for a
  demonstration state to the nearest one at least 20 steps away in time (or in another
  episode): 1 means BC stays as close to the demonstrations as they are to themselves.

Imported NPZ demonstrations carry no terms: control is recomputed from the actions with the
task's weight (unclipped, as the v2 environments charged it), healthy as one per step where the
task pays it, forward as the rest.

Everything is read from the store with Python's `mcap` reader and numpy (no idrex code): the
policies' safetensors and policy.json are evaluated here.

    python analysis/demo_diagnosis.py STORE [--json OUT.json] [--markdown OUT.md]
"""
import argparse
import glob
import json
import math
import os
import struct
import sys
from collections import defaultdict

import numpy as np
from mcap.reader import make_reader

CTRL = {"HalfCheetah-v5": 0.1, "Hopper-v5": 1e-3, "Walker2d-v5": 1e-3, "Ant-v5": 0.5}
HEALTHY = {"HalfCheetah-v5": 0.0, "Hopper-v5": 1.0, "Walker2d-v5": 1.0, "Ant-v5": 1.0}
TERMS = ["reward_forward", "reward_ctrl", "reward_survive", "reward_contact"]
GAP = 20  # steps: a demonstration state's reference neighbour is at least this far in time


def read_rollouts(path):
    """Episodes as dicts of numpy arrays: obs (T+1 rows), actions, rewards, terms (T x 4)."""
    eps = defaultdict(lambda: {"obs": [], "actions": [], "rewards": [], "terms": [], "next": None})
    env = None
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _s, _c, m in reader.iter_messages(topics=["/step"]):
            s = json.loads(m.data)
            e = eps[s["episode"]]
            e["obs"].append(s["obs"])
            e["actions"].append(s["action"])
            e["rewards"].append(s["reward"])
            e["terms"].append([s.get(t, 0.0) for t in TERMS])
            e["next"] = s["next_obs"]
        for meta in reader.iter_metadata():
            if meta.name == "idrex.rollout":
                env = meta.metadata.get("env")
    out = []
    for k in sorted(eps):
        e = eps[k]
        out.append({
            "obs": np.array(e["obs"] + [e["next"]], dtype=np.float64),
            "actions": np.array(e["actions"], dtype=np.float64),
            "rewards": np.array(e["rewards"]),
            "terms": np.array(e["terms"]),
        })
    return env, out


def split_terms(env, eps, imported):
    """Mean per episode of each term, the total and the length."""
    rows = []
    for e in eps:
        t = e["terms"].sum(axis=0)
        n = len(e["rewards"])
        if imported or not np.any(e["terms"]):
            ctrl = -CTRL[env] * float((e["actions"] ** 2).sum())
            healthy = HEALTHY[env] * n
            t = np.array([e["rewards"].sum() - ctrl - healthy, ctrl, healthy, 0.0])
        rows.append(list(t) + [e["rewards"].sum(), n])
    r = np.array(rows).mean(axis=0)
    return dict(zip(["forward", "control", "healthy", "contact", "total", "length"], map(float, r)))


def load_safetensors(path):
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        data = f.read()
    out = {}
    for name, h in header.items():
        if name == "__metadata__":
            continue
        a, b = h["data_offsets"]
        dt = {"F32": np.float32, "F64": np.float64}[h["dtype"]]
        out[name] = np.frombuffer(data[a:b], dtype=dt).reshape(h["shape"]).astype(np.float64)
    return out


class Policy:
    """The actor's mean action: observation normalisation (clipped), then the MLP."""

    def __init__(self, d):
        side = json.load(open(os.path.join(d, "policy.json")))
        w = load_safetensors(os.path.join(d, "policy.safetensors"))
        self.act = side["config"].get("activation", "tanh").lower()
        self.layers = []
        i = 0
        while f"actor.l{i}.weight" in w or f"actor.{i}.weight" in w:
            k = f"actor.l{i}" if f"actor.l{i}.weight" in w else f"actor.{i}"
            self.layers.append((w[k + ".weight"], w[k + ".bias"]))
            i += 1
        if not self.layers:
            raise SystemExit(f"{d}: no actor layers among {sorted(w)}")
        n = side.get("obs_norm")
        self.norm = None if n is None else (np.array(n["mean"]), np.array(n["var"]), float(side.get("obs_clip", 10.0)))

    def mean(self, obs):
        x = obs
        if self.norm is not None:
            m, v, c = self.norm
            x = np.clip((x - m) / np.sqrt(v + 1e-8), -c, c)
        for j, (W, b) in enumerate(self.layers):
            x = x @ W.T + b
            if j + 1 < len(self.layers):
                x = np.tanh(x) if self.act == "tanh" else np.maximum(x, 0.0)
        return x


def rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def nearest(q, ref, chunk=2048):
    """Distance from each row of q to its nearest row of ref."""
    out = np.empty(len(q))
    rr = (ref ** 2).sum(1)
    for i in range(0, len(q), chunk):
        x = q[i:i + chunk]
        d2 = (x ** 2).sum(1)[:, None] - 2 * x @ ref.T + rr[None, :]
        out[i:i + chunk] = np.sqrt(np.maximum(d2.min(1), 0.0))
    return out


def drift(demo_eps, bc_eps):
    """BC's nearest-demonstration distance over the demonstrations' own (GAP steps apart)."""
    demo = np.concatenate([e["obs"][:-1] for e in demo_eps])
    scale = demo.std(0)
    scale[scale < 1e-6] = 1.0
    z = demo / scale
    ep = np.concatenate([np.full(len(e["obs"]) - 1, i) for i, e in enumerate(demo_eps)])
    t = np.concatenate([np.arange(len(e["obs"]) - 1) for e in demo_eps])
    rr = (z ** 2).sum(1)
    d2 = rr[:, None] - 2 * z @ z.T + rr[None, :]
    near = (ep[:, None] == ep[None, :]) & (np.abs(t[:, None] - t[None, :]) < GAP)
    d2[near] = np.inf
    self_d = np.sqrt(np.maximum(d2.min(1), 0.0))
    bc = np.concatenate([e["obs"][:-1] for e in bc_eps]) / scale
    bc_d = nearest(bc, z)
    return {"demo_self": float(np.mean(self_d)), "bc": float(np.mean(bc_d)), "ratio": float(np.mean(bc_d) / np.mean(self_d)),
            "bc_first100": float(np.mean(nearest(np.concatenate([e["obs"][:100] for e in bc_eps]) / scale, z)) / np.mean(self_d))}


def markdown(results):
    """One row per BC: the demonstrations', then BC's, return and terms, and the cloning error."""
    f = lambda x: "-" if x is None else f"{x:.1f}"
    g = lambda x: "-" if x is None else f"{x:.2f}"
    out = ["| env | pipeline | rep | demos: return (forward, control, healthy; length) | mean abs a, outside box | BC: return (forward, control, healthy; length) | BC / demos | BC error vs recorded | noise floor | BC error vs demonstrator mean (on its states) | drift |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        d, b = r["demo_terms"], r["bc_terms"]
        terms = lambda t: f"{f(t['total'])} ({f(t['forward'])}, {f(t['control'])}, {f(t['healthy'])}; {t['length']:.0f})"
        ratio = b["total"] / d["total"] if d["total"] > 0 else None
        out.append(f"| {r['env']} | {r['pipeline']} | {r['replicate']} | {terms(d)} | {g(r['demo_actions']['mean_abs'])}, {100 * r['demo_actions']['outside_box']:.0f} % | {terms(b)} | {g(ratio)} | {g(r['bc_error_vs_recorded'])} | {g(r.get('noise_floor'))} | {g(r.get('bc_error_vs_demonstrator_mean'))} ({g(r.get('bc_error_vs_demonstrator_mean_on_bc_states'))}) | {g(r['drift']['ratio'])} |")
    return "\n".join(out) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store")
    ap.add_argument("--json")
    ap.add_argument("--markdown")
    args = ap.parse_args()
    man = {}
    for m in glob.glob(os.path.join(args.store, "*", "manifest.json")):
        j = json.load(open(m))
        man[j["key"]] = j
    results = []
    for key, j in sorted(man.items(), key=lambda kv: kv[1]["node"]):
        if j["kind"] != "eval" or j["params"].get("method") != "bc":
            continue
        bc_key = j["inputs"].get("policy")
        bc = man.get(bc_key)
        if bc is None or bc["kind"] != "bc":
            continue
        demos = man.get(bc["inputs"].get("demos"))
        if demos is None:
            continue
        env, demo_eps = read_rollouts(os.path.join(args.store, demos["key"], "rollouts.mcap"))
        _, bc_eps = read_rollouts(os.path.join(args.store, key, "rollouts.mcap"))
        imported = demos["kind"] != "demos"
        pol = Policy(os.path.join(args.store, bc_key, "policy"))
        d_obs = np.concatenate([e["obs"][:-1] for e in demo_eps])
        d_act = np.concatenate([e["actions"] for e in demo_eps])
        bc_on_demo = pol.mean(d_obs)
        r = {
            "env": env,
            "pipeline": j["params"].get("pipeline"),
            "replicate": j["params"].get("replicate", 0),
            "demos": "D-REX's (imported)" if imported else "idrex's own",
            "demo_terms": split_terms(env, demo_eps, imported),
            "bc_terms": split_terms(env, bc_eps, False),
            "demo_actions": {"mean_abs": float(np.abs(d_act).mean()), "outside_box": float((np.abs(d_act) > 1.0).mean())},
            "bc_error_vs_recorded": rms(np.clip(bc_on_demo, -1, 1), np.clip(d_act, -1, 1)),
            "drift": drift(demo_eps, bc_eps),
        }
        dem = man.get(demos["inputs"].get("policy", "")) if not imported else None
        if dem is not None:
            dp = Policy(os.path.join(args.store, dem["key"], "policy"))
            mean_on_demo = np.clip(dp.mean(d_obs), -1, 1)
            bc_obs = np.concatenate([e["obs"][:-1] for e in bc_eps])
            std = np.exp(load_safetensors(os.path.join(args.store, dem["key"], "policy", "policy.safetensors"))["log_std"])
            r["demonstrator_std"] = float(std.mean())
            # The Gaussian's mass outside [-1, 1] at the demonstration's states: how often a
            # sampled action would leave the box before clipping (D-REX's recorded 18 %).
            m = dp.mean(d_obs)
            phi = np.vectorize(lambda z: 0.5 * (1.0 + math.erf(z / math.sqrt(2.0))))
            r["demonstrator_outside_box"] = float(((1.0 - phi((1.0 - m) / std)) + phi((-1.0 - m) / std)).mean())
            r["noise_floor"] = rms(np.clip(d_act, -1, 1), mean_on_demo)
            r["bc_error_vs_demonstrator_mean"] = rms(np.clip(bc_on_demo, -1, 1), mean_on_demo)
            r["bc_error_vs_demonstrator_mean_on_bc_states"] = rms(np.clip(pol.mean(bc_obs), -1, 1), np.clip(dp.mean(bc_obs), -1, 1))
        results.append(r)
    results.sort(key=lambda r: (r["env"], r["pipeline"], r["replicate"]))
    if args.json:
        json.dump(results, open(args.json, "w"), indent=1)
    table = markdown(results)
    print(table)
    if args.markdown:
        open(args.markdown, "w").write(table)
    if not results:
        sys.exit(f"{args.store}: no BC evaluation with its BC and demonstrations stored")


if __name__ == "__main__":
    main()
