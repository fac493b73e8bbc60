"""Replays actions in Gymnasium's own environment; the reference side of the equivalence test.

Same interface and output as `idrex env rollout`: start from STATE.json ({"qpos", "qvel"})
via the env's set_state, step through ACTIONS.csv (one action per line), print one JSON line
per step with obs, reward, terminated, truncated and the reward terms; stop after the episode
ends.
"""
import argparse
import json

import gymnasium as gym
import numpy as np

p = argparse.ArgumentParser()
p.add_argument("--env", required=True)
p.add_argument("--state", required=True)
p.add_argument("--actions", required=True)
args = p.parse_args()

# idrex's names for Gymnasium's tasks made with options other than their defaults.
OPTIONS = {"Ant-v5-no-cfrc": ("Ant-v5", {"include_cfrc_ext_in_observation": False})}
gym_id, options = OPTIONS.get(args.env, (args.env, {}))
env = gym.make(gym_id, **options)
env.reset(seed=0)  # starts the TimeLimit counter; the state is then overwritten
with open(args.state) as f:
    state = json.load(f)
env.unwrapped.set_state(np.array(state["qpos"]), np.array(state["qvel"]))
actions = np.loadtxt(args.actions, delimiter=",", ndmin=2)
for t, a in enumerate(actions):
    obs, reward, term, trunc, info = env.step(a)
    # Ant's contact cost; the planar tasks have none.
    contact = {"reward_contact": float(info["reward_contact"])} if "reward_contact" in info else {}
    print(json.dumps({
        "step": t,
        "obs": obs.tolist(),
        "reward": float(reward),
        "terminated": bool(term),
        "truncated": bool(trunc),
        "reward_forward": float(info["reward_forward"]),
        "reward_ctrl": float(info["reward_ctrl"]),
        "reward_survive": float(info.get("reward_survive", 0.0)),
        "x_position": float(info["x_position"]),
        "x_velocity": float(info["x_velocity"]),
        **contact,
    }))
    if term or trunc:
        break
