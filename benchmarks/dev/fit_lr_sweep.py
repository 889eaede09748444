"""A fair fit test of the decoder outputs (issue 41): a learning-rate sweep, then steps doubled
until the fit stops improving.

Notebook 07 fits each decoder output once (800 steps, the probe's default learning rate); the
paper's xyz output ends that run crumpled while its loss still falls. Here each output gets:

1. a sweep over ``--lrs`` at ``--steps`` steps (cosine decay to zero, as ``fit_decoder`` always
   does), all on the same 32 posed hands, codes and seed;
2. at its best learning rate (lowest final vertex error), runs of 2x, 4x, ... the steps until the
   error improves by less than ``--stop`` (a share, default 5 %) from one doubling to the next,
   or ``--max-steps`` is reached: "until the loss stops falling" for a schedule that decays to
   zero, where each run's end is its converged value for that many steps.

Outputs: ``xyz`` (the paper's: the last spiral conv writes coordinates, Xavier head, no
smoothing), ``affine`` (the library default: zero-initialised affine map of the template, 9-mm
smoothing) and ``skinned`` (16 joint rotations and a shape, skinned), all multi-path with
attention. Each row: final vertex error (mm), roughness (degrees), flipped faces, seconds.
Rows are written to ``--out`` (JSON) as they finish; a rerun skips the rows already there.

Run: ``python benchmarks/dev/fit_lr_sweep.py [--out runs/fit_lr_sweep.json] [--threads 1]``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

import handmesh_tutorial as hmt
from handmesh_tutorial._io import write_json
from handmesh_tutorial.train import fit_probe

OUTPUTS = {
    "xyz": dict(output="xyz", smoothing_length=0.0, zero_head=False, head="spiral"),
    "affine": {},
    "skinned": dict(output="skinned"),
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/fit_lr_sweep.json"))
    ap.add_argument("--outputs", nargs="+", default=list(OUTPUTS), choices=list(OUTPUTS))
    ap.add_argument("--lrs", type=float, nargs="+", default=[3e-4, 1e-3, 3e-3, 1e-2])
    ap.add_argument("--steps", type=int, default=800)
    ap.add_argument("--max-steps", type=int, default=6400)
    ap.add_argument("--stop", type=float, default=0.05)
    ap.add_argument("--num", type=int, default=32)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    hand = hmt.hand.HandModel("right")
    hier = hmt.nn.hierarchy.mesh_hierarchy(hand.template_vertices, hand.faces)
    hands, _ = fit_probe.posed_hands(args.num, seed=0, hand=hand)
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []

    def fit(name: str, lr: float, steps: int) -> dict:
        for r in rows:
            if (r["output"], r["lr"], r["steps"]) == (name, lr, steps):
                return r
        res = fit_probe.fit_decoder({"decoder": "multi", **OUTPUTS[name], "template": hand,
                                     "hierarchy": hier}, hands, steps=steps,
                                    batch_size=args.batch, seed=0, lr=lr)
        row = {"output": name, "lr": lr, "steps": steps, "error_mm": res.error_mm,
               "roughness_deg": res.roughness_deg, "flipped": res.flipped,
               "seconds": round(res.seconds, 1),
               "loss_last_tenth_mm": 1000 * float(res.losses[-max(1, steps // 10):].mean())}
        rows.append(row)
        write_json(args.out, {"rows": rows, "settings": {k: (str(v) if isinstance(v, Path)
                                                              else v)
                                                          for k, v in vars(args).items()}})
        print(f"{name:8s} lr {lr:<7g} {steps:5d} steps: {row['error_mm']:6.2f} mm, roughness "
              f"{row['roughness_deg']:5.1f} deg, flipped {row['flipped']:.1%} "
              f"({row['seconds']:.0f} s)", flush=True)
        return row

    for name in args.outputs:
        sweep = [fit(name, lr, args.steps) for lr in args.lrs]
        best = min(sweep, key=lambda r: r["error_mm"])
        last, steps = best, 2 * args.steps
        while steps <= args.max_steps:
            row = fit(name, best["lr"], steps)
            gain = (last["error_mm"] - row["error_mm"]) / last["error_mm"]
            last, steps = row, 2 * steps
            if gain < args.stop:
                break
        print(f"{name}: best lr {best['lr']:g}; converged run {last['steps']} steps: "
              f"{last['error_mm']:.2f} mm, roughness {last['roughness_deg']:.1f} deg, "
              f"flipped {last['flipped']:.1%}", flush=True)


if __name__ == "__main__":
    main()
