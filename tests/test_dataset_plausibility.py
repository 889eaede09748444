"""Bad values and damaged files are named bad samples: the INTER-SH readers refuse finite but
absurd values (plausibility ranges of ``dataset.schema``), wrongly typed or deeply nested JSON and
image bombs, naming the sample, so that ``handmesh verify`` and ``--skip-bad`` find them
(docs/concepts/reliability.md)."""

from __future__ import annotations

import functools
import io
import json
import shutil
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from handmesh_tutorial import data as D
from handmesh_tutorial.apps import cli
from handmesh_tutorial.data import files as F
from handmesh_tutorial.testing import synthetic_sample

SIZE = 32
make = functools.partial(synthetic_sample, image_size=SIZE, resolution=4)


@pytest.fixture()
def root(tmp_path):
    r = tmp_path / "r"
    D.generate_dataset(r, make, 4, 3, "hand-hand", progress=False, durable=False)
    return r


def _npz(d, **changes):
    with np.load(d / "annotation.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update({k: f(arrays[k]) for k, f in changes.items()})
    (d / "annotation.npz").write_bytes(D.npz_bytes(arrays))


def _json(d, **changes):
    ann = json.loads((d / "annotation.json").read_text())
    ann.update(changes)
    (d / "annotation.json").write_text(json.dumps(ann))


def _k(fx=None, cx=None, zero=False):
    def change(K):
        K = np.zeros((3, 3)) if zero else K.copy()
        if fx is not None:
            K[0, 0] = fx
        if cx is not None:
            K[0, 2] = cx
        return K
    return change


# (npz changes, pattern, whether the lean training read sees it too: the target's arrays and K)
ABSURD = [
    ({"joints_1": lambda a: a * 1e30, "vertices_1": lambda a: a * 1e30},
     r"key '(vertices|joints)_1': holds a coordinate of \d\.\d+e\+29 m, beyond \+-10 m", True),
    ({"vertices_2": lambda a: a + 20.0}, r"key 'vertices_2': holds a coordinate of 2\d\.\d* m",
     False),
    ({"joints_1": lambda a: a * [1.0, 1.0, -1.0]},
     r"key 'joints_1': has a hand point at z = -0\.\d+ m, not in front of the camera", True),
    ({"K": _k(zero=True)}, r"key 'K': is not a pinhole matrix", True),
    ({"K": _k(fx=1e-30)}, r"key 'K': focal lengths fx=1e-30, fy=51\.2 px are outside \[0\.1, "
                          r"100\] x the image's larger side 32 px", True),
    ({"K": _k(fx=1e9)}, r"key 'K': focal lengths fx=1e\+09", True),
    ({"K": _k(cx=1e6)}, r"key 'K': principal point \(1e\+06, 15\.5\) px lies more than 5 image "
                        r"sizes outside the 32 x 32 image", True),
]


@pytest.mark.parametrize("changes, pattern, lean", ABSURD, ids=[
    "hand-x1e30", "object-20m-away", "hand-behind-camera", "K-zeros", "focal-1e-30", "focal-1e9",
    "principal-point-1e6"])
def test_absurd_values_are_bad_samples_named_by_verify_and_skip_bad(root, changes, pattern,
                                                                    lean):
    d = root / "samples" / "000001"
    _npz(d, **changes)
    with pytest.raises(ValueError, match="000001/annotation.npz: " + pattern):
        D.read_sample(d)
    if lean:  # what training reads
        with pytest.raises(ValueError, match="000001/annotation.npz: " + pattern):
            F.read_target(d)
    report = D.verify_dataset(root, progress=False)
    assert [n for n, _ in report.bad] == ["000001"] and report.disagree == []
    assert "000001/annotation.npz" in report.bad[0][1]
    if lean:
        from handmesh_tutorial.data import torch_views as TV

        ds = TV.InterSHTorchDataset(root, 32, train=False)
        assert [(b["position"], b["sample"]) for b in TV.find_bad_items(ds)] == [(1, "000001")]
        if "vertices_1" in changes:  # the mean hand's image-free read of the target mesh
            with pytest.raises(ValueError, match="000001/annotation.npz: key 'vertices_1'"):
                ds.target_shape(1)
    for i in (0, 2, 3):
        D.read_sample(root / "samples" / f"{i:06d}")  # the others read


def test_the_writer_refuses_absurd_values_too():
    s = make(0)
    s["joints"] = {1: s["joints"][1] * 1e30, 2: s["joints"][2]}
    with pytest.raises(ValueError, match=r"sample\['joints_1'\]: holds a coordinate"):
        D.encode_sample(s)
    s = make(0)
    s["K"] = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"sample\['K'\]: is not a pinhole matrix"):
        D.encode_sample(s)


