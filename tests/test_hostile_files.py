"""Hostile files: crafted MANO pickles, ``annotation.npz`` files and checkpoints of a few hundred
bytes to a few hundred kilobytes that declare gigabytes, or that crashed the interpreter, are
refused with a ``ValueError`` naming the file, before anything large is allocated.

The files are written here opcode by opcode (``pickle``), header by header (``np.lib.format``)
and member by member (``zipfile``). They are read in one child process under a 2 GB address-space
limit (``RLIMIT_AS``), so a regression shows as a MemoryError, a signal or a timeout in the child,
never as a machine out of memory. Docs page *Reliability*, "Files are never trusted".
"""

from __future__ import annotations

import functools
import io
import json
import os
import re
import resource
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from handmesh_tutorial import data as D
from handmesh_tutorial._untrusted import MAX_NPZ_BYTES, open_npz
from handmesh_tutorial.apps.cli import main as cli_main
from handmesh_tutorial.apps.pose_pretraining import PosePretrainConfig
from handmesh_tutorial.budget import MAX_IMAGE_SIZE, MIN_IMAGE_SIZE
from handmesh_tutorial.hand.mano import unpickler as U
from handmesh_tutorial.testing import synthetic_sample
from handmesh_tutorial.train import TrainConfig, evaluate

CAP = 2 * 2**30  # the child's address space, bytes

# ------------------------------------------------------------------ crafted MANO pickles


def _mano_array(shape, code: bytes, flags: int, raw: bytes) -> bytes:
    """Protocol-0 opcodes of an array as numpy pickles one (``_reconstruct`` + state), with the
    dtype's state (byte order ``|``, ``flags``) and the data given."""
    dims = b"".join(b"I%d\n" % n for n in shape)
    return (b"cnumpy.core.multiarray\n_reconstruct\n(cnumpy\nndarray\n(I0\ntS'b'\ntR"
            b"(I1\n(" + dims + b"tcnumpy\ndtype\n(S'" + code + b"'\nI0\nI1\ntR"
            b"(I3\nS'|'\nNNNI-1\nI-1\nI%d\ntbI00\nS'" % flags + raw + b"'\ntb")


def _in_dict(value: bytes) -> bytes:
    return b"(dp0\nS'a'\n" + value + b"s."


def _shared_lists(levels: int) -> bytes:
    """l0 = [0.0]; l(k+1) = [lk, lk]: ``levels`` memo references, 2**levels leaves."""
    body = b"(lp1\nF0.0\na0"
    for k in range(1, levels + 1):
        body += b"(lp%d\ng%d\nag%d\na0" % (k + 1, k, k)
    return _in_dict(body + b"g%d\n" % (levels + 1))


MANO_FILES = {
    # numpy's dtype.__setstate__ accepts an object dtype without its object flag: numpy then read
    # the 16 bytes as two PyObject pointers (SIGSEGV)
    "object_dtype.pkl": _in_dict(_mano_array((2,), b"O8", 0, b"A" * 16)),
    # the shape in the array's state was never checked (only _reconstruct's)
    "huge_state_shape.pkl": _in_dict(
        b"cnumpy.core.multiarray\n_reconstruct\n(cnumpy\nndarray\n(I0\ntS'b'\ntR"
        b"(I1\n(I330000000\ntcnumpy\ndtype\n(S'O8'\nI0\nI1\ntR(I3\nS'|'\nNNNI-1\nI-1\nI63\ntb"
        b"I00\n(lp1\nNatb"),
    "shared_lists.pkl": _shared_lists(30),  # 2**30 leaves once expanded
    "deep_lists.pkl": _in_dict(b"]" * 100_001 + b"a" * 100_000),
    "cycle.pkl": _in_dict(b"(lp1\ng1\na"),
    # issue 53: 14 bytes declaring 2^45 (MemoryError, no file named); keys that are no strings
    "huge_bytes.pkl": b"\x80\x04\x8e" + (2**45).to_bytes(8, "little") + b".",
    "int_keys.pkl": b"\x80\x02}q\x00(K\x01K\x01X\x01\x00\x00\x00aK\x02u.",
}
MANO_EXPECTED = {
    "object_dtype.pkl": r"refusing numpy\.dtype of dtype 'O8'",
    "huge_state_shape.pkl": r"refusing numpy array of shape \(330000000,\) \(more than",
    "shared_lists.pkl": r"refusing contents that expand to more than 20,000,000 elements",
    "deep_lists.pkl": r"refusing contents nested more than 32 levels",
    "cycle.pkl": r"refusing a container that contains itself",
    "huge_bytes.pkl": r"not a readable MANO pickle \(expected 35184372088832 bytes in a bytes8",
    "int_keys.pkl": r"a MANO file's keys are strings, got int key '1'",
}

