"""Tests of handmesh_tutorial.train: loop, checkpoints, resume, NaN stop, DDP, evaluate, CLI."""

import csv
import dataclasses
import functools
import json
import math
import os
import random
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from handmesh_tutorial import train as T
from handmesh_tutorial.apps.cli import main as cli_main
from handmesh_tutorial.budget import budget
from handmesh_tutorial.data import InterSHDataset, generate_dataset
from handmesh_tutorial.data import augment as A
from handmesh_tutorial.testing import (
    synthetic_sample,
    toy_sample,
    write_freihand_root,
    write_mano_pickle,
)
from handmesh_tutorial.train import config as C

torch.set_num_threads(1)

TINY = {"image_size": 32, "channels": (4, 4, 8, 8, 8), "latent_channels": 8, "threads": 1,
        "progress": False, "durable": False}


@pytest.fixture(scope="module")
def samples():
    return [toy_sample(i, image_size=64) for i in range(8)]


def _data(samples, n_train=4, n_val=2, augment=False):
    tr = A.InterSHTorchDataset(samples[:n_train], 32, train=True, augment=augment)
    va = A.InterSHTorchDataset(samples[n_train:n_train + n_val], 32, train=False)
    return tr, va


def _params(model):
    return {k: v.detach().clone() for k, v in model.named_parameters()}


def test_config_defaults_budget_and_dict_round_trip():
    c = T.TrainConfig()
    assert (c.lr, c.lr_step, c.lr_gamma, c.batch_size, c.epochs) == (1e-4, 50, 0.5, 32, 200)
    full = T.TrainConfig.from_budget(budget("full"))
    assert (full.epochs, full.lr_step, full.batch_size, full.image_size) == (200, 50, 32, 224)
    s = T.TrainConfig.from_budget(budget("default"), out_dir="x")
    b = budget("default")
    assert (s.epochs, s.batch_size, s.image_size, s.threads) == (b.epochs, b.batch_size,
                                                                 b.image_size, b.threads)
    assert s.lr_step == max(1, round(b.epochs / 4))
    assert T.TrainConfig.from_budget(budget("smoke"), epochs=8).lr_step == 2
    d = T.TrainConfig(channels=[4, 4, 8, 8, 8], model_kwargs={"num_blocks": 2}).to_dict()
    assert T.TrainConfig.from_dict(d).to_dict() == d and d["channels"] == [4, 4, 8, 8, 8]
    with pytest.raises(ValueError, match="unknown TrainConfig keys"):
        T.TrainConfig.from_dict({**d, "learning_rate": 1})
    with pytest.raises(ValueError, match="epochs must be a positive integer"):
        T.TrainConfig(epochs=0)
    with pytest.raises(ValueError, match="dataset must be"):
        T.TrainConfig(dataset="coco")
    with pytest.raises(ValueError, match="precision must be"):
        T.TrainConfig(precision="float16")


def test_epoch_batch_sampler_slices_pad_and_order():
    s0 = T.EpochBatchSampler(6, 4, seed=3, rank=0, world_size=2)
    s1 = T.EpochBatchSampler(6, 4, seed=3, rank=1, world_size=2)
    g = s0.global_batches()
    assert [len(b) for b in g] == [4, 4]  # 2 left over, filled up with the first two
    order = np.random.default_rng([3, 0]).permutation(6).tolist()
    assert g[0] == order[:4] and g[1] == order[4:] + order[:2]
    for b, r0, r1 in zip(g, s0, s1, strict=True):
        assert r0 + r1 == b
    s0.set_epoch(1)
    assert s0.global_batches() != g and len(s0) == 2
    with pytest.raises(ValueError, match="divisible"):
        T.EpochBatchSampler(8, 6, world_size=4)


def test_loss_decreases_when_overfitting_four_samples(samples, tmp_path):
    tr, _ = _data(samples)
    cfg = T.TrainConfig(out_dir=str(tmp_path), epochs=12, batch_size=4, lr=1e-3,
                        checkpoint_every=100, **TINY)
    res = T.train(cfg, dataset=tr)
    losses = res.step_losses
    assert len(losses) == 12 and res.steps == 12
    # the model starts at the template (~30 mm from these rotated hands), not at random noise,
    # so the first steps have no init noise to remove: a steady decrease is what is checked
    assert np.mean(losses[-3:]) < 0.95 * losses[0], losses
    assert all(b < a for a, b in zip(losses[:-1], losses[1:], strict=False)), losses
    with open(res.metrics_csv) as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == T.METRIC_COLUMNS and len(rows) == 12
    assert rows[0]["val_pa_mpjpe"] == ""  # no validation set
    assert float(rows[-1]["train_loss"]) == pytest.approx(losses[-1])


def test_resume_continues_exactly(samples, tmp_path):
    tr, va = _data(samples, n_train=4)
    kw = dict(batch_size=2, lr=1e-3, augment=True, **TINY)
    straight = T.train(T.TrainConfig(out_dir=str(tmp_path / "a"), epochs=2, **kw),
                       dataset=A.InterSHTorchDataset(samples[:4], 32, seed=5), val_dataset=va)
    first = T.train(T.TrainConfig(out_dir=str(tmp_path / "b"), epochs=1, **kw),
                    dataset=A.InterSHTorchDataset(samples[:4], 32, seed=5), val_dataset=va)
    resumed = T.train(T.TrainConfig(out_dir=str(tmp_path / "b"), epochs=2, **kw), resume=True,
                      dataset=A.InterSHTorchDataset(samples[:4], 32, seed=5), val_dataset=va)
    assert first.steps == 2 and resumed.steps == straight.steps == 4
    pa, pb = straight.model.state_dict(), resumed.model.state_dict()
    assert pa.keys() == pb.keys()
    assert all(torch.equal(pa[k], pb[k]) for k in pa), [k for k in pa if not torch.equal(pa[k],
                                                                                       pb[k])]
    assert not torch.equal(_params(first.model)["latent_to_mesh.weight"],
                           _params(resumed.model)["latent_to_mesh.weight"])
    assert resumed.step_losses == straight.step_losses
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in straight.history]
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in resumed.history] == strip
    ck = torch.load(resumed.checkpoint, weights_only=True)
    assert ck["epoch"] == 2 and ck["step"] == 4 and ck["scheduler"]["last_epoch"] == 2
    with pytest.raises(ValueError, match="architecture differs"):
        T.train(T.TrainConfig(out_dir=str(tmp_path / "b"), epochs=3, decoder="single",
                              **{**kw, "channels": None}), resume=True, dataset=tr)
    for change in ({"lr": 1e-2}, {"seed": 7}, {"batch_size": 4}, {"data": "elsewhere"}):
        with pytest.raises(ValueError, match=f"other settings.*{next(iter(change))}"):
            T.train(T.TrainConfig(out_dir=str(tmp_path / "b"), epochs=3, **{**kw, **change}),
                    resume=True, dataset=tr)
    assert T.changed_settings(T.TrainConfig(data="x/../x", **kw).to_dict(),
                              T.TrainConfig(data="x", epochs=9,
                                            **{**kw, "threads": 2})) == {}
    with pytest.raises(FileNotFoundError, match="checkpoint not found"):
        T.train(T.TrainConfig(out_dir=str(tmp_path / "none"), epochs=1, **kw), resume=True,
                dataset=tr)


