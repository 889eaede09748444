"""Nothing outside a run's own files is touched (issue 43): repairs, locks and readers facing
foreign entries, symbolic links, non-ASCII names, ``extra`` fields and samples of another set.

A synthetic ``make_sample`` (``testing.synthetic_sample``) stands in for the renderer. Docs page
*Reliability*, "What is promised".
"""

from __future__ import annotations

import errno
import functools
import hashlib
import json
import os
import re
import shutil
from pathlib import Path

import pytest

from handmesh_tutorial import data as D
from handmesh_tutorial._io import EnvironmentFailure, single_writer
from handmesh_tutorial.apps import cli
from handmesh_tutorial.data import files as F
from handmesh_tutorial.data.torch_views import BadSampleError, InterSHTorchDataset, find_bad_items
from handmesh_tutorial.testing import synthetic_sample

SIZE, SEED = 32, 3
make = functools.partial(synthetic_sample, image_size=SIZE, resolution=4)


def gen(root, num=3, seed=SEED, kind="hand-hand", size=SIZE, **kw):
    kw.setdefault("progress", False)
    fn = functools.partial(synthetic_sample, kind=kind, image_size=size, resolution=4)
    return D.generate_dataset(root, fn, num, seed, kind, image_size=size, **kw)


def tree(folder) -> dict:
    """sha256 of every file under ``folder`` (links not followed), locks excluded."""
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()
            and not p.name.endswith(".lock")}


def damage(sample: Path) -> None:
    npz = sample / "annotation.npz"
    npz.write_bytes(npz.read_bytes()[:100])


def edit_annotation(sample: Path, **fields) -> None:
    path = sample / "annotation.json"
    ann = json.loads(path.read_text())
    ann.update(fields)
    path.write_text(json.dumps(ann))


# ------------------------------------------------------------------ item 1: repairs


def test_a_repair_touches_only_the_planned_sample_folders(tmp_path, capsys):
    root = tmp_path / "r"
    gen(root, num=3)
    s = root / "samples"
    damage(s / "000002")  # the one bad folder a repair may delete
    damage(s / "000001")
    (s / "000001" / "photo.jpg").write_bytes(b"a user's photo")  # ... but not this file
    (s / "2024").mkdir()
    (s / "2024" / "notes.txt").write_text("keep")  # digits, not a name the set plans
    (s / "99").write_text("keep")  # a file of digits
    (s / "notes.txt").write_text("keep")
    shutil.copytree(s / "000002", s / "000007")  # a bad folder of an index not planned
    shutil.copytree(s / "000000", s / "\u0660\u0660\u0660\u0660\u0660\u0663")  # Arabic-Indic
    user = {k: v for k, v in tree(s).items() if not k.startswith(("000001/", "000002/"))}
    user["000001/photo.jpg"] = tree(s)["000001/photo.jpg"]

    capsys.readouterr()
    code = cli.main(["verify", str(root), "--remove-bad", "--no-progress"])
    out = capsys.readouterr().out
    assert code == cli.EXIT_CODES["bad-input"]  # not everything bad could be removed
    after = tree(s)
    assert {k: after.get(k) for k in user} == user  # every file of the user's is still there
    assert not (s / "000002").exists()  # the planned bad sample is gone
    assert sorted(os.listdir(s / "000001")) == ["photo.jpg"]  # only the sample's own files went
    report = D.verify_dataset(root, progress=False)
    assert [n for n, _ in report.foreign] == ["notes.txt", "\u0660" * 5 + "\u0663"]
    assert {n for n, _ in report.bad} == {"000001", "000007", "2024", "99"}
    assert "photo.jpg" in out and "meta.json plans no sample 000007" in out
    assert "not a sample (left as it is)" in out


def test_a_symlinked_samples_folder_is_never_repaired_through(tmp_path, capsys):
    root, outside = tmp_path / "r", tmp_path / "outside"
    gen(root, num=3)
    shutil.move(root / "samples", outside)
    (root / "samples").symlink_to(outside, target_is_directory=True)
    damage(outside / "000001")
    (outside / "31").write_text("keep")
    before = tree(outside)
    with pytest.raises(ValueError, match="symbolic link"):
        D.verify_dataset(root, remove=True, progress=False)
    capsys.readouterr()
    assert cli.main(["verify", str(root), "--remove-bad", "--no-progress"]) == 3
    assert "symbolic link" in capsys.readouterr().err
    with pytest.raises(ValueError, match="symbolic link"):
        gen(root, num=4)
    assert tree(outside) == before  # nothing outside the root deleted or written
    assert [n for n, _ in D.verify_dataset(root, progress=False).bad] == ["000001", "31"]


