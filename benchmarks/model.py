"""Benchmark: SpiralConv, single- vs multi-path decoders, with and without attention, full model.

Prints, measured in the same run:

1. ``SpiralConv`` forward+backward vs a plain reference (advanced-index gather ``x[:, idx]`` +
   ``torch.nn.functional.linear``) on the hand's finest mesh. Target: no slower (ratio ~1).
2. Parameters of the mesh part (FC, transformer, decoder) for single-path, multi-path, and
   multi-path + attention (the paper's Table 3 rows), with the ratio to single-path. Target:
   multi-path + attention adds at most ~30% decoder parameters ("minor additional parameter
   cost", paper) with the default channels of :mod:`handmesh_tutorial.nn.model`.
2b. ``SparseVertexMap`` (the up/down maps between hierarchy levels) forward+backward: the
   library's broadcast multiply-and-sum vs ``torch.einsum("bvkc,vk->bvc")`` (which PyTorch runs
   as V tiny batched matmuls), on the finest up map (779 <- 390 vertices, 3 weights per row).
3. Forward and forward+backward time of the decoder part (coarse tokens -> vertices) and of the
   full model (ResNet-18) at the smoke image size (64) and at 224x224, with ratios to
   single-path.
4. One training step (forward+backward+Adam) of the demo's model (multi-path + attention,
   64-px crops, batch ``budget.batch_size``) with a ResNet-10 vs a ResNet-18 encoder.

Sizes: batch = ``hmt.budget().batch_size`` (a quarter of it at 224x224), threads =
``hmt.budget().threads`` unless ``--threads``. Times are the fastest of ``--repeats`` round-robin
runs. Run: ``python benchmarks/model.py [--repeats 5] [--threads 1]``.
"""

from __future__ import annotations

import argparse
import time

import torch
import torch.nn.functional as F

import handmesh_tutorial as hmt
from handmesh_tutorial.hand import HandModel
from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.spiral import SpiralConv


def timeit(fns: dict, repeats: int) -> dict:
    """Fastest of ``repeats`` calls of each function, in seconds, after one warm-up call each.

    The functions are called round-robin, so a load change on a shared machine hits all of them
    alike, and the minimum is the least disturbed measurement.
    """
    for fn in fns.values():
        fn()
    best = {k: float("inf") for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t)
    return best


def bench_spiralconv(spirals, batch: int, repeats: int) -> None:
    idx = spirals[0]
    conv = SpiralConv(32, 32, idx)
    w, b = conv.linear.weight, conv.linear.bias
    idx_t = torch.as_tensor(idx)
    x = torch.randn(batch, len(idx), 32, requires_grad=True)

    def lib():
        conv(x).sum().backward()

    def ref():  # the textbook version: advanced indexing (B, V, L, C), flatten, linear
        F.linear(x[:, idx_t].reshape(batch, len(idx), -1), w, b).sum().backward()

    t = timeit({"lib": lib, "ref": ref}, repeats)
    t_lib, t_ref = t["lib"], t["ref"]
    print(f"SpiralConv fwd+bwd (B={batch}, V={len(idx)}, L={idx.shape[1]}, 32->32): "
          f"library {1e3 * t_lib:.2f} ms, gather+Linear reference {1e3 * t_ref:.2f} ms, "
          f"ratio library/reference = {t_lib / t_ref:.2f}")


def bench_sparse_map(hier, batch: int, repeats: int) -> None:
    from handmesh_tutorial.nn.blocks import SparseVertexMap

    up = SparseVertexMap(hier.up[0])
    x = torch.randn(batch, up.in_vertices, 16, requires_grad=True)
    idx, w = up.index, up.weight

    def lib():
        up(x).sum().backward()

    def ein():
        g = x.index_select(1, idx.reshape(-1)).reshape(batch, up.out_vertices, -1, 16)
        torch.einsum("bvkc,vk->bvc", g, w).sum().backward()

    t = timeit({"lib": lib, "einsum": ein}, repeats)
    print(f"SparseVertexMap fwd+bwd (B={batch}, {up.out_vertices} <- {up.in_vertices}, "
          f"{idx.shape[1]} per row, C=16): library {1e3 * t['lib']:.2f} ms, einsum "
          f"{1e3 * t['einsum']:.2f} ms, ratio einsum/library = {t['einsum'] / t['lib']:.2f}")


