"""One lever of the CPU training recipe, measured: train, then score beside both constant hands.

Trains MSMR-Net with the demo's CPU recipe (``hmt.apps.demo.RECIPES["cpu"]``) plus the overrides
given on the command line on one INTER-SH training root, then scores the best checkpoint on a
held-out
root with ``hmt.train.evaluate`` beside the rest hand and the mean training hand, and measures the
2D keypoint head's error in the crop (pixels, and as a fraction of the crop side so that crop sizes
compare). Writes ``OUT/levers.json`` and prints one line.

Dev-only (not run by ``make benchmarks``): each run takes 10-30 CPU minutes. The numbers on the
docs page "Why the paper starts from pretrained weights" came from runs of this script, e.g.::

    handmesh generate --kind mixed --num 4000 --seed 100 --image-size 224 --out D/train
    handmesh generate --kind mixed --num 200 --seed 101 --image-size 224 --balance-vr --out D/test
    python benchmarks/dev/recipe_levers.py --train D/train --test D/test --out R/crop128 \\
        --image-size 128
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import torch

import handmesh_tutorial as hmt
from handmesh_tutorial.nn.keypoints import KeypointEncoder, normalised_keypoints


def keypoint_errors(model, dataset, batch_size: int = 32) -> np.ndarray:
    """Per-joint 2D error of the keypoint head on every item, as a fraction of the crop side.

    Returns:
        ``(N, 21)`` distances; multiply by the crop side for pixels.
    """
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, shuffle=False)
    errors = []
    model.eval()
    with torch.no_grad():
        for batch in loader:
            out = model(batch["image"])
            target = normalised_keypoints(batch["joints"], batch["root"], batch["K"],
                                          dataset.image_size)
            # normalised units: 2 = the crop side
            errors.append(((out["uv"] - target).norm(dim=-1) / 2).numpy())
    return np.concatenate(errors)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", required=True, help="INTER-SH training root")
    parser.add_argument("--test", required=True, help="held-out INTER-SH root")
    parser.add_argument("--out", required=True, help="run folder")
    parser.add_argument("--image-size", type=int, default=64, help="network crop side, px")
    parser.add_argument("--epochs", type=int, default=8)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--encoder", default="resnet10")
    parser.add_argument("--recipe", default="cpu", choices=sorted(hmt.apps.demo.RECIPES))
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=JSON",
                        help="TrainConfig override, e.g. normal_weight=0.2 or "
                             'model_kwargs={"keypoints":true}')
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    overrides = {k: json.loads(v) for k, v in (s.split("=", 1) for s in args.set)}
    recipe = {**hmt.apps.demo.RECIPES[args.recipe]}
    if "model_kwargs" in overrides:
        recipe["model_kwargs"] = {**recipe.get("model_kwargs", {}), **overrides.pop("model_kwargs")}
    recipe.update(overrides)
    fields = dict(
        data=args.train, out_dir=args.out, val_fraction=0.1, image_size=args.image_size,
        epochs=args.epochs, batch_size=args.batch_size, lr=1e-3,
        lr_step=max(1, round(0.75 * args.epochs)), augment=False, encoder=args.encoder,
        seed=args.seed, device="cpu", threads=args.threads, cache_data=True, progress=False,
        durable=False)
    cfg = hmt.train.TrainConfig(**{**fields, **recipe})
    t0 = time.perf_counter()
    result = hmt.train.train(cfg, resume=(Path(args.out) / "checkpoint_last.pt").exists())
    train_s = time.perf_counter() - t0

    train_set, _ = hmt.train.make_datasets(cfg)
    mean = hmt.train.mean_hand(train_set)
    test_set = hmt.data.augment.InterSHTorchDataset(hmt.data.InterSHDataset(args.test),
                                               image_size=args.image_size, train=False,
                                               augment=False, box_scale=cfg.box_scale)
    model, _ = hmt.train.load_checkpoint(result.best_checkpoint)
    ev = hmt.train.evaluate(model, dataset=test_set, image_size=args.image_size, progress=False,
                            threads=args.threads, mean_hand=mean, device="cpu")
    kp = keypoint_errors(model, test_set) if isinstance(model.encoder, KeypointEncoder) else None

    def pick(scores):
        return {k: float(scores[k]) for k in ("mpjpe", "pa_mpjpe", "pa_mpvpe", "f_at_5mm",
                                               "f_at_15mm", "roughness_deg", "flipped")
                if k in scores}

    report = {
        "args": vars(args), "config": dataclasses.asdict(cfg),
        "steps": result.steps, "train_seconds": train_s,
        "model": pick(ev["scores"]), "rest_hand": pick(ev["baseline"]["scores"]),
        "mean_hand": pick(ev["mean_hand_baseline"]["scores"]),
        "keypoints": None if kp is None else {
            "mean_fraction": float(kp.mean()), "mean_px": float(kp.mean() * args.image_size),
            "median_px": float(np.median(kp) * args.image_size),
            "fingertips_px": float(kp[:, [4, 8, 12, 16, 20]].mean() * args.image_size)},
        "per_kind": {row["bin"]: row for row in ev["kind_table"]},
    }
    Path(args.out, "levers.json").write_text(json.dumps(report, indent=1, default=float))
    m, r, h = report["model"], report["rest_hand"], report["mean_hand"]
    kps = "" if kp is None else (f", keypoints {report['keypoints']['mean_px']:.2f} px "
                                 f"({100 * report['keypoints']['mean_fraction']:.1f}% of side)")
    print(f"{args.out}: PA-MPJPE {m['pa_mpjpe']:.2f} (rest {r['pa_mpjpe']:.2f}, mean hand "
          f"{h['pa_mpjpe']:.2f}; {m['pa_mpjpe'] / r['pa_mpjpe']:.2f}x rest), PA-MPVPE "
          f"{m['pa_mpvpe']:.2f}, rough {m['roughness_deg']:.1f} deg, flipped "
          f"{100 * m['flipped']:.1f}%{kps}; {result.steps} steps in {train_s / 60:.1f} min")
    return report


if __name__ == "__main__":
    main()