@pytest.mark.parametrize("plant, named", [
    ("samples/000001/photo.jpg", "samples/000001 (holds 'photo.jpg', no sample's file)"),
    ("notes.txt", "notes.txt"), ("samples/x.txt", "samples/x.txt (not a sample this run plans)")])
def test_generate_refuses_a_foreign_folder_before_writing_meta_json(tmp_path, plant, named):
    out = tmp_path / "u"
    (out / plant).parent.mkdir(parents=True, exist_ok=True)
    (out / plant).write_bytes(b"the user's")
    with pytest.raises(ValueError, match="holds what this run did not write: " + re.escape(named)):
        gen(out, num=3)
    assert not (out / "meta.json").exists()
    assert (out / plant).read_bytes() == b"the user's"
    # not even its lock is left there (fresh probe: a refused folder kept .generate.lock)
    assert [p.name for p in out.rglob("*") if p.is_file()] == [Path(plant).name]


# ------------------------------------------------------------------ item 17: a lost meta.json


@pytest.mark.parametrize("change, why", [({"kind": "hand-object"}, "kind 'hand-hand'"),
                                         ({"seed": SEED + 1}, "seed"),
                                         ({"size": 48}, "size"),
                                         ({"num": 2}, "not a sample this run plans")])
def test_a_lost_meta_json_resumes_only_with_the_samples_own_parameters(tmp_path, change, why):
    root = tmp_path / "r"
    gen(root, num=3)
    before = tree(root)
    (root / "meta.json").unlink()
    kw = {"num": 3, **change}
    with pytest.raises(ValueError, match=why):
        gen(root, **kw)
    assert not (root / "meta.json").exists()  # refused before anything was written
    assert gen(root, num=3).written == 0 and tree(root) == before  # its own parameters resume


def test_resuming_refuses_a_sample_of_another_kind_or_size(tmp_path):
    gen(tmp_path / "other", num=3, kind="hand-object", size=48)
    root = tmp_path / "r"
    gen(root, num=3)
    shutil.rmtree(root / "samples" / "000001")
    shutil.copytree(tmp_path / "other" / "samples" / "000001", root / "samples" / "000001")
    with pytest.raises(ValueError, match="kind 'hand-object' not in meta.json kinds"):
        gen(root, num=3)


# ------------------------------------------------------------------ item 2: lock files


def test_a_lock_file_that_is_a_link_is_refused_and_its_target_never_created(tmp_path, capsys):
    target = tmp_path / "outside" / "nologin"
    target.parent.mkdir()
    root = tmp_path / "r"
    root.mkdir()
    (root / ".generate.lock").symlink_to(target)
    with pytest.raises(EnvironmentFailure, match="symbolic link"):
        gen(root)
    assert not target.exists() and not (root / "meta.json").exists()
    for name in ("train", "pretrain"):  # train and pretrain-encoder lock the same way
        link = tmp_path / f".{name}.lock"
        link.symlink_to(target)
        with pytest.raises(EnvironmentFailure, match="symbolic link"), single_writer(link, "x"):
            pass
    assert not target.exists()
    target.write_text("the user's")
    capsys.readouterr()
    gen(tmp_path / "ok")
    (tmp_path / "ok" / ".generate.lock").unlink()
    (tmp_path / "ok" / ".generate.lock").symlink_to(target)
    damage(tmp_path / "ok" / "samples" / "000001")
    assert cli.main(["verify", str(tmp_path / "ok"), "--remove-bad", "--no-progress"]) == 6
    assert "symbolic link" in capsys.readouterr().err
    assert target.read_text() == "the user's"
    assert (tmp_path / "ok" / "samples" / "000001").exists()  # nothing removed without the lock


