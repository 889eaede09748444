"""Tests of the ``handmesh generate`` sub-command (CLI wrapper of interact + dataset)."""

from __future__ import annotations

import hashlib
import subprocess
import sys

import numpy as np
import pytest

from handmesh_tutorial import cli, dataset


def _hashes(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and not p.name.startswith(".")}


def _run(capsys, *argv):
    code = cli.main(["generate", *argv])
    return code, capsys.readouterr().out


def test_generate_writes_a_readable_dataset_and_resumes(tmp_path, capsys):
    root = tmp_path / "intersh"
    args = ("--kind", "mixed", "--num", "3", "--seed", "5", "--out", str(root),
            "--image-size", "64", "--quiet", "--no-fsync")
    code, out = _run(capsys, *args)
    assert code == 0
    assert "3 samples written, 0 already present" in out
    assert "[0.95, 1.00]:" in out and "target-hand VR histogram" in out
    ds = dataset.InterSHDataset(root)
    assert len(ds) == 3 and ds.missing == []
    assert sorted(ds.meta["kinds"]) == ["hand-chain", "hand-hand", "hand-object"]
    assert ds.meta["params"]["limits"] == "paper"
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
                     "anatomical", "--quiet", "--no-fsync")
    assert code == 0 and "2 samples written" in out
    ds = dataset.InterSHDataset(root)
    assert ds.meta["shards"] == [[1, 2]] and ds.meta["params"]["limits"] == "anatomical"
    assert sorted(p.name for p in (root / "samples").iterdir()) == ["000002", "000003"]
    # the same sample index is the same scene whatever the shard
    from handmesh_tutorial import interact

    s = interact.make_sample(dataset.sample_seed(2, 3), "hand-object", 64, limits="anatomical")
    assert np.array_equal(s["image"], dataset.read_sample(root / "samples" / "000003")["image"])
    # a different option on the same root is refused, naming the differing key
    with pytest.raises(ValueError, match="params"):
        cli.main(["generate", "--kind", "hand-object", "--num", "4", "--seed", "2", "--out",
                  str(root), "--image-size", "64", "--shard", "1/2", "--quiet"])


@pytest.mark.parametrize("bad", [["--shard", "3/2"], ["--shard", "x"], ["--kind", "foot"],
                                 ["--limits", "none"]])
def test_generate_rejects_bad_arguments(tmp_path, capsys, bad):
    argv = ["generate", "--kind", "hand-hand", "--num", "1", "--out", str(tmp_path), *bad]
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2
    assert "error" in capsys.readouterr().err


def test_generate_help_through_the_module_entry_point():
    r = subprocess.run([sys.executable, "-m", "handmesh_tutorial.cli", "generate", "--help"],
                       capture_output=True, text=True, check=True)
    for opt in ("--kind", "--num", "--seed", "--out", "--image-size", "--workers",
                "--balance-vr", "--shard", "--limits"):
        assert opt in r.stdout
