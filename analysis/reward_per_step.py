"""A learned reward's pay per step on evaluation rollouts, beside the torso's forward velocity
(issue 53, round 10): for one reward in a store and the evaluation rollouts of the policies it
trained (and BC's), the ensemble's mean raw output per step and the mean forward velocity.
A reward that reads the action too (`trex.action_input`) gets each step's action after its
observation, as T-REX fed it.

Read with Python's `mcap` reader and numpy only (no idrex code).

    python analysis/reward_per_step.py STORE REWARD_KEY EVAL_KEY [EVAL_KEY ...]

(full keys or unique prefixes, from `idrex pipeline plan FILE --store STORE`: `drex/trex`,
`bc/eval`, `drex/eval/0` ...).
"""
import json
import os
import sys

import numpy as np
from mcap.reader import make_reader

from reward_features import safetensors


def resolve(store, key):
    hits = [d for d in os.listdir(store) if d.startswith(key)]
    if len(hits) != 1:
        sys.exit(f"{key}: {len(hits)} artifacts in {store} start with it; give more of the key")
    return f"{store}/{hits[0]}"


def load_reward(path):
    """The ensemble's mean raw output as a function of input rows, and what a row holds."""
    config = json.load(open(f"{path}/reward/reward.json"))
    t = safetensors(f"{path}/reward/reward.safetensors")
    members = sorted({k.split(".")[0] for k in t})
    layers = len({k.split(".")[1] for k in t})
    start = config["config"].get("obs_offset") or 0
    seen = slice(start, start + config["config"]["obs_dim"])
    with_action = bool(config.get("hyper", {}).get("trex", {}).get("action_input"))

    def reward(obs, act):
        x = np.concatenate([obs[:, seen], act], axis=1) if with_action else obs[:, seen]
        outs = []
        for m in members:
            h = x
            for i in range(layers):
                h = h @ t[f"{m}.l{i}.weight"].T + t[f"{m}.l{i}.bias"]
                if i < layers - 1:
                    h = np.maximum(h, 0)
            outs.append(h[:, 0])
        return np.mean(outs, axis=0)

    return reward


def rollout(path):
    """Each step's next observation and action."""
    obs, act = [], []
    with open(f"{path}/rollouts.mcap", "rb") as f:
        for _, _, message in make_reader(f).iter_messages(topics=["/step"]):
            d = json.loads(message.data)
            obs.append(d["next_obs"])
            act.append(d["action"])
    return np.array(obs), np.array(act)


def main():
    store, reward_key, evals = sys.argv[1], sys.argv[2], sys.argv[3:]
    reward = load_reward(resolve(store, reward_key))
    for key in evals:
        obs, act = rollout(resolve(store, key))
        vx = 8 if obs.shape[1] == 17 else 5 if obs.shape[1] == 11 else 13
        print(f"{key[:12]}: reward per step {reward(obs, act).mean():.3f}, forward velocity {obs[:, vx].mean():.2f} m/s")


if __name__ == "__main__":
    main()
