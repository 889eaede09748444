"""Progress bars that stay short in log files.

In a terminal and in Jupyter, ``progress_bar`` is tqdm's usual
bar (``tqdm.auto``). When the output is not a terminal (CI logs, ``make demo > log``), a bar
that redraws on every step writes one line per step: thousands of lines. There it writes at most
one line per 10% of a job (``per="job"``, 11 lines at most) or a single line when it ends
(``per="epoch"``, for the bar of one training epoch: one line per epoch).
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterable

__all__ = ["progress_bar", "is_interactive"]


def is_interactive(file=None) -> bool:
    """Whether ``file`` (default ``sys.stderr``, tqdm's output) is a terminal."""
    file = sys.stderr if file is None else file
    try:
        return bool(file.isatty())
    except (AttributeError, ValueError):  # closed or not a real stream
        return False


def progress_bar(iterable: Iterable | None = None, *, per: str = "job", disable: bool = False,
                 file=None, **kwargs):
    """A tqdm bar: tqdm's own in terminals and notebooks, throttled when writing to a log.

    Args:
        iterable: what to iterate over (as for ``tqdm``); ``None`` for a manual bar
            (``total=``, ``update()``).
        per: ``"job"``: in a log, print at most once per 10% of ``total`` (and at the end);
            ``"epoch"``: in a log, print one line when the bar closes (one per epoch), nothing
            while it runs.
        disable: no bar at all.
        file: the stream (default ``sys.stderr``).
        **kwargs: passed to ``tqdm`` (``total``, ``desc``, ``unit``, ``initial``, ``leave``...).

    Returns:
        The ``tqdm`` instance (iterate over it, or call ``update``/``close``).
    """
    from tqdm.auto import tqdm as auto_tqdm
    from tqdm.notebook import tqdm as notebook_tqdm
    from tqdm.std import tqdm as std_tqdm

    if per not in ("job", "epoch"):
        raise ValueError(f"per must be 'job' or 'epoch', got {per!r}")
    if disable:
        return std_tqdm(iterable, disable=True, **kwargs)
    # tqdm.auto is never tqdm.std itself (it adds asyncio support): test for the notebook class
    if file is None and issubclass(auto_tqdm, notebook_tqdm):  # Jupyter: the notebook widget
        return auto_tqdm(iterable, **kwargs)
    stream = sys.stderr if file is None else file
    if is_interactive(stream):
        return std_tqdm(iterable, file=stream, **kwargs)
    total = kwargs.get("total")
    if total is None and iterable is not None:
        try:
            total = len(iterable)  # type: ignore[arg-type]
        except TypeError:
            total = None
    remaining = max(1, (total or 0) - int(kwargs.get("initial", 0) or 0))
    if per == "epoch":
        miniters = remaining + 1  # never redraw while running; close() prints the final line
        kwargs["leave"] = True
    else:
        miniters = max(1, -(-remaining // 10)) if total else 1
    # time plays no part (maxinterval=inf also keeps tqdm from lowering miniters on its own); an
    # unknown total falls back to one line a minute
    kwargs.update(miniters=miniters, mininterval=0 if total else 60.0, maxinterval=float("inf"),
                  dynamic_ncols=False, ncols=kwargs.get("ncols") or 100)
    return std_tqdm(iterable, file=_LineWriter(stream), **kwargs)


class _LineWriter:
    """File-like adapter for tqdm in a log: each redraw (``\\r...``) becomes one whole line.

    Blank redraws (tqdm clearing a ``leave=False`` bar) and the bar's first draw (0%, printed when
    it is created) are dropped.
    """

    def __init__(self, stream):
        self.stream = stream
        self.pending = ""
        self.seen_first = False
        self.last_key = None

    def write(self, s: str) -> None:
        parts = (self.pending + s).replace("\n", "\r").split("\r")
        self.pending = parts.pop()
        for line in parts:
            self._emit(line)

    def _emit(self, line: str) -> None:
        if not line.strip():
            return
        if not self.seen_first:
            self.seen_first = True
            return
        # description, percentage and count (not the bar, whose width varies, nor the timing)
        key = re.sub(r"\|[^|]*\|", "|", line.split("[")[0]).strip()
        if key == self.last_key:  # close() redraws the last state
            return
        self.last_key = key
        self.stream.write(line.rstrip() + "\n")

    def flush(self) -> None:
        self.stream.flush()
