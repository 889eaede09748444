"""INTER-SH storage: round trips, byte determinism, atomic resumable generation, shards, errors.

A synthetic ``make_sample`` (two ray-cast spheres, ``testing.synthetic_sample``) stands in for the
renderer, so these tests need no OpenGL.
"""

import functools
import hashlib
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import types
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fingerprints import differences, fingerprint
from PIL import Image

from handmesh_tutorial import data as D
from handmesh_tutorial.testing import synthetic_sample

SIZE = 32
SEED = 3
make = functools.partial(synthetic_sample, image_size=SIZE, resolution=4)


def gen(root, num=6, seed=SEED, fn=make, **kw):
    kw.setdefault("progress", False)
    return D.generate_dataset(root, fn, num, seed, "hand-hand", **kw)


def tree(root) -> dict:
    """sha256 of every file under root (relative path -> digest), the writer lock excluded."""
    root = Path(root)
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != D.schema._LOCK_FILE}


def sample_dirs(root) -> list[str]:
    return sorted(p.name for p in (Path(root) / D.SAMPLES_DIR).iterdir())


# ------------------------------------------------------------------ write / read
def test_round_trip_preserves_values_and_dtypes(tmp_path):
    s = synthetic_sample(5, kind="hand-object", image_size=SIZE, resolution=4)
    s["alone_images"] = {2: np.full((SIZE, SIZE, 3), 7, np.uint8)}
    s["depth"] = np.linspace(0, 1, SIZE * SIZE, dtype=np.float32).reshape(SIZE, SIZE)
    s["camera_name"] = "cam0"
    s["meshes"][2] = (s["meshes"][2][0].astype(np.float64), s["meshes"][2][1].astype(np.int64))
    D.write_sample(tmp_path / "x", s)
    r = D.read_sample(tmp_path / "x")

    assert r["image"].dtype == np.uint8 and np.array_equal(r["image"], s["image"])
    assert r["scene_mask"].dtype == np.int32 and np.array_equal(r["scene_mask"], s["scene_mask"])
    assert sorted(r["alone_masks"]) == [1, 2]
    for lab, m in s["alone_masks"].items():
        assert r["alone_masks"][lab].dtype == bool and np.array_equal(r["alone_masks"][lab], m)
    for lab, (v, f) in s["meshes"].items():
        rv, rf = r["meshes"][lab]
        # stored as documented: float32 vertices, int32 faces, whatever came in
        assert rv.dtype == np.float32 and rf.dtype == np.int32
        assert np.array_equal(rv, v.astype(np.float32)) and np.array_equal(rf, f)
    for lab, j in s["joints"].items():
        assert r["joints"][lab].dtype == np.float32 and np.array_equal(r["joints"][lab], j)
    for lab, p in s["pose"].items():
        assert np.array_equal(r["pose"][lab], p)
    assert r["K"].dtype == np.float64 and np.array_equal(r["K"], s["K"])
    assert r["vr"] == s["vr"]  # exact: JSON floats round-trip
    for key in ("kind", "target", "sides", "names", "stats"):
        assert r[key] == s[key], key
    assert r["index"] is None and r["seed"] is None
    assert np.array_equal(r["alone_images"][2], s["alone_images"][2])
    assert r["depth"].dtype == np.float32 and np.array_equal(r["depth"], s["depth"])
    assert r["camera_name"] == "cam0"
    with pytest.raises(FileExistsError, match="exists"):
        D.write_sample(tmp_path / "x", s)


def test_large_labels_use_a_16_bit_mask(tmp_path):
    s = synthetic_sample(1, image_size=SIZE, resolution=4)
    relabel = {1: 300, 2: 7}
    s["scene_mask"] = np.vectorize(lambda x: relabel.get(x, 0))(s["scene_mask"])
    for key in ("alone_masks", "meshes", "joints", "pose", "vr", "sides", "names"):
        s[key] = {relabel[k]: v for k, v in s[key].items()}
    s["target"] = 300
    D.write_sample(tmp_path / "x", s)
    with Image.open(tmp_path / "x" / "scene_mask.png") as im:
        assert im.mode == "I;16"
    r = D.read_sample(tmp_path / "x")
    assert np.array_equal(r["scene_mask"], s["scene_mask"])
    assert set(np.unique(r["scene_mask"])) <= {0, 7, 300} and r["target"] == 300


def test_files_do_not_depend_on_the_wall_clock(tmp_path, monkeypatch):
    s = synthetic_sample(2, image_size=SIZE, resolution=4)
    now = time.time()
    monkeypatch.setattr(time, "time", lambda: now)

    def stamped_zip():  # zipfile stamps entries added by name with the clock
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            zf.writestr("x.npy", b"data")
        return buf.getvalue()

    D.write_sample(tmp_path / "a", s)
    zip_a = stamped_zip()
    monkeypatch.setattr(time, "time", lambda: now + 3e6)  # a month later
    D.write_sample(tmp_path / "b", s)
    assert stamped_zip() != zip_a  # the patched clock does reach zipfile: the check can fail
    assert tree(tmp_path / "a") == tree(tmp_path / "b")
    with zipfile.ZipFile(tmp_path / "a" / "annotation.npz") as zf:
        assert {i.date_time for i in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}


def test_npz_bytes_is_a_plain_npz():
    arrays = {"b": np.arange(6, dtype=np.int32).reshape(2, 3), "a": np.eye(3)}
    data = D.npz_bytes(arrays)
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        assert sorted(z.files) == ["a", "b"]
        for k, v in arrays.items():
            assert z[k].dtype == v.dtype and np.array_equal(z[k], v)
    assert D.npz_bytes(dict(reversed(arrays.items()))) == data  # key order does not matter
    with pytest.raises(ValueError):
        D.npz_bytes({"o": np.array([{}], dtype=object)})


