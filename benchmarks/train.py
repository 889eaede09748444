"""Training throughput at the demo's recipe: the optimised path against the original, one run.

The network and batch are the demo's (``hmt.apps.demo.DemoConfig.from_budget(budget("default"))``:
ResNet-10 encoder, multi-path decoder, coarse-mesh attention, the CPU recipe's keypoint and
rotation heads and losses, batch 16, 64-px crops) at the demo's torch threads (2). One step =
forward, the recipe's loss, backward, Adam. Variants, timed in interleaved repeats (medians):

* ``reference``: the path before issue 14: sparse vertex maps as gather + weighted sum
  (``SparseVertexMap.method = "gather"``) and the per-tensor (non-fused) Adam;
* ``optimised``: CSR sparse products (the default) and fused Adam: same results up to float
  rounding (``tests/test_model.py`` compares outputs and gradients);
* ``optimised + bf16``: the same under ``precision="bfloat16"`` autocast (opt-in, not exact).

Prints images/s, the ratio to ``reference``, and achieved GFLOP/s (FLOPs of one step counted by
``torch.utils.flop_counter``) against a plain matmul roofline measured in the same run (float32
and bfloat16, 2048^2 x 2048 at the same threads). ``--accuracy`` also trains the float32 and
bfloat16 variants for ``--accuracy-steps`` steps from the same initialisation on toy hands
(``hmt.testing.toy_sample``) and prints the held-out vertex L1 error of both (the effect of
bfloat16 on accuracy at this scale).

    .venv/bin/python benchmarks/train.py [--repeats 5] [--threads N] [--accuracy]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from handmesh_tutorial import testing, train
from handmesh_tutorial.apps import demo
from handmesh_tutorial.budget import budget
from handmesh_tutorial.data import augment
from handmesh_tutorial.nn.blocks import SparseVertexMap

VARIANTS = {  # name: (sparse map method, fused Adam, precision)
    "reference": ("gather", False, "float32"),
    "optimised": ("csr", True, "float32"),
    "optimised + bf16": ("csr", True, "bfloat16"),
}


def demo_config(**overrides):
    dc = demo.DemoConfig.from_budget(budget("default"))
    return demo.train_config(dc, "unused", "unused", progress=False, **overrides)


def build(cfg, method: str, fused: bool):
    torch.manual_seed(0)
    net = train.build_model_from_config(cfg)
    for m in net.modules():
        if isinstance(m, SparseVertexMap):
            m.method = method
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, fused=fused)
    return net, opt


def random_batch(net, cfg, seed: int = 1) -> dict:
    g = torch.Generator().manual_seed(seed)
    b, s = cfg.batch_size, cfg.image_size
    v = net.joint_regressor.shape[1]
    K = torch.tensor([[2.0 * s, 0, s / 2], [0, 2.0 * s, s / 2], [0, 0, 1]])
    return {"image": torch.randn(b, 3, s, s, generator=g),
            "vertices": torch.randn(b, v, 3, generator=g) * 0.03,
            "joints": torch.randn(b, 21, 3, generator=g) * 0.03,
            "root": torch.tensor([0.0, 0.0, 0.5]).repeat(b, 1), "K": K.repeat(b, 1, 1)}


def step_fn(net, opt, cfg, batch):
    def step():
        opt.zero_grad(set_to_none=True)
        train.loop._train_step(net, batch, 1, torch.device("cpu"), False, cfg, None)
        opt.step()
    return step


def matmul_roofline(dtype, n: int = 2048, repeats: int = 5) -> float:
    """GFLOP/s of a plain (n x n) @ (n x n) product at the current threads."""
    a, b = torch.randn(n, n).to(dtype), torch.randn(n, n).to(dtype)
    a @ b
    t = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        a @ b
        t.append(time.perf_counter() - t0)
    return 2 * n ** 3 / min(t) / 1e9


def accuracy(cfg32, steps: int, n_train: int = 32, n_test: int = 16) -> dict:
    """Held-out vertex L1 (mm) after ``steps`` steps, float32 vs bfloat16, same init and data."""
    size = cfg32.image_size
    samples = [testing.toy_sample(i, image_size=2 * size) for i in range(n_train + n_test)]
    ds_tr = augment.InterSHTorchDataset(samples[:n_train], size, train=True, augment=False)
    ds_te = augment.InterSHTorchDataset(samples[n_train:], size, train=False)
    test = torch.utils.data.default_collate([ds_te[i] for i in range(len(ds_te))])
    order = np.random.default_rng(0).integers(0, n_train, (steps, cfg32.batch_size))
    out = {}
    for precision in ("float32", "bfloat16"):
        cfg = demo_config(precision=precision)
        net, opt = build(cfg, "csr", True)
        for k in range(steps):
            batch = torch.utils.data.default_collate([ds_tr[int(i)] for i in order[k]])
            opt.zero_grad(set_to_none=True)
            train.loop._train_step(net, batch, 1, torch.device("cpu"), False, cfg, None)
            opt.step()
        net.eval()
        with torch.no_grad():
            pred = net(test["image"])["vertices"]
        out[precision] = float((pred - test["vertices"]).abs().mean() * 1e3)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=3, help="steps per timed repeat")
    ap.add_argument("--threads", type=int, default=None, help="default: the demo's")
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--accuracy-steps", type=int, default=40)
    args = ap.parse_args()
    cfg = demo_config()
    threads = args.threads or cfg.threads
    torch.set_num_threads(threads)
    print(f"# demo recipe: {cfg.encoder} + {cfg.decoder}-path decoder, attention "
          f"{cfg.attention}, {cfg.model_kwargs}, batch {cfg.batch_size}, {cfg.image_size} px, "
          f"{threads} threads")
    steps = {}
    for name, (method, fused, precision) in VARIANTS.items():
        c = demo_config(precision=precision)
        net, opt = build(c, method, fused)
        steps[name] = step_fn(net, opt, c, random_batch(net, c))
        steps[name]()  # warm-up
        steps[name]()
    with FlopCounterMode(display=False) as fc:
        steps["optimised"]()
    flops = fc.get_total_flops()
    roof = {"float32": matmul_roofline(torch.float32),
            "bfloat16": matmul_roofline(torch.bfloat16)}
    times = {k: [] for k in steps}
    for _ in range(args.repeats):
        for name, fn in steps.items():
            t0 = time.perf_counter()
            for _ in range(args.steps):
                fn()
            times[name].append((time.perf_counter() - t0) / args.steps)
    roof["float32"] = max(roof["float32"], matmul_roofline(torch.float32))  # after, too
    roof["bfloat16"] = max(roof["bfloat16"], matmul_roofline(torch.bfloat16))
    med = {k: float(np.median(v)) for k, v in times.items()}
    base = med["reference"]
    print(f"FLOPs of one step (matmuls and convolutions): {flops / 1e9:.2f} GFLOP; matmul "
          f"roofline in this run: float32 {roof['float32']:.0f} GFLOP/s, bfloat16 "
          f"{roof['bfloat16']:.0f} GFLOP/s")
    for name, t in med.items():
        r = roof["bfloat16" if "bf16" in name else "float32"]
        print(f"{name:17s}: {t * 1e3:7.1f} ms/step  {cfg.batch_size / t:6.1f} images/s  "
              f"{flops / t / 1e9:6.1f} GFLOP/s ({flops / t / 1e9 / r:.0%} of the matmul "
              f"roofline)  RATIO vs reference ({cfg.batch_size / base:.1f} images/s): "
              f"{base / t:.2f}x")
    if args.accuracy:
        acc = accuracy(cfg, args.accuracy_steps)
        print(f"accuracy after {args.accuracy_steps} steps on toy hands (held-out vertex L1): "
              f"float32 {acc['float32']:.2f} mm, bfloat16 {acc['bfloat16']:.2f} mm")


if __name__ == "__main__":
    main()
