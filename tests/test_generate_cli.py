"""Tests of the ``handmesh generate`` sub-command (CLI wrapper of interact + dataset)."""

from __future__ import annotations

import hashlib
import subprocess
import sys

import numpy as np
import pytest

from handmesh_tutorial import data as dataset
from handmesh_tutorial.apps import cli


def _hashes(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and not p.name.startswith(".")}


def _run(capsys, *argv):
    code = cli.main(["generate", *argv])
    return code, capsys.readouterr().out


def test_generate_writes_a_readable_dataset_and_resumes(tmp_path, capsys):
    root = tmp_path / "intersh"
    args = ("--kind", "mixed", "--num", "3", "--seed", "5", "--out", str(root),
            "--image-size", "64", "--no-progress", "--no-fsync")
    code, out = _run(capsys, *args)
    assert code == 0
    assert "3 samples written, 0 already present" in out
    assert "[0.95, 1.00]:" in out and "target-hand VR histogram" in out
    ds = dataset.InterSHDataset(root)
    assert len(ds) == 3 and ds.missing == []
    assert sorted(ds.meta["kinds"]) == ["hand-chain", "hand-hand", "hand-object"]
    assert ds.meta["params"]["limits"] == "anatomical"  # natural poses by default
    assert ds.meta["format_version"] == dataset.FORMAT_VERSION == 2
    counts = [int(line.rsplit(":", 1)[1]) for line in out.splitlines()
              if line.strip().startswith("[") or "outside the bins" in line]
    assert sum(counts) == 3  # every sample is counted once in the printed histogram
    for i in range(3):
        s = ds[i]
        assert s["image"].shape == (64, 64, 3)
        assert s["kind"] in ("hand-hand", "hand-object", "hand-chain")
        assert s["stats"]["contact_mm"] <= 3.0 and s["stats"]["penetration_mm"] <= 2.0
        if s["kind"] == "hand-hand":
            assert s["sides"][s["target"]] == "left"
    before = _hashes(root)
    # resume: the same command finds everything on disk and writes nothing
    code, out = _run(capsys, *args)
    assert code == 0 and "0 samples written, 3 already present" in out
    assert _hashes(root) == before
    # an interrupted run (a missing sample) is completed to the same bytes
    import shutil

    shutil.rmtree(root / "samples" / "000001")
    code, out = _run(capsys, *args)
    assert "1 samples written, 2 already present" in out
    assert _hashes(root) == before


def test_generate_shard_and_options(tmp_path, capsys):
    root = tmp_path / "shard1"
    code, out = _run(capsys, "--kind", "hand-object", "--num", "4", "--seed", "2", "--out",
                     str(root), "--image-size", "64", "--shard", "1/2", "--limits",
                     "paper", "--no-progress", "--no-fsync")
    assert code == 0 and "2 samples written" in out
    ds = dataset.InterSHDataset(root)
    assert ds.meta["shards"] == [[1, 2]] and ds.meta["params"]["limits"] == "paper"
    assert sorted(p.name for p in (root / "samples").iterdir()) == ["000002", "000003"]
    # the same sample index is the same scene whatever the shard
    from handmesh_tutorial import scenes as interact

    s = interact.make_sample(dataset.sample_seed(2, 3), "hand-object", 64, limits="paper")
    assert np.array_equal(s["image"], dataset.read_sample(root / "samples" / "000003")["image"])
    # a different option (here the default anatomical limits) on the same root is refused,
    # naming the differing key
    capsys.readouterr()
    code = cli.main(["generate", "--kind", "hand-object", "--num", "4", "--seed", "2", "--out",
                     str(root), "--image-size", "64", "--shard", "1/2", "--no-progress"])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"]
    assert "meta.json was written with different parameters" in err and "params" in err
    assert "Traceback" not in err


