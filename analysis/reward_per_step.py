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

from reward_features import forward_velocity_entry, load_reward


def resolve(store, key):
    """The one artifact whose key starts with `key`."""
    hits = [d for d in os.listdir(store) if d.startswith(key)]
    if len(hits) != 1:
        sys.exit(f"{key}: {len(hits)} artifacts in {store} start with it; give more of the key")
    return hits[0]


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
    reward = load_reward(store, resolve(store, reward_key))
    for key in evals:
        obs, act = rollout(f"{store}/{resolve(store, key)}")
        vx = forward_velocity_entry(obs.shape[1])
        print(f"{key[:12]}: reward per step {reward(obs, act).mean():.3f}, forward velocity {obs[:, vx].mean():.2f} m/s")


if __name__ == "__main__":
    main()