# ------------------------------------------------------------------ crafted annotation.npz


def _npy_header(shape, dtype) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
              "shape": tuple(shape)})
    return buf.getvalue()


def _npz_with(path: Path, key: str, header: bytes, data_bytes: int) -> None:
    """Replace member ``key`` of the npz at ``path`` by ``header`` + ``data_bytes`` zero bytes,
    deflated and streamed (the file stays small whatever it declares)."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != key}
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for k, v in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, v)
            zf.writestr(f"{k}.npy", buf.getvalue())
        with zf.open(f"{key}.npy", "w", force_zip64=True) as f:
            f.write(header)
            chunk = bytes(2**20)
            for start in range(0, data_bytes, len(chunk)):
                f.write(chunk[:min(len(chunk), data_bytes - start)])


# ------------------------------------------------------------------ crafted checkpoints


def _deflated_checkpoint(path: Path, numel: int) -> None:
    """A torch.save archive whose one float32 storage declares ``numel`` elements and holds
    them as a deflate stream of zeros (torch's reader inflates members)."""
    buf = io.BytesIO()
    torch.save({"format": "handmesh-checkpoint", "w": torch.zeros(4)}, buf)
    src = zipfile.ZipFile(io.BytesIO(buf.getvalue()))
    with zipfile.ZipFile(path, "w") as zf:
        for info in src.infolist():
            data = src.read(info)
            if info.filename.endswith("data.pkl"):  # numel and shape of the tensor: 4 -> numel
                data = data.replace(b"K\x04t", b"J" + struct.pack("<i", numel) + b"t", 1)
                data = data.replace(b"K\x04\x85", b"J" + struct.pack("<i", numel) + b"\x85", 1)
                zf.writestr(info.filename, data)
            elif info.filename.endswith("/data/0"):
                member = zipfile.ZipInfo(info.filename)
                member.compress_type = zipfile.ZIP_DEFLATED
                with zf.open(member, "w") as f:
                    for _ in range(numel * 4 // 2**20):
                        f.write(bytes(2**20))
            else:
                zf.writestr(info.filename, data)


# ------------------------------------------------------------------ the capped child

_CHILD = r"""
import json, resource, sys, time
for name, reader, path in json.loads(sys.argv[1]):
    t = time.perf_counter()
    try:
        if reader == "mano":
            from handmesh_tutorial.hand.mano import read_mano_pickle as read
        elif reader == "sample":
            from handmesh_tutorial.data.files import read_sample as read
        else:
            from handmesh_tutorial.train.checkpoints import load_checkpoint as read
        repr(read(path))  # touches every value: a bad object array crashes here
        out = {"error": None, "message": "loaded"}
    except BaseException as e:
        out = {"error": type(e).__name__, "value_error": isinstance(e, ValueError),
               "message": str(e)}
    out.update(name=name, seconds=round(time.perf_counter() - t, 3),
               peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
    print(json.dumps(out), flush=True)
"""


def _cap():
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def read_capped(cases: list, timeout: float = 120) -> dict:
    """Read each ``(name, reader, path)`` in a child under `CAP`; a case that kills the child
    (signal, timeout) is recorded and the child restarted for the rest."""
    results, todo = {}, list(cases)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    while todo:
        try:
            proc = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(todo)],
                                  capture_output=True, text=True, timeout=timeout, env=env,
                                  preexec_fn=_cap)
            out, died = proc.stdout, f"child died (exit {proc.returncode}): {proc.stderr[-300:]}"
        except subprocess.TimeoutExpired as e:
            out, died = (e.stdout or b"").decode(), f"child ran past {timeout} s"
        for line in out.splitlines():
            r = json.loads(line)
            results[r["name"]] = r
        todo = [c for c in todo if c[0] not in results]
        if todo:
            results[todo[0][0]] = {"error": "died", "value_error": False, "message": died}
            todo = todo[1:]
    return results


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """Every crafted file, read once in one capped child: ``{file name: result}``."""
    tmp = tmp_path_factory.mktemp("hostile")
    cases = []
    for name, payload in MANO_FILES.items():
        (tmp / name).write_bytes(payload)
        cases.append((name, "mano", str(tmp / name)))
    make = functools.partial(synthetic_sample, image_size=32, resolution=4)
    root = tmp / "root"
    D.generate_dataset(root, make, 3, 3, "hand-hand", progress=False)
    samples = sorted((root / "samples").iterdir())
    # 1.2 GB declared, 64 bytes held
    _npz_with(samples[0] / "annotation.npz", "vertices_1", _npy_header((100_000_000, 3), "<f4"),
              64)
    # 108 MB declared and held, as 100 KB of deflated zeros
    _npz_with(samples[1] / "annotation.npz", "vertices_1", _npy_header((9_000_000, 3), "<f4"),
              108_000_000)
    cases += [("short.npz", "sample", str(samples[0])), ("deflated.npz", "sample",
                                                         str(samples[1]))]
    _deflated_checkpoint(tmp / "deflated.pt", 16 * 2**20)
    torch.save({"format": "handmesh-checkpoint", "w": torch.zeros(1).expand(10**9)},
               tmp / "expanded.pt")
    torch.save({"format": "handmesh-checkpoint"}, tmp / "legacy.pt",
               _use_new_zipfile_serialization=False)
    cases += [(n, "checkpoint", str(tmp / n)) for n in ("deflated.pt", "expanded.pt", "legacy.pt")]
    sizes = {name: os.path.getsize(path if reader != "sample" else Path(path) / "annotation.npz")
             for name, reader, path in cases}
    results = read_capped(cases)
    for name, r in results.items():
        r["file_bytes"] = sizes[name]
        r["path"] = dict((c[0], c[2]) for c in cases)[name]
    return results


