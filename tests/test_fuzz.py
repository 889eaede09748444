"""Damaged input files: a seeded subset of ``benchmarks/fuzz_files.py`` and the bugs its full run
found, each refused with a ``ValueError`` that names the file (docs page *Reliability*).

The subset reads every case in one child process under a 2 GB address-space limit, as the full
run does; a case must end ``clean`` (read fine, plausible values) or ``refused`` (named).
"""

from __future__ import annotations

import json
import pickle
import re
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from handmesh_tutorial.data.freihand import FreiHAND
from handmesh_tutorial.hand.mano import ManoModel, load_mano
from handmesh_tutorial.hand.template import load_template, save_template
from handmesh_tutorial.testing import mano_format_params, write_freihand_root
from handmesh_tutorial.train import TrainConfig, evaluate, load_checkpoint
from handmesh_tutorial.train.checkpoints import CHECKPOINT_FORMAT
from handmesh_tutorial.train.templates import (
    build_model_from_config,
    resolve_template,
    template_hash,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz_files as F  # noqa: E402


def test_a_seeded_subset_of_the_fuzz_run_is_clean_or_refused_by_name(tmp_path):
    base = F.build_corpus(tmp_path)
    # the file-damage targets (the planted-cache and --out targets have their own subset below)
    files = [t for t in F.TARGETS if t not in ("hierarchy-cache", "out-folder")]
    targets = [files[(3 * k) % len(files)] for k in range(10)]
    todo = [(t, F.mutations_of(t)[k % len(F.mutations_of(t))], 7_000 + k)
            for k, t in enumerate(targets)]
    # the classes of hostile roots (issue 43): foreign entries, links, non-ASCII names, extra
    todo += [(t, m, 7_100 + k) for k, (t, m) in enumerate(
        [("intersh-repair", "foreign")] * 4 + [("intersh-verify", "foreign"),
                                               ("intersh-repair", "extra"),
                                               ("intersh-verify", "extra")])]
    # the timeout only detects hangs: the first case also starts the child (imports torch)
    results = F.fuzz(base, todo, timeout=180)
    assert len(results) == len(todo)
    bad = [(r["target"], r["mutation"], r["n"], r["outcome"], r.get("what"),
            r.get("touched"), r.get("message", "")[-200:]) for r in results
           if r["outcome"] not in ("clean", "refused")]
    assert not bad, bad
    assert {r["outcome"] for r in results} == {"clean", "refused"}  # both classes are seen
    assert f"| all | all | {len(todo)} |" in F.table(results)


def test_the_fuzz_run_sees_a_touched_file(tmp_path):
    """The `touched` class is real: a planted file deleted, or a file created outside the root,
    is a failure whatever the reader said."""
    import random

    case = tmp_path / "case"
    (case / "intersh" / "samples").mkdir(parents=True)
    n = next(n for n in range(100) if random.Random(n).choice(F.FOREIGN_KINDS) == "user-files")
    assert F._plant_foreign(random.Random(n), case, tmp_path)[0] == "user-files"
    assert F._untouched(case) == []
    (case / "intersh" / "samples" / "notes.txt").unlink()
    (case / "outside" / "nologin").write_text("")
    assert sorted(F._untouched(case)) == ["intersh/samples/notes.txt deleted or changed",
                                          "outside/nologin created"]
    assert F.classify({"ok": True, "touched": F._untouched(case)}) == "touched"


def _flip_member_byte(path: Path, member: str) -> None:
    """Flip one data byte of a stored zip member (its CRC no longer matches)."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(member)
    raw = bytearray(path.read_bytes())
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 200
    raw[start] ^= 0x10
    path.write_bytes(bytes(raw))


def test_a_damaged_or_implausible_template_file_is_refused_naming_it(tmp_path):
    good = tmp_path / "template.npz"
    from handmesh_tutorial.train import save_template as save_train_template

    save_train_template(good, None)
    t = resolve_template(good)
    crc = tmp_path / "crc.npz"
    crc.write_bytes(good.read_bytes())
    _flip_member_byte(crc, "vertices.npy")  # was zipfile.BadZipFile "Bad CRC-32", no file named
    with pytest.raises(ValueError, match=r"crc\.npz: not a readable npz \(BadZipFile"):
        resolve_template(crc)
    arrays = {"vertices": t.vertices, "faces": t.faces, "joint_regressor": t.joint_regressor}
    for name, change, pattern in (
            ("flat.npz", {"vertices": t.vertices.reshape(-1)},
             r"flat\.npz: template vertices must be \(V, 3\)"),
            ("mm.npz", {"vertices": t.vertices * 1000},  # was accepted
             r"mm\.npz: a template vertex lies [\d.]+ m from the origin, beyond 1 m"),
            ("nan.npz", {"joint_regressor": t.joint_regressor * np.nan},
             r"nan\.npz: template vertices or joint_regressor hold NaN")):
        np.savez(tmp_path / name, **{**arrays, **change})
        with pytest.raises(ValueError, match=pattern):
            resolve_template(tmp_path / name)
    # all vertices at one point: a RuntimeError of the decimation ended `train` with exit 1
    np.savez(tmp_path / "point.npz", **{**arrays, "vertices": t.vertices * 0})
    cfg = TrainConfig(template=str(tmp_path / "point.npz"), encoder="resnet10",
                      channels=(4, 4, 8, 8, 8), latent_channels=8)
    for given in (None, resolve_template(cfg.template)):  # `train` passes the resolved one
        with pytest.raises(ValueError, match=r"point\.npz: this template builds no network "
                                             r"\(RuntimeError: decimation stuck"):
            build_model_from_config(cfg, given)


def test_a_damaged_hand_template_asset_is_named(tmp_path):
    from handmesh_tutorial.hand import HandModel

    path = tmp_path / "hand.npz"
    save_template(HandModel("right").template, path)
    assert load_template(path).vertices.shape[1] == 3
    _flip_member_byte(path, "vertices.npy")
    load_template.cache_clear()
    with pytest.raises(ValueError, match=r"hand\.npz: not a readable npz \(BadZipFile"):
        load_template(path)


def test_a_flipped_bit_in_a_checkpoint_is_refused_not_loaded(tmp_path):
    from handmesh_tutorial._untrusted import load_torch_file

    path = tmp_path / "w.pt"
    torch.save({"w": torch.ones(1000)}, path)
    assert torch.equal(load_torch_file(path)["w"], torch.ones(1000))
    member = next(n for n in zipfile.ZipFile(path).namelist() if n.endswith("/data/0"))
    _flip_member_byte(path, member)  # torch.load alone returns the altered weights
    with pytest.raises(ValueError, match=r"w\.pt: member '.*data/0' fails its CRC-32 check"):
        load_torch_file(path)
    # a local header's extra-field length changed: torch read shifted bytes as the weights
    torch.save({"w": torch.ones(1000)}, path)
    raw = bytearray(path.read_bytes())
    info = zipfile.ZipFile(path).getinfo(member)
    raw[info.header_offset + 28:info.header_offset + 30] = (len(info.extra) + 64).to_bytes(2,
                                                                                           "little")
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"w\.pt: (member .* fails its CRC-32|unreadable)"):
        load_torch_file(path)
    # the central directory says "deflated" for a stored member: was zlib.error (exit code 1)
    torch.save({"w": torch.ones(1000)}, path)
    raw = bytearray(path.read_bytes())
    central = raw.find(b"PK\x01\x02")
    raw[central + 10:central + 12] = (8).to_bytes(2, "little")
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match=r"w\.pt: unreadable checkpoint .*error"):
        load_torch_file(path)


@pytest.mark.parametrize("config, pattern", [
    ({"dataset": 0.0}, r"dataset must be"),  # was a ValueError naming no file
    (7, r"a TrainConfig is a mapping of its fields, got int"),  # was a TypeError (exit 1)
    ({"model_kwargs": {"bogus": 1}}, r"builds no network \(TypeError"),  # was exit 1
    # issue 53: a string listed its letters as keys; sizes allocated 1.44 TB before any check
    ("abc", r"a TrainConfig is a mapping of its fields, got str\)"),
    ({"channels": [200_000] * 5}, r"channels must be at most 4,096 \(MAX_CHANNELS\), got 200,000"),
    ({"latent_channels": 10**8}, r"latent_channels must be an integer in \[1, 4,096\]"),
    ({"encoder": "evil"}, r"encoder must be one of resnet10, .* got 'evil'"),
])
def test_a_checkpoint_with_an_invalid_config_is_refused_naming_it(tmp_path, config, pattern):
    path = tmp_path / "odd.pt"
    torch.save({"format": CHECKPOINT_FORMAT, "model": {}, "config": config,
                "template_hash": template_hash(None),
                "epoch": 0, "step": 0, "history": [], "best": 1.0}, path)
    with pytest.raises(ValueError, match=r"odd\.pt: its 'config' is not a valid TrainConfig|"
                                         r"odd\.pt: its config .* builds no network") as e:
        load_checkpoint(path)
    assert re.search(pattern, str(e.value)), e.value


def test_a_checkpoint_without_weights_or_truncated_is_named_in_one_short_line(tmp_path):
    from handmesh_tutorial import train as T

    path = tmp_path / "none.pt"
    config = T.TrainConfig(encoder="resnet10", image_size=32, channels=(4, 4, 8, 8, 8),
                           latent_channels=8)
    torch.save({"format": CHECKPOINT_FORMAT, "model": {}, "config": config.to_dict(),
                "template_hash": template_hash(None), "epoch": 0, "step": 0, "history": [],
                "best": 1.0}, path)
    with pytest.raises(ValueError) as e:
        load_checkpoint(path)
    msg = str(e.value)  # was about 20 KB: every key of the network
    assert len(msg) < 600 and "\n" not in msg, msg
    assert re.search(r"none\.pt: weights do not fit the architecture .*: \d+ missing \(first "
                     r"encoder\.", msg), msg
    good = tmp_path / "good.pt"
    torch.save({"w": torch.ones(100)}, good)
    cut = tmp_path / "cut.pt"
    cut.write_bytes(good.read_bytes()[:300])
    with pytest.raises(ValueError) as e:
        load_checkpoint(cut)
    msg = str(e.value)  # was nested twice and cut mid-word
    assert msg.count("cut.pt") == 1 and msg.count("unreadable checkpoint") == 1, msg


def test_the_pose_encoder_loader_never_advises_weights_only_false(tmp_path):
    from handmesh_tutorial.nn.pose_encoder import read_pose_encoder

    path = tmp_path / "enc.pt"
    torch.save({"format": "x", "obj": Path("/")}, path)  # an object torch refuses to unpickle
    with pytest.raises(ValueError) as e:
        read_pose_encoder(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: refused: the file holds objects other than tensors"), msg
    assert "will likely succeed" not in msg and msg.count(str(path)) == 1, msg


@pytest.mark.parametrize("key, value, pattern", [
    ("v_template", np.float64(3.0), r"'v_template' has shape \(\), expected Vx3"),  # IndexError
    ("f", "x", r"'f' must be a numeric array, got str"),  # AttributeError
    ("f", None, r"'f' must be a numeric array"),
    ("v_template", "scale", r"'v_template' holds [\d.]+, beyond \+-1 m"),  # accepted in mm
    ("f", "scale", r"'f' must hold vertex ids in \[0, 778\)"),  # accepted, out of range
    ("weights", "scale", r"'weights' holds values in .* expected skinning weights in \[0, 1\]"),
    ("posedirs", "nan", r"'posedirs' holds NaN or infinity"),
    ("J_regressor", "scale", r"'J_regressor' puts a rest joint [\d.]+ m from the origin"),
    ("hands_components", {"a": 1}, r"'hands_components' must be a numeric array"),  # TypeError
])
def test_implausible_mano_arrays_are_refused_naming_the_file(tmp_path, key, value, pattern):
    params = mano_format_params("right")
    if isinstance(value, str) and value in ("scale", "nan"):
        a = params[key]
        a = a.toarray() if hasattr(a, "toarray") else np.asarray(a)
        value = a * 1000 if value == "scale" else a * np.nan
    params[key] = value
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(params, protocol=2))
    with pytest.raises(ValueError, match=r"MANO_RIGHT\.pkl: key " + pattern):
        load_mano(path)
    good = mano_format_params("right")
    assert ManoModel(good, "right").num_vertices == 778  # the real layout still loads
    with pytest.raises(ValueError, match=r"fingertip vertex ids \(1, 2, 3, 4, 800\)"):
        ManoModel(good, "right", fingertips=(1, 2, 3, 4, 800))


def test_a_freihand_json_nested_too_deeply_or_beyond_float_is_named(tmp_path):
    root = write_freihand_root(tmp_path / "fh", 1, image_size=32)
    (root / "training_K.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match=r"training_K\.json: not valid JSON \(nested too deeply"):
        FreiHAND(root, "training").annotation("K")  # was a RecursionError (exit 1)
    (root / "training_K.json").write_text("[[[1" + "0" * 400 + ", 0, 0], [0, 1, 0], [0, 0, 1]]]")
    with pytest.raises(ValueError, match=r"training_K\.json: sample 0 has shape "
                                         r"non-numeric/ragged"):
        FreiHAND(root, "training").annotation("K")  # was an OverflowError (exit 1)


def test_evaluating_a_network_of_another_topology_says_so(tmp_path):
    root = write_freihand_root(tmp_path / "fh", 2, image_size=32)
    cfg = TrainConfig(image_size=32, encoder="resnet10", channels=(4, 4, 8, 8, 8),
                      latent_channels=8)
    net = build_model_from_config(cfg)  # the library's 779-vertex hand; FreiHAND has 778
    res = evaluate(net, root, kind="freihand", split="training", image_size=32, baseline=False,
                   progress=False)  # was: a bare shape-mismatch error
    assert "mpvpe" not in res["scores"] and np.isfinite(res["scores"]["pa_mpjpe"])
    assert any("the network predicts 779 vertices, the ground truth has 778" in n
               and "--template MANO_RIGHT.pkl" in n for n in res["notes"]), res["notes"]
    assert json.dumps(F.OUTCOMES)  # the benchmark's classes are importable from the tests


def test_nan_weights_are_refused_on_load_and_evaluate_never_reports_nan_scores(tmp_path):
    import functools

    from handmesh_tutorial.data import generate_dataset
    from handmesh_tutorial.testing import toy_sample
    from handmesh_tutorial.train import save_checkpoint

    cfg = TrainConfig(image_size=32, encoder="resnet10", channels=(4, 4, 8, 8, 8),
                      latent_channels=8)
    torch.manual_seed(0)
    net = build_model_from_config(cfg).eval()
    name = "encoder.conv1.weight"
    with torch.no_grad():
        net.state_dict()[name].view(-1)[0] = float("nan")
    save_checkpoint(tmp_path / "nan.pt", model=net, config=cfg, template_id=template_hash(None),
                    durable=False)
    with pytest.raises(ValueError, match=r"nan\.pt: weight 'encoder\.conv1\.weight' holds NaN"):
        load_checkpoint(tmp_path / "nan.pt")  # was loaded: every prediction NaN
    root = tmp_path / "data"
    generate_dataset(root, functools.partial(toy_sample, image_size=32), num=2, seed=1,
                     kind="hand-hand", progress=False, durable=False)
    with pytest.raises(ValueError, match=r"predicts NaN or infinity for 2 of 2 items"):
        evaluate(net, root, image_size=32, baseline=False, progress=False)  # was NaN mm, exit 0


@pytest.mark.parametrize("field, value", [("indices", 10**6), ("indptr", 10**6)])
def test_a_mano_sparse_matrix_with_indices_beyond_its_shape_is_refused_not_a_crash(
        tmp_path, field, value):
    import subprocess

    params = mano_format_params("right")
    getattr(params["J_regressor"], field)[3] = value  # one flipped bit in the official file
    path = tmp_path / "MANO_RIGHT.pkl"
    path.write_bytes(pickle.dumps(params, protocol=2))
    code = ("import sys\nfrom handmesh_tutorial.hand.mano import load_mano\ntry:\n"
            "    load_mano(sys.argv[1])\nexcept ValueError as e:\n    print(e)\n")
    # in a child: scipy's toarray wrote out of bounds and the interpreter died (SIGSEGV)
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, (out.returncode, out.stderr[-300:])
    assert re.search(r"MANO_RIGHT\.pkl: sparse matrix .*csc_matrix: inconsistent arrays",
                     out.stdout), out.stdout


def test_a_seeded_subset_of_planted_caches_and_users_files_in_out_is_clean_or_refused(tmp_path):
    """Issue 43: a planted ``hierarchy_*.npz`` is rebuilt with a warning naming it (it crashed
    scipy or changed the scores); the user's files in ``--out`` are refused by name, or left in
    a folder that is the command's own (they were overwritten)."""
    base = F.build_corpus(tmp_path)
    damage = [m for m in F.MUTATIONS if m not in ("foreign", "extra")]  # those: INTER-SH roots
    todo = [("hierarchy-cache", m, 9_100 + i) for i, m in enumerate(damage)]
    todo += [("out-folder", m, 9_200 + i) for i, m in enumerate(damage[:5])]
    results = F.fuzz(base, todo, timeout=120)
    bad = [(r["target"], r["mutation"], r["n"], r["outcome"], r.get("what"),
            r.get("message", "")[-200:]) for r in results if r["outcome"] not in
           ("clean", "refused")]
    assert not bad, bad
    seen = {(r["target"], r["outcome"]) for r in results}
    assert ("hierarchy-cache", "refused") in seen and ("out-folder", "refused") in seen, seen
    assert "clobbered" in F.FAILURES and "| all | all | 12 |" in F.table(results)


def _crops(n: int, size: int = 192) -> dict:
    g = torch.Generator().manual_seed(0)
    return {"image": torch.zeros(n, 3, size, size, dtype=torch.uint8),
            "joints": torch.rand(n, 21, 3, generator=g) * 0.05,
            "root": torch.tensor([[0.0, 0.0, 0.5]]).repeat(n, 1),
            "K": torch.eye(3).repeat(n, 1, 1), "box": torch.full((n,), 128.0)}


@pytest.mark.parametrize("damage, says", [
    (lambda c: list(c.values()), r"not a crop cache \(a list"),  # was a crash
    (lambda c: {**c, "joints": c["joints"] * float("nan")}, r"'joints' holds NaN"),
    (lambda c: {**c, "image": c["image"][:, :, :8, :8]}, r"'image' has shape \(2, 3, 8, 8\), "
                                                         r"expected \(2, 3, 192, 192\)"),
    (lambda c: {**c, "joints": c["joints"] * 1000}, r"'joints' holds values up to"),
    (lambda c: {**c, "K": c["K"].long()}, r"'K' holds NaN, infinity or no floats"),
])
def test_another_runs_crop_cache_is_checked_as_an_untrusted_file(tmp_path, damage, says):
    """Issue 53 item 14: ``pretrain-encoder --scenes-from`` trusted the other run's
    ``crops_train.pt``: a list or NaN joints crashed, 8x8 images trained silently (exit 0)."""
    from handmesh_tutorial.apps.pretraining_data import crop_caches

    other, out = tmp_path / "other", tmp_path / "out"
    other.mkdir()
    out.mkdir()
    torch.save(_crops(2), other / "crops_val.pt")
    splits = {"val": {"root": other / "data" / "val", "scenes": 2}}
    assert crop_caches(out, splits, scenes_from=other, progress=False)["val"]["image"].shape == (
        2, 3, 192, 192)
    torch.save(damage(_crops(2)), other / "crops_val.pt")
    with pytest.raises(ValueError, match=rf"{re.escape(str(other))}/crops_val\.pt: {says}"):
        crop_caches(out, splits, scenes_from=other, progress=False)
    (other / "crops_val.pt").unlink()
    torch.save(_crops(2), tmp_path / "elsewhere.pt")
    (other / "crops_val.pt").symlink_to(tmp_path / "elsewhere.pt")
    with pytest.raises(ValueError, match=r"crops_val\.pt is a symbolic link"):
        crop_caches(out, splits, scenes_from=other, progress=False)
