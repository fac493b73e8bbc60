"""The baseline of `idrex bench learners`: T-REX and BC as plain PyTorch training loops at the
report's shapes (HalfCheetah: 17-dim observations, 6-dim actions), on synthetic data of the
same sizes idrex is given. `idrex bench learners` runs this script itself and prints the
ratios; run alone it prints one JSON line.

T-REX: an ensemble of 3 reward nets 17-256-256-1 (ReLU), each trained on its own pairs, one
after the other: per iteration a batch of 64 pairs of 50-step windows, each window's summed
reward, Bradley-Terry cross-entropy + 0.01 x the sum of squared weights, Adam 1e-4.
BC: 17-256-256-256-256-6 (ReLU), batch 128, squared error summed over action dimensions,
+ 0.001 x the sum of squared weights, Adam 1e-4.

    python analysis/bench_learners.py --threads 2 --trex-iterations 200 --bc-iterations 2000

With `--device cuda` the data, the networks and every step live on the GPU, and each batch's
indices are drawn on the host and copied over, as idrex's GPU path does.
"""
import argparse
import json
import time

import torch
from torch import nn


def mlp(sizes):
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1])


def l2(net):
    return sum((p * p).sum() for name, p in net.named_parameters() if name.endswith("weight"))


def trex(iterations, obs_dim, models, gen, device):
    # 100 trajectories of 1000 steps; pairs drawn as (trajectory, start) x 2 with a label.
    obs = torch.randn(100, 1000, obs_dim, generator=gen).to(device)
    n_pairs, window, batch = 5000, 50, 64
    for _ in range(models):
        net = mlp([obs_dim, 256, 256, 1]).to(device)
        opt = torch.optim.Adam(net.parameters(), lr=1e-4)
        traj = torch.randint(0, 100, (n_pairs, 2), generator=gen).to(device)
        start = torch.randint(0, 1000 - window, (n_pairs, 2), generator=gen).to(device)
        label = torch.randint(0, 2, (n_pairs,), generator=gen).to(device)
        steps = torch.arange(window, device=device)
        for _ in range(iterations):
            pick = torch.randint(0, n_pairs, (batch,), generator=gen).to(device)
            t, s = traj[pick], start[pick]
            x = obs[t[:, :, None], s[:, :, None] + steps]  # [batch, 2, window, obs_dim]
            r = net(x.reshape(-1, obs_dim)).view(batch, 2, window).sum(-1)
            loss = nn.functional.cross_entropy(r, label[pick]) + 0.01 * l2(net)
            opt.zero_grad()
            loss.backward()
            opt.step()


def bc(iterations, obs_dim, act_dim, gen, device):
    x = torch.randn(800, obs_dim, generator=gen).to(device)
    y = torch.randn(800, act_dim, generator=gen).to(device)
    net = mlp([obs_dim, 256, 256, 256, 256, act_dim]).to(device)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    for _ in range(iterations):
        pick = torch.randint(0, 800, (128,), generator=gen).to(device)
        loss = ((net(x[pick]) - y[pick]) ** 2).sum(-1).mean() + 0.001 * l2(net)
        opt.zero_grad()
        loss.backward()
        opt.step()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--trex-iterations", type=int, default=200)
    ap.add_argument("--bc-iterations", type=int, default=2000)
    ap.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    gen = torch.Generator().manual_seed(0)
    models = 3

    def now():
        if args.device == "cuda":
            torch.cuda.synchronize()
        return time.perf_counter()

    t0 = now()
    trex(args.trex_iterations, 17, models, gen, args.device)
    t1 = now()
    bc(args.bc_iterations, 17, 6, gen, args.device)
    t2 = now()
    print(json.dumps({
        "torch": torch.__version__,
        "device": args.device,
        "gpu": torch.cuda.get_device_name() if args.device == "cuda" else None,
        "threads": args.threads,
        "trex_model_iterations_per_s": models * args.trex_iterations / (t1 - t0),
        "bc_iterations_per_s": args.bc_iterations / (t2 - t1),
    }))


if __name__ == "__main__":
    main()
