"""Sparse vertex maps for export: CSR products (the default) vs gather + weighted sum, eager CPU.

``torch.export``, ONNX and ``torch.compile`` cannot trace sparse CSR tensors, so
``SparseVertexMap`` switches to its gather path while a graph is traced. This script measures
what that path would cost if it were the eager default too, in one run (ratios against the CSR
baseline measured in the same run):

1. the decoder part (``MSMRNet.decode``: FC, transformer, decoder, output smoothing) of the
   single-path, multi-path and multi-path + attention networks (``hmt.nn.model.build_model``
   defaults) and of the shipped pretrained network: forward (no grad) and forward+backward;
2. the full pretrained network, forward at its crop size;
3. export costs of the pretrained network: ``torch.export.export``, ONNX export (when ``onnx``
   and ``onnxscript`` are importable) and the first call of ``torch.compile(fullgraph=True)``
   with the ``aot_eager`` and ``inductor`` backends, with the largest difference from eager.

Batch = ``--batch`` (default ``hmt.budget().batch_size``), threads = ``--threads`` (default 1).
Times are the fastest of ``--repeats`` round-robin runs.

    .venv/bin/python benchmarks/export.py [--repeats 5] [--threads 1] [--batch B] [--no-export]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from model import timeit  # benchmarks/model.py: round-robin, fastest of the repeats

import handmesh_tutorial as hmt
from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn.blocks import SparseVertexMap


def set_method(net: torch.nn.Module, method: str) -> None:
    for m in net.modules():
        if isinstance(m, SparseVertexMap):
            m.method = method


def bench_decode(name: str, net, batch: int, repeats: int) -> None:
    feats = torch.randn(batch, net.latent_to_mesh.in_features)
    fns_f, fns_fb = {}, {}
    for method in ("csr", "gather"):
        def fwd(method=method):
            set_method(net, method)
            with torch.no_grad():
                net.decode(feats)

        def fwd_bwd(method=method):
            set_method(net, method)
            net.zero_grad(set_to_none=True)
            net.decode(feats)["vertices"].square().mean().backward()

        fns_f[method], fns_fb[method] = fwd, fwd_bwd
    tf, tfb = timeit(fns_f, repeats), timeit(fns_fb, repeats)
    set_method(net, "csr")
    print(f"{name:<18} forward csr {1e3 * tf['csr']:7.2f} ms, gather {1e3 * tf['gather']:7.2f} "
          f"ms ({tf['gather'] / tf['csr']:.2f}x)   forward+backward csr "
          f"{1e3 * tfb['csr']:7.2f} ms, gather {1e3 * tfb['gather']:7.2f} ms "
          f"({tfb['gather'] / tfb['csr']:.2f}x)")


def bench_exports(net, images) -> None:
    with torch.no_grad():
        ref = net(images)

    def diff(out) -> float:
        if isinstance(out, dict):
            out = [out[k] for k in ref]
        return max(float((torch.as_tensor(o) - ref[k]).abs().max())
                   for o, k in zip(out, ref, strict=True))

    t = time.perf_counter()
    ep = torch.export.export(net, (images,))
    dt = time.perf_counter() - t
    print(f"torch.export.export: {dt:6.1f} s, max |export - eager| "
          f"{diff(ep.module()(images)):.1e} m")
    from handmesh_tutorial._optional import require

    try:
        require("onnx", "ONNX export")
        require("onnxscript", "ONNX export")
    except ImportError as err:
        print(f"ONNX export: skipped ({err})")  # names pip install "handmesh_tutorial[export]"
    else:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "net.onnx"
            t = time.perf_counter()
            torch.onnx.export(net, (images,), path, dynamo=True, verbose=False)
            dt = time.perf_counter() - t
            try:
                ort = require("onnxruntime", "running the ONNX file")
            except ImportError as err:
                print(f"ONNX export: {dt:6.1f} s (not run: {err})")
            else:
                sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
                out = sess.run(None, {sess.get_inputs()[0].name: images.numpy()})
                print(f"ONNX export: {dt:6.1f} s, max |onnxruntime - eager| {diff(out):.1e} m")
    for backend in ("aot_eager", "inductor"):
        torch._dynamo.reset()
        comp = torch.compile(net, fullgraph=True, backend=backend)
        t = time.perf_counter()
        with torch.no_grad():
            out = comp(images)
        dt = time.perf_counter() - t
        print(f"torch.compile(fullgraph=True, backend={backend!r}) first call: {dt:6.1f} s, "
              f"max |compiled - eager| {diff(out):.1e} m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--batch", type=int, default=None,
                        help="batch size (default: the budget's)")
    parser.add_argument("--no-export", action="store_true", help="skip the export timings")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    batch = hmt.budget().batch_size if args.batch is None else args.batch
    print(f"torch {torch.__version__}, threads {args.threads}, batch {batch}")
    hand = hmt.hand.HandModel("right")
    hier = hmt.nn.hierarchy.mesh_hierarchy(hand.template_vertices, hand.faces)
    nets = {"single": M.build_model("resnet10", "single", False, hand, hierarchy=hier),
            "multi": M.build_model("resnet10", "multi", False, hand, hierarchy=hier),
            "multi+attention": M.build_model("resnet10", "multi", True, hand, hierarchy=hier),
            "pretrained": M.pretrained()}
    print(f"\nDecoder part (MSMRNet.decode), batch {batch}: gather time / csr time")
    for name, net in nets.items():
        bench_decode(name, net, batch, args.repeats)

    net = nets["pretrained"]
    size = hmt.pretrained.pretrained_info()["config"]["image_size"]
    images = torch.randn(batch, 3, size, size)
    fns = {}
    for method in ("csr", "gather"):
        def fwd(method=method):
            set_method(net, method)
            with torch.no_grad():
                net(images)
        fns[method] = fwd
    t = timeit(fns, args.repeats)
    set_method(net, "csr")
    print(f"\nPretrained network forward ({batch}, 3, {size}, {size}): csr "
          f"{1e3 * t['csr']:.1f} ms, gather {1e3 * t['gather']:.1f} ms "
          f"({t['gather'] / t['csr']:.2f}x)")
    if not args.no_export:
        print(f"\nExport of the pretrained network, images (1, 3, {size}, {size})")
        bench_exports(net, images[:1])


if __name__ == "__main__":
    main()