def test_a_fifo_or_folder_in_place_of_the_lock_is_refused(tmp_path):
    import socket

    os.mkfifo(tmp_path / "fifo.lock")
    (tmp_path / "dir.lock").mkdir()
    sock = socket.socket(socket.AF_UNIX)  # fresh probe: a socket was exit 1 (ENXIO), unnamed
    sock.bind(str(tmp_path / "sock.lock"))
    for name in ("fifo.lock", "dir.lock", "sock.lock"):
        with pytest.raises(EnvironmentFailure, match="regular file|is a folder"), \
                single_writer(tmp_path / name, "x"):
            pass
    sock.close()


# ------------------------------------------------------------------ item 11: verify's messages


def test_verify_remove_bad_takes_the_writer_lock(tmp_path, capsys):
    fcntl = pytest.importorskip("fcntl")
    root = tmp_path / "r"
    gen(root, num=3)
    damage(root / "samples" / "000001")
    with open(root / ".generate.lock", "a+b") as fh:  # a generate running in this root
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        capsys.readouterr()
        assert cli.main(["verify", str(root), "--remove-bad", "--no-progress"]) == 6
        assert "being written by another process" in capsys.readouterr().err
        assert (root / "samples" / "000001").exists()
        assert cli.main(["verify", str(root), "--no-progress"]) == 3  # reading needs no lock


def test_a_repair_that_cannot_remove_prints_its_list_then_names_the_file(tmp_path, capsys,
                                                                          monkeypatch):
    root = tmp_path / "r"
    gen(root, num=3)
    damage(root / "samples" / "000001")

    def read_only(folder):
        raise OSError(errno.EROFS, "Read-only file system", str(folder / "image.png"))

    monkeypatch.setattr(D.root, "_remove_sample_folder", read_only)
    capsys.readouterr()
    assert cli.main(["verify", str(root), "--remove-bad", "--no-progress"]) == 6
    cap = capsys.readouterr()
    assert "1 bad" in cap.out and "000001: not removed: [Errno 30]" in cap.out
    assert "000001/image.png" in cap.err and "Read-only" in cap.err


def test_verify_remove_bad_says_what_writes_the_removed_samples_again(tmp_path, capsys):
    root = tmp_path / "r"
    gen(root, num=3)
    before = tree(root)
    damage(root / "samples" / "000001")
    capsys.readouterr()
    assert cli.main(["verify", str(root), "--remove-bad", "--no-progress"]) == 0
    assert "rerun the `handmesh generate` command that made it" in capsys.readouterr().out
    assert gen(root, num=3).written == 1 and tree(root) == before  # and it does


def test_generate_verify_repairs_beside_entries_the_set_does_not_plan(tmp_path, capsys):
    """Fresh probe of issue 43: a user's ``samples/99`` or ``samples/2024/`` made ``generate
    --verify`` stop (exit 3, "fix their permissions") with the planned sample removed and not
    written again; only a bad entry where a planned sample belongs stops it now."""
    argv = ["generate", "--kind", "hand-hand", "--num", "3", "--seed", "4", "--out",
            str(tmp_path / "r"), "--image-size", "32", "--no-progress", "--no-fsync"]
    assert cli.main(argv) == 0
    s = tmp_path / "r" / "samples"
    ref = tree(s)
    damage(s / "000001")
    (s / "99").write_text("the user's")
    (s / "2024").mkdir()
    (s / "2024" / "notes.txt").write_text("the user's")
    capsys.readouterr()
    assert cli.main([*argv, "--verify"]) == 0
    out = capsys.readouterr().out
    assert "1 removed" in out and "1 samples written, 2 already present" in out
    assert "99: not removed: meta.json plans no sample 99" in out
    after = tree(s)
    assert {k: after[k] for k in ref} == ref  # 000001 written again, byte for byte
    assert (s / "99").read_text() == (s / "2024" / "notes.txt").read_text() == "the user's"
    shutil.rmtree(s / "000002")
    (s / "000002").write_text("a file where a planned sample belongs")
    assert cli.main([*argv, "--verify"]) == cli.EXIT_CODES["bad-input"]
    err = capsys.readouterr().err
    assert "000002 could not be removed (see above), where samples this set plans belong" in err
    assert (s / "000002").read_text() == "a file where a planned sample belongs"