def test_balanced_hand_chain_reports_unreachable_bins_and_fills_the_rest(tmp_path, capsys):
    """Chains rarely hide half a hand: [0.40, 0.60) is left out up front (a warning), the other
    bins share the samples, and the run never fails on a hard bin."""
    root = tmp_path / "chain"
    with pytest.warns(UserWarning, match=r"VR balancing: .*\[0\.40, 0\.60\).* left out"):
        code, out = _run(capsys, "--kind", "hand-chain", "--num", "3", "--seed", "0", "--out",
                         str(root), "--image-size", "48", "--balance-vr", "--vr-probe", "24",
                         "--no-progress", "--no-fsync")
    assert code == 0 and "3 samples written" in out
    assert "left out: [0.40, 0.60)" in out
    ds = dataset.InterSHDataset(root)
    probe = ds.meta["vr_probe"]
    assert probe["candidates"] == 24 and 0 not in probe["filled"] and probe["filled"]
    bins = dataset.vr_bins()
    off = 0
    for i in range(3):
        want = bins[probe["filled"][i % len(probe["filled"])]]
        vr = ds.annotation(i)["target_vr"]
        off += not (want[0] <= vr < want[1] or vr == want[1] == 1.0)
    assert f"samples written outside their bin: {off}" in out
    # resuming reuses the probe stored in meta.json (no candidate made, same bins reported)
    with pytest.warns(UserWarning, match=r"\[0\.40, 0\.60\).* left out"):
        code, out = _run(capsys, "--kind", "hand-chain", "--num", "3", "--seed", "0", "--out",
                         str(root), "--image-size", "48", "--balance-vr", "--vr-probe", "24",
                         "--no-progress", "--no-fsync")
    assert code == 0 and "0 samples written, 3 already present (skipped), 0 candidates" in out


@pytest.mark.parametrize("bad", [["--shard", "3/2"], ["--shard", "x"], ["--kind", "foot"],
                                 ["--limits", "none"]])
def test_generate_rejects_bad_arguments(tmp_path, capsys, bad):
    argv = ["generate", "--kind", "hand-hand", "--num", "1", "--out", str(tmp_path), *bad]
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2
    assert "error" in capsys.readouterr().err


def test_generate_help_through_the_module_entry_point():
    r = subprocess.run([sys.executable, "-m", "handmesh_tutorial.apps.cli", "generate", "--help"],
                       capture_output=True, text=True, check=True)
    for opt in ("--kind", "--num", "--seed", "--out", "--image-size", "--workers",
                "--balance-vr", "--vr-probe", "--shard", "--limits", "--frame-share"):
        assert opt in r.stdout
    assert "anatomical (default" in r.stdout and "paper" in r.stdout


@pytest.mark.parametrize("size", ["7", "0", "-5", "100000"])
def test_a_bad_image_size_is_refused_before_anything_is_written(tmp_path, capsys, size):
    out = tmp_path / "root"
    code = cli.main(["generate", "--kind", "hand-hand", "--num", "2", "--out", str(out),
                     "--image-size", size, "--no-progress"])
    err = capsys.readouterr().err
    assert code == cli.EXIT_CODES["bad-input"]
    assert f"image_size must be an integer in [32, 4096] pixels, got {size}" in err
    assert not out.exists()  # no meta.json to block the corrected rerun


def test_verify_command_and_generate_verify(tmp_path, capsys):
    argv = ["generate", "--kind", "hand-object", "--num", "3", "--seed", "4", "--out",
            str(tmp_path / "r"), "--image-size", "48", "--no-progress", "--no-fsync"]
    assert cli.main(argv) == 0
    ref = (tmp_path / "r" / "samples" / "000001" / "annotation.npz").read_bytes()
    (tmp_path / "r" / "samples" / "000001" / "annotation.npz").write_bytes(ref[:64])
    capsys.readouterr()
    assert cli.main(["verify", str(tmp_path / "r"), "--no-progress"]) == cli.EXIT_CODES["bad-input"]
    out = capsys.readouterr().out
    assert "3 samples read, 1 bad" in out and "000001" in out
    assert cli.main([*argv, "--verify"]) == 0
    out = capsys.readouterr().out
    assert "1 removed" in out and "1 samples written, 2 already present" in out
    assert (tmp_path / "r" / "samples" / "000001" / "annotation.npz").read_bytes() == ref
    assert cli.main(["verify", str(tmp_path / "r"), "--no-progress"]) == 0