@pytest.mark.parametrize("mutate, pattern", [
    (lambda s: s["joints"].__setitem__(1, np.zeros((20, 3))),
     r"sample\['joints_1'\] has shape \(20, 3\), expected \(21, 3\)"),
    (lambda s: s.__setitem__("image", s["image"].astype(np.float32)), r"'image'.*uint8"),
    (lambda s: [s.__setitem__("target", 2)] + [s[k].pop(2) for k in ("sides", "joints", "pose")],
     r"'target'.*not a hand label"),
    (lambda s: s["vr"].__setitem__(2, 1.5), r"'vr'.*vr of label 2 is 1.5"),
    (lambda s: s.__setitem__("kind", "hand-foot"), r"'kind'.*hand-foot"),
    (lambda s: s["alone_masks"].pop(2), r"'alone_masks'.*labels \[1\], expected \[1, 2\]"),
    (lambda s: s["alone_masks"].__setitem__(1, s["alone_masks"][1] * 3), r"alone_1.*0/1"),
    (lambda s: s["scene_mask"].__setitem__((0, 0), 9), r"labels \[9\] have no mesh"),
    (lambda s: s["meshes"].__setitem__(1, (s["meshes"][1][0], s["meshes"][1][1] + 10_000)),
     r"faces_1.*indices must be in"),
    (lambda s: s.pop("K"), r"'K'.*missing"),
    (lambda s: s["joints"][1].__setitem__((0, 0), np.nan), r"joints_1.*non-finite"),
])
def test_write_sample_rejects_bad_samples(tmp_path, mutate, pattern):
    s = synthetic_sample(4, image_size=SIZE, resolution=4)
    mutate(s)
    with pytest.raises(ValueError, match=pattern):
        D.write_sample(tmp_path / "x", s)
    assert not (tmp_path / "x").exists() and not list(tmp_path.glob(".tmp-*"))


# ------------------------------------------------------------------ seeds, bins
def test_sample_seeds_are_distinct_and_json_safe():
    seeds = {D.sample_seed(SEED, i, a) for i in range(500) for a in range(3)}
    assert len(seeds) == 1500 and max(seeds) < 2**53
    assert D.sample_seed(SEED, 7) == D.sample_seed(SEED, 7, 0) != D.sample_seed(SEED + 1, 7)
    with pytest.raises(ValueError, match="index must be a non-negative"):
        D.sample_seed(SEED, -1)


def test_shard_ranges_partition_the_indices():
    for num, n in ((10, 3), (7, 2), (3, 5)):
        parts = [D.shard_range(num, k, n) for k in range(n)]
        assert [i for p in parts for i in p] == list(range(num))
    with pytest.raises(ValueError, match="shard"):
        D.shard_range(10, 2, 2)


def test_vr_bins_accept_pairs_or_edges():
    pairs = D.vr_bins([(0.4, 0.6), (0.6, 1.0)])
    assert D.vr_bins([0.4, 0.6, 1.0]) == pairs
    assert D.vr_histogram([0.1, 0.4, 0.6, 0.99, 1.0], pairs) == [1, 3]
    assert D.vr_histogram([0.6, 0.8, 1.0], [(0.4, 0.6), (0.6, 0.8)]) == [0, 2]  # last bin closed
    visibility = pytest.importorskip("handmesh_tutorial.visibility")
    for v in np.r_[np.linspace(0, 1, 101), 0.6, 0.95, 1.0, 3 / 5, 19 / 20]:
        assert visibility.vr_bin_index(np.array([v]))[0] == visibility.vr_bin(v), v
    assert D.vr_bins() == tuple(visibility.VR_BINS)
    assert len(D.vr_bins()) >= 1
    with pytest.raises(ValueError, match="VR bins"):
        D.vr_bins([(0.6, 0.4)])


# ------------------------------------------------------------------ generation
def test_generation_is_deterministic_and_seeded_per_index(tmp_path):
    a = gen(tmp_path / "a", params={"light": [1, 2]}, image_size=SIZE)
    gen(tmp_path / "b", params={"light": [1, 2]}, image_size=SIZE)
    assert a.written == 6 and a.skipped == 0 and a.attempts == 6
    ta, tb = tree(tmp_path / "a"), tree(tmp_path / "b")
    assert ta == tb and len(ta) == 1 + 6 * 6  # meta.json + 6 files per sample
    gen(tmp_path / "c", seed=SEED + 1)
    tc = tree(tmp_path / "c")
    assert all(ta[k] != tc[k] for k in ta if k.endswith("image.png"))

    ds = D.InterSHDataset(tmp_path / "a")
    assert len(ds) == 6 and ds.indices.tolist() == list(range(6)) and ds.missing == []
    s = ds[4]  # sample 4 is make_sample(sample_seed(seed, 4)), nothing else
    direct = make(D.sample_seed(SEED, 4))
    assert s["index"] == 4 and s["seed"] == D.sample_seed(SEED, 4) and s["attempt"] == 0
    assert np.array_equal(s["image"], direct["image"]) and s["vr"] == direct["vr"]
    assert ds.meta["params"] == {"light": [1, 2]} and ds.meta["image_size"] == [SIZE, SIZE]
    assert ds.meta["make_sample"] == "handmesh_tutorial.testing.synthetic_sample"


def test_reader_api(tmp_path):
    gen(tmp_path / "r", num=5)
    seen = []
    ds = D.InterSHDataset(tmp_path / "r", transform=lambda s: seen.append(s["index"]) or s["kind"])
    assert ds[-1] == "hand-hand" and seen == [4]
    vr = ds.vr_table()
    plain = D.InterSHDataset(tmp_path / "r")
    assert np.array_equal(vr, [plain[i]["vr"][plain[i]["target"]] for i in range(5)])
    assert plain.annotation(2)["seed"] == D.sample_seed(SEED, 2)
    with pytest.raises(IndexError, match="out of range"):
        plain[5]
    assert "5 samples" in repr(plain) and "0 missing" in repr(plain)
    shutil.rmtree(tmp_path / "r" / "samples" / "000003")
    fewer = D.InterSHDataset(tmp_path / "r")
    assert "4 samples" in repr(fewer) and "1 missing" in repr(fewer) and fewer.missing == [3]


