"""The paper's Table 3 asked in two configurations, with intervals, power and VR bins
([`run_table3`][handmesh_tutorial.apps.demo.table3.run_table3],
[`summarise_table3`][handmesh_tutorial.apps.demo.table3.summarise_table3]).

Table 3 compares three decoders (single path, multi-path, multi-path + attention). We ask it in
two training configurations, on one encoder that none of the compared decoders has trained:

* ``paper``: the paper's network and loss (the decoder regresses the vertex coordinates, one L1
  loss on the root-centred vertices);
* ``cpu``: the library's CPU recipe (2D keypoint head with pose pooling, global-rotation head,
  auxiliary losses, and the skinned output, which reduces any decoder's per-vertex field to 16
  joint rotations and a shape before it becomes a mesh).

If the skinned output hides differences between decoders, the decoders' spread is larger in the
``paper`` configuration; `summarise_table3` tests exactly that (``bottleneck``). Notebook 10 shows
the result; the full run's summary ships as ``assets/table3_results.json``
([`shipped_table3`][handmesh_tutorial.apps.demo.table3.shipped_table3]).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
from scipy import stats

from ...metrics.intervals import detectable_difference, paired_difference, seed_difference
from ...visibility import VR_BINS
from .ablation import run_ablation
from .config import DemoConfig

__all__ = ["CONFIGURATIONS", "run_table3", "summarise_table3", "shipped_table3", "format_table3",
           "RESULTS_FILE"]

CONFIGURATIONS = {
    "paper": "the paper's: xyz output, one L1 loss on the vertices",
    "cpu": "the CPU recipe: keypoint and rotation heads, skinned output, auxiliary losses",
}
"""The two training configurations Table 3 is asked in (``DemoConfig.recipe`` values)."""

RESULTS_FILE = "table3_results.json"
"""The shipped summary of the full two-configuration run (in the package's assets)."""


def run_table3(data: dict, out: str | os.PathLike, *, encoder: str,
               config: DemoConfig | None = None, configurations=tuple(CONFIGURATIONS),
               seeds=(0, 1, 2), epochs: int | None = None, variants: dict | None = None,
               train_overrides: dict | None = None, log=print) -> dict:
    """Train and evaluate every decoder, seed and configuration (resumable per run).

    Args:
        data: ``generate_data(...)``'s ``train`` and ``test`` roots.
        out: folder of the runs (``out/<configuration>/<variant>_seed<k>``).
        encoder: the pose-encoder file every run starts from (frozen), or ``"pretrained"``.
        config: the demo's sizes (default ``DemoConfig()``); its recipe is replaced.
        configurations: names of `CONFIGURATIONS`.
        seeds: training seeds.
        epochs: epochs per run (default ``config.epochs``).
        variants: ``{name: overrides}`` (default the three of Table 3).
        train_overrides: further ``TrainConfig`` fields for every run (``device="cuda"``...).
        log: one line per run.

    Returns:
        ``{configuration: run_ablation(...) result}``.

    Raises:
        ValueError: an unknown configuration.
    """
    unknown = [c for c in configurations if c not in CONFIGURATIONS]
    if unknown:
        raise ValueError(f"unknown configurations {unknown}; known: {list(CONFIGURATIONS)}")
    base = config or DemoConfig()
    return {c: run_ablation(dataclasses.replace(base, recipe=c, init_encoder=encoder), data,
                            Path(out) / c, seeds=seeds, epochs=epochs, variants=variants,
                            train_overrides=train_overrides, log=log)
            for c in configurations}


def _seed_matrix(runs: dict, name: str, seeds, key: str = "per_sample") -> np.ndarray:
    return np.stack([np.asarray(runs[name, s][key], dtype=float) for s in seeds])


def _spread(per_scene: dict, rows=None) -> float:
    means = [v if rows is None else v[rows] for v in per_scene.values()]
    means = [float(np.mean(m)) for m in means]
    return max(means) - min(means)


def summarise_table3(results: dict, *, resamples: int = 10_000, seed: int = 0) -> dict:
    """Table 3 per configuration, paired differences, power, VR bins and the bottleneck test.

    Per configuration: each variant's test PA-MPJPE per seed, mean and 95 % half-width (Student
    t over seeds), surface scores and parameters; each variant against the mean training hand
    (paired per scene, the per-scene errors averaged over seeds); every pair of variants both
    ways, paired per scene (seed-averaged errors: the scene-sampling spread) and Welch over seeds
    (the run-to-run spread); the smallest difference each design detects with 80 % power at the
    5 % level; and the same per VR bin. ``bottleneck``: the decoders' spread (largest minus
    smallest variant mean) in each configuration and the bootstrap interval, over scenes, of
    ``spread(paper) - spread(cpu)``; above zero means the skinned output narrows the decoders'
    differences.

    Args:
        results: `run_table3`'s result.
        resamples: bootstrap resamplings of the bottleneck test.
        seed: bootstrap seed.

    Returns:
        A JSON-serialisable dict (mm; shares in [0, 1]).
    """
    out = {"configurations": {}, "vr_bins": [list(b) for b in VR_BINS]}
    scene_means = {}
    for conf, res in results.items():
        runs, base = res["runs"], res["baselines"]
        names = list(dict.fromkeys(n for n, _ in runs))
        seeds = sorted({s for _, s in runs})
        per_scene = {n: _seed_matrix(runs, n, seeds).mean(0) for n in names}
        scene_means[conf] = per_scene
        first = runs[names[0], seeds[0]]
        vr = np.asarray(first.get("vr", np.full(len(per_scene[names[0]]), np.nan)), dtype=float)
        mean_ps = np.asarray(base["mean hand per sample"], dtype=float)
        rest_ps = np.asarray(base["rest hand per sample"], dtype=float)
        rows = {}
        for n in names:
            per_seed = [float(runs[n, s]["scores"]["pa_mpjpe"]) for s in seeds]
            t = float(stats.t.ppf(0.975, len(seeds) - 1)) if len(seeds) > 1 else float("nan")
            rows[n] = {
                "pa_mpjpe_per_seed": per_seed, "pa_mpjpe": float(np.mean(per_seed)),
                "half_width": t * float(np.std(per_seed, ddof=1)) / np.sqrt(len(seeds))
                if len(seeds) > 1 else None,
                **{k: float(np.mean([runs[n, s]["scores"].get(k, np.nan) for s in seeds]))
                   for k in ("pa_mpvpe", "f_at_5mm", "f_at_15mm", "roughness_deg", "flipped")},
                "params": int(runs[n, seeds[0]]["params"]),
                "seconds_per_epoch": float(np.median([runs[n, s]["seconds"] for s in seeds])),
                "vs_mean_hand": paired_difference(per_scene[n], mean_ps),
                "ratio_to_rest_hand": float(per_scene[n].mean() / rest_ps.mean()),
            }
        pairs = []
        seed_sd = float(np.sqrt(np.mean([np.var(rows[n]["pa_mpjpe_per_seed"], ddof=1)
                                         for n in names]))) if len(seeds) > 1 else float("nan")
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                scenes = paired_difference(per_scene[a], per_scene[b])
                pair = {"a": a, "b": b, "scenes": scenes,
                        "detectable_scenes": detectable_difference(scenes["sd"], scenes["n"])}
                if len(seeds) > 1:
                    pair["seeds"] = seed_difference(rows[a]["pa_mpjpe_per_seed"],
                                                    rows[b]["pa_mpjpe_per_seed"])
                    pair["detectable_seeds"] = detectable_difference(seed_sd, len(seeds),
                                                                     paired=False)
                pairs.append(pair)
        bins = []
        for lo, hi in VR_BINS:
            m = (vr >= lo) & ((vr < hi) if hi < 1 else (vr <= hi))
            row = {"bin": [lo, hi], "count": int(m.sum())}
            if m.sum() >= 2:
                row["variants"] = {n: float(per_scene[n][m].mean()) for n in names}
                row["mean_hand"] = float(mean_ps[m].mean())
                row["rest_hand"] = float(rest_ps[m].mean())
                row["pairs"] = [{"a": a, "b": b,
                                 **paired_difference(per_scene[a][m], per_scene[b][m])}
                                for i, a in enumerate(names) for b in names[i + 1:]]
            bins.append(row)
        out["configurations"][conf] = {
            "description": CONFIGURATIONS.get(conf, conf), "seeds": seeds,
            "scenes": int(len(mean_ps)), "variants": rows, "pairs": pairs,
            "seed_sd": seed_sd, "vr_table": bins,
            "mean_hand": float(mean_ps.mean()), "rest_hand": float(rest_ps.mean()),
            "spread": _spread(per_scene)}
    if {"paper", "cpu"} <= set(scene_means):
        n = len(next(iter(scene_means["paper"].values())))
        rng = np.random.default_rng(seed)
        draws = np.array([_spread(scene_means["paper"], r) - _spread(scene_means["cpu"], r)
                          for r in rng.integers(0, n, size=(int(resamples), n))])
        d = _spread(scene_means["paper"]) - _spread(scene_means["cpu"])
        lo, hi = (float(q) for q in np.quantile(draws, [0.025, 0.975]))
        out["bottleneck"] = {"spread_paper": _spread(scene_means["paper"]),
                             "spread_cpu": _spread(scene_means["cpu"]),
                             "difference": float(d), "low": lo, "high": hi}
    return out


def shipped_table3() -> dict:
    """The shipped summary of the full run (``assets/table3_results.json``): ``summary``
    (`summarise_table3`'s result) and ``provenance`` (command, encoder lineage, data, seconds).

    Raises:
        FileNotFoundError: this installation has no such file.
    """
    import json

    from ... import _version

    path = _version.shipped_file(RESULTS_FILE, "python benchmarks/dev/table3_two_configs.py")
    return json.loads(path.read_text())


def format_table3(summary: dict) -> str:
    """`summarise_table3`'s result as markdown: per configuration the decoders' rows (PA-MPJPE
    mean +- 95 % half-width over seeds, per seed, the paired difference to the mean training
    hand, roughness, flipped faces) and every pair (scene-paired and seed intervals, the smallest
    detectable differences); then the bottleneck test. Millimetres."""
    out = []
    for conf, c in summary["configurations"].items():
        out += [f"**{conf}** ({c['description']}; {c['scenes']} test scenes, seeds "
                f"{', '.join(map(str, c['seeds']))}; mean training hand {c['mean_hand']:.2f}, "
                f"rest hand {c['rest_hand']:.2f})", "",
                "| decoder | PA-MPJPE | per seed | vs mean hand (95 % CI) | / rest hand | "
                "roughness (deg) | flipped |", "|---|---|---|---|---|---|---|"]
        for name, r in c["variants"].items():
            d = r["vs_mean_hand"]
            hw = "" if r["half_width"] is None else f" ± {r['half_width']:.2f}"
            out.append(f"| {name} | {r['pa_mpjpe']:.2f}{hw} | "
                       f"{', '.join(f'{v:.2f}' for v in r['pa_mpjpe_per_seed'])} | "
                       f"{d['difference']:+.2f} ({d['low']:+.2f} to {d['high']:+.2f}) | "
                       f"{r['ratio_to_rest_hand']:.2f} | {r['roughness_deg']:.1f} | "
                       f"{100 * r['flipped']:.2f} % |")
        out += ["", "| pair (a - b) | over scenes (95 % CI) | over seeds (95 % CI) | "
                "detectable: scenes / seeds |", "|---|---|---|---|"]
        for pr in c["pairs"]:
            s, sd = pr["scenes"], pr.get("seeds")
            seeds = "-" if sd is None else \
                f"{sd['difference']:+.2f} ({sd['low']:+.2f} to {sd['high']:+.2f})"
            det = f"{pr['detectable_scenes']:.2f}" + (
                "" if "detectable_seeds" not in pr else f" / {pr['detectable_seeds']:.2f}")
            out.append(f"| {pr['a']} - {pr['b']} | {s['difference']:+.2f} ({s['low']:+.2f} to "
                       f"{s['high']:+.2f}) | {seeds} | {det} |")
        out.append("")
    if "bottleneck" in summary:
        b = summary["bottleneck"]
        out.append(f"Spread of the decoders' means: {b['spread_paper']:.2f} mm in the paper's "
                   f"configuration, {b['spread_cpu']:.2f} mm in the CPU recipe; difference "
                   f"{b['difference']:+.2f} mm (95 % bootstrap interval over scenes "
                   f"{b['low']:+.2f} to {b['high']:+.2f}).")
    return "\n".join(out)