def test_skip_bad_names_sample_ids_not_positions_and_a_singular_k_is_a_bad_sample(root):
    from handmesh_tutorial.data import torch_views as TV

    shutil.rmtree(root / "samples" / "000000")  # positions 0, 1, 2 are samples 1, 2, 3
    png = root / "samples" / "000002" / "image.png"
    png.write_bytes(png.read_bytes()[:100])
    _npz(root / "samples" / "000003", K=_k(zero=True))  # np.linalg.inv: 'Singular matrix'
    ds = TV.InterSHTorchDataset(root, 32, train=True)
    bad = TV.find_bad_items(ds)
    assert [(b["position"], b["index"], b["sample"]) for b in bad] == [(1, 1, "000002"),
                                                                         (2, 2, "000003")]
    assert "000003/annotation.npz: key 'K'" in bad[1]["error"]
    with pytest.raises(TV.BadSampleError, match=r"^sample 000003: .*000003/annotation\.npz"):
        ds[2]
    kept, _ = TV.drop_bad_items(ds)
    assert len(kept) == 1 and kept[0]["image"].shape == (3, 32, 32)


def _nested(d):
    text = (d / "annotation.json").read_text()  # 100,000 brackets: json's RecursionError
    (d / "annotation.json").write_text(text.replace('"labels"', '"x": ' + "[" * 100_000
                                                    + "]" * 100_000 + ', "labels"'))


DAMAGED_JSON = [
    (_nested, r"annotation\.json: not valid JSON \(nested too deeply"),
    (functools.partial(_json, image_size=5),
     r"annotation\.json: 'image_size' must be \[height, width\]"),
    (functools.partial(_json, image_size=[100_000, 100_000]),
     r"annotation\.json: 'image_size' .* integers in \[1, 4096\] \(MAX_IMAGE_SIZE\)"),
    (functools.partial(_json, extra=[1]),
     r"annotation\.json: 'extra' must be a JSON object, got list"),
    (functools.partial(_json, extra_arrays=5),
     r"annotation\.json: 'extra_arrays' must be a JSON list, got int"),
    (functools.partial(_json, extra_arrays=["../x"]),
     r"annotation\.json: 'extra_arrays' must list identifiers"),
    (functools.partial(_json, scene_mask_bits="8"),
     r"annotation\.json: 'scene_mask_bits' must be 8 or 16"),
]


@pytest.mark.parametrize("damage, pattern", DAMAGED_JSON, ids=[
    "nested-1e5-deep", "image_size-int", "image_size-huge", "extra-list", "extra_arrays-int",
    "extra_arrays-path", "scene_mask_bits-str"])
def test_damaged_annotation_json_is_a_named_bad_sample(root, damage, pattern, capsys):
    d = root / "samples" / "000001"
    damage(d)
    for read in (D.read_sample, F.read_target, D.read_annotation):
        with pytest.raises(ValueError, match="000001/" + pattern):
            read(d)
    report = D.verify_dataset(root, progress=False)
    assert [n for n, _ in report.bad] == ["000001"]
    capsys.readouterr()
    assert cli.main(["verify", str(root), "--no-progress"]) == cli.EXIT_CODES["bad-input"]
    out, err = capsys.readouterr()
    assert "1 bad" in out and "000001" in out and err == ""


def test_any_other_error_of_a_reader_names_the_sample(root, monkeypatch):
    def broken(*args):
        raise TypeError("unsupported operand")

    monkeypatch.setattr(F, "_canonical", broken)
    with pytest.raises(ValueError, match=r"000001: not a readable sample folder \(TypeError: "
                                         r"unsupported operand\)"):
        D.read_sample(root / "samples" / "000001")


def _png_declaring(width, height):
    """A valid small PNG whose header declares ``width`` x ``height`` (the IHDR patched)."""
    buf = io.BytesIO()
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(buf, format="PNG")
    data = bytearray(buf.getvalue())
    data[16:24] = struct.pack(">II", width, height)
    data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
    return bytes(data)


@pytest.mark.parametrize("side, pattern", [
    (20_000, r": not a readable PNG \(DecompressionBombError"),
    (10_000, r": not a readable PNG \(DecompressionBombWarning"),
    (64, r" has shape \(64, 64\), expected \(32, 32\) \(.*not decoded\)"),
])
def test_an_image_bomb_is_a_named_bad_sample_refused_before_decoding(root, side, pattern):
    d = root / "samples" / "000001"
    (d / "image.png").write_bytes(_png_declaring(side, side))
    for read in (D.read_sample, F.read_target):
        with pytest.raises(ValueError, match=r"000001/image\.png" + pattern):
            read(d)
    assert [n for n, _ in D.verify_dataset(root, progress=False).bad] == ["000001"]


def test_generate_refuses_more_samples_than_meta_json_may_declare(tmp_path):
    with pytest.raises(ValueError, match=r"num must be an integer in \[1, 100,000,000\] "
                                         r"\(MAX_SAMPLES"):
        D.generate_dataset(tmp_path / "r", make, D.MAX_SAMPLES + 1, 0, "hand-hand",
                           shard=(0, D.MAX_SAMPLES // 2), progress=False)  # a 2-sample shard
    assert not (tmp_path / "r").exists()  # no meta.json its reader would refuse