def test_read_target_equals_the_full_read_and_names_what_is_wrong(tmp_path):
    gen(tmp_path / "r", num=3)
    ds = D.InterSHDataset(tmp_path / "r")
    for i in range(3):
        full, lean = ds[i], ds.target(i)
        t = full["target"]
        want = (full["image"], full["K"], full["meshes"][t][0], full["joints"][t],
                full["sides"][t], full["vr"][t])
        for a, b in zip(lean, want, strict=True):
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b)
            else:
                assert a == b
    d = ds.sample_dir(1)
    t = ds.annotation(1)["target"]
    with np.load(d / "annotation.npz") as z:
        arrays = {k: z[k] for k in z.files if k != f"joints_{t}"}
    np.savez(d / "annotation.npz", **arrays)
    with pytest.raises(ValueError, match=f"annotation.npz: missing key 'joints_{t}'"):
        ds.target(1)
    arrays[f"joints_{t}"] = np.zeros((20, 3), np.float32)
    np.savez(d / "annotation.npz", **arrays)
    with pytest.raises(ValueError, match=rf"'joints_{t}' has shape \(20, 3\)"):
        ds.target(1)
    (d / "annotation.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="annotation.npz: not a readable npz"):
        ds.target(1)
    (ds.sample_dir(2) / "image.png").unlink()
    with pytest.raises(FileNotFoundError, match="image.png missing"):
        ds.target(2)


def test_kind_and_image_size_are_checked(tmp_path):
    with pytest.raises(ValueError, match="kind 'hand-object' is not one of"):
        D.generate_dataset(tmp_path / "k", functools.partial(make, kind="hand-object"), 2, 0,
                           "hand-hand", progress=False)
    with pytest.raises(ValueError, match=r"image size \(32, 32\), expected \(64, 64\)"):
        gen(tmp_path / "s", image_size=64)
    with pytest.raises(ValueError, match="kind must be one of"):
        D.generate_dataset(tmp_path / "x", make, 2, 0, "hand-foot", progress=False)


INTERRUPT_AT = None  # index at which _flaky raises KeyboardInterrupt (None: never)


def _flaky(seed):
    if INTERRUPT_AT is not None and seed == D.sample_seed(SEED, INTERRUPT_AT):
        raise KeyboardInterrupt
    return make(seed)


def test_ctrl_c_then_resume_gives_the_same_bytes(tmp_path, monkeypatch):
    gen(tmp_path / "ref", num=7, fn=_flaky)
    monkeypatch.setattr(sys.modules[__name__], "INTERRUPT_AT", 4)
    with pytest.raises(KeyboardInterrupt):
        gen(tmp_path / "run", num=7, fn=_flaky)
    # no half-written sample, no temporary left behind by a clean interrupt
    assert sample_dirs(tmp_path / "run") == [f"{i:06d}" for i in range(4)]
    monkeypatch.setattr(sys.modules[__name__], "INTERRUPT_AT", None)
    summary = gen(tmp_path / "run", num=7, fn=_flaky)
    assert (summary.written, summary.skipped, summary.stale_removed) == (3, 4, 0)
    assert tree(tmp_path / "run") == tree(tmp_path / "ref")


def test_interrupt_during_a_write_leaves_no_partial_sample(tmp_path, monkeypatch):
    gen(tmp_path / "ref", num=4)
    calls = []
    write_file = D.files._write_file  # called there: patch the submodule

    def failing_write(path, data, durable):
        calls.append(path)
        if len(calls) == 2 * 6 + 3:  # third file of sample 2
            raise KeyboardInterrupt
        write_file(path, data, durable)

    monkeypatch.setattr(D.files, "_write_file", failing_write)
    with pytest.raises(KeyboardInterrupt):
        gen(tmp_path / "run", num=4)
    assert ".tmp-000002" in str(calls[-1])  # files go to a temporary folder first
    assert sample_dirs(tmp_path / "run") == ["000000", "000001"]  # no partial 000002, no temp
    monkeypatch.setattr(D.files, "_write_file", write_file)
    gen(tmp_path / "run", num=4)
    assert tree(tmp_path / "run") == tree(tmp_path / "ref")


KILL_SCRIPT = textwrap.dedent("""
    import os, sys, time
    from handmesh_tutorial import data as D
    from handmesh_tutorial.testing import synthetic_sample

    def make(seed):
        return synthetic_sample(seed, image_size=32, resolution=4)

    if os.environ.get("SLOW"):  # slow writes, so that the kill most likely lands mid-sample
        _write_file = D.files._write_file  # called in dataset.files: patch it there

        def slow_write(path, data, durable):
            _write_file(path, data, durable)
            time.sleep(0.04)

        D.files._write_file = slow_write

    if __name__ == "__main__":
        s = D.generate_dataset(sys.argv[1], make, 10, 3, "hand-hand", progress=False)
        print(s.written, s.skipped, s.stale_removed)
""")


def test_sigkill_then_resume_gives_the_same_bytes(tmp_path):
    script = tmp_path / "gen_script.py"
    script.write_text(KILL_SCRIPT)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    def run(root, **extra):
        out = subprocess.run([sys.executable, str(script), str(root)], env={**env, **extra},
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        return [int(x) for x in out.stdout.split()]

    assert run(tmp_path / "ref") == [10, 0, 0]
    root = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, str(script), str(root)], env={**env, "SLOW": "1"})
    deadline = time.time() + 60
    while time.time() < deadline:
        done = [p for p in (root / "samples").glob("0*")] if (root / "samples").is_dir() else []
        if len(done) >= 3:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    present = sorted(p.name for p in (root / "samples").glob("0*"))
    assert 3 <= len(present) < 10, present
    for name in present:  # every visible sample is complete
        D.read_sample(root / "samples" / name)
    real_stale = list((root / "samples").glob(".tmp-*"))
    print(f"killed after {len(present)} samples; {len(real_stale)} half-written temp folder(s)")
    # what a kill during a write leaves (added in case the kill landed between samples)
    stale = root / "samples" / ".tmp-000009-999-deadbeef"
    stale.mkdir(exist_ok=True)
    (stale / "image.png").write_bytes(b"\x89PNG half")
    written, skipped, removed = run(root)
    assert (written, skipped) == (10 - len(present), len(present))
    assert removed == 1 + len(real_stale) and not list(root.rglob(".tmp-*"))
    assert tree(root) == tree(tmp_path / "ref")


def test_resume_refuses_different_parameters(tmp_path):
    gen(tmp_path / "r", params={"light": 1})
    with pytest.raises(ValueError, match=r"differing keys: params\.light, seed") as e:
        gen(tmp_path / "r", seed=SEED + 1, params={"light": 2})
    assert "meta.json" in str(e.value) and "on disk" in str(e.value)
    with pytest.raises(ValueError, match="differing keys: kinds"):
        D.generate_dataset(tmp_path / "r", make, 6, SEED, "hand-object", progress=False,
                           params={"light": 1})
    with pytest.raises(ValueError, match="differing keys: ranges, shards"):
        gen(tmp_path / "r", params={"light": 1}, shard=(0, 2))
    again = gen(tmp_path / "r", params={"light": 1})  # same call: nothing to do
    assert (again.written, again.skipped, again.attempts) == (0, 6, 0)


