"""Worker processes of the generation driver: start-up, the per-process task, the run loop.

Functions sent to worker processes must be importable by their module path
(``handmesh_tutorial.data.workers._init_worker`` / ``_worker_make``); the task a worker runs is
the module global ``_WORKER_TASK`` of this module. Taught in notebook 05 ("Rendering and the
visibility ratio").
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

from .._io import EnvironmentFailure
from .candidates import _make_and_write, _probe_outcome, _Task

__all__: list[str] = []  # private helpers only; see the package


def _callable_name(fn: Callable | None) -> str | None:
    if fn is None:
        return None
    base = getattr(fn, "func", fn)  # functools.partial: its function (put its args in params)
    name = getattr(base, "__qualname__", type(base).__name__)
    return f"{getattr(base, '__module__', '?')}.{name}"



_WORKER_TASK: _Task | None = None


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker process exit when the process that started it dies.

    Without it, ``kill -9`` of ``generate``'s main process leaves its workers running (and
    writing queued samples) for seconds. On Linux the kernel delivers ``SIGKILL`` to the worker
    when its parent dies (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon thread polls the
    parent's pid once a second.
    """
    import threading

    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0:
            if os.getppid() != parent_pid:  # the parent died before prctl took effect
                os._exit(1)
            return

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="die-with-parent").start()


def _init_worker(task: _Task, worker_init: Callable[[], Any] | None,
                 parent_pid: int | None = None) -> None:
    global _WORKER_TASK
    if parent_pid is not None:
        _die_with_parent(parent_pid)
    _WORKER_TASK = task
    if worker_init is not None:
        worker_init()  # e.g. one OffscreenRenderer per process, kept in a module global


def _worker_make(index: int, filled: tuple[int, ...] | None = None) -> dict:
    assert _WORKER_TASK is not None, "worker not initialised"
    _WORKER_TASK.filled = None if filled is None else tuple(filled)
    return _make_and_write(_WORKER_TASK, index)


def _worker_probe(k: int) -> int | None:
    assert _WORKER_TASK is not None, "worker not initialised"
    return _probe_outcome(_WORKER_TASK, k)



def _start_method(requested: str) -> str:
    """The multiprocessing start method of the worker pool for ``mp_context=requested``.

    ``"auto"`` forks where forking is safe and otherwise spawns. A spawned worker starts a fresh
    interpreter and imports everything again (torch, the library, pyrender: seconds, in every
    worker of every run), and at the end runs the interpreter's full teardown; a forked worker
    inherits the parent's imports and leaves with ``os._exit`` (costs: docs page "Performance",
    "Worker start-up"). Forking is safe here when

    * the platform is Linux (macOS system frameworks and Windows do not support it);
    * this process has opened no OpenGL context
      ([`render.gl_opened`][handmesh_tutorial.render.backend.gl_opened]; e.g. an earlier run
      with ``workers=1`` rendered in this process), since a child would inherit the driver's
      state without its threads;
    * this process has not imported torch: once torch has run an operation on several threads,
      its OpenMP thread pool exists, and a forked child that runs torch on several threads hangs
      (GNU OpenMP is not fork-safe);
    * no other Python thread runs (a Jupyter kernel has several), whose locks a child could
      inherit held. tqdm's monitor thread is the exception: it only takes tqdm's own lock, which
      workers never use.

    ``handmesh generate`` and the demo's two sets meet all four (the generator imports torch
    and pyrender only inside its workers, where a ``balance_vr`` probe runs too); a notebook or
    a script that rendered or trained first spawns.
    """
    import multiprocessing
    import threading

    if requested != "auto":
        if requested not in multiprocessing.get_all_start_methods():
            raise ValueError(f"mp_context must be 'auto' or one of "
                             f"{multiprocessing.get_all_start_methods()}, got {requested!r}")
        return requested
    if not sys.platform.startswith("linux"):
        return "spawn"
    # look the renderer's flag up without importing the render package (and pyrender)
    backend = sys.modules.get("handmesh_tutorial.render.backend")
    if backend is not None and backend.gl_opened():
        return "spawn"
    if "torch" in sys.modules:
        return "spawn"
    others = [t for t in threading.enumerate()
              if t is not threading.current_thread() and t.name != "tqdm_monitor"]
    return "spawn" if others else "fork"


