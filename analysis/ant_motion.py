"""How an Ant rollout set moves (issue 54, round 4): per set, the torso's forward velocity
(observation entry 13, qvel[0]) and the mean absolute joint velocity (entries 19-26) over every
step, and the learned reward per step where the file carries it. It tells a policy that makes
progress from one that moves its legs in place, which the return's terms alone do not.

Read with Python's `mcap` reader and numpy only (no idrex code):

    python analysis/ant_motion.py STORE NAME=KEY[,KEY...][@NOISE[@GROUP]] ...

Each KEY is a stage's key prefix from `idrex pipeline plan FILE --store STORE` (an evaluation,
or a ranked set `drex/noise`); several keys pool their episodes (a method's three RL runs);
@NOISE keeps one noise level of a ranked set, @GROUP one of its groups (`noise.toward: both`:
0 random actions, 1 the zero action).
"""
import glob
import json
import sys

import numpy as np
from mcap.reader import make_reader

FORWARD_VELOCITY = 13
JOINT_VELOCITIES = slice(19, 27)


def episodes(store, key):
    """(episode entry, next observations, learned rewards or None) of one stage's rollouts."""
    path = glob.glob(f"{store}/{key}*/rollouts.mcap")
    if len(path) != 1:
        sys.exit(f"{key}: {len(path)} rollout files match in {store}; give a longer key prefix")
    reader = make_reader(open(path[0], "rb"))
    meta = {m.name: m.metadata for m in reader.iter_metadata()}
    entries = [json.loads(v) for _, v in sorted(meta["idrex.episodes"].items())]
    steps = {}
    for _, _, msg in reader.iter_messages(topics=["/step"]):
        m = json.loads(msg.data)
        steps.setdefault(m["episode"], []).append((m["next_obs"], m.get("learned_reward")))
    for i, e in enumerate(entries):
        obs = np.array([s[0] for s in steps.get(i, [])])
        learned = [s[1] for s in steps.get(i, [])]
        yield e, obs, (None if not learned or learned[0] is None else np.array(learned))


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    store = sys.argv[1]
    for spec in sys.argv[2:]:
        name, _, rest = spec.partition("=")
        keys, *pick = rest.split("@")
        noise = float(pick[0]) if pick else None
        group = int(pick[1]) if len(pick) > 1 else None
        forward, joints, learned, n = [], [], [], 0
        for key in keys.split(","):
            for e, obs, lr in episodes(store, key):
                if (noise is not None and abs(e["noise"] - noise) > 1e-9) or (group is not None and e["group"] != group):
                    continue
                if len(obs) == 0:
                    continue
                n += 1
                forward.append(obs[:, FORWARD_VELOCITY])
                joints.append(np.abs(obs[:, JOINT_VELOCITIES]).mean(axis=1))
                if lr is not None:
                    learned.append(lr)
        if n == 0:
            sys.exit(f"{name}: no episode matches")
        line = f"{name:32s} {n:3d} episodes  forward velocity {np.concatenate(forward).mean():6.3f}"
        line += f"  mean |joint velocity| {np.concatenate(joints).mean():5.2f}"
        if learned:
            line += f"  learned reward per step {np.concatenate(learned).mean():6.3f}"
        print(line)


if __name__ == "__main__":
    main()