def test_a_run_started_in_one_folder_resumes_from_another(tmp_path, monkeypatch):
    """Relative paths are recorded as given; a run made from the repository root resumes from
    notebooks/ (and a run of another data folder is still refused)."""
    root = tmp_path / "repo"
    for name, seed in (("data", 11), ("other", 12)):
        generate_dataset(root / "nb" / name, functools.partial(toy_sample, image_size=64), num=8,
                         seed=seed, kind="hand-hand", progress=False, durable=False)
    monkeypatch.chdir(root)
    T.train(T.TrainConfig(data="nb/data", out_dir="nb/runs/r", epochs=1, batch_size=4, **TINY))
    monkeypatch.chdir(root / "nb")
    kw = dict(out_dir="runs/r", epochs=2, batch_size=4, **TINY)
    res = T.train(T.TrainConfig(data="data", **kw), resume=True)
    assert res.history[-1]["epoch"] == 2
    with pytest.raises(ValueError, match=r"data changed since this run started \(data "
                       r"meta.json: seed 11 -> 12"):  # another set, not the same one moved
        T.train(T.TrainConfig(data="other", **{**kw, "epochs": 3}), resume=True)
    assert C._saved_folder(root / "nb" / "runs" / "r", "nb/runs/r") == str(root.resolve())
    assert C._saved_folder(root / "nb" / "runs" / "r", "elsewhere/r") is None
    assert C._saved_folder(root / "nb" / "runs" / "r", str(root / "nb" / "runs" / "r")) is None


def test_a_run_resumes_on_its_data_moved_elsewhere_when_told_where(tmp_path):
    """Issue 53 item 18: a run whose data moved could not resume ("data ('/old/...',
    'new/...')"), and nothing let the user say where the data went."""
    data = tmp_path / "old" / "data"
    generate_dataset(data, functools.partial(toy_sample, image_size=64), num=8, seed=11,
                     kind="hand-hand", progress=False, durable=False)
    kw = dict(out_dir=str(tmp_path / "run"), batch_size=4, **TINY)
    T.train(T.TrainConfig(data=str(data), epochs=1, **kw))
    (tmp_path / "new").mkdir()
    data.rename(tmp_path / "new" / "data")
    with pytest.warns(UserWarning, match=r"the run's data moved \(data .*old/data -> "
                                         r".*new/data\): the same meta\.json and samples"):
        res = T.train(T.TrainConfig(data=str(tmp_path / "new" / "data"), epochs=2, **kw),
                      resume=True)
    assert res.history[-1]["epoch"] == 2
    saved = json.loads((tmp_path / "run" / "config.json").read_text())["config"]
    assert saved["data"] == str(tmp_path / "new" / "data")  # the next resume finds it there


def test_resume_refuses_data_replaced_at_the_same_path(tmp_path):
    data = tmp_path / "data"

    def make(root, seed, num=8):
        generate_dataset(root, functools.partial(toy_sample, image_size=64), num=num, seed=seed,
                         kind="hand-hand", progress=False, durable=False)

    make(data, 11)
    cfg = dict(data=str(data), out_dir=str(tmp_path / "run"), batch_size=4, **TINY)
    T.train(T.TrainConfig(epochs=1, **cfg))
    ck = torch.load(tmp_path / "run" / "checkpoint_last.pt", weights_only=True)
    fp = ck["data_fingerprint"]["data"]
    assert fp["meta"]["seed"] == 11 and fp["samples"] == 8
    assert json.loads((tmp_path / "run" / "config.json").read_text())["data_fingerprint"] == \
        ck["data_fingerprint"]
    data.rename(tmp_path / "first")
    make(data, 12)  # another set at the same path: only the path used to be compared
    with pytest.raises(ValueError, match=r"data changed since this run started \(data "
                       r"meta.json: seed 11 -> 12\).*mix two data sets"):
        T.train(T.TrainConfig(epochs=2, **cfg), resume=True)
    import shutil

    shutil.rmtree(data)
    make(data, 11, num=9)  # the same generator settings, one sample more
    with pytest.raises(ValueError, match=r"num_samples 8 -> 9.*data sample ids: 8 -> 9 "):
        T.train(T.TrainConfig(epochs=2, **cfg), resume=True)
    shutil.rmtree(data)
    (tmp_path / "first").rename(data)
    # a checkpoint written before fingerprints: resumes, with a warning
    del ck["data_fingerprint"]
    torch.save(ck, tmp_path / "run" / "checkpoint_last.pt")
    with pytest.warns(UserWarning, match="predates data fingerprints"):
        res = T.train(T.TrainConfig(epochs=2, **cfg), resume=True)
    assert res.epochs == 2


def test_fresh_run_refuses_an_existing_run_and_cleans_only_its_own_temp_files(samples, tmp_path):
    tr, va = _data(samples, n_train=4)
    cfg = T.TrainConfig(out_dir=str(tmp_path / "run"), epochs=1, batch_size=2, **TINY)
    first = T.train(cfg, dataset=tr)
    before = (tmp_path / "run" / "checkpoint_last.pt").read_bytes()
    with pytest.raises(FileExistsError, match=r"checkpoint_last\.pt.*--resume.*--overwrite"):
        T.train(cfg, dataset=tr)
    assert (tmp_path / "run" / "checkpoint_last.pt").read_bytes() == before  # nothing lost
    assert T.existing_run(tmp_path / "run") == ["checkpoint_last.pt"]
    # a killed run's half-written checkpoint goes; a user's own files stay
    stale = tmp_path / "run" / ".checkpoint_last.pt.k2j4x9.tmp"
    stale.write_bytes(b"truncated")
    mine = [tmp_path / "run" / ".tmp-my-notes.txt", tmp_path / "run" / ".my-file.pt.x.tmp"]
    for m in mine:
        m.write_text("keep me")
    again = T.train(dataclasses.replace(cfg, epochs=2), dataset=tr, resume=True)
    assert again.steps == 2 * first.steps and not stale.exists()
    assert all(m.read_text() == "keep me" for m in mine)
    fresh = T.train(cfg, dataset=tr, overwrite=True)
    assert fresh.steps == first.steps
    assert torch.load(fresh.checkpoint, weights_only=True)["epoch"] == 1