def _assert_refused(r: dict, pattern: str) -> None:
    assert r["error"] not in (None, "died"), r
    assert r["value_error"], r
    assert Path(r["path"]).name in r["message"] or r["path"] in r["message"], r
    assert re.search(pattern, r["message"]), (pattern, r)


@pytest.mark.parametrize("name", sorted(MANO_FILES))
def test_crafted_mano_pickles_are_refused_before_allocating(hostile, name):
    r = hostile[name]
    assert r["file_bytes"] < 1_000_000
    _assert_refused(r, MANO_EXPECTED[name])


def test_a_legitimate_array_still_loads_through_the_checked_path(tmp_path):
    # the same opcodes as object_dtype.pkl with a float dtype and its 16 bytes
    raw = np.array([1.5, -2.0]).tobytes()
    assert b"'" not in raw and b"\\" not in raw and b"\n" not in raw
    path = tmp_path / "ok.pkl"
    path.write_bytes(_in_dict(_mano_array((2,), b"<f8", 0, raw)))
    got = U.read_mano_pickle(path)["a"]
    assert got.dtype == np.float64 and got.flags.writeable
    np.testing.assert_array_equal(got, [1.5, -2.0])
    path.write_bytes(_shared_lists(3))  # 8 leaves: shared references are fine when small
    assert np.asarray(U.read_mano_pickle(path)["a"]).shape == (2, 2, 2, 1)