def bench_demo_step(hand, hier, batch: int, repeats: int) -> None:
    images = torch.randn(batch, 3, 64, 64)
    steps = {}
    for enc in ("resnet10", "resnet18"):
        net = M.build_model(enc, template=hand, hierarchy=hier)
        opt = torch.optim.Adam(net.parameters(), 1e-3)

        def step(net=net, opt=opt):
            opt.zero_grad(set_to_none=True)
            net(images)["vertices"].abs().mean().backward()
            opt.step()

        steps[enc] = step
    t = timeit(steps, repeats)
    print(f"\nDemo training step (multi-path + attention, B={batch}, 64 px): ResNet-10 "
          f"{1e3 * t['resnet10']:.0f} ms, ResNet-18 {1e3 * t['resnet18']:.0f} ms, ratio "
          f"ResNet-18/ResNet-10 = {t['resnet18'] / t['resnet10']:.2f}")


def report(models: dict, fwd, fwd_bwd, repeats: int, fmt: str) -> None:
    """Print forward and forward+backward times per model variant, with ratios to the first."""
    tf = timeit({k: (lambda n=n: fwd(n)) for k, n in models.items()}, repeats)
    tfb = timeit({k: (lambda n=n: fwd_bwd(n)) for k, n in models.items()}, repeats)
    f0, fb0 = next(iter(tf.values())), next(iter(tfb.values()))
    for name in models:
        print(f"{name:<18} forward {1e3 * tf[name]:{fmt}} ms ({tf[name] / f0:.2f}x)   "
              f"forward+backward {1e3 * tfb[name]:{fmt}} ms ({tfb[name] / fb0:.2f}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=None,
                        help="torch threads (default: the budget's; 1 is steadier on a busy box)")
    args = parser.parse_args()
    B = hmt.budget()
    threads = B.threads if args.threads is None else args.threads
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    print(f"budget {B.name}: batch {B.batch_size}, threads {threads}, torch {torch.__version__}")
    hand = HandModel("right")
    hier = mesh_hierarchy(hand.template_vertices, hand.faces)
    print(f"hand hierarchy: {hier.num_vertices} vertices")

    variants = {"single": dict(decoder="single", attention=False),
                "multi": dict(decoder="multi", attention=False),
                "multi+attention": dict(decoder="multi", attention=True)}
    models = {k: M.build_model("resnet18", template=hand, hierarchy=hier, **kw)
              for k, kw in variants.items()}
    bench_spiralconv(models["single"].spirals, B.batch_size, args.repeats)
    bench_sparse_map(hier, B.batch_size, args.repeats)

    print("\nParameters (decoder part = transformer + decoder; FC shared by all variants)")
    base = None
    print(f"{'variant':<18}{'FC':>10}{'transformer':>13}{'decoder':>10}{'decoder part':>14}"
          f"{'ratio':>7}{'depth':>7}{'FC/decoder':>12}")
    for name, net in models.items():
        c = M.parameter_counts(net)
        part = c["transformer"] + c["decoder"]
        base = base or part
        print(f"{name:<18}{c['latent_to_mesh']:>10,}{c['transformer']:>13,}{c['decoder']:>10,}"
              f"{part:>14,}{part / base:>7.2f}{net.decoder.depth:>7}"
              f"{c['latent_to_mesh'] / c['decoder']:>12.2f}")
    print("encoder (resnet18):", f"{M.parameter_counts(models['single'])['encoder']:,}")
    print("\n" + M.parameter_table(models["multi+attention"]))

    print(f"\nDecoder part (tokens (B, {models['single'].coarse_vertices}, "
          f"{models['single'].latent_channels}) -> vertices), B={B.batch_size}")
    tokens = torch.randn(B.batch_size, models["single"].coarse_vertices,
                         models["single"].latent_channels)
    def dec_fwd(net):
        with torch.no_grad():
            net.decoder(net.transformer(tokens))

    def dec_fwd_bwd(net):
        net.zero_grad(set_to_none=True)
        net.decoder(net.transformer(tokens)).square().mean().backward()

    report(models, dec_fwd, dec_fwd_bwd, args.repeats, "8.2f")

    for size in sorted({64, 224}):
        batch = B.batch_size if size == 64 else max(1, B.batch_size // 4)
        images = torch.randn(batch, 3, size, size)
        print(f"\nFull model (resnet18), images ({batch}, 3, {size}, {size})")

        def fwd(net, images=images):
            with torch.no_grad():
                net(images)

        def fwd_bwd(net, images=images):
            net.zero_grad(set_to_none=True)
            out = net(images)
            (out["vertices"].abs().mean() + out["joints"].abs().mean()).backward()

        report(models, fwd, fwd_bwd, args.repeats, "8.1f")

    bench_demo_step(hand, hier, B.batch_size, args.repeats)


if __name__ == "__main__":
    main()
