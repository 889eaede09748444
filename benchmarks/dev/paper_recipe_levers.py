"""The paper's recipe on a CPU: each of its own levers measured beside both constant hands.

The paper's network and loss (``TrainConfig.preset("paper")``: the decoder regresses the vertex
coordinates, one L1 loss on the root-centred vertices) at the demo's sizes, from the frozen
pretrained encoder, with one lever changed per run: learning rate, epochs, batch size, the
spiral output head CMR uses, the crop side, and where the encoder's features are pooled. Each run
is scored on the same held-out scenes beside the rest hand and the mean training hand, with the
paired 95 % interval of its difference to the mean hand, its surface roughness and flipped faces.

Tuned on data of seed 20 (not the demo's 0, nor any test seed the docs report), so the
choice is not made on the scenes the demo reports. Resumable: finished runs are read back from
``OUT/<lever>/result.json``. Dev-only: each run takes 3-8 CPU minutes. Example::

    python benchmarks/dev/paper_recipe_levers.py --out runs/paper_levers \
        --levers base,spiral_head,lr3e-4,lr3e-3,epochs20,batch32,joint_pooling
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

LEVERS: dict[str, dict] = {
    "base": {},
    "spiral_head": {"model_kwargs": {"output": "xyz", "smoothing_length": 0.0,
                                     "head": "spiral"}},
    "lr3e-4": {"lr": 3e-4},
    "lr3e-3": {"lr": 3e-3},
    "lr1e-2": {"lr": 1e-2},
    # DemoConfig's freeze_encoder=10: past epoch 10 the encoder is fine-tuned at 0.1x the rate
    "epochs20": {"epochs": 20, "lr_step": 15},
    # the paper's schedule shape: halved after each quarter of the epochs (it: 50 of 200)
    "quarter_halving": {"lr_step": 3},
    "epochs20_quarter_halving": {"epochs": 20, "lr_step": 5},
    "epochs20_frozen_quarter_halving": {"epochs": 20, "lr_step": 5, "freeze_encoder": 20},
    "batch32": {"batch_size": 32},
    "batch8": {"batch_size": 8},
    "joint_pooling": {"model_kwargs": {"output": "xyz", "smoothing_length": 0.0,
                                       "keypoints": True}},
    "joint_pooling_spiral": {"model_kwargs": {"output": "xyz", "smoothing_length": 0.0,
                                              "keypoints": True, "head": "spiral"}},
}
"""Overrides of the paper recipe's demo config, one lever each (``base``: none)."""


def run_lever(name: str, overrides: dict, data: dict, out: Path, encoder: str,
              seed: int = 0, threads: int = 2) -> dict:
    import handmesh_tutorial.train as T
    from handmesh_tutorial.apps.demo import DemoConfig, train_config
    from handmesh_tutorial.metrics.intervals import paired_difference

    path = out / name / "result.json"
    if path.exists():
        return json.loads(path.read_text())
    cfg = DemoConfig(recipe="paper", init_encoder=encoder, threads=threads)
    tcfg = train_config(cfg, data["train"], out / name, seed=seed, progress=False, **overrides)
    t = time.perf_counter()
    res = T.train(tcfg, resume=(out / name / "checkpoint_last.pt").exists())
    seconds = time.perf_counter() - t
    mean = T.mean_hand(T.make_datasets(tcfg)[0])
    ev = T.evaluate(res.best_checkpoint or res.checkpoint, str(data["test"]), progress=False,
                    mean_hand=mean, image_size=tcfg.image_size)
    model = np.asarray(ev["per_sample"]["pa_mpjpe"])
    mean_ps = np.asarray(ev["mean_hand_baseline"]["per_sample"]["pa_mpjpe"])
    row = {"lever": name, "overrides": overrides, "encoder": encoder,
           "pa_mpjpe": ev["scores"]["pa_mpjpe"], "pa_mpvpe": ev["scores"]["pa_mpvpe"],
           "roughness_deg": ev["scores"].get("roughness_deg"),
           "flipped": ev["scores"].get("flipped"),
           "rest_hand": ev["baseline"]["scores"]["pa_mpjpe"],
           "mean_hand": ev["mean_hand_baseline"]["scores"]["pa_mpjpe"],
           "vs_mean_hand": paired_difference(model, mean_ps),
           "val_pa_mpjpe": [r.get("val_pa_mpjpe") for r in res.history],
           "epochs": res.epochs, "train_seconds": round(seconds, 1),
           "per_sample_pa_mpjpe": model.tolist()}
    path.write_text(json.dumps(row, indent=1))
    return row


def main(argv=None) -> list:
    from handmesh_tutorial.apps.demo import DemoConfig, generate_data

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--data", default=None, help="demo data root (default: OUT/data)")
    p.add_argument("--data-seed", type=int, default=20)
    p.add_argument("--encoder", default="pretrained", help="pose-encoder file or 'pretrained'")
    p.add_argument("--levers", default=",".join(LEVERS))
    p.add_argument("--threads", type=int, default=2, help="torch threads per run")
    args = p.parse_args(argv)
    out = Path(args.out)
    data = generate_data(Path(args.data) if args.data else out / "data", DemoConfig(),
                         seed=args.data_seed, progress=False)
    rows = []
    for name in args.levers.split(","):
        r = run_lever(name, LEVERS[name], data, out, args.encoder, threads=args.threads)
        d = r["vs_mean_hand"]
        print(f"{name:>22}: PA-MPJPE {r['pa_mpjpe']:.2f} mm (mean hand {r['mean_hand']:.2f}, "
              f"rest {r['rest_hand']:.2f}; vs mean {d['difference']:+.2f} [{d['low']:+.2f}, "
              f"{d['high']:+.2f}]) rough {r['roughness_deg']:.1f} deg, flipped "
              f"{100 * r['flipped']:.2f} %, {r['train_seconds']:.0f} s", flush=True)
        rows.append(r)
    # each lever against the base run on the same scenes: what the lever gained
    base = next((r for r in rows if r["lever"] == "base"), None)
    if base is not None:
        from handmesh_tutorial.metrics.intervals import paired_difference

        for r in rows:
            if r is not base:
                d = paired_difference(np.asarray(r["per_sample_pa_mpjpe"]),
                                      np.asarray(base["per_sample_pa_mpjpe"]))
                r["vs_base"] = d
                print(f"{r['lever']:>22} - base: {d['difference']:+.2f} mm "
                      f"[{d['low']:+.2f}, {d['high']:+.2f}]", flush=True)
    (out / "levers.json").write_text(json.dumps(
        [{k: v for k, v in r.items() if k != "per_sample_pa_mpjpe"} for r in rows], indent=1))
    return rows


if __name__ == "__main__":
    main()
