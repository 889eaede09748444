"""The paper's Table 3 ablation at laptop scale
([`run_ablation`][handmesh_tutorial.apps.demo.ablation.run_ablation]).

Single path, multi-path and multi-path + attention, at equal depth, on the same data, from the same
encoder weights, a few seeds each; every run scored on the same held-out scenes beside the two
constant hands, and the variants compared by their differences with 95 % intervals
([`compare_variants`][handmesh_tutorial.apps.demo.ablation.compare_variants]). Taught in notebook 10
("Ablation"); `benchmarks/dev/ablation_encoder_init.py` runs it from another encoder.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .config import DemoConfig, train_config

__all__ = ["VARIANTS", "run_ablation", "compare_variants", "T95"]

VARIANTS = {
    "single path": {"decoder": "single", "attention": False},
    "multi-path": {"decoder": "multi", "attention": False},
    "multi-path + attention": {"decoder": "multi", "attention": True},
}
"""The three rows of the paper's Table 3 (``build_model`` / ``TrainConfig`` overrides)."""

T95 = {2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 8: 2.306, 10: 2.228}
"""Two-sided 95 % Student t quantiles by degrees of freedom."""


def _t95(df: float) -> float:
    keys = sorted(T95)
    return T95[min(keys, key=lambda k: abs(k - df))] if df < 30 else 1.96


def run_ablation(config: DemoConfig, data: dict, out: str | os.PathLike, *,
                 seeds=(0, 1, 2), epochs: int | None = None, variants: dict | None = None,
                 init_encoder: str | None = "config", train_overrides: dict | None = None,
                 log=print) -> dict:
    """Train and evaluate every variant with every seed (resumable: finished runs are read back).

    Args:
        config: the demo's sizes ([`DemoConfig`][handmesh_tutorial.apps.demo.config.DemoConfig]).
        data: [`generate_data`][handmesh_tutorial.apps.demo.run.generate_data]'s result (``train``
            and ``test`` roots).
        out: folder of the runs (one sub-folder per variant and seed).
        seeds: training seeds (initial weights of the trained parts, data order, validation split).
        epochs: epochs per run (default ``config.epochs``); the rate is halved after three
            quarters of them.
        variants: ``{name: overrides}`` (default
            [`VARIANTS`][handmesh_tutorial.apps.demo.ablation.VARIANTS]).
        init_encoder: ``"config"`` (the config's), ``None`` (random weights), ``"pretrained"`` or a
            pose-encoder file.
        train_overrides: further [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig]
            fields for every run (e.g. ``device="cuda"``).
        log: one line per run (``None``: silent).

    Returns:
        ``{"runs": {(variant, seed): {...}}, "baselines": {...}, "val_baselines": {seed: {...}}}``:
        per run the test ``scores``, ``per_sample`` PA-MPJPE (mm), ``history``, ``predictions``,
        ``index``, ``vr`` (the target's visibility ratio per test scene), ``seconds`` (median
        per epoch), ``params``; the constant hands' test scores
        and, per seed, their scores on that seed's validation scenes.
    """
    from ... import train as T
    from ...nn.model import parameter_counts

    say = log or (lambda *_: None)
    variants = VARIANTS if variants is None else variants
    epochs = config.epochs if epochs is None else int(epochs)
    extra = {"epochs": epochs, "lr_step": max(1, round(0.75 * epochs))}
    if init_encoder != "config":
        extra["init_encoder"] = init_encoder
        if init_encoder is None:
            extra.update(freeze_encoder=0, encoder_lr_scale=1.0)
    extra.update(train_overrides or {})
    out = Path(out)
    runs, val_base, mean = {}, {}, None
    for seed in seeds:
        for name, kw in variants.items():
            run_dir = out / (name.replace(" ", "_").replace("+", "plus") + f"_seed{seed}")
            tcfg = train_config(config, data["train"], run_dir, seed=seed, progress=False,
                                **kw, **extra)
            if mean is None:  # the data's average hand: one constant for every run
                mean = T.mean_hand(T.make_datasets(tcfg)[0])
            if seed not in val_base:
                val_ds = T.make_datasets(tcfg)[1]
                val_base[seed] = {"rest hand": T.constant_hand_scores(val_ds),
                                  "mean training hand": T.constant_hand_scores(val_ds, mean)}
            res = T.train(tcfg, resume=(run_dir / "checkpoint_last.pt").exists())
            best = res.best_checkpoint or res.checkpoint
            ev = T.evaluate(best, str(data["test"]), progress=False, mean_hand=mean,
                            image_size=tcfg.image_size)
            runs[name, seed] = {
                "scores": ev["scores"], "history": res.history,
                "per_sample": np.asarray(ev["per_sample"]["pa_mpjpe"], dtype=float),
                "vr": np.asarray(ev["per_sample"]["vr"], dtype=float),
                "predictions": ev["predictions"]["vertices"], "index": ev["per_sample"]["index"],
                "seconds": float(np.median([r["seconds"] for r in res.history])),
                "params": parameter_counts(res.model)["total"], "faces": res.model.faces}
            say(f"{name:>24}, seed {seed}: PA-MPJPE {ev['scores']['pa_mpjpe']:.2f} mm, "
                f"PA-MPVPE {ev['scores']['pa_mpvpe']:.2f} mm")
    baselines = {"rest hand": ev["baseline"]["scores"],
                 "mean training hand": ev["mean_hand_baseline"]["scores"],
                 "rest hand per sample": np.asarray(ev["baseline"]["per_sample"]["pa_mpjpe"]),
                 "mean hand per sample": np.asarray(
                     ev["mean_hand_baseline"]["per_sample"]["pa_mpjpe"])}
    return {"runs": runs, "baselines": baselines, "val_baselines": val_base}


def compare_variants(runs: dict, key: str = "pa_mpjpe") -> list[dict]:
    """Every pair of variants: the difference of their seed means with a 95 % interval.

    The interval is Welch's t interval over the per-seed scores (each seed one independent run),
    so it counts the run-to-run spread; a pair whose interval contains 0 is not told apart.

    Args:
        runs: ``run_ablation(...)["runs"]``.
        key: the score compared.

    Returns:
        One dict per pair: ``a``, ``b``, ``difference`` (a - b), ``low``, ``high``.
    """
    names = list(dict.fromkeys(n for n, _ in runs))
    vals = {n: np.array([r["scores"][key] for (m, _), r in runs.items() if m == n]) for n in names}
    rows = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            va, vb = vals[a].var(ddof=1) / len(vals[a]), vals[b].var(ddof=1) / len(vals[b])
            se = math.sqrt(va + vb)
            df = (va + vb) ** 2 / (va ** 2 / (len(vals[a]) - 1) + vb ** 2 / (len(vals[b]) - 1)) \
                if se > 0 else 30
            d = float(vals[a].mean() - vals[b].mean())
            h = _t95(df) * se
            rows.append({"a": a, "b": b, "difference": d, "low": d - h, "high": d + h})
    return rows
