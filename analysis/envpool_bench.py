"""EnvPool's MuJoCo environments, timed the way `idrex bench env` times idrex's.

For each configuration (N environments stepped as one synchronous batch by T threads;
N = 1, T = 1 is one environment on one thread): uniform random actions in [-1, 1],
EnvPool's own auto-reset, a warm-up, then RUNS timed passes of STEPS environment steps
each. Prints one JSON object per configuration: {"env", "num_envs", "threads",
"steps_per_s": [one per run]}. Run by `idrex bench env --envpool PYTHON`, with the Python
of analysis/envpool/env.sh.
"""
import argparse
import json
import time

import envpool
import numpy as np

p = argparse.ArgumentParser()
p.add_argument("--env", required=True)
p.add_argument("--config", action="append", required=True, help="N:T, repeatable")
p.add_argument("--steps", type=int, default=50000)
p.add_argument("--runs", type=int, default=5)
args = p.parse_args()

for config in args.config:
    n, t = (int(x) for x in config.split(":"))
    env = envpool.make(args.env, env_type="gymnasium", num_envs=n, batch_size=n, num_threads=t, seed=0)
    width = env.action_space.shape[0]
    batches = max(1, args.steps // n)
    actions = np.random.default_rng(1).uniform(-1.0, 1.0, size=(batches, n, width))
    env.reset()
    for a in actions[: min(batches, max(1, 2000 // n))]:  # warm-up, as in the Rust pass
        env.step(a)
    rates = []
    for _ in range(args.runs):
        start = time.perf_counter()
        for a in actions:
            env.step(a)
        rates.append(batches * n / (time.perf_counter() - start))
    env.close()
    print(json.dumps({"env": args.env, "num_envs": n, "threads": t, "steps_per_s": rates}))
