"""Training-step cost on this machine at the smoke and default run sizes.

Prints, per tier: seconds per optimisation step (forward + L1 loss + backward + Adam) of the
default MSMR-Net (ResNet-18, multi-path decoder, attention) at the tier's image and batch size,
the ratio to a forward pass alone (the baseline measured in the same run), and the seconds per
augmented training crop from the data pipeline (toy samples in memory).

    .venv/bin/python benchmarks/train.py [--steps 3] [--threads N]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from handmesh_tutorial import augment, train
from handmesh_tutorial.budget import budget


def _timeit(fn, repeats: int) -> float:
    fn()  # warm-up
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t) / repeats


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    for tier in ("smoke", "default"):
        b = budget(tier)
        torch.set_num_threads(args.threads or b.threads)
        cfg = train.TrainConfig.from_budget(b)
        torch.manual_seed(0)
        net = train.build_model_from_config(cfg)
        opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
        x = torch.randn(b.batch_size, 3, b.image_size, b.image_size)
        y = torch.randn(b.batch_size, net.joint_regressor.shape[1], 3) * 0.03

        def step(net=net, opt=opt, x=x, y=y):
            opt.zero_grad()
            train.vertex_loss(net(x)["vertices"], y).backward()
            opt.step()

        def forward(net=net, x=x):
            with torch.no_grad():
                net(x)

        t_step = _timeit(step, args.steps)
        net.eval()
        t_fwd = _timeit(forward, args.steps)
        samples = [train.toy_sample(i, image_size=2 * b.image_size) for i in range(4)]
        ds = augment.InterSHTorchDataset(samples, b.image_size, train=True)
        t_item = _timeit(lambda ds=ds: [ds[i] for i in range(len(ds))], 2) / len(ds)
        print(f"{tier:8s} image {b.image_size:3d} batch {b.batch_size:2d} threads "
              f"{torch.get_num_threads()}: {t_step:.3f} s/step, forward {t_fwd:.3f} s "
              f"(step/forward {t_step / t_fwd:.2f}), {1000 * t_item:.1f} ms per augmented crop "
              f"({1000 * t_item * b.batch_size / max(t_step, 1e-9) / 1000:.2f} of a step per "
              f"batch); epoch of {b.samples} samples ~ "
              f"{np.ceil(b.samples / b.batch_size) * (t_step + t_item * b.batch_size):.0f} s")


if __name__ == "__main__":
    main()
