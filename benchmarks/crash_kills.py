"""Crash test: kill `handmesh generate --workers 2` and `handmesh train` at random moments.

Each phase first makes a reference with one uninterrupted run, then runs the same command into a
second folder, SIGKILLs it after a random delay (alternately the main process only and the whole
process group), checks that no process of the killed run survives, and reruns the command until
it completes. At the end the folder must equal the reference byte for byte (generation) or hold
the same weights (training), with no temporary file left behind.

    python benchmarks/crash_kills.py [--kills 10] [--num 12] [--seed 0] [--keep DIR]

Prints one line per kill and a summary; exits 1 if any check fails. Not part of `make test`
(it takes minutes); `make benchmarks` runs it with the defaults.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

HANDMESH = [sys.executable, "-m", "handmesh_tutorial.cli"]


def tree(root: Path) -> dict[str, str]:
    """sha256 of every file below ``root`` (the writer lock excluded)."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != ".generate.lock"}


def temporaries(root: Path) -> list[str]:
    """Temporary entries our writers make (``.tmp-*`` folders/files, ``.*.tmp`` files)."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")
                  if p.name.startswith(".tmp-") or (p.name.startswith(".")
                                                    and p.name.endswith(".tmp")))


def descendants(pid: int) -> set[int]:
    """All processes below ``pid`` (from /proc)."""
    parent = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parent[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    found, frontier = set(), {pid}
    while frontier:
        frontier = {p for p, pp in parent.items() if pp in frontier} - found
        found |= frontier
    return found


def alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def run(argv: list[str]) -> float:
    t0 = time.perf_counter()
    out = subprocess.run(argv, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({out.returncode}):\n{out.stderr}")
    return time.perf_counter() - t0


def kill_loop(name: str, first: list[str], again, out: Path, check, kills: int, span: float,
              rng: random.Random) -> tuple[int, int, list[bool]]:
    """Kill ``kills`` times; whenever a run completes, ``check()`` it and start afresh.

    ``again()`` gives the command line of a rerun after a kill; ``check()`` compares the
    completed ``out`` with the reference. The last series is finished without a kill.

    Returns:
        (kills done, processes that outlived a kill by 10 s, one check result per series).
    """
    done = survivors = 0
    checks: list[bool] = []
    argv = first
    while done < kills:
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                start_new_session=True)
        delay = rng.uniform(0.1, 0.9) * span
        t0, seen = time.perf_counter(), set()
        while time.perf_counter() - t0 < delay and proc.poll() is None:
            seen |= descendants(proc.pid)
            time.sleep(0.02)
        if proc.poll() is not None:  # the series completed before the kill: check, restart
            if proc.returncode != 0:
                raise SystemExit(f"{name}: run failed ({proc.returncode}): "
                                 f"{proc.stderr.read().decode()[-2000:]}")
            checks.append(check())
            print(f"{name}: series {len(checks)} completed after {done} kills; "
                  f"check {'passed' if checks[-1] else 'FAILED'}")
            shutil.rmtree(out)
            argv = first
            continue
        seen |= descendants(proc.pid)
        whole = done % 2 == 1
        if whole:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.perf_counter() + 10
        while time.perf_counter() < deadline and any(alive(p) for p in seen):
            time.sleep(0.05)
        left = [p for p in seen if alive(p)]
        survivors += len(left)
        for p in left:  # do not let a survivor spoil the next checks
            os.kill(p, signal.SIGKILL)
        done += 1
        print(f"{name}: kill {done} ({'process group' if whole else 'main process only'}) "
              f"after {delay:.1f} s; {len(seen)} child process(es), {len(left)} survived 10 s")
        argv = again()
    run(again())
    checks.append(check())
    return done, survivors, checks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=10, help="kills per phase (default 10)")
    ap.add_argument("--num", type=int, default=12, help="scenes to generate (default 12)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", help="work in this folder instead of a temporary one")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    base = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="crash_kills_"))
    base.mkdir(parents=True, exist_ok=True)
    failures = []

    gen = [*HANDMESH, "generate", "--kind", "mixed", "--num", str(args.num), "--seed",
           str(args.seed), "--image-size", "64", "--workers", "2", "--no-fsync", "--quiet"]
    ref_s = run([*gen, "--out", str(base / "gen_ref")])
    print(f"generate: reference of {args.num} scenes in {ref_s:.1f} s")
    g = [*gen, "--out", str(base / "gen_run")]

    def gen_check() -> bool:
        same = tree(base / "gen_run") == tree(base / "gen_ref")
        tmps = temporaries(base / "gen_run")
        if tmps:
            print(f"generate: temporaries left: {tmps}")
        return same and not tmps

    kills, surv, checks = kill_loop("generate", g, lambda: g, base / "gen_run", gen_check,
                                    args.kills, ref_s, rng)
    print(f"generate: {kills} kills, {surv} surviving processes, {len(checks)} completed series,"
          f" {sum(checks)} byte-identical to the reference with no temporaries left")
    if not all(checks) or surv:
        failures.append("generate")

    tr = [*HANDMESH, "train", "--data", str(base / "gen_ref"), "--epochs", "4",
          "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
          "--latent-channels", "8", "--threads", "1", "--no-progress", "--no-fsync",
          "--budget", "smoke"]
    ref_s = run([*tr, "--out", str(base / "train_ref")])
    print(f"train: reference run in {ref_s:.1f} s")
    t = [*tr, "--out", str(base / "train_run")]
    out = base / "train_run"
    want = torch.load(base / "train_ref" / "checkpoint_last.pt", weights_only=True)

    def train_check() -> bool:
        got = torch.load(out / "checkpoint_last.pt", weights_only=True)
        tmps = temporaries(out)
        if tmps:
            print(f"train: temporaries left: {tmps}")
        return not tmps and got["epoch"] == want["epoch"] and all(
            torch.equal(got["model"][k], want["model"][k]) for k in want["model"])

    # --resume once the run has started (config.json written); before that, a fresh start
    kills, surv, checks = kill_loop(
        "train", t, lambda: [*t, "--resume"] if (out / "config.json").exists() else t, out,
        train_check, args.kills, ref_s, rng)
    print(f"train: {kills} kills, {surv} surviving processes, {len(checks)} completed series, "
          f"{sum(checks)} with the reference's weights and no temporaries left")
    if not all(checks) or surv:
        failures.append("train")
    print(f"crash_kills: {'FAILED ' + ', '.join(failures) if failures else 'all checks passed'}"
          f" ({base})")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
