"""Crash test: kill `handmesh generate --workers 2` and `handmesh train` at random moments.

Each phase first makes a reference with one uninterrupted run, then runs the same command into a
second folder, SIGKILLs it after a random delay (alternately the main process only and the whole
process group), checks that no process of the killed run survives, and reruns the command until
it completes. At the end the folder must equal the reference byte for byte (generation) or hold
the same weights (training), with no temporary file left behind.

Three more phases cover the other ways a run can be disturbed (docs page *Reliability*):

* ``workers``: SIGKILL one *worker* of ``generate --workers 2`` (not the main process): the run
  must end within 10 s with exit code 6 naming the worker, and the reruns must complete to the
  reference's bytes;
* ``writers``: two ``generate`` into one folder and two ``train`` into one run folder, started
  together: one of each must be refused with exit code 6 ("being written by another process")
  while the other completes to the reference;
* ``replaced``: the training data replaced by another set at the same path between a run and its
  ``--resume``: refused with exit code 3 naming what differs.

    python benchmarks/crash_kills.py [--kills 10] [--num 12] [--seed 0] [--keep DIR]
                                     [--phases generate,workers,writers,train,replaced]

Prints one line per kill and a summary; exits 1 if any check fails. Not part of `make test`
(it takes minutes); `make benchmarks` runs it with the defaults.
"""

from __future__ import annotations

import argparse
import hashlib
import math
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

HANDMESH = [sys.executable, "-m", "handmesh_tutorial.apps.cli"]
PHASES = ("generate", "workers", "writers", "train", "replaced")


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
    ap.add_argument("--phases", default=",".join(PHASES),
                    help=f"comma-separated subset of {','.join(PHASES)} (default: all)")
    args = ap.parse_args()
    phases = set(args.phases.split(","))
    if phases - set(PHASES):
        ap.error(f"unknown phases {sorted(phases - set(PHASES))}; choose from {PHASES}")
    rng = random.Random(args.seed)
    base = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="crash_kills_"))
    base.mkdir(parents=True, exist_ok=True)
    failures = []

    gen = [*HANDMESH, "generate", "--kind", "mixed", "--num", str(args.num), "--seed",
           str(args.seed), "--image-size", "64", "--workers", "2", "--no-fsync", "--no-progress"]
    ref_s = run([*gen, "--out", str(base / "gen_ref")])
    print(f"generate: reference of {args.num} scenes in {ref_s:.1f} s")
    g = [*gen, "--out", str(base / "gen_run")]

    def gen_check() -> bool:
        same = tree(base / "gen_run") == tree(base / "gen_ref")
        tmps = temporaries(base / "gen_run")
        if tmps:
            print(f"generate: temporaries left: {tmps}")
        return same and not tmps

    if "generate" in phases:
        kills, surv, checks = kill_loop("generate", g, lambda: g, base / "gen_run", gen_check,
                                        args.kills, ref_s, rng)
        print(f"generate: {kills} kills, {surv} surviving processes, {len(checks)} completed "
              f"series, {sum(checks)} byte-identical to the reference with no temporaries left")
        if not all(checks) or surv:
            failures.append("generate")
    if "workers" in phases:
        w = [*gen, "--out", str(base / "workers_run")]
        kills, late, checks = worker_kill_loop(w, base / "workers_run",
                                               lambda: tree(base / "workers_run")
                                               == tree(base / "gen_ref")
                                               and not temporaries(base / "workers_run"),
                                               args.kills, ref_s, rng)
        print(f"workers: {kills} worker kills, {late} runs that did not end within 10 s with "
              f"exit code 6 naming the worker, {len(checks)} completed series, {sum(checks)} "
              "byte-identical to the reference")
        if not all(checks) or late or not checks:
            failures.append("workers")
    if "writers" in phases:
        ok = two_writers("generate", [*gen, "--out", str(base / "gen_twice")],
                         lambda: tree(base / "gen_twice") == tree(base / "gen_ref"))
        if not ok:
            failures.append("writers (generate)")

    tr = [*HANDMESH, "train", "--data", str(base / "gen_ref"), "--epochs", "4",
          "--batch-size", "4", "--image-size", "32", "--channels", "4,4,8,8,8",
          "--latent-channels", "8", "--threads", "1", "--no-progress", "--no-fsync",
          "--budget", "smoke"]
    if not phases & {"train", "writers", "replaced"}:
        return report(failures, base)
    ref_s = run([*tr, "--out", str(base / "train_ref")])
    print(f"train: reference run in {ref_s:.1f} s")
    want = torch.load(base / "train_ref" / "checkpoint_last.pt", weights_only=True)

    def same_weights(out: Path) -> bool:
        got = torch.load(out / "checkpoint_last.pt", weights_only=True)
        tmps = temporaries(out)
        if tmps:
            print(f"train: temporaries left: {tmps}")
        return not tmps and got["epoch"] == want["epoch"] and all(
            torch.equal(got["model"][k], want["model"][k]) for k in want["model"])

    if "train" in phases:
        t = [*tr, "--out", str(base / "train_run")]
        out = base / "train_run"
        # --resume once the run has started (config.json written); before that, a fresh start
        kills, surv, checks = kill_loop(
            "train", t, lambda: [*t, "--resume"] if (out / "config.json").exists() else t, out,
            lambda: same_weights(out), args.kills, ref_s, rng)
        print(f"train: {kills} kills, {surv} surviving processes, {len(checks)} completed "
              f"series, {sum(checks)} with the reference's weights and no temporaries left")
        if not all(checks) or surv:
            failures.append("train")
    if "writers" in phases and not two_writers(
            "train", [*tr, "--out", str(base / "train_twice")],
            lambda: same_weights(base / "train_twice")):
        failures.append("writers (train)")
    if "replaced" in phases and not replaced_data(tr, base, args):
        failures.append("replaced")
    return report(failures, base)