def test_stale_temporaries_are_removed_but_not_a_users_files(tmp_path):
    gen(tmp_path / "r", num=2)
    half = tmp_path / "r" / "samples" / ".tmp-000001-1-0123abcd"
    half.mkdir()
    (half / "image.png").write_bytes(b"\x89PNG half")
    (tmp_path / "r" / "samples" / ".tmp-000002-7-89abcdef").mkdir()
    (tmp_path / "r" / ".tmp-meta.json-1-0123abcd").write_text("{")
    # a user's own files that merely start with ".tmp-": never touched
    notes = tmp_path / "r" / ".tmp-my-notes"
    notes.mkdir()
    (notes / "todo.txt").write_text("keep")
    lookalike = tmp_path / "r" / "samples" / ".tmp-000003-5-0123abcd"
    lookalike.mkdir()
    (lookalike / "thesis.tex").write_text("keep")
    (tmp_path / "r" / ".tmp-plan.txt").write_text("keep")
    s = gen(tmp_path / "r", num=2)
    assert s.stale_removed == 3
    left = sorted(p.relative_to(tmp_path / "r").as_posix()
                  for p in (tmp_path / "r").rglob(".tmp-*"))
    assert left == [".tmp-my-notes", ".tmp-plan.txt", "samples/.tmp-000003-5-0123abcd"]
    assert (notes / "todo.txt").read_text() == "keep"


def test_a_second_writer_is_refused(tmp_path):
    fcntl = pytest.importorskip("fcntl")
    (tmp_path / "r").mkdir()
    with open(tmp_path / "r" / D.schema._LOCK_FILE, "a+b") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        with pytest.raises(RuntimeError, match="being written by another process"):
            gen(tmp_path / "r")


def test_shards_merge_into_the_same_bytes_as_one_run(tmp_path):
    gen(tmp_path / "full", num=7)
    a = gen(tmp_path / "s0", num=7, shard=(0, 2))
    b = gen(tmp_path / "s1", num=7, shard=(1, 2))
    assert (a.indices, b.indices) == ([[0, 3]], [[3, 7]])
    assert sample_dirs(tmp_path / "s1") == ["000003", "000004", "000005", "000006"]
    info = D.merge_shards([tmp_path / "s1", tmp_path / "s0"], tmp_path / "m", progress=False)
    assert info == {"copied": 7, "skipped": 0, "ranges": [[0, 7]], "complete": True}
    assert tree(tmp_path / "m") == tree(tmp_path / "full")  # meta.json included
    again = D.merge_shards([tmp_path / "s0", tmp_path / "s1"], tmp_path / "m", progress=False)
    assert (again["copied"], again["skipped"]) == (0, 7)

    part = D.merge_shards([tmp_path / "s1"], tmp_path / "part", progress=False, link=True)
    assert part["complete"] is False
    ds = D.InterSHDataset(tmp_path / "part")
    assert ds.indices.tolist() == [3, 4, 5, 6] and ds.missing == []
    assert ds[0]["index"] == 3
    with pytest.raises(ValueError, match="overlap"):
        D.merge_shards([tmp_path / "s0", tmp_path / "full"], tmp_path / "bad", progress=False)
    gen(tmp_path / "other", num=7, seed=SEED + 1, shard=(1, 2))
    with pytest.raises(ValueError, match="cannot merge.*differing keys: seed"):
        D.merge_shards([tmp_path / "s0", tmp_path / "other"], tmp_path / "bad", progress=False)
    (tmp_path / "s1" / "samples" / "000005" / "image.png").unlink()
    os.rename(tmp_path / "s1" / "samples" / "000005", tmp_path / "s1" / "samples" / "gone")
    with pytest.raises(ValueError, match=r"s1 is incomplete: 1 samples missing \(first \[5\]\)"):
        D.merge_shards([tmp_path / "s0", tmp_path / "s1"], tmp_path / "bad2", progress=False)


def _mark_worker(folder):
    Path(folder, str(os.getpid())).touch()


@pytest.mark.parametrize("start", ["spawn", "fork", "auto"])
def test_workers_give_the_same_bytes(tmp_path, start):
    if start not in ("spawn", "auto") and not sys.platform.startswith("linux"):
        pytest.skip("fork start method: Linux only")
    marks1, marks2 = tmp_path / "m1", tmp_path / "m2"
    marks1.mkdir()
    marks2.mkdir()
    gen(tmp_path / "w1", num=4, worker_init=functools.partial(_mark_worker, marks1))
    s = gen(tmp_path / "w2", num=4, workers=2, worker_init=functools.partial(_mark_worker, marks2),
            mp_context=start)
    assert s.written == 4
    assert tree(tmp_path / "w1") == tree(tmp_path / "w2")
    assert [p.name for p in marks1.iterdir()] == [str(os.getpid())]  # in-process, once
    pids = [p.name for p in marks2.iterdir()]
    assert 1 <= len(pids) <= 2 and str(os.getpid()) not in pids
    with pytest.raises(ValueError, match="picklable"):
        gen(tmp_path / "w3", num=4, workers=2, fn=lambda seed: make(seed))


