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

Run: ``python benchmarks/dev/fit_lr_sweep.py [--out runs/fit_lr_sweep.json] [--threads 1]``
(one process per output with ``--outputs`` runs them side by side). ``--install A.json B.json
...`` merges such files into the package's ``assets/fit_sweep_results.json`` with their
provenance (``hmt.train.fit_probe.shipped_fit_sweep`` reads it; notebook 07 prints it).
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


def summarise(rows: list[dict], base_steps: int, stop: float) -> dict:
    """Per output: the best rate at ``base_steps`` and the run where doubling stopped paying."""
    best = {}
    for name in dict.fromkeys(r["output"] for r in rows):
        sweep = [r for r in rows if r["output"] == name and r["steps"] == base_steps]
        top = min(sweep, key=lambda r: r["error_mm"])
        chain = sorted((r for r in rows if r["output"] == name and r["lr"] == top["lr"]),
                       key=lambda r: r["steps"])
        last = chain[0]
        for row in chain[1:]:
            gain = (last["error_mm"] - row["error_mm"]) / last["error_mm"]
            last = row
            if gain < stop:
                break
        best[name] = {"lr": top["lr"], "swept": sorted(r["lr"] for r in sweep),
                      "converged": last, "converged_by_stop_rule": len(chain) > 1 and gain < stop}
    return best


def install(files: list[Path]) -> Path:
    """Merge sweep files into ``assets/fit_sweep_results.json`` with their provenance."""
    import datetime
    import sys

    from handmesh_tutorial import _version
    from handmesh_tutorial._io import atomic_write_text
    from handmesh_tutorial.apps.pretrain_network import _commit, _hardware

    rows, settings = [], {}
    for f in files:
        d = json.loads(Path(f).read_text())
        rows += d["rows"]
        settings = {**d["settings"], "outputs": sorted({r["output"] for r in rows})}
    for key in ("out", "install", "lrs"):  # the rates swept are per output, in "best"
        settings.pop(key, None)
    doc = {"rows": rows, "best": summarise(rows, settings["steps"], settings["stop"]),
           "settings": settings,
           "provenance": {"command": "python benchmarks/dev/fit_lr_sweep.py (one process per "
                                     "output) then --install", "commit": _commit(),
                          "date": datetime.date.today().isoformat(), "hardware": _hardware("cpu"),
                          "torch": torch.__version__, "python": sys.version.split()[0],
                          "hands": f"{settings['num']} posed hands of the MakeHuman right hand "
                                   "(fit_probe.posed_hands, seed 0), batch "
                                   f"{settings['batch']}, multi-path decoder with attention"}}
    target = _version.ASSET_DIR / fit_probe.SWEEP_FILE
    atomic_write_text(target, json.dumps(doc, indent=1, sort_keys=True) + "\n")
    return target


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
    ap.add_argument("--install", type=Path, nargs="+", help="merge these sweep files into the "
                    "package's assets/fit_sweep_results.json and stop")
    args = ap.parse_args(argv)
    if args.install:
        print(f"wrote {install(args.install)}")
        return
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
