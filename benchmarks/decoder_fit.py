"""Benchmark: the decoder fit test (auto-decoder on posed hands) for the levers of issue 11.

Each row builds the model's mesh part with some :func:`handmesh_tutorial.nn.model.build_model`
options, fits it to ``--num`` posed hands of the library's hand with
``fit_decoder`` of ``benchmarks/fit_probe.py`` (one learnable code per hand, L1 vertex loss, Adam,
cosine decay) and prints the mean vertex error (mm), the roughness (mean |dihedral-angle
difference|, degrees), the flipped-face fraction and the CPU time of the optimisation.

``old`` is the decoder before the fixes (xyz output, Xavier spiral head, no template, no
smoothing); ``new`` the current defaults (zero-initialised linear head, per-vertex affine map of
the template, output smoothing over 9 mm). The rows in between switch one lever at a time.

Run: ``python benchmarks/decoder_fit.py [--rows old new ...] [--decoder multi single]
[--num 32] [--steps 1000] [--batch 8] [--rotate] [--threads 1]``. One row takes about two CPU
minutes at the defaults (multi-path, 799-vertex hand, one thread).
"""

from __future__ import annotations

import argparse

import fit_probe as fit
import torch

import handmesh_tutorial as hmt

OLD = dict(output="xyz", smoothing_length=0.0, zero_head=False, head="spiral")
ROWS = {
    "old": OLD,
    "zero-head": {**OLD, "zero_head": True},
    "offset": {**OLD, "output": "offset"},
    "offset+zero-head": {**OLD, "output": "offset", "zero_head": True},
    "offset+zero+linear": dict(output="offset", smoothing_length=0.0),
    "offset+zero+linear+smooth": dict(output="offset", smoothing_length=0.0075),
    "affine+zero+linear": dict(output="affine", smoothing_length=0.0),
    "affine+smooth7.5": dict(output="affine", smoothing_length=0.0075),
    "affine+smooth9+spiral-head": dict(output="affine", head="spiral"),
    "affine+smooth9+pyramid-head": dict(output="affine", head="pyramid"),
    "new": {},
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", nargs="+", default=["old", "new"], choices=sorted(ROWS))
    ap.add_argument("--decoder", nargs="+", default=["multi"], choices=["multi", "single"])
    ap.add_argument("--num", type=int, default=32, help="posed hands N")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--batch", type=int, default=8, help="hands per step (0 = all)")
    ap.add_argument("--rotate", action="store_true", help="random global rotations too")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    hand = hmt.hand.HandModel("right")
    targets, _ = fit.posed_hands(args.num, seed=args.seed, hand=hand, rotate=args.rotate)
    rotated = ", rotated" if args.rotate else ""
    print(f"{args.num} posed hands ({hand.num_vertices} vertices){rotated}; {args.steps} steps"
          f", batch {args.batch or args.num}, {args.threads} thread(s)")
    print(f"{'decoder':<8}{'row':<30}{'error mm':>9}{'rough deg':>10}{'flipped':>8}"
          f"{'init mm':>8}{'CPU s':>7}")
    for kind in args.decoder:
        for name in args.rows:
            cfg = dict(decoder=kind, template=hand, **ROWS[name])
            r = fit.fit_decoder(cfg, targets, steps=args.steps, seed=args.seed,
                                batch_size=args.batch or None)
            print(f"{kind:<8}{name:<30}{r.error_mm:9.2f}{r.roughness_deg:10.1f}"
                  f"{100 * r.flipped:7.1f}%{r.init_error_mm:8.1f}{r.cpu_seconds:7.0f}",
                  flush=True)


if __name__ == "__main__":
    main()