START_METHOD_SCRIPT = textwrap.dedent("""
    import sys, threading
    from handmesh_tutorial.data.workers import _start_method

    def show(what):
        print(what, _start_method("auto"), _start_method("spawn"))

    show("fresh")
    monitor = threading.Thread(target=lambda: None, name="tqdm_monitor")
    monitor.start()  # tqdm's monitor: ignored
    show("tqdm-monitor")
    monitor.join()
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    show("thread")
    stop.set()
    other.join()
    show("thread-ended")
    if sys.argv[1] == "gl":
        from handmesh_tutorial.render import Renderer, gl_opened
        assert not gl_opened()
        Renderer(16).close()  # closed, but the driver's state stays in this process
        assert gl_opened()
        show("gl")
    else:
        import torch
        show("torch")
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forks only on Linux")
@pytest.mark.parametrize("case", ["gl", "torch"])
def test_auto_start_method_forks_only_where_it_is_safe(tmp_path, case):
    script = tmp_path / "start.py"
    script.write_text(START_METHOD_SCRIPT)
    out = subprocess.run([sys.executable, str(script), case], capture_output=True, text=True,
                         check=True, timeout=120).stdout.split("\n")
    assert out[:5] == ["fresh fork spawn", "tqdm-monitor fork spawn", "thread spawn spawn",
                       "thread-ended fork spawn", f"{case} spawn spawn"]


def test_unknown_start_method_is_refused_before_writing(tmp_path):
    with pytest.raises(ValueError, match="mp_context must be 'auto' or one of .*'bogus'"):
        gen(tmp_path / "r", num=2, workers=2, mp_context="bogus")
    assert not (tmp_path / "r").exists()


def test_notebook_functions_are_refused_for_workers(tmp_path, monkeypatch):
    fake_main = types.ModuleType("__main__")  # a notebook's __main__ has no __file__

    def cell_sample(seed):
        return make(seed)

    cell_sample.__module__, cell_sample.__qualname__ = "__main__", "cell_sample"
    fake_main.cell_sample = cell_sample
    monkeypatch.setitem(sys.modules, "__main__", fake_main)
    with pytest.raises(ValueError, match="__main__.cell_sample is defined in an interactive"):
        gen(tmp_path / "nb", num=2, workers=2, fn=cell_sample)
    assert gen(tmp_path / "nb1", num=2, fn=cell_sample).written == 2  # fine in-process


def test_vr_balanced_generation(tmp_path):
    bins = ((0.0, 0.5), (0.5, 0.9), (0.9, 1.0))
    s = gen(tmp_path / "b", num=6, balance_vr=bins)
    assert s.vr_histogram == [2, 2, 2] and s.vr_outside == 0 and s.attempts > 6
    ds = D.InterSHDataset(tmp_path / "b")
    assert ds.meta["vr_bins"] == [list(b) for b in bins] and ds.meta["balance_vr"] is True
    for i in range(6):
        ann = ds.annotation(i)
        lo, hi = bins[i % 3]
        assert lo <= ann["target_vr"] <= hi
        # the kept candidate is the FIRST attempt whose target VR falls in the bin
        tries = [make(D.sample_seed(SEED, i, a)) for a in range(ann["attempt"] + 1)]
        in_bin = [lo <= t["vr"][t["target"]] < hi or (hi == 1.0 == t["vr"][t["target"]])
                  for t in tries]
        assert in_bin == [False] * ann["attempt"] + [True]
        assert ann["seed"] == D.sample_seed(SEED, i, ann["attempt"])
    s2 = gen(tmp_path / "b2", num=6, balance_vr=bins)
    assert tree(tmp_path / "b2") == tree(tmp_path / "b")
    assert s2.attempts == s.attempts


def _never_below_half(seed):
    """A generator whose target VR is never below 0.5 (like hand-chain scenes and low VRs)."""
    s = make(seed)
    s["vr"][s["target"]] = 0.5 + 0.5 * (seed % 997) / 997
    return s


def test_vr_balancing_leaves_out_unreachable_bins_up_front(tmp_path):
    bins = ((0.0, 0.3), (0.5, 0.75), (0.75, 1.0))
    with pytest.warns(UserWarning, match=r"1 of 3 bins .* \[0\.00, 0\.30\) left out"):
        s = gen(tmp_path / "u", num=6, fn=_never_below_half, balance_vr=bins, vr_probe=16)
    assert s.written == 6 and s.off_bin == 0 and s.probe_attempts == 16
    assert s.vr_histogram == [0, 3, 3] and s.vr_unreachable == [(0.0, 0.3)]
    assert "bins left out (reached by fewer than 2 of 16 probe candidates): [0.00, 0.30)" in str(s)
    ds = D.InterSHDataset(tmp_path / "u")
    probe = ds.meta["vr_probe"]
    assert probe["filled"] == [1, 2] and probe["hits"][0] == 0 and sum(probe["hits"]) == 16
    for i in range(6):  # the reachable bins take turns
        lo, hi = bins[1 + i % 2]
        assert lo <= ds.annotation(i)["target_vr"] <= hi
    # the probe used its own seeds, never a sample's
    probe_seeds = {D.probe_seed(SEED, k) for k in range(16)}
    assert not probe_seeds & {D.sample_seed(SEED, i, a) for i in range(6) for a in range(100)}
    # resume: the probe comes from meta.json (no candidate made), same bytes
    before = tree(tmp_path / "u")
    import shutil

    for name in ("000004", "000005"):
        shutil.rmtree(tmp_path / "u" / "samples" / name)
    with pytest.warns(UserWarning, match="left out"):
        again = gen(tmp_path / "u", num=6, fn=_never_below_half, balance_vr=bins, vr_probe=16)
    assert again.probe_attempts == 0 and again.written == 2
    assert tree(tmp_path / "u") == before
    with pytest.raises(ValueError, match="vr_probe must be >= 1|must be >= 1"):
        gen(tmp_path / "z", num=2, balance_vr=bins, vr_probe=0)


def _fails_on_probe_seeds(seed):
    if seed in {D.probe_seed(SEED, k) for k in range(16)}:
        raise RuntimeError(f"broken candidate {seed}")
    return _never_below_half(seed)


@pytest.mark.parametrize("start", ["spawn", "fork", "auto"])
def test_vr_probe_runs_in_the_workers(tmp_path, start):
    """With workers, the probe's candidates are made by the pool (this process renders
    nothing, so "auto" can fork), and the result is the same as in-process, to the byte."""
    if start == "fork" and not sys.platform.startswith("linux"):
        pytest.skip("fork start method: Linux only")
    bins = ((0.0, 0.3), (0.5, 0.75), (0.75, 1.0))
    marks = tmp_path / "marks"
    marks.mkdir()
    with pytest.warns(UserWarning, match="left out"):
        one = gen(tmp_path / "p1", num=6, fn=_never_below_half, balance_vr=bins, vr_probe=16)
    with pytest.warns(UserWarning, match="left out"):
        two = gen(tmp_path / "p2", num=6, fn=_never_below_half, balance_vr=bins, vr_probe=16,
                  workers=2, mp_context=start, worker_init=functools.partial(_mark_worker, marks))
    assert tree(tmp_path / "p1") == tree(tmp_path / "p2")      # meta.json and its probe too
    assert two.vr_probe == one.vr_probe and two.probe_attempts == 16 and two.written == 6
    assert two.vr_histogram == [0, 3, 3] and two.off_bin == 0
    pids = [p.name for p in marks.iterdir()]
    assert 1 <= len(pids) <= 2 and str(os.getpid()) not in pids  # worker_init only in workers
    # a candidate that raises stops the run before anything is written
    with pytest.raises(RuntimeError, match="broken candidate"):
        gen(tmp_path / "p3", num=6, fn=_fails_on_probe_seeds, balance_vr=bins, vr_probe=16,
            workers=2, mp_context=start)
    assert not (tmp_path / "p3" / D.META_FILE).exists()


def test_vr_balancing_never_stops_on_a_hard_bin(tmp_path, monkeypatch):
    """A bin the probe kept but a sample cannot reach: the nearest candidate is written."""
    monkeypatch.setattr(D.candidates, "PROBE_MIN_HITS", 0)  # keep even the bin nobody reaches
    bins = ((0.0, 0.3), (0.5, 1.0))
    s = gen(tmp_path / "h", num=4, fn=_never_below_half, balance_vr=bins, vr_probe=4,
            max_attempts=5)
    assert s.written == 4 and s.off_bin == 2 and s.attempts == 5 + 1 + 5 + 1
    ds = D.InterSHDataset(tmp_path / "h")
    for i in (0, 2):  # wanted [0, 0.3): the candidate nearest to it, out of 5
        ann = ds.annotation(i)
        vrs = [_never_below_half(D.sample_seed(SEED, i, a)) for a in range(5)]
        best = min(range(5), key=lambda a: vrs[a]["vr"][vrs[a]["target"]])
        assert ann["attempt"] == best
    assert "samples written outside their bin: 2" in str(s)


def test_version_1_roots_stay_readable(small_root):
    meta = json.loads((small_root / "meta.json").read_text())
    (small_root / "meta.json").write_text(json.dumps({**meta, "format_version": 1}))
    _rewrite_json(small_root / "samples" / "000000" / "annotation.json", format_version=1)
    ds = D.InterSHDataset(small_root)
    assert ds[0]["image"].shape == (SIZE, SIZE, 3)
    with pytest.raises(ValueError, match="format_version"):  # but not resumed by version 2
        gen(small_root, num=3)


def test_accept_filter_and_its_limit(tmp_path):
    def other_fully_visible(sample):
        return sample["vr"][2] == 1.0

    gen(tmp_path / "a", num=4, accept=other_fully_visible)
    ds = D.InterSHDataset(tmp_path / "a")
    assert all(ds.annotation(i)["vr"][2] == 1.0 for i in range(4))
    assert ds.meta["accept"].endswith("other_fully_visible")
    with pytest.raises(RuntimeError, match="sample 0: no candidate accepted in 3 attempts"):
        gen(tmp_path / "n", num=2, accept=lambda s: False, max_attempts=3)
    assert sample_dirs(tmp_path / "n") == []


# ------------------------------------------------------------------ corrupt files
@pytest.fixture()
def small_root(tmp_path):
    gen(tmp_path / "r", num=3)
    return tmp_path / "r"


def _rewrite_npz(path, **changes):
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    for k, v in changes.items():
        if v is None:
            del arrays[k]
    path.write_bytes(D.npz_bytes(arrays))


def _rewrite_json(path, **changes):
    ann = json.loads(path.read_text())
    ann.update(changes)
    path.write_text(json.dumps(ann))


@pytest.mark.parametrize("damage, error, pattern", [
    (lambda d: (d / "scene_mask.png").unlink(), FileNotFoundError,
     r"000001/scene_mask\.png missing"),
    (lambda d: (d / "annotation.npz").unlink(), FileNotFoundError,
     r"000001/annotation\.npz missing"),
    (lambda d: _rewrite_npz(d / "annotation.npz", joints_1=np.zeros((20, 3), np.float32)),
     ValueError, r"000001/annotation\.npz: key 'joints_1' has shape \(20, 3\), expected \(21, 3\)"),
    (lambda d: _rewrite_npz(d / "annotation.npz", faces_2=None), ValueError,
     r"000001/annotation\.npz: missing key 'faces_2'"),
    (lambda d: (d / "annotation.npz").write_bytes(b"PK\x03\x04junk"), ValueError,
     r"000001/annotation\.npz: not a readable npz"),
    (lambda d: (d / "image.png").write_bytes((d / "image.png").read_bytes()[:60]), ValueError,
     r"000001/image\.png: not a readable PNG"),
    (lambda d: Image.fromarray(np.zeros((16, 16), bool)).save(d / "alone_2.png"), ValueError,
     r"000001/alone_2\.png has shape \(16, 16\), expected \(32, 32\)"),
    (lambda d: Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(d / "scene_mask.png"),
     ValueError, r"000001/scene_mask\.png: PNG mode RGB"),
    (lambda d: _rewrite_json(d / "annotation.json", vr={"1": 1.5, "2": 0.5}), ValueError,
     r"000001/annotation\.json: 'vr'.*1\.5"),
    (lambda d: _rewrite_json(d / "annotation.json", labels=[1]), ValueError,
     r"000001/scene_mask\.png: labels \[2\] have no mesh"),
    (lambda d: _rewrite_json(d / "annotation.json", target=5), ValueError,
     r"000001/annotation\.json: 'target' 5 is not a hand label"),
    (lambda d: (d / "annotation.json").write_text("{oops"), ValueError,
     r"000001/annotation\.json: not valid JSON"),
    (lambda d: _rewrite_json(d / "annotation.json", labels="12"), ValueError,
     r"000001/annotation\.json: 'labels' must be a list of labels, got '12'"),
    (lambda d: _rewrite_json(d / "annotation.json", vr={"1": 1.0, "2": "0.8"}), ValueError,
     r"000001/annotation\.json: 'vr' of label 2 must be a number in \[0, 1\], got '0\.8'"),
])
def test_damaged_files_are_named(small_root, damage, error, pattern):
    damage(small_root / "samples" / "000001")
    ds = D.InterSHDataset(small_root)
    with pytest.raises(error, match=pattern):
        ds[1]
    ds[0], ds[2]  # the other samples still load  # noqa: B018


def test_dataset_level_errors(small_root, tmp_path):
    _rewrite_json(small_root / "samples" / "000002" / "annotation.json", index=7)
    ds = D.InterSHDataset(small_root)
    with pytest.raises(ValueError, match="index 7 but folder is 000002"):
        ds[2]
    with pytest.raises(ValueError, match=re.escape("000002/annotation.json") + ".*do not match"):
        gen(small_root, num=3)  # resuming checks the samples it skips
    with pytest.raises(FileNotFoundError, match=r"nothing/meta\.json missing"):
        D.InterSHDataset(tmp_path / "nothing")
    good = (small_root / "meta.json").read_text()
    for change, pattern in (({"index_width": "6"}, "'index_width' must be an integer"),
                            ({"num_samples": 10**11}, "'num_samples' must be an integer"),
                            ({"ranges": [[0, 10**11]]}, "'ranges' must be"),
                            ({"ranges": "0-3"}, "'ranges' must be"),
                            ({"kinds": "hand-hand"}, "'kinds' must be a non-empty list"),
                            ({"image_size": [32, "32"]}, "'image_size' must be null or"),
                            ({"seed": -1}, "'seed' must be a non-negative integer")):
        (small_root / "meta.json").write_text(good)
        _rewrite_json(small_root / "meta.json", **change)
        with pytest.raises(ValueError, match=r"meta\.json: " + pattern):
            D.InterSHDataset(small_root)


def _reject_even_seeds(seed):
    if seed % 2 == 0:
        raise D.SampleRejected(f"seed {seed} cannot be built")
    return make(seed)


def test_sample_rejected_is_a_rejected_candidate(tmp_path):
    s = D.generate_dataset(tmp_path / "r", _reject_even_seeds, 6, SEED, "hand-hand",
                           progress=False, image_size=SIZE)
    ds = D.InterSHDataset(tmp_path / "r")
    for i in range(6):
        ann = ds.annotation(i)
        seeds = [D.sample_seed(SEED, i, a) for a in range(ann["attempt"] + 1)]
        # kept: the first odd seed; every even one before it was skipped, not fatal
        assert [x % 2 for x in seeds] == [0] * ann["attempt"] + [1]
        assert ann["seed"] == seeds[-1]
    assert s.attempts == sum(ds.annotation(i)["attempt"] + 1 for i in range(6))

    def always(seed):
        raise D.SampleRejected("never")

    with pytest.raises(RuntimeError, match="sample 0: no candidate accepted in 2 attempts"):
        D.generate_dataset(tmp_path / "n", always, 1, SEED, "hand-hand", progress=False,
                           max_attempts=2)


def test_interaction_error_is_a_sample_rejection():
    from handmesh_tutorial.scenes import InteractionError

    err = InteractionError("hand-chain", 3, "no contact")
    assert isinstance(err, D.SampleRejected) and isinstance(err, RuntimeError)


def test_a_sample_finished_by_another_writer_is_kept(tmp_path):
    # a worker of a killed run may finish sample i while the resumed run writes it too
    target = tmp_path / "samples" / "000004"
    target.mkdir(parents=True)
    (target / "image.png").write_bytes(b"first writer")
    D.files._write_folder(target, {"image.png": b"second writer"}, durable=False)
    assert (target / "image.png").read_bytes() == b"first writer"
    assert sorted(p.name for p in (tmp_path / "samples").iterdir()) == ["000004"]
    (tmp_path / "plain").write_text("x")  # a file in the way is still an error
    with pytest.raises(OSError):
        D.files._write_folder(tmp_path / "plain", {"image.png": b"y"}, durable=False)


ORPHAN_SCRIPT = textwrap.dedent("""
    import sys, time
    from handmesh_tutorial import data as D
    from handmesh_tutorial.testing import synthetic_sample

    def make(seed):
        time.sleep(0.5)  # slow samples: the workers are busy when the main process dies
        return synthetic_sample(seed, image_size=32, resolution=4)

    if __name__ == "__main__":
        D.generate_dataset(sys.argv[1], make, 40, 3, "hand-hand", workers=2, progress=False,
                           mp_context=sys.argv[2])
