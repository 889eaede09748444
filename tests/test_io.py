"""The one copy of atomic writes and JSON-safe values (`handmesh_tutorial._io`)."""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from handmesh_tutorial import _io


def test_json_safe_turns_numpy_paths_and_non_finite_floats_into_plain_json():
    value = {"a": np.float32(1.5), "b": np.int64(3), "c": np.array([[1, 2]]), 4: (np.bool_(True),),
             "nan": float("nan"), "inf": np.float64(-np.inf), "path": Path("x") / "y.json"}
    out = _io.json_safe(value)
    assert out == {"a": 1.5, "b": 3, "c": [[1, 2]], "4": [True], "nan": None, "inf": None,
                   "path": os.path.join("x", "y.json")}
    assert type(out["b"]) is int and type(out["4"][0]) is bool
    json.dumps(out, allow_nan=False)  # strict JSON accepts it


def test_json_safe_names_where_an_unstorable_value_sits():
    with pytest.raises(ValueError, match=r"stats\['inner'\]\['x'\]: value of type object"):
        _io.json_safe({"inner": {"x": object()}}, "stats")


def test_write_json_round_trips_with_a_final_newline_and_no_nan(tmp_path):
    path = _io.write_json(tmp_path / "sub" / "m.json", {"z": 1, "a": [np.float64(0.25), math.nan]})
    text = path.read_text()
    assert text.endswith("\n") and text.index('"a"') < text.index('"z"')  # sorted keys
    assert json.loads(text) == {"a": [0.25, None], "z": 1}


def test_a_failing_writer_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "out.bin"
    _io.atomic_write_bytes(path, b"old")

    def broken(fh):
        fh.write(b"half")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError, match="disk on fire"):
        _io.atomic_write_with(path, broken)
    assert path.read_bytes() == b"old"
    assert _io.leftover_temporaries(path) == [] and sorted(os.listdir(tmp_path)) == ["out.bin"]


def test_text_mode_custom_temporary_name_and_shared_permissions(tmp_path):
    path = tmp_path / "report.md"
    _io.atomic_write_with(path, lambda fh: fh.write("h\u00e9llo"), binary=False,
                          tmp_path=tmp_path / ".tmp-report.md-1")
    assert path.read_text(encoding="utf-8") == "h\u00e9llo"
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~_umask()
    assert not (tmp_path / ".tmp-report.md-1").exists()
    _io.atomic_write_text(path, "second", durable=False)
    assert path.read_text() == "second"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize("mask", [0o022, 0o077])
def test_written_files_honour_the_users_umask_as_samples_do(tmp_path, mask):
    old = os.umask(mask)
    try:
        path = _io.write_json(tmp_path / "eval.json", {"a": 1}, durable=False)
        with open(tmp_path / "plain", "w"):
            pass
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == stat.S_IMODE((tmp_path / "plain").stat().st_mode)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask


def test_atomic_savez_round_trips_both_formats_and_refuses_object_arrays(tmp_path):
    a = np.arange(6.0).reshape(2, 3)
    for compressed in (True, False):
        p = _io.atomic_savez(tmp_path / f"a{compressed}.npz", compressed=compressed, a=a)
        with np.load(p, allow_pickle=False) as z:
            np.testing.assert_array_equal(z["a"], a)
    with pytest.raises(ValueError, match=r"array 'bad' has dtype object"):
        _io.atomic_savez(tmp_path / "b.npz", bad=np.array([{}, None], dtype=object))
    assert not (tmp_path / "b.npz").exists()