def report(failures: list[str], base: Path) -> int:
    print(f"crash_kills: {'FAILED ' + ', '.join(failures) if failures else 'all checks passed'}"
          f" ({base})")
    return 1 if failures else 0


def worker_kill_loop(argv: list[str], out: Path, check, kills: int, span: float,
                     rng: random.Random) -> tuple[int, int, list[bool]]:
    """SIGKILL one generator worker ``kills`` times; each killed run must end within 10 s with
    exit code 6 naming the worker; reruns continue until a series completes, then ``check()``.

    Returns:
        (worker kills done, killed runs that failed that test, one check result per series).
    """
    done = late = 0
    checks: list[bool] = []
    while done < kills:
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                start_new_session=True)
        t0, workers = time.perf_counter(), []
        while proc.poll() is None and len(workers) < 2:  # the workers fork once set up
            workers = [p for p in descendants(proc.pid) if alive(p) and b"resource_tracker"
                       not in _cmdline(p)]
            time.sleep(0.02)
        t0, delay = time.perf_counter(), rng.uniform(0.0, 0.6) * span  # from the workers' start
        while time.perf_counter() - t0 < delay and proc.poll() is None:
            time.sleep(0.02)
        if proc.poll() is not None:
            if proc.returncode != 0:
                raise SystemExit(f"workers: run failed ({proc.returncode}): "
                                 f"{proc.stderr.read().decode()[-2000:]}")
            checks.append(check())
            print(f"workers: series {len(checks)} completed after {done} kills; check "
                  f"{'passed' if checks[-1] else 'FAILED'}")
            shutil.rmtree(out)
            continue
        victim = rng.choice(workers)
        os.kill(victim, signal.SIGKILL)
        t_kill = time.perf_counter()
        try:
            _, err = proc.communicate(timeout=10)
            ended = time.perf_counter() - t_kill
            named = proc.returncode == 6 and f"worker process {victim}" in err.decode()
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            ended, named = math.inf, False
        late += not named
        done += 1
        print(f"workers: kill {done} of worker {victim} after {delay:.1f} s; the run ended "
              f"{ended:.1f} s later, exit code {proc.returncode}"
              f"{'' if named else ' -- NOT the expected exit code 6 naming the worker'}")
    run(argv)
    checks.append(check())
    return done, late, checks


def _cmdline(pid: int) -> bytes:
    try:
        return (Path("/proc") / str(pid) / "cmdline").read_bytes()
    except OSError:
        return b""


def two_writers(name: str, argv: list[str], check) -> bool:
    """Start ``argv`` twice at once: exactly one must be refused with exit code 6 (the writer
    lock) unless the first finished before the second started; the folder must pass ``check``.
    """
    procs = [subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
             for _ in range(2)]
    results = [(p.wait(), p.stderr.read().decode()) for p in procs]
    codes = sorted(code for code, _ in results)
    refused = [err for code, err in results if code == 6]
    ok = codes in ([0, 6], [0, 0]) and all("being written by another process" in e
                                           for e in refused) and check()
    print(f"writers ({name}): two at once exited {codes}; "
          f"{'one refused by the lock, ' if codes == [0, 6] else ''}"
          f"result {'equals' if ok else 'DIFFERS FROM'} the reference")
    return ok


def replaced_data(tr: list[str], base: Path, args) -> bool:
    """Train one epoch, replace the data folder by another set at the same path, resume: the
    resume must be refused (exit code 3) naming what differs."""
    data = base / "replaced_data"
    gen = [*HANDMESH, "generate", "--kind", "hand-hand", "--num", "4", "--image-size", "64",
           "--no-fsync", "--no-progress"]
    run([*gen, "--seed", str(args.seed), "--out", str(data)])
    t = [a if a != str(base / "gen_ref") else str(data) for a in tr]
    t = [*t[:t.index("--epochs") + 1], "1", *t[t.index("--epochs") + 2:], "--val-fraction", "0"]
    run([*t, "--out", str(base / "replaced_run")])
    shutil.rmtree(data)
    run([*gen, "--seed", str(args.seed + 1), "--out", str(data)])
    t[t.index("--epochs") + 1] = "2"
    out = subprocess.run([*t, "--out", str(base / "replaced_run"), "--resume"],
                         capture_output=True, text=True)
    ok = out.returncode == 3 and "data changed since this run started" in out.stderr \
        and f"seed {args.seed} -> {args.seed + 1}" in out.stderr
    print(f"replaced: resume on another data set at the same path exited {out.returncode}: "
          f"{out.stderr.strip().splitlines()[0][:160] if out.stderr.strip() else ''}")
    return ok


if __name__ == "__main__":
    sys.exit(main())
