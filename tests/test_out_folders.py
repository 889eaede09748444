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


def _tree(folder):
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("link", ["eval", "data/train", "report.md", ".handmesh-demo"])
def test_a_link_where_a_command_writes_is_refused_never_written_through(tmp_path, link):
    """Fresh probe of issue 43: in the demo's own folder, ``eval`` a link to a folder outside
    made the demo's evaluation write eval.json, predictions.npz and figures there."""
    outside = tmp_path / "outside"
    (outside / "dir").mkdir(parents=True)
    (outside / "file").write_text("the user's")
    before = _tree(outside)
    out = tmp_path / "run"
    (out / "data").mkdir(parents=True)
    (out / ".handmesh-demo").write_text("{}")
    (out / link).unlink(missing_ok=True)
    target = outside / ("file" if "." in link else "dir")
    (out / link).symlink_to(target, target_is_directory=target.is_dir())
    outputs = ("report.md", "data", "train", "eval")
    for overwrite in (False, True):
        with pytest.raises(FileExistsError, match=rf"run/{link} is a symbolic link \(to "
                                                  rf".*outside/(file|dir)\): demo never writes "
                                                  "through a link nor over one"):
            claim_out_dir(out, "demo", outputs, overwrite=overwrite)
    assert _tree(outside) == before and (out / link).is_symlink()
    (out / link).unlink()  # the user removes it: the folder is the demo's own again
    (out / ".handmesh-demo").write_text("{}")
    claim_out_dir(out, "demo", outputs)


def test_evaluate_refuses_a_link_at_one_of_its_files(toy_root, tmp_path, net, capsys):
    out = tmp_path / "ev"
    T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False, num_samples=2,
               baseline=False)
    (tmp_path / "y").write_text("outside")
    (out / "pred.json").symlink_to(tmp_path / "y")
    with pytest.raises(FileExistsError, match="pred.json is a symbolic link"):
        T.evaluate(net, toy_root, image_size=32, out_dir=out, progress=False, num_samples=2,
                   baseline=False, overwrite=True)
    assert (tmp_path / "y").read_text() == "outside"


@pytest.mark.parametrize("command", ["pretrain", "pretrain-encoder"])
def test_pretraining_refuses_the_users_files_and_links_before_any_scene(tmp_path, capsys,
                                                                        monkeypatch, command):
    """Fresh probe of issue 43: ``pretrain`` and ``pretrain-encoder`` took any --out: a user's
    ``history.json`` or weight file was overwritten, a ``data`` link was generated through."""
    from handmesh_tutorial._version import PRETRAINED_FILE
    from handmesh_tutorial.apps import pretrain_network, pretraining_data
    from handmesh_tutorial.nn.pose_encoder import ENCODER_FILE

    assert PRETRAINED_FILE in pretraining_data.PRETRAINING_OUTPUTS["pretrain"]
    assert ENCODER_FILE in pretraining_data.PRETRAINING_OUTPUTS["pretrain-encoder"]

    def never(*a, **k):
        raise AssertionError("generated scenes before claiming --out")

    monkeypatch.setattr(pretrain_network, "generate_train_val", never)
    mine = "history.json" if command == "pretrain-encoder" else "msmr_net_float16.pt"
    out = tmp_path / "run"
    before = _user_files(out, [mine, "notes.txt"])
    argv = [command, "--out", str(out), "--device", "cpu", "--no-progress"]
    assert cli_main(argv) == 5
    assert f"did not write ({', '.join(sorted(before))})" in capsys.readouterr().err
    assert {n: (out / n).read_text() for n in before} == before
    assert sorted(p.name for p in out.iterdir()) == sorted(before)
    (out / "data").symlink_to(tmp_path, target_is_directory=True)
    assert cli_main([*argv, "--overwrite"]) == 5
    assert "data is a symbolic link" in capsys.readouterr().err
    (out / "data").unlink()
    # an older version's run folder (no marker) is recognised by its scenes, and resumes
    old = tmp_path / "old"
    (old / "data" / "val").mkdir(parents=True)
    (old / "data" / "val" / "meta.json").write_text(json.dumps({"seed": 1, "num_samples": 2}))
    (old / "crops_val.pt").write_text("")
    assert pretraining_data.claim_pretraining_dir(old, command) == old


@pytest.mark.parametrize("made", [False, True])
def test_a_refused_command_leaves_no_marker_lock_or_empty_out(toy_root, tmp_path, capsys, made):
    """Issue 53 item 21: ``.handmesh-evaluate``, ``.train.lock``, ``.handmesh-train`` or an empty
    ``--out`` were left behind by a command refused after claiming its folder."""
    garbage = tmp_path / "garbage.pt"
    garbage.write_text("not a checkpoint")
    out = tmp_path / "new" / "eval"
    if made:  # the user's own empty folder stays; only what the command made goes
        out.mkdir(parents=True)
    code = cli_main(["evaluate", "--checkpoint", str(garbage), "--data", str(toy_root),
                     "--out", str(out), "--no-progress"])
    assert code == 3, capsys.readouterr().err
    assert (sorted(out.iterdir()) == [] if made else not (tmp_path / "new").exists())
    run = tmp_path / "new" / "run"
    code = cli_main(["train", "--data", str(toy_root), "--out", str(run), *TRAIN,
                     "--batch-size", "100"])  # refused once the training items are counted
    assert code == 3 and "batch_size 100 is more than twice" in capsys.readouterr().err
    assert not run.exists()
    # a folder that holds the command's outputs keeps its marker (it resumes from there)
    done = tmp_path / "done"
    assert cli_main(["train", "--data", str(toy_root), "--out", str(done), *TRAIN]) == 0
    capsys.readouterr()
    assert cli_main(["train", "--data", str(toy_root), "--out", str(done), *TRAIN,
                     "--resume", "--lr", "0.5"]) == 3
    assert (done / ".handmesh-train").is_file() and (done / "checkpoint_last.pt").is_file()