def test_frame_share_sets_the_target_hands_share_and_is_recorded(tmp_path, capsys):
    root = tmp_path / "loose"
    args = ["--kind", "mixed", "--num", "3", "--seed", "6", "--out", str(root), "--image-size",
            "64", "--no-progress", "--no-fsync"]
    code, _ = _run(capsys, *args, "--frame-share", "0.3,0.4")
    assert code == 0
    ds = dataset.InterSHDataset(root)
    assert ds.meta["params"]["frame_share"] == [0.3, 0.4]
    shares = [dataset.read_annotation(root / "samples" / f"{i:06d}")["stats"]["target_share"]
              for i in range(3)]
    assert all(0.3 - 1e-6 <= s <= 0.4 + 1e-6 for s in shares), shares
    # the default framing (0.45-0.75) leaves meta.json as before: no frame_share key
    assert _run(capsys, *args[:7], str(tmp_path / "default"), *args[8:])[0] == 0
    assert "frame_share" not in dataset.InterSHDataset(tmp_path / "default").meta["params"]
    # resuming with another framing is refused (it would mix two framings in one root)
    code = cli.main(["generate", *args, "--frame-share", "0.3,0.5"])
    assert code == cli.EXIT_CODES["bad-input"] and "frame_share" in capsys.readouterr().err


@pytest.mark.parametrize("share,why", [("0.5,0.3", "0 < min <= max <= 0.84"),
                                       ("0.3,0.9", "0 < min <= max <= 0.84"),
                                       ("0,0.5", "0 < min <= max <= 0.84")])
def test_a_bad_frame_share_is_refused_before_anything_is_written(tmp_path, capsys, share, why):
    out = tmp_path / "root"
    code = cli.main(["generate", "--kind", "hand-hand", "--num", "2", "--out", str(out),
                     "--frame-share", share, "--no-progress"])
    assert code == cli.EXIT_CODES["bad-input"]
    assert why in capsys.readouterr().err
    assert not out.exists()


def test_frame_share_must_be_two_numbers(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["generate", "--kind", "hand-hand", "--num", "1", "--out", str(tmp_path),
                  "--frame-share", "half"])
    assert e.value.code == 2 and "--frame-share must look like MIN,MAX" in capsys.readouterr().err


def test_thumb_zero_elevation_flag_is_recorded_and_none_is_the_earlier_generator(tmp_path, capsys):
    import handmesh_tutorial as hmt

    gen = cli.build_parser()._subparsers._group_actions[0].choices["generate"]
    default = next(a.default for a in gen._actions if a.dest == "thumb_zero_elevation")
    assert default == hmt.lcs.THUMB_ZERO_ELEVATION_DEG
    args = ["--kind", "hand-object", "--num", "2", "--seed", "4", "--image-size", "64",
            "--no-progress", "--no-fsync"]
    roots = {}
    for flag in ("5", "none"):
        roots[flag] = tmp_path / flag
        code, _ = _run(capsys, *args, "--out", str(roots[flag]), "--thumb-zero-elevation", flag)
        assert code == 0
    meta = {f: dataset.InterSHDataset(r).meta["params"]["config"] for f, r in roots.items()}
    assert meta["5"]["thumb_zero_elevation"] == 5.0 and meta["none"]["thumb_zero_elevation"] is None
    # 'none' draws the same scenes with the template's rest thumb as zero: other thumbs
    new, old = (dataset.InterSHDataset(r) for r in roots.values())
    for i in range(2):
        a, b = new[i], old[i]
        t = a["target"]
        ea = hmt.lcs.thumb_elevation(a["joints"][t], a["sides"][t])
        eb = hmt.lcs.thumb_elevation(b["joints"][t], b["sides"][t])
        assert eb > ea + 5.0
    # resuming with another thumb zero is refused (one root, one generator)
    code = cli.main(["generate", *args, "--out", str(roots["5"]), "--thumb-zero-elevation",
                     "none"])
    assert code == cli.EXIT_CODES["bad-input"] and "thumb_zero_elevation" in \
        capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        cli.main(["generate", *args, "--out", str(tmp_path / "x"), "--thumb-zero-elevation",
                  "flat"])
    assert e.value.code == 2 and "degrees or 'none'" in capsys.readouterr().err


