"""Table 3 in two configurations: the summary's statistics, and a tiny end-to-end run."""

import json

import numpy as np
import pytest

from handmesh_tutorial.apps.demo import DemoConfig, generate_data
from handmesh_tutorial.apps.demo.table3 import format_table3, run_table3, summarise_table3
from handmesh_tutorial.budget import budget


def _fake(shifts: dict, n=120, seeds=(0, 1, 2), noise=0.02, rng=None):
    """A run_ablation-like result: variant errors = a shared per-scene error + a shift."""
    rng = rng or np.random.default_rng(0)
    base = rng.gamma(4.0, 1.5, n)
    vr = np.linspace(0.40, 1.0, n)
    runs = {}
    for name, shift in shifts.items():
        for s in seeds:
            ps = base + shift + rng.normal(0, noise, n)
            runs[name, s] = {"per_sample": ps, "vr": vr, "params": 1000, "seconds": 1.0,
                             "scores": {"pa_mpjpe": float(ps.mean()), "pa_mpvpe": 1.0,
                                        "f_at_5mm": 0.5, "f_at_15mm": 0.9,
                                        "roughness_deg": 2.0, "flipped": 0.001}}
    baselines = {"mean hand per sample": base + 2.0, "rest hand per sample": base + 5.0}
    return {"runs": runs, "baselines": baselines, "val_baselines": {}}


def test_the_summary_recovers_known_differences_and_the_bottleneck():
    rng = np.random.default_rng(1)
    results = {"paper": _fake({"single": 0.0, "multi": -0.3, "attn": -0.5}, rng=rng),
               "cpu": _fake({"single": 0.0, "multi": -0.02, "attn": 0.01}, rng=rng)}
    s = summarise_table3(results, resamples=500)
    json.dumps(s)  # serialisable as it is written to the results file
    paper = s["configurations"]["paper"]
    pair = {(p["a"], p["b"]): p for p in paper["pairs"]}
    assert pair["single", "multi"]["scenes"]["difference"] == pytest.approx(0.3, abs=0.01)
    assert pair["single", "attn"]["scenes"]["low"] > 0.45
    assert pair["single", "multi"]["seeds"]["low"] > 0.2
    assert paper["variants"]["multi"]["vs_mean_hand"]["difference"] == pytest.approx(-2.3,
                                                                                     abs=0.01)
    assert paper["variants"]["single"]["ratio_to_rest_hand"] < 1
    # VR bins partition the scenes; each bin's pair difference is the shift again
    assert sum(b["count"] for b in paper["vr_table"]) == paper["scenes"]
    for b in paper["vr_table"]:
        d = {(p["a"], p["b"]): p for p in b["pairs"]}
        assert d["single", "attn"]["difference"] == pytest.approx(0.5, abs=0.02)
    b = s["bottleneck"]
    assert b["spread_paper"] == pytest.approx(0.5, abs=0.02)
    assert b["spread_cpu"] < 0.06 and b["low"] > 0.3
    md = format_table3(s)
    single = paper["variants"]["single"]
    assert f"| single | {single['pa_mpjpe']:.2f} ± {single['half_width']:.2f} |" in md
    assert md.count("| single - multi |") == 2 and f"{b['spread_paper']:.2f} mm" in md


def test_no_bottleneck_is_reported_when_both_configurations_spread_alike():
    rng = np.random.default_rng(2)
    shifts = {"single": 0.0, "multi": -0.1, "attn": -0.2}
    s = summarise_table3({"paper": _fake(shifts, rng=rng), "cpu": _fake(shifts, rng=rng)},
                         resamples=500)
    assert s["bottleneck"]["low"] < 0 < s["bottleneck"]["high"]


def test_an_unknown_configuration_is_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown configurations"):
        run_table3({}, tmp_path, encoder="pretrained", configurations=("xyz",))


def test_a_tiny_two_configuration_run_trains_both_outputs(tmp_path):
    cfg = DemoConfig.from_budget(budget("smoke"))
    data = generate_data(tmp_path / "data", cfg, seed=5, progress=False)
    variants = {"single path": {"decoder": "single", "attention": False},
                "multi-path + attention": {"decoder": "multi", "attention": True}}
    res = run_table3(data, tmp_path / "runs", encoder="pretrained", config=cfg, seeds=(0, 1),
                     epochs=1, variants=variants, log=None)
    for conf, output in (("paper", "xyz"), ("cpu", "skinned")):
        ck = tmp_path / "runs" / conf / "single_path_seed0" / "checkpoint_last.pt"
        import torch

        saved = torch.load(ck, weights_only=True)["config"]
        assert saved["model_kwargs"]["output"] == output
        assert saved["init_encoder"] == "pretrained" and saved["freeze_encoder"] >= 1
        assert len(res[conf]["runs"]) == 4
    s = summarise_table3(res, resamples=200)
    assert set(s["configurations"]) == {"paper", "cpu"} and "bottleneck" in s