def test_a_balanced_run_starts_no_more_workers_than_there_is_work(tmp_path, monkeypatch):
    """Issue 43 item 11 (seen once, to check): ``--balance-vr`` started every ``--workers``
    process for its probe, whatever the work (2 candidates and 1 sample here)."""
    from handmesh_tutorial.data import generate as G

    class Started(Exception):
        pass

    sizes = []

    def pool(task, workers, *args):
        sizes.append(workers)
        raise Started

    monkeypatch.setattr(G, "_Pool", pool)
    with pytest.raises(Started):
        gen(tmp_path / "r", num=1, balance_vr=True, workers=8, vr_probe=2)
    with pytest.raises(Started):
        gen(tmp_path / "s", num=3, balance_vr=True, workers=8, vr_probe=64)
    assert sizes == [2, 8]


# ------------------------------------------------------------------ item 4: extra fields


@pytest.mark.parametrize("extra", [{"image": 5}, {"attempt": "zz"}, {"vr": {"1": 42}},
                                   {"target": 7}, {"K": [[1, 0], [0, 1]]}, {"seed": None},
                                   {"alone_images": {}}, {"not an id": 1}])
def test_extra_entries_never_shadow_a_field(tmp_path, extra):
    root = tmp_path / "r"
    gen(root, num=3)
    s = root / "samples"
    edit_annotation(s / "000000", extra=extra)
    damage(s / "000002")  # a truly damaged sample: still removed
    with pytest.raises(ValueError, match="'extra' entries"):
        F.read_sample(s / "000000")
    with pytest.raises(ValueError, match="'extra' entries"):
        D.InterSHDataset(root).target(0)
    report = D.verify_dataset(root, remove=True, progress=False)
    assert [n for n, _ in report.bad] == ["000000", "000002"] and "extra" in dict(report.bad)[
        "000000"]
    assert report.removed == ["000000", "000002"]
    assert D.InterSHDataset(root)[0]["index"] == 1  # the good sample still reads


def test_extra_arrays_never_shadow_a_field_and_wrong_types_are_bad_samples(tmp_path):
    root = tmp_path / "r"
    gen(root, num=2)
    s = root / "samples"
    edit_annotation(s / "000000", extra_arrays=["K"])
    edit_annotation(s / "000001", attempt="zz")
    report = D.verify_dataset(root, progress=False)
    why = dict(report.bad)
    assert "'extra' entries ['K']" in why["000000"]
    assert "'attempt' must be a non-negative integer" in why["000001"]


# ------------------------------------------------------------------ item 5: non-ASCII names


def test_non_ascii_digits_are_no_sample_numbers(tmp_path):
    root = tmp_path / "r"
    gen(root, num=3)
    s = root / "samples"
    (s / "\u00b2").mkdir()  # superscript two: str.isdigit() says True, int() fails
    shutil.copytree(s / "000001", s / ("\u0660" * 5 + "\u0661"))  # Arabic-Indic 000001
    shutil.copytree(s / "000002", s / ("\uff10" * 5 + "\uff12"))  # fullwidth 000002
    shutil.copytree(s / "000002", s / "2")  # a short name of sample 2
    ds = D.InterSHDataset(root)
    assert ds.indices.tolist() == [0, 1, 2] and ds.missing == []
    assert InterSHTorchDataset(root, train=False).vr_values().shape == (3,)
    assert gen(root, num=3).written == 0  # generate resumes, counting each sample once
    report = D.verify_dataset(root, progress=False)
    assert len(report.foreign) == 3 and report.checked == 4
    assert report.disagreements() == {"index_width": ["2"]}
    ann = json.loads((s / "000000" / "annotation.json").read_text())
    ann["vr"] = {"\u00b9": 0.5, "2": 0.5}  # a superscript label
    (s / "000000" / "annotation.json").write_text(json.dumps(ann))
    with pytest.raises(ValueError, match=r"000000/annotation.json: 'vr'.*label '\u00b9'"):
        F.read_annotation(s / "000000")


# ------------------------------------------------------------------ item 6: foreign samples


@pytest.mark.parametrize("other, why", [({"kind": "hand-object"}, "kind"),
                                        ({"size": 48}, "size"),
                                        ({"seed": SEED + 6}, "seed rule")])