@pytest.mark.parametrize("name, pattern", [
    ("short.npz", r"annotation\.npz: member 'vertices_1\.npy' declares shape \(100000000, 3\)"),
    ("deflated.npz", r"annotation\.npz: its members hold more than 67,108,864 bytes"),
])
def test_an_annotation_npz_that_declares_gigabytes_is_refused_before_reading(hostile, name,
                                                                                 pattern):
    r = hostile[name]
    assert r["file_bytes"] < 1_000_000
    _assert_refused(r, pattern)


def test_the_npz_check_accepts_real_files_and_refuses_object_arrays(tmp_path):
    good = tmp_path / "good.npz"
    np.savez_compressed(good, a=np.arange(6.0).reshape(2, 3), b=np.zeros(0, np.int64))
    with open_npz(good) as z:
        np.testing.assert_array_equal(z["a"], np.arange(6.0).reshape(2, 3))
    np.savez(tmp_path / "obj.npz", a=np.array([None, 1], dtype=object))
    with pytest.raises(ValueError, match=r"obj\.npz: member 'a\.npy' has dtype object"):
        with open_npz(tmp_path / "obj.npz"):
            pass
    with pytest.raises(ValueError, match=r"good\.npz: its members hold more than 10 bytes"):
        with open_npz(good, max_bytes=10):
            pass
    assert MAX_NPZ_BYTES >= 2**20


@pytest.mark.parametrize("name, pattern", [
    ("deflated.pt", r"deflated\.pt: its members expand to [\d,]+ bytes from a [\d,]+-byte file"),
    ("expanded.pt", r"expanded\.pt: tensor \['w'\] of shape \(1000000000,\) claims"),
    ("legacy.pt", r"legacy\.pt: unreadable checkpoint \(truncated, or not a zip archive"),
])
def test_a_checkpoint_that_expands_is_refused_before_reading(hostile, name, pattern):
    r = hostile[name]
    assert r["file_bytes"] < 1_000_000
    _assert_refused(r, pattern)


def test_image_sizes_have_one_bounded_range(tmp_path, capsys):
    assert (MIN_IMAGE_SIZE, MAX_IMAGE_SIZE) == (32, 4096)
    for bad in (100_000, 31, 5000):
        with pytest.raises(ValueError, match=r"image_size must be an integer in \[32, 4096\]"):
            TrainConfig(image_size=bad)
    with pytest.raises(ValueError, match=r"image_sizes must be an integer in \[32, 4096\]"):
        PosePretrainConfig(image_sizes=(64, 100_000))
    with pytest.raises(ValueError, match=r"render_size must be an integer in \[32, 4096\]"):
        PosePretrainConfig(render_size=5000)
    # evaluate checks the size before it opens the checkpoint or the data (neither exists here)
    with pytest.raises(ValueError, match=r"image_size .* got 100000"):
        evaluate(tmp_path / "none.pt", data=tmp_path / "none", image_size=100_000)
    code = cli_main(["evaluate", "--checkpoint", str(tmp_path / "none.pt"), "--data",
                     str(tmp_path / "none"), "--image-size", "100000"])
    assert code == 3 and "image_size must be an integer in [32, 4096]" in capsys.readouterr().err
    assert TrainConfig(image_size=4096).image_size == 4096



# ------------------------------------------------------------------ one reader rule: no links

def _toy_root(root: Path, num: int = 4, shard=None) -> Path:
    from handmesh_tutorial.testing import toy_sample

    D.generate_dataset(root, functools.partial(toy_sample, image_size=64), num=num, seed=11,
                       kind="hand-hand", shard=shard, progress=False, durable=False)
    return root


@pytest.fixture
def two_shards(tmp_path):
    shards = [_toy_root(tmp_path / f"s{k}", shard=(k, 2)) for k in range(2)]
    outside = tmp_path / "outside"
    outside.mkdir()
    return shards, outside