def test_repair_commands_never_delete_samples_when_meta_json_disagrees(tmp_path, capsys):
    root = tmp_path / "r"
    argv = ["generate", "--kind", "hand-object", "--num", "2", "--seed", "4", "--out", str(root),
            "--image-size", "32", "--no-progress", "--no-fsync"]
    assert cli.main(argv) == 0
    before = _hashes(root)
    good = (root / "meta.json").read_text()
    (root / "meta.json").write_text(good.replace('"seed": 4', '"seed": 5'))  # one edited field
    capsys.readouterr()
    assert cli.main(["verify", str(root), "--remove-bad", "--no-progress"]) == \
        cli.EXIT_CODES["bad-input"]
    out, err = capsys.readouterr()
    assert "0 bad" in out and "meta.json 'seed' disagrees with 2 sample(s) (000000, 000001)" in out
    assert "none of them was removed" in err and "restore those keys" in err
    assert cli.main([*argv, "--verify"]) == cli.EXIT_CODES["bad-input"]  # no data loss either
    assert "'seed'" in capsys.readouterr().err
    (root / "meta.json").write_text(good)
    assert _hashes(root) == before  # every sample is still there, unchanged
    assert cli.main([*argv, "--verify"]) == 0
    assert "0 samples written, 2 already present" in capsys.readouterr().out


def test_a_num_above_the_readers_maximum_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "root"  # a 2-sample shard of it would be quick to write: nothing is
    code = cli.main(["generate", "--kind", "hand-hand", "--num", str(dataset.MAX_SAMPLES + 1),
                     "--shard", f"0/{dataset.MAX_SAMPLES // 2}", "--out", str(out),
                     "--image-size", "32", "--no-progress", "--no-fsync"])
    assert code == cli.EXIT_CODES["bad-input"]
    assert "num must be an integer in [1, 100,000,000] (MAX_SAMPLES" in capsys.readouterr().err
    assert not out.exists()  # no meta.json that read_meta would refuse


# ------------------------------------------------------------------ a killed worker
DEATH_SCRIPT = """
import os, sys, time
from pathlib import Path
from handmesh_tutorial import data as D
from handmesh_tutorial.testing import synthetic_sample

def make(seed):
    if os.environ.get("SLOW"):
        time.sleep(0.3)  # the workers are busy when one of them is killed
    return synthetic_sample(seed, image_size=32, resolution=4)

if __name__ == "__main__":
    s = D.generate_dataset(sys.argv[1], make, 8, 5, "hand-hand", workers=2, progress=False,
                           durable=False)
    print(s.written, s.skipped)
"""


