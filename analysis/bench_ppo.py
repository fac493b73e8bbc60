"""PPO speed: idrex against Stable-Baselines3 (2.9.2), same machine, same settings.

Both run CleanRL's continuous-action settings: one environment, 2048-step rollouts, 32
minibatches (64 samples), 10 epochs, lr 3e-4 linearly annealed, gamma 0.99, GAE 0.95, clip
0.2 (policy and value), entropy 0, vf 0.5, grad-norm 0.5, separate 64-64 tanh actor and
critic, state-independent log-std, orthogonal init, observation and return normalisation
(clipped to +-10), actions clipped to the box, one thread each (torch.set_num_threads(1)
for SB3, --threads 1 for idrex).

SB3 is installed on first use (with --no-deps, into ~/.cache/idrex/sb3-2.9.2, next to the
bootstrap environment's torch and gymnasium); nothing else is changed.

Usage: python analysis/bench_ppo.py [--env HalfCheetah-v5] [--steps 100000] [--idrex PATH] [--sb3-only]
Prints one JSON line per library and the ratio (`--sb3-only`: Stable-Baselines3's line alone,
as `idrex bench ppo` runs it).
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

p = argparse.ArgumentParser()
p.add_argument("--env", default="HalfCheetah-v5")
p.add_argument("--steps", type=int, default=100_000)
p.add_argument("--idrex", default=None, help="the idrex binary (default: the release build)")
p.add_argument("--sb3-only", action="store_true", help="time Stable-Baselines3 alone (idrex bench ppo runs it so)")
args = p.parse_args()

repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
idrex_sps = None
if not args.sb3_only:
    binary = args.idrex
    if binary is None:
        meta = json.loads(subprocess.check_output(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=repo))
        binary = os.path.join(meta["target_directory"], "release", "idrex")

    # --- idrex ---------------------------------------------------------------------------
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        text = subprocess.check_output(
            [binary, "train", "ppo", "--env", args.env, "--steps", str(args.steps), "--seed", "0", "--out", out,
             "--eval-every", "0", "--checkpoint-every", "0", "--threads", "1"], text=True)
        idrex_wall = time.perf_counter() - start
    m = re.search(r"in ([0-9.]+) s \((\d+) steps/s\)", text)
    idrex_sps = float(m.group(2))
    print(json.dumps({"library": "idrex", "env": args.env, "steps": args.steps, "train_s": float(m.group(1)),
                      "process_wall_s": idrex_wall, "steps_per_s": idrex_sps}))

# --- Stable-Baselines3 ---------------------------------------------------------------------
sb3_dir = os.path.expanduser(os.environ.get("IDREX_CACHE", "~/.cache/idrex")) + "/sb3-2.9.2"
if not os.path.isdir(os.path.join(sb3_dir, "stable_baselines3")):
    subprocess.check_call([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", sb3_dir,
                           "stable-baselines3==2.9.2", "pandas", "python-dateutil", "pytz", "tzdata", "six"])
sys.path.insert(0, sb3_dir)

import gymnasium as gym  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import VecNormalize  # noqa: E402

torch.set_num_threads(1)
env = VecNormalize(make_vec_env(args.env, n_envs=1, seed=0), gamma=0.99, clip_obs=10.0, clip_reward=10.0)
model = PPO(
    "MlpPolicy", env, n_steps=2048, batch_size=64, n_epochs=10, learning_rate=lambda f: 3e-4 * f,
    gamma=0.99, gae_lambda=0.95, clip_range=0.2, clip_range_vf=0.2, ent_coef=0.0, vf_coef=0.5,
    max_grad_norm=0.5, normalize_advantage=True, device="cpu", seed=0,
    policy_kwargs=dict(net_arch=dict(pi=[64, 64], vf=[64, 64]), activation_fn=torch.nn.Tanh,
                       log_std_init=0.0, ortho_init=True),
)
start = time.perf_counter()
model.learn(total_timesteps=args.steps)
sb3_s = time.perf_counter() - start
sb3_sps = args.steps / sb3_s
print(json.dumps({"library": "stable-baselines3 2.9.2", "env": args.env, "steps": args.steps, "train_s": sb3_s,
                  "steps_per_s": sb3_sps}))
if idrex_sps is not None:
    print(json.dumps({"env": args.env, "steps": args.steps, "idrex_vs_sb3": idrex_sps / sb3_sps}))