@pytest.mark.parametrize("durable", [False, True])
def test_merge_never_copies_nor_links_what_a_link_points_to(two_shards, tmp_path, durable):
    (s0, s1), outside = two_shards
    secret = outside / "secret.json"
    secret.write_text('{"secret": 1}')
    sample = sorted((s1 / "samples").iterdir())[0]
    (sample / "annotation.json").unlink()
    (sample / "annotation.json").symlink_to(secret)
    with pytest.raises(ValueError, match=r"annotation\.json is a symbolic link"):
        D.merge_shards([s0, s1], tmp_path / "m1", link=True, progress=False, durable=durable)
    assert os.stat(secret).st_nlink == 1  # the outside file gained no hard link
    assert not any(p.name == "annotation.json" and p.read_bytes() == secret.read_bytes()
                   for p in (tmp_path / "m1").rglob("annotation.json"))
    # a linked sub-folder inside a sample (a link to / would copy the filesystem)
    sample.joinpath("annotation.json").unlink()
    (sample / "annotation.json").write_bytes((sorted((s0 / "samples").iterdir())[0]
                                              / "annotation.json").read_bytes())
    (sample / "extra").symlink_to(outside, target_is_directory=True)
    with pytest.raises(ValueError, match=r"extra is a symbolic link"):
        D.merge_shards([s0, s1], tmp_path / "m2", progress=False, durable=durable)
    (sample / "extra").unlink()
    (sample / "sub").mkdir()  # a real sub-folder: no IsADirectoryError, no recursive copy
    with pytest.raises(ValueError, match=r"sub is a folder"):
        D.merge_shards([s0, s1], tmp_path / "m3", progress=False, durable=durable)


def test_a_sample_folder_linked_outside_is_no_sample_for_any_reader(two_shards, tmp_path):
    (s0, s1), outside = two_shards
    sample = sorted((s1 / "samples").iterdir())[0]
    real = outside / sample.name
    sample.rename(real)
    sample.symlink_to(real, target_is_directory=True)
    with pytest.raises(ValueError, match=r"incomplete: 1 samples missing"):
        D.merge_shards([s0, s1], tmp_path / "m", link=True, progress=False)
    assert all(os.stat(p).st_nlink == 1 for p in real.iterdir())
    ds = D.InterSHDataset(s1)  # train, evaluate and the lean read count the samples here
    assert int(sample.name) not in ds.indices.tolist() and int(sample.name) in ds.missing
    report = D.verify_dataset(s1, progress=False)
    assert (sample.name, "not a sample folder (a link)") in report.bad


def test_a_linked_file_in_a_sample_folder_is_refused_by_every_read(tmp_path):
    root = _toy_root(tmp_path / "root", num=2)
    sample = sorted((root / "samples").iterdir())[0]
    image = tmp_path / "image.png"
    (sample / "image.png").rename(image)
    (sample / "image.png").symlink_to(image)
    ds = D.InterSHDataset(root)
    for read in (lambda: ds[0], lambda: ds.target(0), lambda: D.read_sample(sample)):
        with pytest.raises(ValueError, match=r"image\.png is a symbolic link"):
            read()
    report = D.verify_dataset(root, progress=False)
    assert [n for n, _ in report.bad] == [sample.name]
    assert "symbolic link" in report.bad[0][1]


def test_generate_neither_counts_nor_writes_through_a_linked_sample_folder(tmp_path):
    root = _toy_root(tmp_path / "root", num=3)
    outside = tmp_path / "outside"
    sample = root / "samples" / "000001"
    sample.rename(outside)
    sample.symlink_to(outside, target_is_directory=True)
    before = sorted(p.name for p in outside.iterdir())
    with pytest.raises(ValueError, match=r"000001 is a link where a sample folder belongs"):
        _toy_root(root, num=3)
    assert sorted(p.name for p in outside.iterdir()) == before and sample.is_symlink()