def _workers_of(pid: int) -> list[int]:
    from pathlib import Path

    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_text(errors="replace")
        except OSError:
            continue
        if int(fields[1]) == pid and "resource_tracker" not in cmd:
            kids.append(int(stat.parent.name))
    return kids


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_killed_worker_ends_the_run_named_and_a_rerun_gives_the_same_bytes(tmp_path):
    import os
    import signal
    import time

    script = tmp_path / "death.py"
    script.write_text(DEATH_SCRIPT)
    run = [sys.executable, str(script)]
    ref = subprocess.run([*run, str(tmp_path / "ref")], capture_output=True, text=True,
                         timeout=120)
    assert ref.returncode == 0, ref.stderr
    root = tmp_path / "run"
    proc = subprocess.Popen([*run, str(root)], stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "SLOW": "1"})
    deadline, workers = time.time() + 90, []
    while time.time() < deadline and proc.poll() is None:
        workers = _workers_of(proc.pid)
        if len(workers) == 2 and len(list((root / "samples").glob("0*"))) >= 1:
            break
        time.sleep(0.02)
    assert len(workers) == 2, "the two workers never started"
    os.kill(workers[0], signal.SIGKILL)
    try:  # before the fix, a death at the wrong moment left the main process waiting forever
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        for p in [proc.pid, *_workers_of(proc.pid)]:
            os.kill(p, signal.SIGKILL)
        raise AssertionError("the run did not end after one of its workers was killed") from None
    assert proc.returncode != 0
    last = err.strip().splitlines()[-1]
    assert last.startswith("handmesh_tutorial._io.EnvironmentFailure: generation worker "
                           f"process {workers[0]} (killed by SIGKILL) died"), err
    assert "rerun the same command" in last
    assert not [w for w in workers if os.path.exists(f"/proc/{w}")
                and open(f"/proc/{w}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"]
    again = subprocess.run([*run, str(root)], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert _hashes(root) == _hashes(tmp_path / "ref")


POOL_CLOSE_SCRIPT = """
import multiprocessing, os, signal, time
from handmesh_tutorial.data import workers as W

if __name__ == "__main__":
    for trial in range(8):
        pool = W._Pool(None, 2, None, "fork")
        got = []
        pool.map(abs, [(-i,) for i in range(4)], got.append)
        time.sleep(0.05)  # both workers idle: one of them holds the task queue's read lock
        workers = sorted(multiprocessing.active_children(), key=lambda p: p.pid)
        os.kill(workers[trial % 2].pid, signal.SIGKILL)
        pool.close()  # every result is in: ends, killing the worker that cannot get its stop
        # no worker runs on (active_children() may still list a reaped one for a moment)
        running = [w.pid for w in workers if os.path.exists(f"/proc/{w.pid}")
                   and open(f"/proc/{w.pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"]
        assert sorted(got) == [0, 1, 2, 3] and not running, (got, running)
    print("closed 8 pools")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork")
def test_a_pool_closes_when_a_worker_died_idle(tmp_path):
    # ProcessPoolExecutor.shutdown(wait=True) alone hung in about a third of these trials: the
    # dead worker held the queue's lock, the other never got its stop message
    script = tmp_path / "close.py"
    script.write_text(POOL_CLOSE_SCRIPT)
    try:
        out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                             timeout=60)
    except subprocess.TimeoutExpired:
        raise AssertionError("closing a pool with a dead idle worker hung") from None
    assert out.returncode == 0 and "closed 8 pools" in out.stdout, out.stderr


def test_generation_summary_prints_lines_that_fit_a_page():
    from handmesh_tutorial.data.generate import GenerationSummary

    summary = GenerationSummary(
        root="runs/intersh_default/train", indices=[[0, 3000]], written=3000, skipped=0,
        attempts=3016, stale_removed=0, seconds=161.4,
        vr_bins=[(0.4, 0.6), (0.6, 0.8), (0.8, 0.95), (0.95, 1.0)],
        vr_histogram=[251, 452, 778, 1367], vr_outside=152,
        vr_probe={"min_hits": 2, "candidates": 64, "filled": [0, 1, 2, 3]}, off_bin=0)
    text = str(summary)
    assert max(len(line) for line in text.splitlines()) <= 100, text
    for part in ("wrote 3000", "3016 make_sample calls", "18.59 samples/s", "[0.95, 1.00]: 1367",
                 "outside bins: 152", "bins left out", "outside their bin: 0"):
        assert part in text, part
