"""The decoder-neutral encoder's levers, measured before its long run (issue 51).

What buys validation accuracy, and what buys speed, for ``handmesh pretrain-encoder`` on a CPU:

1. **Speed** (``speed``): seconds per training step (forward, loss, backward, AdamW) at batch
   ``--batch-size`` for float32 vs bfloat16 autocast, contiguous vs channels-last images, and
   64 vs 128 px crops; medians of interleaved repeats, printed as ratios to the recipe's
   (bfloat16, contiguous, the 64/96/128 mix).
2. **Quality** (the other arms): each arm trains a ResNet-10 pose network from random weights for
   ``--steps`` steps (the recipe of ``make pretrained-encoder`` otherwise: batch, learning rate,
   cosine schedule, augmentation), one lever changed:

   * ``recipe``: all training crops, crops 64/96/128 px in turn, augmentation on;
   * ``scenes-8k``: only the first 8,000 training crops (the old encoder's count);
   * ``crops-64`` / ``crops-128``: one crop side only;
   * ``no-augment``: no rotation, zoom, shift or colour change.

   Every arm is scored on the same held-out crops (the run's validation scenes) at 64 and 128
   px; each arm is compared with ``recipe`` crop by crop (paired differences of PA-MPJPE: mean
   and 95 % interval, normal approximation over crops), beside the constant answers (rest hand,
   mean training hand). ``recipe``'s validations every ``steps / 4`` give the steps curve.

Arms are ``pretrain_pose_encoder`` runs in ``--out/<arm>``: a killed run resumes from its
checkpoint when rerun, finished arms are read back, results go to ``--out/levers.json``
(atomically) after each arm. Dev-only (hours of CPU; not run by ``make benchmarks``)::

    # the scenes and crops of a pretrain-encoder run (its --out), e.g. made by
    # handmesh pretrain-encoder --out R --data-seed 1200 --train-scenes 40000 --stop-after-steps 1
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/dev/encoder_levers.py --run R \\
        --out runs/encoder_levers --steps 1500 [--arms speed,recipe,scenes-8k,...]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from handmesh_tutorial._io import write_json
from handmesh_tutorial._untrusted import load_torch_file
from handmesh_tutorial.apps.pose_pretraining import (
    PosePretrainConfig,
    _draws,
    _procrustes_mean,
    evaluate_pose,
    pretrain_pose_encoder,
)
from handmesh_tutorial.data.batched_crops import augment_crops
from handmesh_tutorial.hand import HandModel
from handmesh_tutorial.nn.pose_encoder import build_pose_net, pose_loss

ARMS = {  # name: (config changes, training crops kept: None = all)
    "recipe": ({}, None),
    "scenes-8k": ({}, 8000),
    "crops-64": ({"image_sizes": (64,)}, None),
    "crops-128": ({"image_sizes": (128,)}, None),
    "no-augment": ({"rotation": 0.0, "scale": 0.0, "shift": 0.0, "colour": 0.0}, None),
}


def _timed_steps(net, opt, cache: dict, config: PosePretrainConfig, *, size: int,
                 precision: str, channels_last: bool, block: int, steps: int) -> list[float]:
    """Seconds of each of ``steps`` training steps (after one untimed warm-up step)."""
    n = len(cache["image"])
    times = []
    for s in range(steps + 1):
        idx = torch.as_tensor(np.random.default_rng([block, s]).choice(n, config.batch_size,
                                                                      replace=False))
        t0 = time.perf_counter()
        b = {k: v[idx] for k, v in cache.items()}
        v = augment_crops(b, size, draws=_draws(config, len(idx), s, torch.device("cpu")))
        images = v["image"]
        if channels_last:
            images = images.contiguous(memory_format=torch.channels_last)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bfloat16"):
            o = net(images)
        o = {k: t.float() for k, t in o.items()}
        loss, _ = pose_loss(o, v["joints"], v["root"], v["K"], size,
                            config.keypoint_weight, config.aligned_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if s:  # the first step of a block warms caches up
            times.append(time.perf_counter() - t0)
    return times


def speed(cache: dict, config: PosePretrainConfig, repeats: int, steps: int = 5) -> dict:
    """Seconds per step of each variant: medians over ``repeats`` interleaved blocks."""
    variants = {  # name: (sizes, precision, channels_last)
        "recipe (bf16, 64/96/128 mix)": (config.image_sizes, "bfloat16", False),
        "float32": (config.image_sizes, "float32", False),
        "channels-last": (config.image_sizes, "bfloat16", True),
        "64 px only": ((64,), "bfloat16", False),
        "128 px only": ((128,), "bfloat16", False),
    }
    nets = {}
    for name, (_, _, cl) in variants.items():
        torch.manual_seed(0)
        net = build_pose_net(config.backbone).train()
        if cl:
            net = net.to(memory_format=torch.channels_last)
        nets[name] = (net, torch.optim.AdamW(net.parameters(), lr=1e-4))
    times: dict[str, list[float]] = {name: [] for name in variants}
    for block in range(repeats + 1):  # block 0 warms every variant up, untimed
        for name, (sizes, precision, cl) in variants.items():
            per_size = [np.median(_timed_steps(*nets[name], cache, config, size=s,
                                               precision=precision, channels_last=cl,
                                               block=block, steps=steps)) for s in sizes]
            if block:
                times[name].append(float(np.mean(per_size)))
    out = {name: float(np.median(t)) for name, t in times.items()}
    for name, t in out.items():
        print(f"  {name:32s} {t:.3f} s/step", flush=True)
    base = out["recipe (bf16, 64/96/128 mix)"]
    return {"seconds_per_step": out, "ratio_to_recipe": {k: v / base for k, v in out.items()}}


def paired(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of ``a - b`` (mm) with its 95 % interval over crops (normal approximation)."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    half = 1.96 * d.std(ddof=1) / math.sqrt(len(d))
    return {"mean": float(d.mean()), "low": float(d.mean() - half),
            "high": float(d.mean() + half)}


def scores(folder: Path, config: PosePretrainConfig, val: dict, baselines: dict) -> dict:
    ck = load_torch_file(folder / "checkpoint.pt")
    net = build_pose_net(config.backbone)
    net.load_state_dict(ck["model"])
    return {"steps": int(ck["step"]), "history": ck["history"],
            **evaluate_pose(net, val, baselines=baselines, per_crop=True)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True,
                    help="a pretrain-encoder --out folder holding crops_train.pt, crops_val.pt")
    ap.add_argument("--out", type=Path, default=Path("runs/encoder_levers"))
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch-size", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=3, help="speed: interleaved repeats")
    ap.add_argument("--arms", default="speed," + ",".join(ARMS))
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    train = load_torch_file(args.run / "crops_train.pt")
    val = load_torch_file(args.run / "crops_val.pt")
    base = PosePretrainConfig(batch_size=args.batch_size, max_steps=args.steps,
                              train_scenes=len(train["image"]), val_scenes=len(val["image"]))
    results_file = args.out / "levers.json"
    results = json.loads(results_file.read_text()) if results_file.exists() else {}
    results["setup"] = {"train_crops": len(train["image"]), "val_crops": len(val["image"]),
                        "steps": args.steps, "batch_size": args.batch_size,
                        "threads": torch.get_num_threads(), "run": args.run.name}
    rest = HandModel()().joints[0]
    baselines = {"rest hand": rest - rest[9],
                 "mean training hand": _procrustes_mean(train["joints"][:4000])}
    arms = [a for a in args.arms.split(",") if a]
    for arm in arms:
        if arm == "speed":
            print(f"speed (s per step, batch {args.batch_size}):", flush=True)
            results["speed"] = speed(train, base, args.repeats)
        else:
            changes, keep = ARMS[arm]
            crops = train if keep is None else {k: v[:keep] for k, v in train.items()}
            config = replace(base, train_scenes=len(crops["image"]), **changes)
            t0 = time.perf_counter()
            pretrain_pose_encoder(crops, val, args.out / arm, config,
                                  val_every=max(1, args.steps // 4), log=print)
            got = scores(args.out / arm, config, val, baselines)
            results.setdefault("arms", {})[arm] = {
                "changes": {k: list(v) if isinstance(v, tuple) else v
                            for k, v in changes.items()},
                "train_crops": len(crops["image"]), "steps": got["steps"],
                "seconds_this_call": round(time.perf_counter() - t0, 1),
                "curve": [{"step": h["step"], "64": h["64"]["pa_mpjpe"],
                           "128": h["128"]["pa_mpjpe"]} for h in got["history"]],
                **{s: {"pa_mpjpe": got[s]["pa_mpjpe"]} for s in ("64", "128")},
                "per_crop": {s: got[s]["pa_per_crop"].round(4).tolist() for s in ("64", "128")},
                "baselines": {n: got[n]["pa_mpjpe"] for n in baselines}}
            base_pc = {n: got[n]["pa_per_crop"] for n in baselines}
            results["baselines_per_crop"] = {n: v.round(4).tolist() for n, v in base_pc.items()}
        write_json(results_file, results)
    rec = results.get("arms", {}).get("recipe")
    if rec:
        print("\nheld-out PA-MPJPE (mm) and paired difference to 'recipe' (95 % interval):")
        for arm, r in results["arms"].items():
            line = f"  {arm:12s} steps {r['steps']:6d}"
            for s in ("64", "128"):
                d = paired(r["per_crop"][s], rec["per_crop"][s])
                line += (f" | {s} px {r[s]['pa_mpjpe']:.2f} ({d['mean']:+.2f}, "
                         f"{d['low']:+.2f} to {d['high']:+.2f})")
            print(line)
        for n, v in results["baselines_per_crop"].items():
            print(f"  {n}: {np.mean(v):.2f}")
    write_json(results_file, results)


if __name__ == "__main__":
    main()