""")


def _children(pid: int) -> list[int]:
    """Pids whose parent is ``pid`` (from /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("start", ["spawn", "fork"])
def test_workers_die_with_a_killed_main_process(tmp_path, start):
    script = tmp_path / "orphans.py"
    script.write_text(ORPHAN_SCRIPT)
    root = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, str(script), str(root), start])
    deadline, workers = time.time() + 90, []
    while time.time() < deadline:  # until both workers have written a sample
        workers = [k for k in _children(proc.pid) if "resource_tracker" not in
                   (Path("/proc") / str(k) / "cmdline").read_text(errors="replace")]
        if len(workers) == 2 and len(list((root / "samples").glob("0*"))) >= 2:
            break
        time.sleep(0.05)
    assert len(workers) == 2, "the two workers never started"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 10
    while time.time() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.05)
    assert not any(_alive(w) for w in workers), "workers outlived their parent"
    n_before = len(list((root / "samples").glob("0*")))
    time.sleep(1.0)  # nobody writes any more
    assert len(list((root / "samples").glob("0*"))) == n_before


def test_verify_lists_bad_samples_and_regenerating_them_restores_the_bytes(tmp_path):
    gen(tmp_path / "ref", num=6)
    root = tmp_path / "run"
    gen(root, num=6)
    s = root / "samples"
    npz = s / "000001" / "annotation.npz"
    npz.write_bytes(npz.read_bytes()[:100])  # truncated
    from PIL import Image

    Image.fromarray(np.zeros((5, 7, 3), np.uint8)).save(s / "000002" / "image.png")  # foreign
    shutil.rmtree(s / "000004")
    (s / "000004").write_text("a file where a sample folder belongs")
    # resuming without a check counts the damaged folders as done; the file is in the way
    with pytest.raises(NotADirectoryError, match="000004"):
        gen(root, num=6)
    report = D.verify_dataset(root, progress=False)
    assert report.checked == 6 and [n for n, _ in report.bad] == ["000001", "000002", "000004"]
    why = dict(report.bad)
    assert "annotation.npz" in why["000001"] and "(5, 7)" in why["000002"]
    assert "not a sample folder" in why["000004"] and report.removed == []
    assert "3 bad" in str(report)
    fixed = D.verify_dataset(root, remove=True, progress=False)
    # a file is no sample folder the generator made: listed and left, never deleted
    assert fixed.removed == ["000001", "000002"] and not fixed.ok
    assert [n for n, _ in fixed.kept] == ["000004"] and "move it away" in str(fixed)
    assert (s / "000004").read_text() == "a file where a sample folder belongs"
    (s / "000004").unlink()  # the user moves it away
    assert gen(root, num=6).written == 3
    assert tree(root) == tree(tmp_path / "ref")
    assert D.verify_dataset(root, progress=False).bad == []