def test_a_kill_between_checkpoint_writes_leaves_a_consistent_run(samples, tmp_path,
                                                                  monkeypatch):
    tr, va = _data(samples, n_train=4)
    kw = dict(batch_size=2, lr=1e-3, **TINY)
    T.train(T.TrainConfig(out_dir=str(tmp_path / "ref"), epochs=2, **kw), dataset=tr,
            val_dataset=va)
    # the case that matters: epoch 2 improves, so it writes both checkpoints
    assert torch.load(tmp_path / "ref" / "checkpoint_best.pt", weights_only=True)["epoch"] == 2
    cfg = T.TrainConfig(out_dir=str(tmp_path / "run"), epochs=2, **kw)
    T.train(dataclasses.replace(cfg, epochs=1), dataset=tr, val_dataset=va)
    real_save, saved = T.save_checkpoint, []

    def killed_between_the_two_writes(path, **k):
        if k["epoch"] == 2 and saved:
            raise KeyboardInterrupt  # the process dies here, whichever file comes second
        if k["epoch"] == 2:
            saved.append(Path(path).name)
        return real_save(path, **k)

    monkeypatch.setattr(T.loop, "save_checkpoint", killed_between_the_two_writes)
    with pytest.raises(KeyboardInterrupt):
        T.train(cfg, dataset=tr, val_dataset=va, resume=True)
    monkeypatch.setattr(T.loop, "save_checkpoint", real_save)
    (tmp_path / "run" / "metrics.csv").write_text("garbage from a killed run\n")
    res = T.train(cfg, dataset=tr, val_dataset=va, resume=True)
    for name in ("checkpoint_last.pt", "checkpoint_best.pt"):
        got = torch.load(tmp_path / "run" / name, weights_only=True)
        want = torch.load(tmp_path / "ref" / name, weights_only=True)
        assert got["epoch"] == want["epoch"] and got["best"] == want["best"], name
        assert all(torch.equal(got["model"][k], want["model"][k]) for k in want["model"]), name
    with open(res.metrics_csv) as fh:
        assert [int(r["epoch"]) for r in csv.DictReader(fh)] == [1, 2]


def test_resume_before_the_first_checkpoint_starts_afresh(samples, tmp_path):
    tr, _ = _data(samples, n_train=4)
    cfg = T.TrainConfig(out_dir=str(tmp_path / "run"), epochs=1, batch_size=2, **TINY)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / ".handmesh-train").write_text("{}")  # the run's marker, then
    (tmp_path / "run" / "config.json").write_text("{}")  # killed before its first checkpoint
    (tmp_path / "run" / "metrics.csv").write_text("epoch\n1\n")
    with pytest.warns(UserWarning, match="no checkpoint_last.pt yet"):
        res = T.train(cfg, dataset=tr, resume=True)
    assert res.epochs == 1 and res.checkpoint.exists()


class _NaNAt(torch.utils.data.Dataset):
    def __init__(self, base, bad):
        self.base, self.bad = base, bad

    def __len__(self):
        return len(self.base)

    def __getitem__(self, i):
        item = dict(self.base[i])
        if i == self.bad:
            item["vertices"] = item["vertices"].clone()
            item["vertices"][0, 0] = float("nan")
        return item


def test_nan_loss_stops_with_epoch_and_step(samples, tmp_path):
    tr, _ = _data(samples)
    cfg = T.TrainConfig(out_dir=str(tmp_path), epochs=3, batch_size=2, **TINY)
    # sample 1 is in the second global batch of epoch 1 with this seed? find where it lands
    order = T.EpochBatchSampler(4, 2, seed=0).global_batches(0)
    step = next(k for k, b in enumerate(order) if 1 in b) + 1
    with pytest.raises(FloatingPointError, match=rf"epoch 1 .*step {step} .*not taken"):
        T.train(cfg, dataset=_NaNAt(tr, 1))


def test_checkpoint_weights_only_load_and_mismatch_errors(samples, tmp_path):
    tr, va = _data(samples)
    cfg = T.TrainConfig(out_dir=str(tmp_path), epochs=1, batch_size=4, **TINY)
    res = T.train(cfg, dataset=tr, val_dataset=va)
    ck = torch.load(res.checkpoint, weights_only=True)
    for key in ("model", "optimizer", "scheduler", "epoch", "step", "rng", "config",
                "template_hash"):
        assert key in ck, key
    assert isinstance(ck["rng"]["torch"], torch.Tensor) and ck["rng"]["numpy"]["keys"].numel() \
        == 624 and ck["rng"]["python"]["state"].numel() == 625
    assert res.best_checkpoint is not None and res.best_checkpoint.exists()
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes left no temp files
    net, info = T.load_checkpoint(res.checkpoint)
    x = torch.stack([va[i]["image"] for i in range(2)])
    torch.testing.assert_close(T.predict(net, x)["vertices"], T.predict(res.model, x)["vertices"])
    assert info["config"]["channels"] == [4, 4, 8, 8, 8]
    # a different template: clear error naming both hashes and vertex counts
    sv, sf = synthetic_sample(0)["meshes"][1]
    other = (sv.astype(np.float64), sf, np.full((21, len(sv)), 1.0 / len(sv)))
    with pytest.raises(ValueError, match=r"trained with template .*779 vertices.*114 vertices"):
        T.load_checkpoint(res.checkpoint, template=other)
    # same template, other architecture
    ck["config"]["channels"] = [4, 4, 8, 8, 16]
    bad = tmp_path / "bad.pt"
    torch.save(ck, bad)
    with pytest.raises(ValueError, match="weights do not fit the architecture"):
        T.load_checkpoint(bad)
    torch.save({"model": {}}, bad)
    with pytest.raises(ValueError, match="not a handmesh_tutorial checkpoint"):
        T.load_checkpoint(bad)


def test_template_file_round_trip_and_data_mismatch(tmp_path):
    sv, sf = synthetic_sample(0)["meshes"][1]
    jr = np.random.default_rng(0).random((21, len(sv)))
    jr /= jr.sum(1, keepdims=True)
    path = T.save_template(tmp_path / "sphere.npz", (sv.astype(np.float64), sf, jr))
    t = T.resolve_template(str(path))
    assert t.vertices.shape == (114, 3) and T.template_hash(path) == T.template_hash(t)
    assert T.template_hash(path) != T.template_hash(None)
    with pytest.raises(FileNotFoundError, match="template file not found"):
        T.resolve_template(str(tmp_path / "missing.npz"))
    spheres = [synthetic_sample(i) for i in range(2)]
    ds = A.InterSHTorchDataset(spheres, 32, augment=False)
    with pytest.raises(ValueError, match=r"vertices \(114, 3\), the template has \(779, 3\)"):
        T.train(T.TrainConfig(out_dir=str(tmp_path / "o"), epochs=1, batch_size=2, **TINY),
                dataset=ds)


