"""What a learned reward pays for, per step (issue 54, round 3): for one D-REX reward in a
store, its ensemble's mean output per step on the ranked set's rollouts by noise level beside
the forward velocity, the correlation of the per-step reward with each observation entry over
the ranked set, and, on evaluation rollouts, the reward per step with the mean of each entry
in units of the ranked set's spread (where PPO's policies sit outside what the ranking saw),
and how far the ensemble's members agree there (each member's output in units of its own
spread over the ranked set; a conservative reward, mean minus k standard deviations across
members, can only act where they disagree).

Read with Python's `mcap` reader and numpy only (no idrex code): the reward's safetensors are
evaluated here, a reward that reads part of each observation (`trex.observation`) from its
sidecar's offset.

    python analysis/reward_features.py STORE REWARD_KEY RANKED_SET_KEY [EVAL_KEY ...]

(the keys from `idrex pipeline plan FILE --store STORE`: `drex/trex`, `drex/noise`,
`drex/eval/0`). The forward velocity is the entry after the positions (qvel[0]; 8 on
HalfCheetah and Walker2d).
"""
import json
import sys

import numpy as np
from mcap.reader import make_reader

from demo_diagnosis import load_safetensors


def load_reward(store, key, members_apart=False):
    """The ensemble's mean raw output, a function of whole observation rows (each member's
    output, members x rows, with `members_apart`); a reward that reads the action too
    (`trex.action_input`) takes each row's action as the second argument, after the
    observation as T-REX fed it."""
    d = f"{store}/{key}/reward"
    whole = json.load(open(f"{d}/reward.json"))
    config = whole["config"]
    with_action = bool(whole.get("hyper", {}).get("trex", {}).get("action_input"))
    t = load_safetensors(f"{d}/reward.safetensors")
    start = config.get("obs_offset") or 0
    seen = slice(start, start + config["obs_dim"])
    members = sorted({k.split(".")[0] for k in t})
    layers = len({k.split(".")[1] for k in t})

    def reward(x, act=None):
        if with_action and act is None:
            raise ValueError(f"{key}: this reward reads the action too; pass each row's action")
        rows = np.concatenate([x[:, seen], act], axis=1) if with_action else x[:, seen]
        outs = []
        for m in members:
            h = rows
            for i in range(layers):
                h = h @ t[f"{m}.l{i}.weight"].T + t[f"{m}.l{i}.bias"]
                if i < layers - 1:
                    h = np.maximum(h, 0)
            outs.append(h[:, 0])
        return np.array(outs) if members_apart else np.mean(outs, axis=0)

    return reward


def forward_velocity_entry(obs_dim):
    """Where qvel[0] sits: after the positions (HalfCheetah and Walker2d 17, Hopper 11, Ant)."""
    return 8 if obs_dim == 17 else 5 if obs_dim == 11 else 13


def steps(store, key):
    """Every step's next observation and its episode's noise level."""
    obs, noise, level = [], [], {}
    with open(f"{store}/{key}/rollouts.mcap", "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=["/episode", "/step"]):
            d = json.loads(message.data)
            if channel.topic == "/episode":
                level[d["episode"]] = d.get("noise", 0.0)
            else:
                obs.append(d["next_obs"])
                noise.append(level.get(d["episode"], 0.0))
    return np.array(obs), np.array(noise)


def main():
    store, reward_key, ranked_key, evals = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
    reward = load_reward(store, reward_key)
    x, noise = steps(store, ranked_key)
    r = reward(x)
    config = json.load(open(f"{store}/{reward_key}/reward/reward.json"))["config"]
    vx = forward_velocity_entry(x.shape[1])
    print(f"ranked set: {len(x)} steps; the forward velocity is entry {vx} (reads {config['obs_dim']} entries)")
    print("noise  forward velocity  reward per step")
    for level in sorted(set(noise)):
        on = noise == level
        print(f"{level:5.2f}  {x[on, vx].mean():16.2f}  {r[on].mean():15.3f}")
    corr = [np.corrcoef(r, x[:, j])[0, 1] if x[:, j].std() > 0 else 0.0 for j in range(x.shape[1])]
    print("correlation of the reward per step with each entry:", " ".join(f"{j}:{c:+.2f}" for j, c in enumerate(corr)))
    mu, sd = x.mean(0), x.std(0) + 1e-8
    members = load_reward(store, reward_key, members_apart=True)
    per_member = members(x)
    m_mu, m_sd = per_member.mean(1, keepdims=True), per_member.std(1, keepdims=True)

    def agreement(rows):
        z = (members(rows) - m_mu) / m_sd
        return z.mean(1), z.std(0).mean()

    for level in (min(noise), max(noise)):
        means, spread = agreement(x[noise == level])
        print(f"members on noise {level:.2f}: " + " ".join(f"{v:+.2f}" for v in means) + f" (own spreads), {spread:.2f} apart per step")
    for key in evals:
        means, spread = agreement(steps(store, key)[0])
        print(f"members on eval {key[:12]}: " + " ".join(f"{v:+.2f}" for v in means) + f" (own spreads), {spread:.2f} apart per step")
    for key in evals:
        y, _ = steps(store, key)
        z = ((y - mu) / sd).mean(0)
        print(f"eval {key[:12]}: reward per step {reward(y).mean():.3f}, forward velocity {y[:, vx].mean():.2f}; entries in ranked-set spreads:",
              " ".join(f"{j}:{v:+.1f}" for j, v in enumerate(z)))


if __name__ == "__main__":
    main()