@pytest.mark.parametrize("key, value", [("seed", SEED + 1), ("image_size", [48, 48]),
                                        ("kinds", ["hand-object"]), ("index_width", 7)])
def test_a_meta_json_that_disagrees_with_every_sample_removes_nothing(tmp_path, key, value):
    """One edited field of meta.json makes every sample disagree: verify names the field and
    the samples, and `remove=True` deletes none of them (they read correctly on their own)."""
    root = tmp_path / "r"
    gen(root, num=3)
    before = tree(root)
    npz = root / "samples" / "000002" / "annotation.npz"
    npz.write_bytes(npz.read_bytes()[:100])  # one truly bad sample: that one is removed
    good = (root / "meta.json").read_text()
    _rewrite_json(root / "meta.json", **{key: value})
    report = D.verify_dataset(root, remove=True, progress=False)
    # with 7-digit names planned, 000002 is no name of the set: a repair leaves it
    planned = key != "index_width"
    assert [n for n, _ in report.bad] == ["000002"]
    assert report.removed == (["000002"] if planned else [])
    assert [n for n, _ in report.kept] == ([] if planned else ["000002"])
    assert report.disagreements() == {key: ["000000", "000001"]} and not report.ok
    assert f"meta.json '{key}' disagrees with 2 sample(s) (000000, 000001)" in str(report)
    assert "none of them was removed" in report.advice() and key in report.advice()
    # the readable samples are all kept
    assert sample_dirs(root) == ["000000", "000001"] + ([] if planned else ["000002"])
    if not planned:
        shutil.rmtree(root / "samples" / "000002")
    (root / "meta.json").write_text(good)  # the user restores meta.json: the run completes
    assert gen(root, num=3).written == 1 and tree(root) == before
    assert D.verify_dataset(root, progress=False).ok


