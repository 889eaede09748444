"""Output folders hold one command's own files (issue 43 items 7-9; docs page *Reliability*).

A command writes, replaces or removes only the files it made: an ``--out`` folder that holds files
the command did not write is refused (exit code 5, the files listed) before any work unless
``--overwrite``; ``--overwrite`` removes the previous run's files before the new run writes; an
evaluation's files are one evaluation's.
"""

from __future__ import annotations

import errno
import json

import pytest
import torch

from handmesh_tutorial import train as T
from handmesh_tutorial._io import claim_out_dir
from handmesh_tutorial.apps.cli import main as cli_main
from handmesh_tutorial.train.checkpoints import RUN_OUTPUTS, is_train_run

TRAIN = ["--epochs", "1", "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
         "--latent-channels", "8", "--threads", "1", "--no-progress", "--no-fsync"]
TINY = dict(image_size=32, channels=(4, 4, 8, 8, 8), latent_channels=8)



def _user_files(folder, names):
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_text(f"the user's own {name}\n")
    return {name: (folder / name).read_text() for name in names}


def test_train_overwrite_removes_the_previous_runs_best_checkpoint(toy_root, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--data", str(toy_root), "--out", str(out), *TRAIN]
    assert cli_main([*argv, "--val-fraction", "0.25"]) == 0
    assert (out / "checkpoint_best.pt").exists()
    capsys.readouterr()
    # issue 43 item 7: a new run without validation kept the old best and printed it as its own
    assert cli_main([*argv, "--val-fraction", "0", "--overwrite"]) == 0
    text = capsys.readouterr().out
    assert not (out / "checkpoint_best.pt").exists()
    assert "best checkpoint" not in text, text
    assert (out / "checkpoint_last.pt").exists() and (out / "metrics.csv").exists()


@pytest.mark.parametrize("names", [("config.json", "metrics.csv", "steps.csv"),
                                   ("notes.txt",)])
def test_train_refuses_a_folder_of_the_users_files_before_any_work(toy_root, tmp_path, capsys,
                                                                   names):
    out = tmp_path / "mine"
    before = _user_files(out, names)
    code = cli_main(["train", "--data", str(toy_root), "--out", str(out), *TRAIN])
    err = capsys.readouterr().err
    assert code == 5, err  # was 0: the user's config.json, metrics.csv, steps.csv overwritten
    assert all(n in err for n in names) and "--overwrite" in err, err
    assert sorted(p.name for p in out.iterdir()) == sorted(names)  # nothing written, no lock
    assert {n: (out / n).read_text() for n in names} == before


def test_train_overwrite_writes_beside_the_users_other_files(toy_root, tmp_path):
    out = tmp_path / "mine"
    _user_files(out, ["notes.txt", "metrics.csv"])
    assert cli_main(["train", "--data", str(toy_root), "--out", str(out), *TRAIN,
                     "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "the user's own notes.txt\n"  # left
    assert (out / "metrics.csv").read_text().startswith("epoch")  # train's name: replaced
    # the folder is now the run's own: resuming it needs no --overwrite
    assert cli_main(["train", "--data", str(toy_root), "--out", str(out), *TRAIN,
                     "--resume"]) == 0


@pytest.mark.parametrize("argv", [
    ["train", "--data", "d"], ["evaluate", "--checkpoint", "c", "--data", "d"], ["demo"],
    ["generate", "--kind", "hand-hand", "--num", "1"], ["pretrain"], ["pretrain-encoder"]])
def test_an_empty_out_is_refused_not_the_current_folder(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:  # was: written into the current folder, exit 0
        cli_main([*argv, "--out", ""])
    assert e.value.code == 2
    assert "--out: must name a folder" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_the_python_api_refuses_an_empty_out_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=r"output folder of train is empty \(''\)"):
        T.train(T.TrainConfig(out_dir="", **TINY))
    net = T.build_model_from_config(T.TrainConfig(encoder="resnet10", **TINY))
    with pytest.raises(ValueError, match=r"output folder of evaluate is empty"):
        T.evaluate(net, tmp_path, image_size=32, out_dir="", progress=False)
    assert not list(tmp_path.iterdir())


def test_demo_refuses_a_folder_with_the_users_report_before_any_work(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "mine"
    before = _user_files(out, ["report.md", "loss.png"])
    code = cli_main(["demo", "--out", str(out), "--budget", "smoke", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 5, err  # was: a whole demo run, then report.md and loss.png overwritten
    assert "report.md" in err and "loss.png" in err and "--overwrite" in err
    assert sorted(p.name for p in out.iterdir()) == ["loss.png", "report.md"]
    assert {n: (out / n).read_text() for n in before} == before


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    return T.build_model_from_config(T.TrainConfig(encoder="resnet10", **TINY)).eval()


def _files(folder):
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def test_an_evaluation_replaces_the_previous_evaluations_files_as_a_set(toy_root, tmp_path, net,
                                                                       monkeypatch):
    pytest.importorskip("matplotlib")
    out = tmp_path / "ev"
    first = T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False)
    assert "vr" in first["files"] and (out / "vr.png").exists()
    (out / "pred.json").write_text("[]")  # as a FreiHAND evaluation into this folder left it
    (out / "notes.txt").write_text("mine")
    # a second evaluation stopped by a full disk at predictions.npz: was its new eval.json
    # beside the first one's predictions.npz, vr.png and pred.json
    import handmesh_tutorial.train.evaluation as E

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(E, "atomic_savez", full)
    with pytest.raises(OSError, match="No space left"):
        T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False, num_samples=3)
    assert _files(out) == ["notes.txt"]  # nothing of either evaluation is taken for a result
    monkeypatch.undo()
    T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False, num_samples=3,
               baseline=False)
    assert "pred.json" not in _files(out) and (out / "notes.txt").read_text() == "mine"
    saved = json.loads((out / "eval.json").read_text())
    import numpy as np

    with np.load(out / "predictions.npz") as z:
        assert saved["num_samples"] == 3 == len(z["index"])  # one evaluation's files


def test_evaluate_refuses_a_folder_of_the_users_files_before_evaluating(toy_root, tmp_path, net,
                                                                         monkeypatch):
    out = tmp_path / "mine"
    before = _user_files(out, ["eval.json", "vr.png"])
    import handmesh_tutorial.train.evaluation as E

    def never(*a, **k):
        raise AssertionError("evaluated before refusing --out")

    monkeypatch.setattr(E, "load_checkpoint", never)
    with pytest.raises(FileExistsError, match=r"did not write \(eval\.json, vr\.png\)"):
        T.evaluate("x.pt", toy_root, out_dir=out, progress=False)
    assert _files(out) == ["eval.json", "vr.png"] and not (out / ".handmesh-evaluate").exists()
    assert {n: (out / n).read_text() for n in before} == before
    monkeypatch.undo()
    ev = T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False, num_samples=2,
                    baseline=False, overwrite=True)
    assert json.loads((out / "eval.json").read_text())["num_samples"] == ev["num_samples"] == 2


def test_a_run_folder_of_an_older_version_is_still_the_runs_own(tmp_path):
    """Folders written before the marker files: recognised by their record, not refused."""
    out = tmp_path / "old_run"
    out.mkdir()
    (out / "config.json").write_text(json.dumps({"config": {}, "template_hash": "x"}))
    (out / "metrics.csv").write_text("epoch\n")
    assert is_train_run(out)
    assert claim_out_dir(out, "train", RUN_OUTPUTS, recognise=is_train_run) == out
    assert (out / ".handmesh-train").is_file()
    (out / "config.json").write_text('{"mine": true}')
    (out / ".handmesh-train").unlink()
    assert not is_train_run(out)
    with pytest.raises(FileExistsError, match=r"config\.json, metrics\.csv"):
        claim_out_dir(out, "train", RUN_OUTPUTS, recognise=is_train_run)
    # a killed write's temporary and the lock do not make a new folder foreign
    new = tmp_path / "new"
    new.mkdir()
    (new / ".metrics.csv.abc123.tmp").write_text("")
    (new / ".train.lock").write_text("")
    claim_out_dir(new, "train", RUN_OUTPUTS, hidden=(".train.lock",))
    (new / "a_file").write_text("")
    with pytest.raises(NotADirectoryError, match="is a file"):
        claim_out_dir(new / "a_file", "train")
