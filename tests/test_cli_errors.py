"""Exit codes and one-line messages of ``handmesh``: bad input vs the environment vs a bug."""

from __future__ import annotations

import errno
import functools
import tempfile

import pytest
import torch

from handmesh_tutorial import _io
from handmesh_tutorial import train as T
from handmesh_tutorial.apps import cli
from handmesh_tutorial.data import files as F
from handmesh_tutorial.data import generate_dataset
from handmesh_tutorial.testing import toy_sample

TRAIN = ["--epochs", "1", "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
         "--latent-channels", "8", "--threads", "1", "--no-progress", "--no-fsync"]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    r = tmp_path_factory.mktemp("toy_intersh")
    generate_dataset(r, functools.partial(toy_sample, image_size=64), num=8, seed=11,
                     kind="hand-hand", progress=False, durable=False)
    return r


def _fail_with(monkeypatch, err):
    def command(args):
        raise err

    monkeypatch.setattr(cli, "_cmd_verify", command)
    return cli.main(["verify", "some/root"])


@pytest.mark.parametrize("err, kind, words", [
    (OSError(errno.ENOSPC, "No space left on device", "runs/data/samples/000003"),
     "environment", ["No space left on device: runs/data/samples/000003", "free some space",
                     "rerun the same command"]),
    (PermissionError(errno.EACCES, "Permission denied", "/ro/out/eval.json"), "environment",
     ["Permission denied: /ro/out/eval.json", "permissions"]),
    (OSError(errno.EROFS, "Read-only file system", "/ro/out"), "environment",
     ["Read-only file system: /ro/out", "another output folder"]),
    (_io.EnvironmentFailure("runs/x is being written by another process"), "environment",
     ["runs/x is being written by another process"]),
    (ValueError("meta.json: bad seed"), "bad-input", ["meta.json: bad seed"]),
    (FileNotFoundError("template file not found: t.npz"), "not-found", ["t.npz"]),
    (TypeError("unsupported operand"), "unexpected", ["unsupported operand"]),
])
def test_exit_codes_tell_bad_input_the_environment_and_a_bug_apart(monkeypatch, capsys, err,
                                                                   kind, words):
    assert cli.EXIT_CODES["environment"] == 6  # the other codes keep their numbers
    assert {k: cli.EXIT_CODES[k] for k in ("ok", "unexpected", "usage", "bad-input",
                                           "not-found", "exists", "interrupted")} == {
        "ok": 0, "unexpected": 1, "usage": 2, "bad-input": 3, "not-found": 4, "exists": 5,
        "interrupted": 130}
    assert _fail_with(monkeypatch, err) == cli.EXIT_CODES[kind]
    line = capsys.readouterr().err.splitlines()[0]
    assert line.startswith("handmesh verify: error: ")
    for w in words:
        assert w in line, line


def test_a_full_disk_error_names_the_file(tmp_path, monkeypatch):
    def full(fh):
        raise OSError(errno.ENOSPC, "No space left on device")  # as write() raises it

    target = tmp_path / "out" / "metrics.csv"
    with pytest.raises(OSError) as e:
        _io.atomic_write_with(target, full)
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(target)
    assert not list(target.parent.iterdir())  # no temporary left
    # a sample folder: the error names the sample, and its temporary folder is gone
    monkeypatch.setattr(F, "_write_file", lambda path, data, durable: full(None))
    (tmp_path / "samples").mkdir()
    with pytest.raises(OSError) as e:
        F._write_folder(tmp_path / "samples" / "000007", {"image.png": b"x"}, durable=False)
    assert e.value.errno == errno.ENOSPC
    assert e.value.filename == str(tmp_path / "samples" / "000007")
    assert not list((tmp_path / "samples").iterdir())