def _read_freihand_submission(path) -> tuple[np.ndarray, np.ndarray]:
    """pred.json read as FreiHAND's published format says (eval.py: ``pred = json_load(...)``;
    ``xyz_pred_list, verts_pred_list = pred[0], pred[1]``; one entry per evaluation sample, 21
    keypoints and 778 MANO vertices of [x, y, z] in metres), written here without the library."""
    with open(path) as fh:
        pred = json.load(fh)
    assert isinstance(pred, list) and len(pred) == 2, "pred.json must be [xyz_list, verts_list]"
    xyz, verts = pred
    assert len(xyz) == len(verts)
    for j, v in zip(xyz, verts, strict=True):
        assert len(j) == 21 and all(len(p) == 3 for p in j)
        assert len(v) == 778 and all(len(p) == 3 for p in v)
    return np.array(xyz, dtype=np.float64), np.array(verts, dtype=np.float64)


def test_freihand_end_to_end_from_a_mano_pickle(tmp_path, capsys, mano_freihand):
    """A user's MANO_RIGHT.pkl as the template of handmesh train on a FreiHAND-format root, then
    handmesh evaluate --dataset freihand writes a pred.json that FreiHAND's format accepts."""
    pkl, root = mano_freihand
    run, ev_dir = tmp_path / "run", tmp_path / "eval"
    code = cli_main(["train", "--data", str(root), "--dataset", "freihand", "--val-data",
                     str(root), "--template", str(pkl), "--out", str(run), "--budget", "smoke",
                     "--epochs", "1", "--batch-size", "4", "--image-size", "32", "--channels",
                     "4,4,8,8,8", "--latent-channels", "8", "--threads", "1", "--no-augment",
                     "--no-progress", "--no-fsync"])
    assert code == 0, capsys.readouterr().err
    code = cli_main(["evaluate", "--checkpoint", str(run / "checkpoint_last.pt"), "--data",
                     str(root), "--dataset", "freihand", "--out", str(ev_dir), "--threads", "1",
                     "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0 and f"pred_json: {ev_dir / 'pred.json'}" in out
    xyz, verts = _read_freihand_submission(ev_dir / "pred.json")
    assert xyz.shape == (3, 21, 3) and verts.shape == (3, 778, 3)
    with np.load(ev_dir / "predictions.npz") as z:   # the same predictions, camera frame
        np.testing.assert_allclose(xyz, z["joints"], atol=1e-6)
        np.testing.assert_allclose(verts, z["vertices"], atol=1e-6)
    # scored independently against the raw annotation files: eval.json's root-relative MPJPE
    gt = np.array(json.loads((root / "evaluation_xyz.json").read_text()))
    mpjpe = 1000 * np.linalg.norm(xyz - gt, axis=2).mean()
    got = json.loads((ev_dir / "eval.json").read_text())["scores"]["mpjpe"]
    assert abs(got - mpjpe) < 1e-3 * max(1.0, mpjpe)
    # predictions in the network frame cannot be a submission: no pred.json, a note says why
    ev = T.evaluate(str(run / "checkpoint_last.pt"), root, kind="freihand", progress=False,
                    camera_frame=False, out_dir=tmp_path / "net_frame")
    assert "pred_json" not in ev["files"] and not (tmp_path / "net_frame" / "pred.json").exists()
    assert any("network frame" in n for n in ev["notes"])


def test_mano_pickle_is_a_template(tmp_path, mano_freihand):
    """A user's MANO_RIGHT.pkl is a template wherever a .npz is: read through the restricted
    MANO loader, the flat rest hand with MANO's 21-keypoint regressor; a left file is refused."""
    from handmesh_tutorial.hand.mano import UnsafePickleError, load_mano

    pkl = mano_freihand[0]
    t = T.resolve_template(pkl)
    m = load_mano(pkl)
    np.testing.assert_allclose(t.vertices, m.template_vertices, atol=1e-7)
    np.testing.assert_array_equal(t.faces, m.faces)
    np.testing.assert_allclose(t.joint_regressor @ t.vertices, m().joints[0].numpy(), atol=1e-6)
    # save_template turns it into the .npz form: the same template, the same hash
    npz = T.save_template(tmp_path / "mano.npz", str(pkl))
    assert T.template_hash(npz) == T.template_hash(str(pkl)) == T.template_hash(t)
    left = write_mano_pickle(tmp_path / "MANO_LEFT.pkl", "left")
    with pytest.raises(ValueError, match=r"MANO_LEFT.pkl: a left-hand MANO file.*MANO_RIGHT"):
        T.resolve_template(left)
    evil = tmp_path / "evil_RIGHT.pkl"
    evil.write_bytes(b"cos\nsystem\n(S'echo hacked'\ntR.")
    with pytest.raises(UnsafePickleError, match="os.system"):
        T.resolve_template(evil)


def test_ddp_two_processes_match_micro_batch_semantics(toy_root, tmp_path):
    """torchrun, gloo, 2 ranks: identical weights on both ranks, equal to 1 process x 2 chunks."""
    script = tmp_path / "ddp_train.py"
    script.write_text(textwrap.dedent(f"""
        import os, sys, torch
        from handmesh_tutorial import train as T
        cfg = T.TrainConfig(data={str(toy_root)!r}, out_dir=sys.argv[1], epochs=1, batch_size=4,
                            val_fraction=0.25, lr=1e-3, device="cpu", **{TINY!r})
        res = T.train(cfg)
        torch.save({{"params": {{k: v.detach() for k, v in res.model.named_parameters()}},
                    "world": res.world_size,
                    "steps": res.steps}}, os.path.join(sys.argv[1], f"rank{{res.rank}}.pt"))
    """))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "ddp"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
         "--master_addr=127.0.0.1", f"--master_port={port}", str(script), str(out)],
        capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    d0 = torch.load(out / "rank0.pt", weights_only=True)
    d1 = torch.load(out / "rank1.pt", weights_only=True)
    assert (d0["world"], d0["steps"], d1["world"], d1["steps"]) == (2, 2, 2, 2)
    r0, r1 = d0["params"], d1["params"]
    assert all(torch.equal(r0[k], r1[k]) for k in r0)
    single_cfg = T.TrainConfig(data=str(toy_root), out_dir=str(tmp_path / "one"), epochs=1,
                               batch_size=4, micro_batches=2, val_fraction=0.25, lr=1e-3,
                               device="cpu", **TINY)
    single = T.train(single_cfg)
    ref = {k: v.detach() for k, v in single.model.named_parameters()}
    worst = max(float((r0[k] - ref[k]).abs().max()) for k in r0)
    assert worst < 1e-5, worst
    torch.manual_seed(single_cfg.seed)  # the initial weights of both runs
    init = dict(T.build_model_from_config(single_cfg).named_parameters())
    assert max(float((r0[k] - init[k].detach()).abs().max()) for k in r0) > 1e-4  # it trained
    with open(out / "metrics.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 1 and rows[-1]["val_pa_mpjpe"] != ""


def test_evaluate_vr_table_predictions_and_files(toy_root, tmp_path):
    cfg = T.TrainConfig(data=str(toy_root), out_dir=str(tmp_path / "run"), epochs=1,
                        batch_size=4, val_fraction=0.25, **TINY)
    res = T.train(cfg)
    ev = T.evaluate(res.checkpoint, toy_root, out_dir=tmp_path / "eval", progress=False,
                    batch_size=3)
    raw = InterSHDataset(toy_root)
    vr = raw.vr_table()
    bins = ((0.40, 0.60), (0.60, 0.80), (0.80, 0.95), (0.95, 1.00))
    expected = [int(((vr >= lo) & ((vr <= hi) if k == 3 else (vr < hi))).sum())
                for k, (lo, hi) in enumerate(bins)]
    assert [r["count"] for r in ev["vr_table"]] == expected
    assert [(r["lo"], r["hi"]) for r in ev["vr_table"]] == list(bins)
    assert ev["num_samples"] == 8 and "| VR |" in ev["table"] and "| all |" in ev["table"]
    for k in ("pa_mpjpe", "pa_mpvpe", "mpjpe", "f_at_5mm", "auc_joints"):
        assert math.isfinite(ev["scores"][k])
    # predictions are back in each image's camera frame: per-sample errors against the raw
    # (unmirrored, unrotated) ground truth equal the network-frame errors
    pj = ev["predictions"]["joints"]
    for i in range(len(raw)):
        s = raw[i]
        gt = s["joints"][s["target"]]
        err = 1000 * np.linalg.norm(pj[i] - gt, axis=1).mean()
        assert err == pytest.approx(ev["per_sample"]["mpjpe"][i], rel=1e-4, abs=1e-3)
    assert ev["per_sample"]["mirrored"].tolist() == [raw[i]["sides"][raw[i]["target"]] == "left"
                                                     for i in range(len(raw))]
    np.testing.assert_allclose(ev["per_sample"]["vr"], vr, atol=1e-6)
    assert np.mean(ev["per_sample"]["pa_mpjpe"]) == pytest.approx(ev["scores"]["pa_mpjpe"])
    for name in ("eval.json", "predictions.npz", "pck.png", "vr.png"):
        assert (tmp_path / "eval" / name).stat().st_size > 0, name
    net, _ = T.load_checkpoint(res.checkpoint)
    ev2 = T.evaluate(net, toy_root, image_size=32, camera_frame=False, num_samples=3,
                     progress=False)
    assert ev2["num_samples"] == 3 and ev2["predictions"]["frame"] == "network"
    np.testing.assert_allclose(ev2["per_sample"]["pa_mpjpe"], ev["per_sample"]["pa_mpjpe"][:3],
                               rtol=1e-5)


def _umeyama_pa_mpjpe(pred, gt):
    """Independent PA-MPJPE (mm): Umeyama similarity alignment, reflections allowed."""
    out = []
    for p, g in zip(pred, gt, strict=True):
        pc, gc = p - p.mean(0), g - g.mean(0)
        u, w, vt = np.linalg.svd(gc.T @ pc)
        rot = u @ vt
        scale = w.sum() / (pc ** 2).sum()
        out.append(1000 * np.linalg.norm(scale * pc @ rot.T + g.mean(0) - g, axis=1).mean())
    return np.array(out)


def test_evaluate_out_without_matplotlib_writes_scores_and_names_the_extra(toy_root, tmp_path,
                                                                          monkeypatch):
    for name in [m for m in sys.modules if m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as in a core install
    net = T.build_model_from_config(T.TrainConfig(data=str(toy_root), **TINY))
    with pytest.warns(UserWarning, match=r'handmesh_tutorial\[notebooks\].*without the figures'):
        ev = T.evaluate(net, toy_root, image_size=32, progress=False, num_samples=2,
                        baseline=False, out_dir=tmp_path / "ev")
    assert sorted(ev["files"]) == ["json", "predictions"]
    assert sorted(p.name for p in (tmp_path / "ev").iterdir()) == [
        ".handmesh-evaluate", "eval.json", "predictions.npz"]  # its marker, scores, predictions


def test_evaluate_scores_the_rest_hand_baseline_beside_the_model(toy_root, tmp_path):
    """An untrained network (zero head) outputs the template: its scores equal the rest hand's;
    the baseline's PA-MPJPE equals an independent Umeyama alignment of the template joints."""
    torch.manual_seed(0)
    cfg = T.TrainConfig(data=str(toy_root), out_dir=str(tmp_path / "run"), **TINY)
    net = T.build_model_from_config(cfg)
    ev = T.evaluate(net, toy_root, image_size=32, progress=False, out_dir=tmp_path / "ev")
    base = ev["baseline"]
    for k in ("pa_mpjpe", "pa_mpvpe", "f_at_15mm", "roughness_deg", "flipped"):
        assert ev["scores"][k] == pytest.approx(base["scores"][k], rel=1e-4, abs=1e-6), k
    tmpl = net.template.double().numpy()
    tj = net.joint_regressor.double().numpy() @ tmpl
    gt = ev["errors"]["joint_err"]  # shape check only: (N, 21)
    assert gt.shape == (8, 21)
    ds = A.InterSHTorchDataset(toy_root, 32, train=False)
    gj = np.stack([ds[i]["joints"].double().numpy() for i in range(len(ds))])
    np.testing.assert_allclose(base["per_sample"]["pa_mpjpe"],
                               _umeyama_pa_mpjpe(np.broadcast_to(tj, gj.shape), gj), rtol=1e-4)
    # the toy hands are posed: the rest hand's surface differs from theirs
    assert base["scores"]["roughness_deg"] > 0.5
    assert 0.0 <= base["scores"]["flipped"] < 1.0
    assert [r["bin"] for r in ev["kind_table"]] == ["hand-hand"]
    assert ev["kind_table"][0]["count"] == 8
    assert "| hand-hand | 8 |" in ev["comparison"] and "| all | 8 |" in ev["comparison"]
    pa = f"{ev['scores']['pa_mpjpe']:.2f} / {base['scores']['pa_mpjpe']:.2f}"
    assert pa in ev["comparison"]
    import json

    saved = json.loads((tmp_path / "ev" / "eval.json").read_text())
    assert saved["baseline"]["scores"]["pa_mpjpe"] == pytest.approx(base["scores"]["pa_mpjpe"])
    assert saved["per_sample"]["kind"] == ["hand-hand"] * 8
    none = T.evaluate(net, toy_root, image_size=32, progress=False, baseline=False)
    assert none["baseline"] is None and none["comparison"] == ""


def test_cli_train_and_evaluate(toy_root, tmp_path, capsys):
    out = tmp_path / "cli"
    code = cli_main(["train", "--data", str(toy_root), "--out", str(out), "--epochs", "1",
                     "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
                     "--latent-channels", "8", "--threads", "1", "--no-progress",
                     "--no-fsync"])
    assert code == 0
    text = capsys.readouterr().out
    assert "checkpoint" in text and (out / "checkpoint_last.pt").exists()
    assert (out / "metrics.csv").exists() and (out / "config.json").exists()
    code = cli_main(["evaluate", "--checkpoint", str(out / "checkpoint_last.pt"), "--data",
                     str(toy_root), "--out", str(tmp_path / "ev"), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "PA-MPJPE" in text and "[0.95, 1.00]" in text
    assert (tmp_path / "ev" / "eval.json").exists()


def test_cpu_recipe_terms_train_and_each_changes_the_objective(samples, tmp_path):
    """The optional loss terms: each one active shows up in training_loss's parts and adds to
    the objective; a keypoint weight without a keypoint head is refused up front."""
    tr, _ = _data(samples)
    batch = {k: torch.stack([tr[i][k] for i in range(4)]) for k in
             ("image", "vertices", "joints", "root", "K")}
    cfg = T.TrainConfig(out_dir=str(tmp_path / "r"), model_kwargs={"keypoints": True},
                        keypoint_weight=0.1, aligned_weight=1.0, edge_weight=1.0,
                        normal_weight=0.1, **TINY)
    torch.manual_seed(0)
    net = T.build_model_from_config(cfg)
    out = net(batch["image"])
    assert out["uv"].shape == (4, 21, 2)
    faces = torch.as_tensor(np.asarray(net.faces), dtype=torch.int64)
    total, parts = T.training_loss(out, batch, cfg, faces)
    assert set(parts) == {"vertex", "keypoint", "aligned", "edge", "normal"}
    weights = {"vertex": 1.0, "keypoint": 0.1, "aligned": 1.0, "edge": 1.0, "normal": 0.1}
    assert float(total.detach()) == pytest.approx(sum(weights[k] * v for k, v in parts.items()),
                                                  rel=1e-5)
    plain = T.TrainConfig(out_dir=str(tmp_path / "p"), **TINY)
    assert set(T.training_loss(out, batch, plain, faces)[1]) == {"vertex"}
    with pytest.raises(ValueError, match="keypoint_weight > 0 needs model_kwargs"):
        T.TrainConfig(out_dir=str(tmp_path / "x"), keypoint_weight=0.1, **TINY)
    with pytest.raises(ValueError, match="edge_weight must be a number >= 0"):
        T.TrainConfig(out_dir=str(tmp_path / "x"), edge_weight=-1, **TINY)
    res = T.train(T.TrainConfig(out_dir=str(tmp_path / "run"), epochs=1, batch_size=2,
                                model_kwargs={"keypoints": True}, keypoint_weight=0.1,
                                aligned_weight=1.0, edge_weight=1.0, normal_weight=0.1, **TINY),
                  dataset=tr)
    assert res.steps == 2 and all(math.isfinite(x) for x in res.step_losses)
    net2, ck = T.load_checkpoint(res.checkpoint)
    assert ck["config"]["keypoint_weight"] == 0.1 and "uv" in net2(batch["image"])


def test_mean_hand_is_the_procrustes_mean_and_evaluate_scores_it(toy_root, tmp_path):
    """Rotated, scaled copies of one posed hand average to that hand (up to a similarity);
    evaluate scores a given mean hand as a third column; bad shapes are named."""
    from handmesh_tutorial.metrics import procrustes_align

    cfg = T.TrainConfig(data=str(toy_root), out_dir=str(tmp_path / "r"), val_fraction=0.0,
                        augment=False, **TINY)
    train_ds = T.make_datasets(cfg)[0]
    posed = train_ds[0]["vertices"].double().numpy()
    for i in range(len(train_ds)):  # read without the image: the item's mesh up to translation
        a, b = train_ds.target_shape(i), train_ds[i]["vertices"].double().numpy()
        np.testing.assert_allclose(a - a.mean(0), b - b.mean(0), atol=1e-6)
    rng = np.random.default_rng(0)

    class Copies(torch.utils.data.Dataset):
        def __len__(self):
            return 6

        def __getitem__(self, i):
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            rot = q * np.sign(np.linalg.det(q))
            return {"vertices": torch.tensor((1 + 0.1 * i) * posed @ rot.T)}

    mean = T.mean_hand(Copies())
    err = np.linalg.norm(procrustes_align(mean[None], posed[None]) - posed, axis=-1).max()
    assert err < 1e-6
    tmpl = T.resolve_template(None)
    assert np.allclose(tmpl.joint_regressor[9] @ mean, 0.0, atol=1e-9)  # root at the origin
    # the data's mean is closer (after alignment) to the data than the rest hand is
    mean = T.mean_hand(train_ds)
    torch.manual_seed(0)
    net = T.build_model_from_config(cfg)
    ev = T.evaluate(net, toy_root, image_size=32, progress=False, mean_hand=mean)
    m, r = ev["mean_hand_baseline"]["scores"], ev["baseline"]["scores"]
    assert m["pa_mpvpe"] < r["pa_mpvpe"]
    want = T.constant_hand_scores(A.InterSHTorchDataset(toy_root, 32, train=False), mean)
    assert m["pa_mpjpe"] == pytest.approx(want["pa_mpjpe"], rel=1e-5)
    line = next(ln for ln in ev["comparison"].splitlines() if ln.startswith("| all |"))
    assert line.split("|")[3].strip() == (f"{ev['scores']['pa_mpjpe']:.2f} / {r['pa_mpjpe']:.2f}"
                                          f" / {m['pa_mpjpe']:.2f}")
    with pytest.raises(ValueError, match=r"mean_hand must be \(779, 3\), got \(5, 3\)"):
        T.evaluate(net, toy_root, image_size=32, progress=False, mean_hand=np.zeros((5, 3)))


class _Payload:
    """Unpickling this runs ``print``: a stand-in for code hidden in a crafted checkpoint."""

    def __reduce__(self):
        return (print, ("PAYLOAD RAN",))


def test_cli_errors_are_one_line_with_an_exit_code(toy_root, tmp_path, capsys):
    from handmesh_tutorial.apps.cli import EXIT_CODES

    crafted = tmp_path / "crafted.pt"
    torch.save({"format": T.CHECKPOINT_FORMAT, "model": _Payload()}, crafted)
    code = cli_main(["evaluate", "--checkpoint", str(crafted), "--data", str(toy_root),
                     "--no-progress"])
    out, err = capsys.readouterr()
    assert code == EXIT_CODES["bad-input"] == 3
    assert "PAYLOAD RAN" not in out + err and "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("handmesh evaluate: error: ")
    assert str(crafted) in lines[0] and "never load it with weights_only=False" in lines[0]
    assert "--debug" in lines[1]

    code = cli_main(["evaluate", "--checkpoint", str(tmp_path / "nope.pt"), "--data",
                     str(toy_root), "--no-progress"])
    err = capsys.readouterr().err
    assert code == EXIT_CODES["not-found"] == 4 and "nope.pt" in err

    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(crafted.read_bytes()[:50])
    code = cli_main(["evaluate", "--checkpoint", str(truncated), "--data", str(toy_root),
                     "--no-progress"])
    err = capsys.readouterr().err
    assert code == 3 and "truncated.pt: unreadable checkpoint" in err

    run = ["train", "--data", str(toy_root), "--out", str(tmp_path / "run"), "--epochs", "1",
           "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
           "--latent-channels", "8", "--threads", "1", "--no-progress", "--no-fsync"]
    assert cli_main(run) == 0
    capsys.readouterr()
    assert cli_main(run) == EXIT_CODES["exists"] == 5
    err = capsys.readouterr().err
    assert "already holds a training run" in err and "--resume" in err
    assert cli_main(["--debug", *run]) == 5
    assert "Traceback" in capsys.readouterr().err
    assert cli_main([*run, "--overwrite"]) == 0


def _root_with_a_bad_sample(toy_root, tmp_path, bad=3):
    import shutil

    root = tmp_path / "root"
    shutil.copytree(toy_root, root)
    png = root / "samples" / f"{bad:06d}" / "image.png"
    png.write_bytes(png.read_bytes()[:100])  # truncated, as by a full disk or a kill
    return root, png


def test_a_bad_sample_stops_train_and_evaluate_named_and_skip_bad_lists_it(toy_root, tmp_path,
                                                                           capsys):
    root, png = _root_with_a_bad_sample(toy_root, tmp_path)
    run = ["train", "--data", str(root), "--epochs", "1", "--batch-size", "4", "--image-size",
           "32", "--channels", "4,4,8,8,8", "--latent-channels", "8", "--threads", "1",
           "--no-progress", "--no-fsync", "--val-fraction", "0"]
    # default: fail fast, the file named in one line (also from a DataLoader worker process)
    for extra in ([], ["--loader-workers", "1"]):
        assert cli_main([*run, "--out", str(tmp_path / "stopped"), *extra]) == 3
        err = capsys.readouterr().err
        assert f"error: sample 000003: {png}: not a readable PNG" in err, err
        assert "Caught" not in err and "Traceback" not in err
    assert not (tmp_path / "stopped" / "checkpoint_last.pt").exists()

    out = tmp_path / "skipping"
    assert cli_main([*run, "--out", str(out), "--skip-bad"]) == 0
    text = capsys.readouterr().out
    assert "skipped 1 bad sample(s)" in text and f"train sample 000003: {png}" in text
    listed = json.loads((out / "skipped.json").read_text())["skipped"]
    assert [(s["split"], s["index"], s["sample"]) for s in listed] == [("train", 3, "000003")]
    ck = torch.load(out / "checkpoint_last.pt", weights_only=True)

    # the same run on the 7 good samples, given as a dataset, reaches the same weights
    good = A.InterSHTorchDataset(root, 32, train=True, indices=[0, 1, 2, 4, 5, 6, 7])
    cfg = T.TrainConfig.preset("paper", out_dir=str(tmp_path / "ref"), epochs=1, batch_size=4,
                               **TINY)  # `handmesh train` defaults to the paper recipe
    ref = T.train(cfg, dataset=good)
    for k, v in ref.model.state_dict().items():
        torch.testing.assert_close(ck["model"][k], v, msg=k)

    ev = ["evaluate", "--checkpoint", str(out / "checkpoint_last.pt"), "--data", str(root),
          "--no-progress", "--threads", "1"]
    assert cli_main(ev) == 3
    assert f"sample 000003: {png}" in capsys.readouterr().err
    assert cli_main([*ev, "--skip-bad", "--out", str(tmp_path / "ev")]) == 0
    assert f"sample 000003: {png}" in capsys.readouterr().out
    saved = json.loads((tmp_path / "ev" / "eval.json").read_text())
    assert saved["num_samples"] == 7 and [s["index"] for s in saved["skipped"]] == [3]
    assert saved["per_sample"]["index"] == [0, 1, 2, 4, 5, 6, 7]
    net, _ = T.load_checkpoint(out / "checkpoint_last.pt")
    want = T.evaluate(net, dataset=A.InterSHTorchDataset(
        root, 32, train=False, indices=[0, 1, 2, 4, 5, 6, 7]), progress=False)
    assert saved["scores"]["pa_mpjpe"] == pytest.approx(want["scores"]["pa_mpjpe"], rel=1e-9)


def test_skip_bad_keeps_the_dataset_type_and_refuses_an_all_bad_set(toy_root, tmp_path):
    root, _ = _root_with_a_bad_sample(toy_root, tmp_path, bad=0)
    ds = A.InterSHTorchDataset(root, 32, train=True, indices=[5, 0, 2])
    bad = A.find_bad_items(ds)
    assert [(b["position"], b["index"]) for b in bad] == [(1, 0)]
    kept = A.without_items(ds, [1])
    assert type(kept) is A.InterSHTorchDataset and kept.indices == [5, 2]
    assert ds.indices == [5, 0, 2]
    torch.testing.assert_close(kept[1]["image"], ds[2]["image"])  # same augmentation draw
    sub = A.without_items(torch.utils.data.Subset(ds, [0, 1]), [1])
    assert isinstance(sub, torch.utils.data.Subset) and len(sub) == 1
    only_bad = A.InterSHTorchDataset(root, 32, train=False, indices=[0])
    with pytest.raises(ValueError, match="every evaluation sample is bad"):
        T.evaluate(T.build_model_from_config(T.TrainConfig(**TINY)), dataset=only_bad,
                   progress=False, skip_bad=True)


def test_bfloat16_precision_trains_close_to_float32(samples, tmp_path):
    # the opt-in autocast: weights stay float32, the loss falls like the float32 run's
    tr, _ = _data(samples)
    runs = {}
    for precision in ("float32", "bfloat16"):
        torch.manual_seed(0)
        cfg = T.TrainConfig(out_dir=str(tmp_path / precision), epochs=6, batch_size=4, lr=1e-3,
                            checkpoint_every=100, precision=precision, **TINY)
        runs[precision] = T.train(cfg, dataset=tr)
    f32, b16 = (np.array(runs[p].step_losses) for p in ("float32", "bfloat16"))
    assert all(p.dtype == torch.float32 for p in runs["bfloat16"].model.parameters())
    assert np.isfinite(b16).all() and b16[-1] < 0.97 * b16[0], b16
    np.testing.assert_allclose(b16, f32, rtol=0.05)


class _DeviceTensor(torch.Tensor):
    """Stands in for a CUDA tensor on a CPU-only machine: ``.numpy()`` refuses, ``.cpu()``
    gives a plain tensor (what torch.load(map_location="cuda") hands a resumed GPU run)."""

    def numpy(self, *args, **kwargs):
        raise TypeError("can't convert cuda:0 device type tensor to numpy")

    def cpu(self, *args, **kwargs):
        return self.as_subclass(torch.Tensor)


def test_random_states_restore_from_tensors_on_the_training_device():
    from handmesh_tutorial.train.checkpoints import _rng_state, _set_rng_state

    def on_device(x):
        if isinstance(x, torch.Tensor):
            return x.clone().as_subclass(_DeviceTensor)
        if isinstance(x, dict):
            return {k: on_device(v) for k, v in x.items()}
        return x

    state = on_device(_rng_state())
    want = (np.random.rand(3), torch.rand(3), random.random())  # noqa: NPY002
    _set_rng_state(state)
    got = (np.random.rand(3), torch.rand(3), random.random())  # noqa: NPY002
    assert np.array_equal(want[0], got[0]) and torch.equal(want[1], got[1]) and want[2] == got[2]


@pytest.fixture(scope="module")
def mano_freihand(tmp_path_factory):
    """A MANO-format ``MANO_RIGHT.pkl`` and a 3-sample FreiHAND root of its posed hands, both
    written by the library's testing module (as a user's own tests would)."""
    tmp = tmp_path_factory.mktemp("mano_freihand")
    pkl = write_mano_pickle(tmp / "MANO_RIGHT.pkl")
    return pkl, write_freihand_root(tmp / "freihand", 3, image_size=32, seed=5)


def test_evaluate_on_freihand_data(tmp_path, capsys, mano_freihand):
    """A FreiHAND reader has an ``annotation`` method too; evaluate must not take it for an
    INTER-SH reader (it asked it for annotation 0 and failed). No scene kinds on FreiHAND."""
    tpath, root = mano_freihand
    cfg = T.TrainConfig(data=str(root), dataset="freihand", template=str(tpath),
                        out_dir=str(tmp_path / "run"), **TINY)
    torch.manual_seed(0)
    net = T.build_model_from_config(cfg)
    assert net.template.shape == (778, 3)
    ds = A.FreiHANDTorchDataset(root, "evaluation", image_size=32, train=False)
    ev = T.evaluate(net, dataset=ds, progress=False, template=str(tpath))
    assert ev["num_samples"] == 3 and ev["kind_table"] == [] and ev["vr_table"] == []
    assert "kind" not in ev["per_sample"]
    # predictions are back in the camera frame: their error against the reader's raw ground
    # truth, computed here, is the per-sample MPJPE
    pj = ev["predictions"]["joints"]
    assert ev["predictions"]["frame"] == "camera" and pj.shape == (3, 21, 3)
    want = 1000 * np.linalg.norm(pj - np.stack([ds.source[i]["joints"] for i in range(3)]),
                                 axis=2).mean(1)
    np.testing.assert_allclose(ev["per_sample"]["mpjpe"], want, rtol=1e-4, atol=1e-3)
    by_root = T.evaluate(net, root, kind="freihand", image_size=32, progress=False,
                         template=str(tpath))
    np.testing.assert_allclose(by_root["per_sample"]["pa_mpjpe"], ev["per_sample"]["pa_mpjpe"])
    # the command line, from a checkpoint trained on FreiHAND (its config says so) or told
    ck = T.save_checkpoint(tmp_path / "ck.pt", model=net, config=cfg,
                           template_id=T.template_hash(str(tpath)), durable=False)
    for extra in ([], ["--dataset", "freihand"]):
        code = cli_main(["evaluate", "--checkpoint", str(ck), "--data", str(root),
                         "--no-progress", "--threads", "1", *extra])
        assert code == 0, extra
        assert "handmesh evaluate: 3 samples" in capsys.readouterr().out


def test_evaluate_scores_joints_only_when_the_network_s_mesh_is_not_the_data_s(tmp_path, capsys,
                                                                               mano_freihand):
    """The shipped network (the MakeHuman hand's vertices) on FreiHAND (MANO's 778): joint
    scores equal to ``freihand_scores`` of the predictions against the reader's joints, no
    vertex keys, a note that says why; ``handmesh evaluate --checkpoint pretrained`` on a
    FreiHAND root prints them (it stopped on the vertex shapes)."""
    from handmesh_tutorial import metrics
    from handmesh_tutorial.data.freihand import FreiHAND

    _, root = mano_freihand
    ev = T.evaluate("pretrained", root, kind="freihand", progress=False, threads=1,
                    out_dir=tmp_path / "ev")
    nv = ev["predictions"]["vertices"].shape[1]
    assert nv != 778 and ev["predictions"]["frame"] == "camera"
    gt = np.stack([FreiHAND(root, "evaluation")[i]["joints"] for i in range(3)])
    want = metrics.freihand_scores(pred_joints=ev["predictions"]["joints"].astype(float),
                                   gt_joints=gt)
    assert set(ev["scores"]) == set(want)  # no vertex keys, no surface scores
    for key, value in want.items():
        assert ev["scores"][key] == pytest.approx(value, rel=1e-4, abs=1e-3), key
    assert not {"mpvpe", "pa_mpvpe", "f_at_15mm"} & set(ev["per_sample"])
    assert "pa_mpvpe" not in ev["baseline"]["scores"]  # the rest hand: joints only too
    note = next(n for n in ev["notes"] if n.startswith("vertex scores left out"))
    assert f"predicts {nv} vertices, the ground truth has 778" in note and "--template" in note
    saved = json.loads((tmp_path / "ev" / "eval.json").read_text())
    assert saved["scores"]["pa_mpjpe"] == pytest.approx(ev["scores"]["pa_mpjpe"])
    capsys.readouterr()
    assert cli_main(["evaluate", "--checkpoint", "pretrained", "--data", str(root), "--dataset",
                     "freihand", "--no-progress", "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "handmesh evaluate: 3 samples" in out and "note: vertex scores left out" in out
    assert not [ln for ln in out.splitlines() if ln.startswith("MPVPE")]  # no vertex line