def test_the_lean_training_read_refuses_a_foreign_sample_as_the_full_read_does(
        tmp_path, other, why):
    gen(tmp_path / "other", num=3, **other)
    root = tmp_path / "r"
    gen(root, num=3)
    shutil.rmtree(root / "samples" / "000001")
    shutil.copytree(tmp_path / "other" / "samples" / "000001", root / "samples" / "000001")
    ds = D.InterSHDataset(root)
    with pytest.raises(ValueError, match=why):
        ds[1]
    with pytest.raises(ValueError, match=why):
        ds.target(1)  # the read training and evaluation use
    crops = InterSHTorchDataset(root, train=False)
    hint = f"handmesh verify {re.escape(str(root))}"
    with pytest.raises(BadSampleError, match=f"sample 000001: .*{why}.*{hint}"):
        crops[1]
    assert [b["sample"] for b in find_bad_items(crops)] == ["000001"]
    assert crops[0]["image"].shape[-1] == 128 and crops[2] is not None


def test_a_bad_freihand_sample_is_not_sent_to_verify(tmp_path):
    """`handmesh verify` reads INTER-SH roots only: a FreiHAND bad sample's message says how to
    list such samples there (--skip-bad), not verify."""
    from handmesh_tutorial.data.torch_views import FreiHANDTorchDataset
    from handmesh_tutorial.testing import write_freihand_root

    root = write_freihand_root(tmp_path / "fh", 2, image_size=32)
    image = sorted((root / "training" / "rgb").iterdir())[0]
    image.write_bytes(image.read_bytes()[:50])
    with pytest.raises(BadSampleError, match="--skip-bad lists each one") as err:
        FreiHANDTorchDataset(root, "training", image_size=32, train=False)[0]
    assert "handmesh verify" not in str(err.value)


# ------------------------------------------------------------------ a run in parts (fresh probe)


def test_a_run_in_parts_writes_and_deletes_only_its_own_shards(tmp_path):
    """The shards of ``generate_dataset(parts=...)`` live in ``.<root>-shards/`` beside the root
    until they are merged; that folder used to be removed whole (a user's file in it deleted)
    and written through when it was a link (shards created outside)."""
    outside = tmp_path / "outside"
    outside.mkdir()
    shards = tmp_path / ".r-shards"
    shards.symlink_to(outside, target_is_directory=True)
    with pytest.raises(ValueError, match=r"\.r-shards is a symbolic link"):
        gen(tmp_path / "r", num=4, parts=2)
    assert list(outside.iterdir()) == [] and not (tmp_path / "r").exists()
    shards.unlink()
    shards.mkdir()
    (shards / "notes.txt").write_text("the user's")
    with pytest.raises(ValueError, match=r"holds what a run in parts did not write \(notes.txt\)"):
        gen(tmp_path / "r", num=4, parts=2)
    assert (shards / "notes.txt").read_text() == "the user's" and not (tmp_path / "r").exists()
    (shards / "notes.txt").unlink()
    gen(tmp_path / "r", num=4, parts=2)  # the folder holds nothing else: runs, then removed
    assert not shards.exists() and D.InterSHDataset(tmp_path / "r").indices.tolist() == [0, 1, 2, 3]
    gen(tmp_path / "ref", num=4)
    assert tree(tmp_path / "r" / "samples") == tree(tmp_path / "ref" / "samples")


def test_removing_merged_shards_leaves_what_no_shard_wrote(tmp_path):
    from handmesh_tutorial.data.root import _remove_shards

    shards = tmp_path / ".r-shards"
    gen(shards / "0000", num=2)
    (shards / "0000" / "samples" / "000001" / "photo.jpg").write_bytes(b"the user's")
    (shards / "0000" / "mine.txt").write_text("the user's")
    left = _remove_shards(shards)
    assert sorted(left) == [".r-shards/0000/mine.txt", ".r-shards/0000/samples/000001/photo.jpg"]
    assert sorted(str(p.relative_to(shards)) for p in shards.rglob("*") if p.is_file()) == \
        ["0000/mine.txt", "0000/samples/000001/photo.jpg"]