def test_a_held_lock_exits_with_the_environment_code(root, tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    with _io.single_writer(out / ".train.lock", "test"):
        code = cli.main(["train", "--data", str(root), "--out", str(out), *TRAIN])
    assert code == cli.EXIT_CODES["environment"] == 6
    err = capsys.readouterr().err
    assert f"{out} (training) is being written by another process" in err


@pytest.mark.parametrize("option, value", [("--threads", "0"), ("--device", "banana"),
                                           ("--channels", "0,4,8,8,8"), ("--batch-size", "-1")])
def test_bad_option_values_are_usage_errors_naming_the_option(root, tmp_path, capsys, option,
                                                              value):
    argv = ["train", "--data", str(root), "--out", str(tmp_path / "run"), *TRAIN, option, value]
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == cli.EXIT_CODES["usage"] == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and repr(value) in err, err
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_bad_values_from_python_are_value_errors():
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        T.TrainConfig(threads=0)
    with pytest.raises(ValueError, match="channels must be positive"):
        T.TrainConfig(channels=(0, 4, 8, 8, 8))
    from handmesh_tutorial.train._distributed import _resolve_device

    with pytest.raises(ValueError, match="device must be .*got 'banana'"):
        _resolve_device("banana")


def test_a_garbage_checkpoint_is_named_not_a_missing_key(root, tmp_path, capsys):
    text = tmp_path / "notes.pt"
    text.write_text("hello, this is not a checkpoint\n")  # torch's unpickler: KeyError 101
    empty = tmp_path / "empty.pt"
    torch.save({"format": T.CHECKPOINT_FORMAT}, empty)
    for path, words in ((text, "unreadable checkpoint (truncated, or not a zip archive"),
                        (empty, "not a handmesh_tutorial checkpoint (missing keys ['best', "
                                "'config', 'epoch', 'history', 'model', 'step', "
                                "'template_hash'])")):
        code = cli.main(["evaluate", "--checkpoint", str(path), "--data", str(root),
                         "--no-progress"])
        err = capsys.readouterr().err
        assert code == cli.EXIT_CODES["bad-input"], err
        assert f"error: {path}: {words}" in err and "missing key 101" not in err, err


def test_a_template_that_is_not_an_npz_is_named(root, tmp_path, capsys):
    notes = tmp_path / "template.txt"
    notes.write_text("vertices: many\n")
    code = cli.main(["train", "--data", str(root), "--out", str(tmp_path / "run"), *TRAIN,
                     "--template", str(notes)])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"]
    assert f"{notes}: not a template file" in err and "allow_pickle" not in err, err


def test_evaluate_checks_its_output_folder_before_evaluating(root, tmp_path, capsys,
                                                             monkeypatch):
    from handmesh_tutorial.train import evaluation

    ck = T.train(T.TrainConfig(data=str(root), out_dir=str(tmp_path / "run"), epochs=1,
                               batch_size=4, image_size=32, channels=(4, 4, 8, 8, 8),
                               latent_channels=8, threads=1, progress=False,
                               durable=False)).checkpoint

    def read_only(*args, dir=None, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    def never(*args, **kwargs):
        raise AssertionError("evaluated before finding that --out cannot be written")

    monkeypatch.setattr(tempfile, "TemporaryFile", read_only)
    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    monkeypatch.setattr(evaluation, "_run_dataset", never)
    out = tmp_path / "eval"
    code = cli.main(["evaluate", "--checkpoint", str(ck), "--data", str(root), "--out", str(out),
                     "--no-progress"])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["environment"], err
    assert f"Read-only file system: {out}" in err


@pytest.mark.parametrize("argv, message", [
    (["pretrain", "--device", "cdua"], r"device must be 'auto', 'cpu', 'cuda', 'cuda:N' or 'mps', "
                                       r"got 'cdua'"),
    (["pretrain", "--lr", "-1"], r"lr must be a finite number > 0, got -1\.0"),
    (["pretrain", "--lr", "nan"], r"lr must be a finite number > 0, got nan"),
    (["pretrain", "--image-size", "100000"], r"image_size must be an integer in \[32, 4096\]"),
    (["pretrain", "--device", "cuda:99"], r"device 'cuda:99': this machine has \d+ CUDA"),
    (["pretrain-encoder", "--device", "gpu"], r"device must be .* got 'gpu'"),
    (["pretrain-encoder", "--device", "cuda:99"], r"device 'cuda:99': this machine has"),
    (["pretrain-encoder", "--lr", "0"], r"lr must be a finite number > 0, got 0\.0"),
])
def test_pretrain_checks_its_options_before_generating_any_scene(argv, message, tmp_path, capsys,
                                                                 monkeypatch):
    """Issue 43 item 11: ``--device``, ``--image-size`` and ``--lr`` were checked by the training
    run, after the scenes (hours at the default sizes) were generated."""
    import re

    from handmesh_tutorial.apps import pretrain_network

    def never(*a, **k):
        raise AssertionError("generated scenes before checking the options")

    monkeypatch.setattr(pretrain_network, "generate_train_val", never)
    out = tmp_path / "run"
    code = cli.main([*argv, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 3, err
    assert re.search(message, err), err
    assert not out.exists()


@pytest.mark.parametrize("argv, code, message", [
    (["pretrain", "--init", "/nonexistent.pt"], 4, r"--init /nonexistent\.pt: checkpoint not "
                                                   r"found"),
    (["pretrain", "--init", "CRAFTED"], 3, r"--init \S*crafted\.pt: unreadable checkpoint"),
    (["pretrain", "--init-encoder", "/nonexistent.pt"], 4, r"--init-encoder /nonexistent\.pt"),
    (["pretrain", "--max-generate-seconds", "-5"], 3, r"--max-generate-seconds must be a "
                                                      r"finite number of seconds > 0, got -5"),
    (["pretrain", "--max-train-seconds", "nan"], 3, r"--max-train-seconds must be .* got nan"),
    (["pretrain-encoder", "--init", "/nonexistent.pt"], 4, r"--init /nonexistent\.pt: "),
    (["pretrain-encoder", "--init", "CRAFTED"], 3, r"--init \S*crafted\.pt: unreadable "
                                                   r"checkpoint"),
    (["pretrain-encoder", "--max-train-seconds", "-1"], 3, r"--max-train-seconds must be a "
                                                           r"finite number of seconds > 0"),
    (["pretrain-encoder", "--max-train-seconds", "nan"], 3, r"got nan"),
    (["pretrain-encoder", "--stop-after-steps", "-1"], 3, r"--stop-after-steps must be a "
                                                          r"positive integer \(steps\), got -1"),
    (["pretrain-encoder", "--max-generate-seconds", "-3"], 3, r"--max-generate-seconds"),
    (["pretrain-encoder", "--lr", "inf"], 3, r"lr must be a finite number > 0, got inf"),
    (["pretrain", "--loader-workers", "10000"], 3, r"loader_workers must be an integer in "
                                                   r"\[0, [\d,]+\] \(at most 4 x the \d+ CPU"),
    (["pretrain", "--workers", "10000"], 3, r"workers must be an integer in \[0, "),
    (["pretrain-encoder", "--workers", "10000"], 3, r"workers must be an integer in \[0, "),
    (["pretrain-encoder", "--batch-size", "100000000"], 3, r"batch_size must be an integer in "
                                                           r"\[1, 65,536\]"),
    (["pretrain-encoder", "--train-scenes", "10", "--batch-size", "64"], 3,
     r"batch_size 64 is more than the 10 training scenes"),
    (["pretrain", "--train-scenes", "10", "--batch-size", "64"], 3,
     r"batch_size 64 is more than twice the 10 training scenes"),
    (["generate", "--kind", "hand-hand", "--num", "2", "--workers", "10000"], 3,
     r"workers must be an integer in \[1, "),
    (["demo", "--init-encoder", "/nonexistent.pt"], 4, r"--init-encoder /nonexistent\.pt: no "
                                                       r"such pose-encoder file"),
])
def test_starting_files_and_budgets_are_checked_before_any_scene(argv, code, message, tmp_path,
                                                                 capsys, monkeypatch):
    """Issue 53 items 15-17: a missing or crafted ``--init`` failed after the scenes were
    generated (hours at the default sizes); negative or NaN budgets and step counts were
    accepted (``--stop-after-steps -1`` exported an untrained encoder, exit 0)."""
    import re

    from handmesh_tutorial.apps import pretrain_network, pretraining_data
    from handmesh_tutorial.apps.demo import run as demo_run

    def never(*a, **k):
        raise AssertionError("generated scenes before checking the options")

    for module, name in ((pretrain_network, "generate_train_val"),
                         (pretraining_data, "generate_training_scenes"),
                         (demo_run, "generate_data")):
        monkeypatch.setattr(module, name, never)
    crafted = tmp_path / "crafted.pt"
    crafted.write_bytes(b"PK\x03\x04 not a checkpoint at all")
    argv = [str(crafted) if a == "CRAFTED" else a for a in argv]
    out = tmp_path / "run"
    got = cli.main([*argv, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert got == code, err
    assert re.search(message, err), err
    assert not out.exists()


def test_starting_files_are_read_in_a_child_before_torch_is_imported(tmp_path, monkeypatch):
    import sys

    from handmesh_tutorial.apps.pretraining_data import check_start_file

    monkeypatch.delitem(sys.modules, "torch")  # as in a fresh `handmesh pretrain`
    crafted = tmp_path / "crafted.pt"
    crafted.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=rf"^--init {crafted}: unreadable checkpoint"):
        check_start_file(crafted, "checkpoint", "--init")
    assert "torch" not in sys.modules


def test_a_time_budget_on_fewer_than_ten_training_scenes_is_cut_into_as_many_shards(
        tmp_path, monkeypatch):
    """Issue 53 item 16: ``--train-scenes 4 --max-generate-seconds 100`` failed with "parts must
    be an integer in [1, num=4], got 10"."""
    from handmesh_tutorial.apps import pretraining_data

    calls = []

    def fake(root, num, seed, *, parts=1, max_seconds=None, **kw):
        calls.append((num, parts, max_seconds))
        return {"root": root, "scenes": num, "seconds": 1.0, "shards": parts}

    monkeypatch.setattr(pretraining_data, "generate_training_scenes", fake)
    pretraining_data.generate_train_val(tmp_path, 4, 2, 7, render_size=64, workers=1,
                                        max_generate_seconds=100, log=None)
    assert calls == [(2, 1, None), (4, 4, 99.0)]
    calls.clear()
    pretraining_data.generate_train_val(tmp_path, 40, 2, 7, render_size=64, workers=1,
                                        max_generate_seconds=0.5, log=None)
    assert calls[1] == (40, 10, 0.0)  # the validation scenes took the budget: one shard


def test_pretrain_encoder_image_sizes_that_are_not_numbers_name_the_option(capsys):
    with pytest.raises(SystemExit) as e:  # was exit 3 "invalid literal for int()", no option
        cli.main(["pretrain-encoder", "--image-sizes", "64,abc"])
    assert e.value.code == 2
    assert "--image-sizes: must be comma-separated crop sides in pixels (e.g. 64,96,128), got " \
           "'64,abc'" in capsys.readouterr().err


def test_a_finished_command_does_not_fail_on_a_terminal_that_cannot_show_its_output(tmp_path):
    """Issue 43 item 11: under ``PYTHONIOENCODING=ascii`` (or a C locale) a finished ``generate``
    into a folder named with an accent exited 3 ("'ascii' codec can't encode")."""
    import os
    import subprocess
    import sys

    root = tmp_path / "données"
    generate_dataset(root, functools.partial(toy_sample, image_size=64), num=2, seed=1,
                     kind="hand-hand", progress=False, durable=False)
    env = dict(os.environ, PYTHONIOENCODING="ascii")
    out = subprocess.run([sys.executable, "-m", "handmesh_tutorial.apps.cli", "verify", str(root),
                          "--no-progress"], capture_output=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr.decode("ascii", "replace")
    assert b"donn\\xe9es: 2 samples read, 0 bad" in out.stdout, out.stdout


# ------------------------------------------------------------------ partial roots are said

def _partial(root, tmp_path, gone=(1, 3)):
    import shutil

    copy = tmp_path / "partial"
    shutil.copytree(root, copy)
    for i in gone:
        shutil.rmtree(copy / "samples" / f"{i:06d}")
    return copy


def test_verify_fails_when_planned_samples_are_missing(root, tmp_path, capsys):
    import json
    import shutil

    part = _partial(root, tmp_path)
    assert cli.main(["verify", str(part), "--no-progress"]) == cli.EXIT_CODES["bad-input"]
    out = capsys.readouterr().out
    assert "6 samples read, 0 bad, 2 of 8 planned samples missing (first 000001, 000003)" \
        in out, out
    assert cli.main(["verify", str(part), "--no-progress", "--remove-bad"]) == 0  # a repair
    assert "to write the missing samples" in capsys.readouterr().out
    shutil.rmtree(part / "samples")
    (part / "samples").write_text("not a folder")
    assert cli.main(["verify", str(part), "--no-progress"]) == 3
    assert "8 of 8 planned samples missing" in capsys.readouterr().out
    (part / "samples").unlink()
    shutil.copytree(root / "samples", part / "samples")
    meta = json.loads((part / "meta.json").read_text())
    meta.update(num_samples=10**8, ranges=[[0, 10**8]])
    (part / "meta.json").write_text(json.dumps(meta))
    assert cli.main(["verify", str(part), "--no-progress"]) == 3
    assert "99,999,992" not in (out := capsys.readouterr().out)
    assert ("99999992 of 100000000 planned samples missing (first 000008, 000009, 000010, "
            "000011, 000012)") in out, out


def test_evaluate_says_it_scored_a_partial_root(root, tmp_path, capsys):
    torch.manual_seed(0)
    net = T.build_model_from_config(T.TrainConfig(encoder="resnet10", image_size=32,
                                                  channels=(4, 4, 8, 8, 8),
                                                  latent_channels=8)).eval()
    part = _partial(root, tmp_path)
    ev = T.evaluate(net, part, image_size=32, progress=False, baseline=False,
                    out_dir=tmp_path / "ev")
    assert ev["num_samples"] == 6 and ev["planned"] == 8
    assert ev["notes"][0].startswith(f"scored 6 of 8 planned samples: {part}: 6 of 8 planned "
                                     "samples present (first missing 000001, 000003); rerun")
    import json

    assert json.loads((tmp_path / "ev" / "eval.json").read_text())["planned"] == 8
    with _io.single_writer(part / ".generate.lock", str(part)):  # a generate is writing it
        ev = T.evaluate(net, part, image_size=32, progress=False, baseline=False)
    assert "a `handmesh generate` is writing it now" in ev["notes"][0]
    ev = T.evaluate(net, root, image_size=32, progress=False, baseline=False)
    assert ev["notes"] == [] and ev["planned"] == ev["num_samples"] == 8


def test_train_warns_that_a_root_misses_planned_samples(root, tmp_path):
    from handmesh_tutorial.train.data import make_datasets

    part = _partial(root, tmp_path)
    with pytest.warns(UserWarning, match=r"training on 6 samples: .*6 of 8 planned samples "
                                         r"present \(first missing 000001, 000003\)"):
        make_datasets(T.TrainConfig(data=str(part), image_size=32))


@pytest.mark.parametrize("how", ["empty", "file"])
def test_train_on_a_root_without_samples_says_so(root, tmp_path, capsys, how):
    import shutil

    part = _partial(root, tmp_path, gone=range(8))
    if how == "file":
        shutil.rmtree(part / "samples")
        (part / "samples").write_text("")
    code = cli.main(["train", "--data", str(part), "--out", str(tmp_path / "run"), *TRAIN])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"], err
    assert f"no sample to train on: {part}: 0 of 8 planned samples present" in err, err
    assert "out of range" not in err
    if how == "file":
        assert "samples is not a folder" in err


# ------------------------------------------------------------------ sizes bounded, checked first

@pytest.mark.parametrize("option, value, says", [
    ("--batch-size", "100000000", r"batch_size must be an integer in \[1, 65,536\] "
                                  r"\(MAX_BATCH_SIZE\), got 100000000"),
    ("--loader-workers", "10000", r"num_workers must be an integer in \[0, [\d,]+\] \(at most 4 x "
                                  r"the \d+ CPU cores of this machine, at least 8\), got 10000"),
    ("--threads", "100000", r"threads must be an integer in \[1, [\d,]+\] \(at most 4 x the \d+ "
                            r"CPU cores"),
    ("--lr", "inf", r"lr must be a finite number > 0, got inf"),
    ("--lr", "nan", r"lr must be a finite number > 0, got nan"),
    ("--encoder-lr-scale", "inf", r"encoder_lr_scale must be a finite number >= 0, got inf"),
    ("--encoder", "evil", r"encoder must be one of resnet10, .*got 'evil'"),
    ("--latent-channels", "-1", r"latent_channels must be an integer in \[1, 4,096\]"),
    ("--latent-channels", "100000000", r"latent_channels must be an integer in \[1, 4,096\]"),
    ("--channels", "200000,4,8,8,8", r"channels must be at most 4,096 \(MAX_CHANNELS\)"),
    ("--device", "mps", r"device 'mps': this machine has no MPS"),
    ("--device", "cuda:99", r"device 'cuda:99': this machine has \d+ CUDA device"),
])
def test_train_bounds_every_size_before_any_work(root, tmp_path, capsys, option, value, says):
    import re

    if option == "--device" and value == "mps" and torch.backends.mps.is_available():
        pytest.skip("this machine has an MPS device")
    out = tmp_path / "run"
    code = cli.main(["train", "--data", str(root), "--out", str(out), *TRAIN, option, value])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"], err
    assert re.search(says, err), err
    assert "template" not in err and not out.exists()


def test_a_batch_larger_than_the_training_items_is_refused_not_padded(root, tmp_path, capsys):
    code = cli.main(["train", "--data", str(root), "--out", str(tmp_path / "run"), *TRAIN,
                     "--batch-size", "100"])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"], err
    assert "batch_size 100 is more than twice the 7 training items" in err, err
    with pytest.raises(ValueError, match="batch_size 13 is more than twice the 6 training items"):
        T.EpochBatchSampler(6, 13)
    assert len(T.EpochBatchSampler(6, 12).global_batches(0)[0]) == 12  # a small set: padded


@pytest.mark.parametrize("option, value, says", [
    ("--threads", "100000", r"threads must be an integer in \[1, "),
    ("--device", "cuda:99", r"device 'cuda:99': this machine has"),
    ("--batch-size", "100000000", r"batch_size must be an integer in \[1, 65,536\]"),
])
def test_evaluate_names_the_option_not_the_checkpoint(root, tmp_path, capsys, option, value,
                                                     says):
    import re

    code = cli.main(["evaluate", "--checkpoint", str(tmp_path / "none.pt"), "--data", str(root),
                     "--no-progress", option, value])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"], err
    assert re.search(says, err) and "unreadable" not in err, err


@pytest.mark.parametrize("command", [["generate", "--kind", "hand-hand", "--num", "1"],
                                     ["train", "--data", "ROOT"],
                                     ["evaluate", "--checkpoint", "c.pt", "--data", "ROOT"]])
def test_an_out_name_too_long_is_a_usage_error_naming_the_option(root, tmp_path, capsys,
                                                                 command):
    """Issue 53 item 19: a 256-character ``--out`` name (ENAMETOOLONG) was exit 1."""
    out = tmp_path / ("x" * 256)
    argv = [str(root) if a == "ROOT" else a for a in command]
    with pytest.raises(SystemExit) as e:
        cli.main([*argv, "--out", str(out)])
    assert e.value.code == cli.EXIT_CODES["usage"]
    assert "argument --out: a folder name is at most 255 bytes, got one of 256" in \
        capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing written
    err = OSError(errno.ENAMETOOLONG, "File name too long", str(out))  # from anywhere else
    assert cli.error_kind(err) == "bad-input"


def test_a_tampered_train_seconds_file_is_named(tmp_path):
    from handmesh_tutorial.apps.pretrain_network import _prior_train_seconds

    clock = tmp_path / "train_seconds.json"
    clock.write_text('{"epoch": 2, "seconds": 10.5}')
    assert _prior_train_seconds(clock, [{"epoch": 3, "seconds": 4.0}]) == 14.5
    for text, says in (("{", r"train_seconds\.json: not valid JSON"),  # was "Expecting value"
                       ('{"epoch": "x", "seconds": 1}', r"train_seconds\.json: expected "),
                       ('[1, 2]', r"train_seconds\.json: expected ")):
        clock.write_text(text)
        with pytest.raises(ValueError, match=says):
            _prior_train_seconds(clock, [])