def _with_generator_version(root: Path, version: str) -> None:
    path = root / D.META_FILE
    meta = json.loads(path.read_text())
    meta["generator_version"] = version
    path.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")


@pytest.mark.parametrize("version, resumes", [
    (D.schema.SAME_SAMPLES_SINCE, True),   # the oldest version that makes the same samples
    ("0.2.0", False),                      # before it: other samples
    ("99.0.0", False),                     # a later library: it may make other samples
    ("0.3.x", False),                      # not a version at all
])
def test_a_set_of_an_older_version_resumes_only_when_its_samples_are_the_same(
        tmp_path, version, resumes):
    root = tmp_path / "r"
    gen(root)
    for name in sample_dirs(root)[3:]:  # a run cut short: three of the six samples are left
        shutil.rmtree(root / D.SAMPLES_DIR / name)
    _with_generator_version(root, version)
    if resumes:
        summary = gen(root)
        assert summary.written == 3 and summary.skipped == 3
        assert json.loads((root / D.META_FILE).read_text())["generator_version"] == version
    else:
        before = tree(root)
        with pytest.raises(ValueError, match=r"differing keys: generator_version\b.*\n.*"
                                             + re.escape(repr(version)) + " on disk"):
            gen(root)
        assert tree(root) == before


def _scene_arrays() -> dict:
    """The labels and geometry of one small scene of each kind, by name (the rendered pixels
    are left out: they may differ by a bit between OpenGL drivers)."""
    from handmesh_tutorial import scenes

    arrays = {}
    for i, kind in enumerate(("hand-hand", "hand-object", "hand-chain")):
        s = scenes.make_sample(D.sample_seed(7, i), kind, 32)
        labels = json.dumps([s["kind"], s["target"], sorted(s["sides"].items()),
                             sorted(s["names"].items())])
        arrays[f"{kind}/labels"] = np.frombuffer(labels.encode(), np.uint8)  # exact
        for key in ("joints", "pose"):
            for label in sorted(s[key]):
                arrays[f"{kind}/{key}/{label}"] = np.asarray(s[key][label], np.float64)
        for label in sorted(s["meshes"]):
            vertices, faces = s["meshes"][label][:2]
            arrays[f"{kind}/vertices/{label}"] = np.asarray(vertices, np.float64)
            arrays[f"{kind}/faces/{label}"] = np.asarray(faces, np.int64)  # exact
        arrays[f"{kind}/K"] = np.asarray(s["K"], np.float64)
    return arrays


# The scene generator's output, as SAME_SAMPLES_SINCE vouches for it: on a mismatch, the samples
# of a seed changed, so sets written before no longer match what a resumed run adds. Labels,
# faces and shapes are compared exactly, the numbers to the spread of CPU kernels
# (tests/fingerprints.py): the same seed makes the same scene on every x86-64 CPU, equal to
# within 6e-7 of each array's norm (measured across kernel paths), not bit for bit. The
# geometry is float64 numpy, so the bound is tighter than a network's: 1e-5 of the norm, about
# 0.02 mm for a hand's joints 30-50 cm from the camera.
SCENE_FINGERPRINTS = Path(__file__).parent / "fixtures" / "scene_fingerprints.json"
SCENE_RTOL = 1e-5


@pytest.mark.recorded
def test_the_scene_generator_makes_the_samples_its_same_samples_since_version_made():
    since = D.schema.SAME_SAMPLES_SINCE
    recorded = json.loads(SCENE_FINGERPRINTS.read_text())
    problems = differences(fingerprint(_scene_arrays()), recorded.get(since, {}),
                           SCENE_RTOL)
    assert not problems, (
        f"the scene generator's samples changed ({'; '.join(problems[:3])}), but "
        f"SAME_SAMPLES_SINCE is still {since}: set it in handmesh_tutorial/data/schema.py to "
        f"this version and record the fingerprint under it in {SCENE_FINGERPRINTS.name}")


@pytest.mark.recorded
def test_the_scene_fingerprint_sees_a_moved_joint_and_a_changed_label():
    recorded = json.loads(SCENE_FINGERPRINTS.read_text())[D.schema.SAME_SAMPLES_SINCE]
    arrays = _scene_arrays()
    key = next(k for k in arrays if "/joints/" in k)
    moved = dict(arrays, **{key: arrays[key] + np.eye(21, 3) * 1e-4})  # 0.1 mm, one joint
    assert any(p.startswith(key) for p in differences(fingerprint(moved), recorded,
                                                           SCENE_RTOL))
    relabelled = dict(arrays, **{"hand-hand/labels": arrays["hand-hand/labels"][::-1]})
    assert any("labels: sha256" in p for p in differences(fingerprint(relabelled), recorded))


def test_a_library_version_that_is_not_numbers_resumes_only_its_own_sets(tmp_path, monkeypatch):
    """A development version ("0.6.0.dev1") cannot be placed after SAME_SAMPLES_SINCE: a set
    of another version is refused, not compared (and not a TypeError)."""
    import handmesh_tutorial
    from handmesh_tutorial import _version

    root = tmp_path / "r"
    gen(root)
    for module in (handmesh_tutorial, _version):
        monkeypatch.setattr(module, "__version__", "0.6.0.dev1")
    with pytest.raises(ValueError, match=r"differing keys: generator_version\b"):
        gen(root)