def _check_for_workers(fns: Sequence[Callable | None], mp_context: str) -> None:
    """Fail early, with a hint, on callables that worker processes could not receive."""
    try:
        pickle.dumps(tuple(fns))
    except Exception as e:
        raise ValueError("make_sample, accept and worker_init must be picklable for workers > 1 "
                         f"(module-level functions or functools.partial of them): {e}") from e
    main = sys.modules.get("__main__")
    interactive = main is not None and not getattr(main, "__file__", None)
    for fn in fns:
        base = getattr(fn, "func", fn)
        if fn is not None and interactive and mp_context != "fork" \
                and getattr(base, "__module__", None) == "__main__":
            raise ValueError(f"{_callable_name(fn)} is defined in an interactive session "
                             f"(notebook/REPL); {mp_context!r} worker processes cannot import it. "
                             "Move it to a module, or use workers=1")


_POLL_S = 0.5
"""Seconds between the checks `_Pool.map` makes that every worker process is alive."""
_CLOSE_S = 30.0
"""Seconds `_Pool.close` gives idle workers to exit before it kills them."""


def _how_it_ended(exitcode: int | None) -> str:
    if exitcode is None:
        return "unknown exit"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


class _Pool:
    """The worker processes of one ``generate_dataset`` call (a ``ProcessPoolExecutor`` whose
    workers hold the task), for the VR probe and then the samples.

    A worker that dies (``kill -9``, the out-of-memory killer) ends the run within seconds with
    ``_io.EnvironmentFailure`` naming it, and the other workers are killed: a dead worker can
    leave the pool's queues locked, and ``ProcessPoolExecutor`` alone can then wait for the
    others forever. Killing a worker loses nothing: samples are written atomically and a rerun
    resumes.

    Args:
        task: the `_Task` every worker receives once.
        workers: processes.
        worker_init: called once in each worker.
        mp_context: ``"auto"``, ``"fork"``, ``"spawn"``... (see `_start_method`).
    """

    def __init__(self, task: _Task, workers: int, worker_init: Callable | None,
                 mp_context: str):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self._failed = False   # after an error: shut down without waiting for queued work
        self._seen: dict = {}  # pid -> worker process
        self._ex = ProcessPoolExecutor(max_workers=workers,
                                       mp_context=multiprocessing.get_context(
                                           _start_method(mp_context)),
                                       initializer=_init_worker,
                                       initargs=(task, worker_init, os.getpid()))

    def _processes(self) -> list:
        """The worker processes so far (the executor's own table, which starts with the first
        task and is dropped at shutdown)."""
        self._seen.update(getattr(self._ex, "_processes", None) or {})
        return list(self._seen.values())

    def _dead_now(self) -> list:
        """The workers that have died (their sentinel is ready; nothing is reaped here)."""
        from multiprocessing.connection import wait

        procs = self._processes()
        ready = set(wait([p.sentinel for p in procs], timeout=0)) if procs else set()
        return [p for p in procs if p.sentinel in ready]

    def _death(self, dead: list) -> EnvironmentFailure:
        """Kill the workers and return the error that names the ``dead`` ones and how they
        ended."""
        self._failed = True
        self._kill()
        deadline = time.monotonic() + 5.0  # the executor's thread may be reaping them
        while any(p.exitcode is None for p in dead) and time.monotonic() < deadline:
            time.sleep(0.02)
        # once one died the executor terminates the others (SIGTERM): name the first victim
        first = [p for p in dead if p.exitcode != -signal.SIGTERM] or dead
        who = ", ".join(f"{p.pid} ({_how_it_ended(p.exitcode)})" for p in first) or "?"
        text = (f"generation worker process {who} died; the samples on disk are complete: "
                "rerun the same command to resume (a worker killed by the system was likely "
                "out of memory: use fewer workers)")
        if any(p.exitcode is not None and p.exitcode > 0 for p in first):
            text += ("; a worker that exits at once may have failed to start (a script using "
                     "workers needs an `if __name__ == '__main__':` guard)")
        return EnvironmentFailure(text)

    def map(self, fn: Callable, args: Sequence[tuple], on_result: Callable[[Any], None]) -> None:
        """Run ``fn(*a)`` for every ``a`` of ``args`` in the workers; ``on_result`` gets each
        result as it comes (any order). A worker's exception is raised here, and then the pool
        is shut down (its queued work cancelled, its workers killed).

        Raises:
            EnvironmentFailure: a worker process died (named, with its signal or exit code).
        """
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        it, pending = iter(args), set()
        try:
            # A bounded window of submissions keeps Ctrl-C responsive and memory flat.
            for a in it:
                pending.add(self._ex.submit(fn, *a))
                if len(pending) >= 2 * self.workers:
                    break
            # note the workers now: once one dies the executor drops its table, and `close`
            # must still find (and end) the others
            self._processes()
            while pending:
                finished, pending = wait(pending, timeout=_POLL_S,
                                         return_when=FIRST_COMPLETED)
                if not finished and (dead := self._dead_now()):
                    raise self._death(dead)  # a death the executor has not noticed (yet)
                for fut in finished:
                    try:
                        result = fut.result()  # re-raises a worker's error here
                    except BrokenProcessPool as e:
                        raise self._death(self._dead_now()) from e
                    on_result(result)
                    nxt = next(it, None)
                    if nxt is not None:
                        pending.add(self._ex.submit(fn, *nxt))
        except BaseException:
            self._failed = True
            self._kill()
            raise

    def _kill(self) -> None:
        """Cancel the queued work and kill the workers (what they wrote is complete)."""
        procs = self._processes()
        self._ex.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            if p.exitcode is None:
                p.kill()
        for p in procs:
            p.join(timeout=5.0)

    def close(self) -> None:
        """End the workers (idempotent): after an error, kill them; else let them exit, and
        kill them if one died meanwhile (the others may then never get their stop message) or
        after `_CLOSE_S` seconds."""
        if self._failed:
            self._kill()
            return
        procs = self._processes()
        self._ex.shutdown(wait=False)
        deadline = time.monotonic() + _CLOSE_S
        while any(p.exitcode is None for p in procs) and time.monotonic() < deadline:
            if any(p.exitcode not in (None, 0) for p in procs):
                break
            time.sleep(0.02)
        if any(p.exitcode is None for p in procs):
            self._kill()


def _run(task: _Task, todo: list[int], workers: int, worker_init: Callable | None,
         progress: bool, total: int, initial: int, mp_context: str, desc: str,
         initialised: bool = False, pool: _Pool | None = None) -> list[dict]:
    """Make and write the samples ``todo``: in this process (``workers == 1``, or a single sample
    and no ``pool``), else in ``pool`` (the call's pool, which ran the VR probe) or a new one."""
    from .._progress import progress_bar

    results: list[dict] = []
    bar = progress_bar(total=total, initial=initial, disable=not progress, desc=desc,
                       unit="sample")

    def done(result: dict) -> None:
        results.append(result)
        bar.update(1)

    try:
        if pool is None and (workers == 1 or len(todo) <= 1):
            if worker_init is not None and todo and not initialised:
                worker_init()
            for i in todo:
                done(_make_and_write(task, i))
            return results
        own = pool is None
        if own:
            pool = _Pool(task, min(workers, len(todo)), worker_init, mp_context)
        # the bins to fill travel with each sample: a probe in the pool ran after it started
        pool.map(_worker_make, [(i, task.filled) for i in todo], done)
        if own:
            pool.close()
        return results
    finally:
        bar.close()
