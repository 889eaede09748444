"""The demo job: runs end to end (smoke budget), its report matches eval.json, it resumes."""

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

import handmesh_tutorial as hmt
from handmesh_tutorial.apps import cli, demo

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    code = cli.main(["demo", "--out", str(out), "--seed", "3", "--budget", "smoke",
                     "--no-progress"])
    assert code == 0
    return out


def _fmt_round(x, fmt):
    return float(fmt.format(x))


def test_demo_writes_report_and_figures(smoke_run, capsys):
    out = smoke_run
    for rel in ("report.md", "demo.json", "overlays.png", "loss.png", "eval/eval.json",
                "eval/pck.png", "eval/predictions.npz", "train/checkpoint_last.pt"):
        assert (out / rel).is_file(), rel
        assert (out / rel).stat().st_size > 0, rel
    report = (out / "report.md").read_text()
    # every image the report links exists
    import re

    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert len(links) >= 3
    for link in links:
        assert (out / link).is_file(), link
        with open(out / link, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_report_numbers_equal_eval_json(smoke_run):
    out = smoke_run
    ev = json.loads((out / "eval" / "eval.json").read_text())
    report = (out / "report.md").read_text()
    got = demo.parse_headline(report)
    for key, _, fmt in demo.HEADLINE:
        assert got[key] == pytest.approx(_fmt_round(ev["scores"][key], fmt), abs=1e-12), key
    # the VR table: one line per bin with the bin's count and PA-MPJPE as in eval.json
    for row in ev["vr_table"]:
        line = next(ln for ln in report.splitlines() if ln.startswith(f"| {row['bin']} |"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert int(cells[1]) == row["count"]
        pa = row["pa_mpjpe"]
        assert cells[3] == ("-" if pa is None or (isinstance(pa, float) and math.isnan(pa))
                            else f"{pa:.2f}")
    assert sum(r["count"] for r in ev["vr_table"]) == ev["num_samples"]
    # the scores are recomputable from the stored predictions (camera frame, ground-truth root)
    summary = json.loads((out / "demo.json").read_text())
    assert summary["scores"]["pa_mpjpe"] == pytest.approx(ev["scores"]["pa_mpjpe"])


def test_demo_held_out_scores_recompute_from_predictions(smoke_run):
    out = smoke_run
    ev = json.loads((out / "eval" / "eval.json").read_text())
    pred = np.load(out / "eval" / "predictions.npz")
    test = hmt.data.InterSHDataset(out / "data" / "test")
    gt_j, gt_v = [], []
    for i in pred["index"]:
        s = test[int(i)]
        gt_j.append(s["joints"][s["target"]])
        gt_v.append(s["meshes"][s["target"]][0])
    sc = hmt.metrics.freihand_scores(pred_joints=pred["joints"], gt_joints=np.stack(gt_j),
                                     pred_verts=pred["vertices"], gt_verts=np.stack(gt_v))
    # float32 storage of the predictions: agree to a few micrometres
    assert sc["pa_mpjpe"] == pytest.approx(ev["scores"]["pa_mpjpe"], abs=1e-2)
    assert sc["f_at_15mm"] == pytest.approx(ev["scores"]["f_at_15mm"], abs=1e-2)
    # the size diagnostic of the report: predicted vs true bounding-box diagonal
    diag = [np.linalg.norm(p.max(0) - p.min(0)) / np.linalg.norm(g.max(0) - g.min(0))
            for p, g in zip(pred["vertices"].astype(float), gt_v, strict=True)]
    summary = json.loads((out / "demo.json").read_text())
    assert summary["train"]["size_ratio"] == pytest.approx(np.mean(diag), rel=1e-4)
    assert f"{100 * summary['train']['size_ratio']:.0f}% of the size" in (
        out / "report.md").read_text()


def test_rest_hand_baseline_row_equals_an_independent_computation(smoke_run):
    """The report's baseline row: the template's open hand for every test image, scored by
    freihand_scores on the targets as the torch dataset gives them to the network."""
    out = smoke_run
    from handmesh_tutorial.data.augment import InterSHTorchDataset

    ds = InterSHTorchDataset(out / "data" / "test", 64, train=False)
    items = [ds[i] for i in range(len(ds))]
    gv = np.stack([it["vertices"].numpy() for it in items]).astype(float)
    gj = np.stack([it["joints"].numpy() for it in items]).astype(float)
    tmpl = hmt.nn.model.as_template(None)
    rest_v = hmt.nn.model.root_centred_template(tmpl)
    rest_j = tmpl.joint_regressor @ rest_v
    n = len(gv)
    want = hmt.metrics.freihand_scores(
        pred_joints=np.repeat(rest_j[None], n, 0), gt_joints=gj,
        pred_verts=np.repeat(rest_v[None], n, 0), gt_verts=gv)
    row = demo.parse_headline((out / "report.md").read_text(), demo.BASELINE_ROW)
    for key in ("pa_mpjpe", "pa_mpvpe", "f_at_15mm"):
        fmt = next(f for k, _, f in demo.HEADLINE if k == key)
        assert row[key] == pytest.approx(_fmt_round(want[key], fmt), abs=0.011), key
    summary = json.loads((out / "demo.json").read_text())
    assert summary["baseline"] == demo.BASELINE_ROW
    assert summary["baseline_scores"]["pa_mpjpe"] == pytest.approx(want["pa_mpjpe"], abs=1e-3)
    assert "Model / rest hand / mean hand per VR bin and scene kind" in (
        out / "report.md").read_text()
    mean = demo.parse_headline((out / "report.md").read_text(), demo.MEAN_ROW)
    assert mean["pa_mpjpe"] == pytest.approx(round(summary["mean_hand_scores"]["pa_mpjpe"], 2))


def test_pretrained_row_is_the_shipped_network_on_the_same_scenes(smoke_run):
    """The report's pretrained row equals an independent evaluation of the shipped file on the
    demo's test scenes, at the network's own crop size."""
    out = smoke_run
    info = hmt.pretrained.pretrained_info()
    want = hmt.train.evaluate(hmt.pretrained.pretrained(), str(out / "data" / "test"),
                              image_size=info["config"]["image_size"], baseline=False,
                              progress=False)["scores"]
    row = demo.parse_headline((out / "report.md").read_text(), demo.PRETRAINED_ROW)
    for key, _, fmt in demo.HEADLINE:
        assert row[key] == pytest.approx(_fmt_round(want[key], fmt), abs=1e-12), key
    summary = json.loads((out / "demo.json").read_text())
    assert summary["pretrained_scores"]["pa_mpjpe"] == pytest.approx(want["pa_mpjpe"])


def test_demo_without_a_pretrained_file_leaves_its_row_out(tmp_path, monkeypatch):
    from handmesh_tutorial import _version

    assets = tmp_path / "no_network"  # the shipped encoder only
    assets.mkdir()
    (assets / "hand_encoder_pretrained.pt").symlink_to(
        _version.ASSET_DIR / "hand_encoder_pretrained.pt")
    monkeypatch.setattr(_version, "ASSET_DIR", assets)
    said = []
    cfg = demo.DemoConfig.from_budget(hmt.budget("smoke"), train_samples=4, test_samples=4,
                                      epochs=1)
    res = demo.run_demo(tmp_path / "run", seed=5, config=cfg, progress=False, log=said.append)
    assert res.pretrained_scores is None
    assert any("no pretrained network" in m for m in said)
    with pytest.raises(ValueError, match="no row"):
        demo.parse_headline(res.report.read_text(), demo.PRETRAINED_ROW)


def test_demo_resumes(smoke_run):
    out = smoke_run
    before = json.loads((out / "eval" / "eval.json").read_text())["scores"]
    ck1 = torch.load(out / "train" / "checkpoint_last.pt", weights_only=True)
    smoke_epochs = demo.DemoConfig.from_budget(hmt.budget("smoke")).epochs
    assert int(ck1["epoch"]) == smoke_epochs
    cfg = demo.DemoConfig.from_budget(hmt.budget("smoke"), epochs=smoke_epochs + 1)
    res = demo.run_demo(out, seed=3, config=cfg, progress=False, log=None)
    # data reused: same scenes; training continued for one more epoch
    assert res.train_epochs == smoke_epochs + 1
    ck = torch.load(out / "train" / "checkpoint_last.pt", weights_only=True)
    assert int(ck["epoch"]) == smoke_epochs + 1
    assert len(ck["history"]) == smoke_epochs + 1
    assert ck["history"][0]["train_loss"] == ck1["history"][0]["train_loss"]  # epoch 1 kept
    assert json.loads((out / "eval" / "eval.json").read_text())["scores"] == res.scores
    assert res.scores["num_samples"] == before["num_samples"]
    assert demo.parse_headline(res.report.read_text())["pa_mpjpe"] == pytest.approx(
        round(res.scores["pa_mpjpe"], 2))


def test_headline_round_trip_and_missing_table():
    scores = {"pa_mpjpe": 12.345, "pa_mpvpe": 11.1, "f_at_5mm": 0.2345, "f_at_15mm": 0.87654,
              "auc_joints": 0.5, "auc_joints_20mm": 0.25, "roughness_deg": 7.0, "flipped": 0.01}
    scores["mpjpe"] = 20.0
    base = {k: 2 * v for k, v in scores.items()}
    text = "# x\n\n" + demo.headline(scores, base) + "\n\nmore text\n"
    got = demo.parse_headline(text)
    assert got["pa_mpjpe"] == 12.35 or got["pa_mpjpe"] == 12.34  # rounding of 12.345 in binary
    assert got["f_at_15mm"] == 0.877 and got["mpjpe"] == 20.0
    assert demo.parse_headline(text, demo.BASELINE_ROW)["pa_mpvpe"] == 22.2
    with pytest.raises(ValueError, match="no row 'other'"):
        demo.parse_headline(text, "other")
    assert demo.BASELINE_ROW not in demo.headline(scores)
    four = demo.headline(scores, base, base, {k: 3 * v for k, v in scores.items()})
    assert [ln.split("|")[1].strip() for ln in four.splitlines()[2:]] == [
        demo.MODEL_ROW, demo.PRETRAINED_ROW, demo.BASELINE_ROW, demo.MEAN_ROW]
    assert demo.parse_headline(four, demo.PRETRAINED_ROW)["mpjpe"] == 60.0
    del scores["flipped"]  # a score a row lacks prints as "-" and reads back as NaN
    assert math.isnan(demo.parse_headline(demo.headline(scores))["flipped"])
    with pytest.raises(ValueError, match="no headline table"):
        demo.parse_headline("# a report without scores")


def test_config_from_budget_sizes():
    b = hmt.budget("default")
    c = demo.DemoConfig.from_budget(b)
    assert (c.train_samples, c.test_samples) == (5 * b.samples, b.eval_samples // 2)
    assert c.image_size == b.image_size and c.render_size == b.image_size
    assert (c.epochs, c.batch_size) == (b.epochs // 2, b.batch_size)
    assert (c.encoder, c.augment, c.balance_train) == ("resnet10", False, False)
    # the paper's protocol: the pretrained encoder, frozen for the whole run
    assert c.init_encoder == "pretrained" and c.freeze_encoder >= c.epochs
    t = demo.train_config(c, "data", "out")
    assert (t.init_encoder, t.freeze_encoder) == ("pretrained", c.freeze_encoder)
    r = demo.train_config(demo.DemoConfig.from_budget(b, init_encoder=None), "data", "out")
    assert (r.init_encoder, r.freeze_encoder, r.encoder_lr_scale) == (None, 0, 1.0)
    f, full = demo.DemoConfig.from_budget(hmt.budget("full")), hmt.budget("full")
    assert f.augment and (f.train_samples, f.epochs) == (full.samples, full.epochs)
    assert demo.DemoConfig.from_budget(b, epochs=3).epochs == 3


def test_the_paper_recipe_halves_its_rate_each_quarter_with_the_encoder_frozen():
    b = hmt.budget("default")
    cpu, paper = demo.DemoConfig.from_budget(b), demo.DemoConfig.from_budget(b, recipe="paper")
    t = demo.train_config(paper, "data", "out")
    assert (t.epochs, t.lr_step, t.freeze_encoder) == (10, 3, 10)  # halved at 3, 6, 9
    assert demo.train_config(cpu, "data", "out").lr_step == 8  # once, at three quarters
    # an explicit schedule wins; an impossible one is refused by name
    assert demo.train_config(dataclasses.replace(paper, lr_step=7), "d", "o").lr_step == 7
    with pytest.raises(ValueError, match="lr_step must be >= 1 epoch, got 0"):
        demo.train_config(dataclasses.replace(paper, lr_step=0), "d", "o")


def test_plot_mesh_on_image_projects_with_K():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = np.array([[0.0, 0.0, 0.5], [0.05, 0.0, 0.5], [0.0, 0.05, 0.6]])
    f = np.array([[0, 1, 2]])
    K = np.array([[100.0, 0, 32], [0, 120.0, 30], [0, 0, 1]])
    fig, ax = plt.subplots()
    coll = hmt.viz.plot_mesh_on_image(ax, np.zeros((64, 64, 3), np.uint8), v, f, K)
    poly = coll.get_paths()[0].vertices[:3]
    expect = np.array([[100 * x / z + 32, 120 * y / z + 30] for x, y, z in v])
    np.testing.assert_allclose(poly, expect, atol=1e-9)
    assert ax.get_ylim()[0] > ax.get_ylim()[1]  # image rows grow downwards
    with pytest.raises(ValueError, match="K must be"):
        hmt.viz.plot_mesh_on_image(ax, None, v, f, np.eye(2))
    plt.close(fig)


def test_recipes_reach_the_training_config(smoke_run, tmp_path):
    ck = torch.load(smoke_run / "train" / "checkpoint_last.pt", weights_only=True)
    cfg = ck["config"]
    assert cfg["model_kwargs"] == {"keypoints": True, "global_rotation": True,
                                   "output": "skinned"}
    assert (cfg["keypoint_weight"], cfg["aligned_weight"]) == (0.5, 1.0)
    assert "recipe `cpu`" in (smoke_run / "report.md").read_text()
    paper = demo.train_config(demo.DemoConfig(recipe="paper"), tmp_path, tmp_path / "t")
    # the paper's output and loss, reading the frozen pretrained encoder as it was trained
    assert paper.model_kwargs == {"output": "xyz", "smoothing_length": 0.0, "keypoints": True}
    assert paper.keypoint_weight == 0 and paper.aligned_weight == 0
    assert paper.freeze_encoder >= paper.epochs
    glob = demo.train_config(demo.DemoConfig(recipe="paper", pooling="global"), tmp_path,
                             tmp_path / "t")
    assert glob.model_kwargs == {"output": "xyz", "smoothing_length": 0.0}
    with pytest.raises(ValueError, match="pooling must be"):
        demo.train_config(demo.DemoConfig(recipe="paper", pooling="x"), tmp_path, tmp_path / "t")
    with pytest.raises(ValueError, match="choice of the paper recipe"):
        demo.train_config(demo.DemoConfig(pooling="global"), tmp_path, tmp_path / "t")
    with pytest.raises(ValueError, match=r"recipe must be one of \['cpu', 'paper'\], got 'x'"):
        demo.train_config(demo.DemoConfig(recipe="x"), tmp_path, tmp_path / "t")


def test_demo_cli_pooling_reaches_the_config_and_is_refused_before_any_scene(tmp_path, capsys,
                                                                             monkeypatch):
    seen = []

    def fake_run_demo(out, seed, config, progress, overwrite):
        seen.append(config)
        raise SystemExit(0)

    monkeypatch.setattr(demo, "run_demo", fake_run_demo)
    with pytest.raises(SystemExit):
        cli.main(["demo", "--out", str(tmp_path / "a"), "--recipe", "paper", "--pooling",
                  "global", "--budget", "smoke"])
    assert seen[-1].pooling == "global" and seen[-1].recipe == "paper"
    code = cli.main(["demo", "--out", str(tmp_path / "b"), "--pooling", "global", "--budget",
                     "smoke"])
    assert code == 3 and len(seen) == 1 and not (tmp_path / "b").exists()
    assert "--pooling global is a choice of --recipe paper" in capsys.readouterr().err
