"""The shipped network on one 128-px crop, batch 1: torch eager, best torch, onnxruntime.

Rows, measured in one run, interleaved round by round so that a busy machine slows each alike:

* ``torch eager``: ``net(x)`` under ``torch.inference_mode()`` (what ``predict_hand`` runs);
* ``torch channels_last``: the network and input in channels-last memory format;
* ``torch jit freeze``: ``torch.jit.trace`` + ``torch.jit.freeze`` +
  ``torch.jit.optimize_for_inference`` (batch norm folded into the convolutions; the best torch
  setting found without a C++ compiler: ``torch.compile``'s inductor costs minutes to compile
  on 2 CPUs, docs page "Exporting the network");
* ``onnxruntime``: ``hmt.export.onnx_network(threads=...)`` (the fast path of ``predict_hand``).

Each row prints the median and the minimum over ``--repeats`` calls (ms) and the median's ratio
to torch eager's; the largest difference of each row's vertices from eager's (m) is printed too.
The end-to-end call (``predict_hand`` on a 640 x 480 image, crop included) is timed for eager and
onnxruntime. Run: ``python benchmarks/inference_backends.py [--threads 1] [--repeats 60]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

import handmesh_tutorial as hmt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=60)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    net = hmt.pretrained.pretrained()
    size = hmt.pretrained.pretrained_info()["config"]["image_size"]
    x = torch.randn(1, 3, size, size, generator=torch.Generator().manual_seed(0))
    t0 = time.perf_counter()
    fast = hmt.export.onnx_network(threads=args.threads)
    export_s = time.perf_counter() - t0
    with torch.no_grad():
        frozen = torch.jit.optimize_for_inference(torch.jit.freeze(
            torch.jit.trace(net, (x,), strict=False, check_trace=False).eval()))
    import copy

    cl = copy.deepcopy(net).to(memory_format=torch.channels_last)
    xcl = x.contiguous(memory_format=torch.channels_last)
    rows = {
        "torch eager": lambda: net(x),
        "torch channels_last": lambda: cl(xcl),
        "torch jit freeze": lambda: frozen(x),
        "onnxruntime": lambda: fast(x),
    }
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    box = (250, 180, 390, 330)
    rows["predict_hand, eager"] = lambda: hmt.inference.predict_hand(image, box, "right")
    rows["predict_hand, onnxruntime"] = lambda: hmt.inference.predict_hand(image, box, "right",
                                                                           model=fast)
    with torch.inference_mode():
        ref = net(x)["vertices"]
        diffs = {k: float((torch.as_tensor(f()["vertices"]) - ref).abs().max())
                 for k, f in list(rows.items())[:4]}
        for f in rows.values():  # warm-up
            for _ in range(3):
                f()
        times: dict[str, list[float]] = {k: [] for k in rows}
        for _ in range(args.repeats):
            for k, f in rows.items():
                s = time.perf_counter()
                f()
                times[k].append(time.perf_counter() - s)
    print(f"{size}-px crop, batch 1, {args.threads} thread(s), {args.repeats} calls per row, "
          f"os.cpu_count()={os.cpu_count()}, load average {os.getloadavg()[0]:.2f}; "
          f"ONNX export {export_s:.1f} s")
    base = float(np.median(times["torch eager"]))
    print(f"{'':28s} {'median ms':>10s} {'min ms':>8s} {'x eager':>8s} {'max|dv| m':>10s}")
    for k, ts in times.items():
        med = float(np.median(ts))
        d = f"{diffs[k]:.1e}" if k in diffs else ""
        print(f"{k:28s} {med * 1e3:10.2f} {min(ts) * 1e3:8.2f} {med / base:8.2f} {d:>10s}")


if __name__ == "__main__":
    main()
