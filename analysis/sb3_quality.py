"""PPO quality beside a peer: Stable-Baselines3 (2.9.2) trained on the ground-truth reward with
the settings `analysis/bench_ppo.py` gives it (CleanRL's continuous-action PPO, the settings
idrex's PPO uses), then its final stochastic policy's mean return over 20 episodes, the number
`analysis/ppo_quality.sh` reports for idrex. Answers: is idrex's PPO return on a task (Ant-v5)
what a standard PPO reaches at the same budget?

SB3 comes from the same cache `bench_ppo.py` installs it into; one thread.

Usage: python analysis/sb3_quality.py --env Ant-v5 --steps 1000000 --seed 0
Prints one JSON line.
"""
import argparse
import json
import os
import sys
import time

p = argparse.ArgumentParser()
p.add_argument("--env", default="Ant-v5")
p.add_argument("--steps", type=int, default=1_000_000)
p.add_argument("--seed", type=int, default=0)
p.add_argument("--episodes", type=int, default=20)
args = p.parse_args()

sb3_dir = os.path.expanduser(os.environ.get("IDREX_CACHE", "~/.cache/idrex")) + "/sb3-2.9.2"
if not os.path.isdir(os.path.join(sb3_dir, "stable_baselines3")):
    sys.exit(f"Stable-Baselines3 is not in {sb3_dir}: run analysis/bench_ppo.py --sb3-only once to install it")
sys.path.insert(0, sb3_dir)

import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

torch.set_num_threads(1)
env = VecNormalize(make_vec_env(args.env, n_envs=1, seed=args.seed), gamma=0.99, clip_obs=10.0, clip_reward=10.0)
model = PPO(
    "MlpPolicy", env, n_steps=2048, batch_size=64, n_epochs=10, learning_rate=lambda f: 3e-4 * f,
    gamma=0.99, gae_lambda=0.95, clip_range=0.2, clip_range_vf=0.2, ent_coef=0.0, vf_coef=0.5,
    max_grad_norm=0.5, normalize_advantage=True, device="cpu", seed=args.seed,
    policy_kwargs=dict(net_arch=dict(pi=[64, 64], vf=[64, 64]), activation_fn=torch.nn.Tanh,
                       log_std_init=0.0, ortho_init=True),
)
start = time.perf_counter()
model.learn(total_timesteps=args.steps)
train_s = time.perf_counter() - start

# The final stochastic policy on the true reward, observation statistics frozen.
env.training = False
env.norm_reward = False
env.seed(args.seed + 100)
obs = env.reset()
returns, lengths, ret, length = [], [], 0.0, 0
while len(returns) < args.episodes:
    action, _ = model.predict(obs, deterministic=False)
    obs, _, done, info = env.step(action)
    ret += float(env.get_original_reward()[0])
    length += 1
    if done[0]:
        returns.append(ret)
        lengths.append(length)
        ret, length = 0.0, 0
print(json.dumps({"library": "stable-baselines3 2.9.2", "env": args.env, "steps": args.steps, "seed": args.seed,
                  "train_s": train_s, "episodes": args.episodes, "mean": float(np.mean(returns)),
                  "std": float(np.std(returns)), "mean_length": float(np.mean(lengths))}))
