"""Gymnasium's own environment, timed the way `idrex bench env` times ours.

Random uniform actions in [-1, 1], reset on termination or truncation; prints
{"env": ..., "steps": ..., "steps_per_s": ...}. Run by `idrex bench env`.
"""
import argparse
import json
import time

import gymnasium as gym
import numpy as np

p = argparse.ArgumentParser()
p.add_argument("--env", required=True)
p.add_argument("--steps", type=int, default=20000)
args = p.parse_args()

env = gym.make(args.env)
rng = np.random.default_rng(0)
actions = rng.uniform(-1.0, 1.0, size=(args.steps,) + env.action_space.shape)
env.reset(seed=0)
for a in actions[: min(2000, args.steps)]:  # warm-up, as in the Rust pass
    _, _, term, trunc, _ = env.step(a)
    if term or trunc:
        env.reset()
env.reset(seed=0)
start = time.perf_counter()
for a in actions:
    _, _, term, trunc, _ = env.step(a)
    if term or trunc:
        env.reset()
elapsed = time.perf_counter() - start
print(json.dumps({"env": args.env, "steps": args.steps, "steps_per_s": args.steps / elapsed}))
