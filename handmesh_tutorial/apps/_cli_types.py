"""The argument types of the ``handmesh`` command (``--shard``, ``--channels``, ``--device``,
``--out``...) and its tolerant output streams: each type's error names the option and the form it
wants (argparse adds the option's name). Part of `handmesh_tutorial.apps.cli`; docs page "The
pipeline" (apps layer)."""

from __future__ import annotations

import argparse
import os
import re
import sys


def _two_numbers(text: str, sep: str, cast, form: str):
    """``"a<sep>b"`` -> ``(cast(a), cast(b))``; argparse's error names the expected ``form``."""
    try:
        a, b = (cast(x) for x in text.split(sep))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{form}, got {text!r}") from None
    return a, b


def _share(text: str) -> tuple[float, float]:
    return _two_numbers(text, ",", float, "--frame-share must look like MIN,MAX (e.g. 0.3,0.5)")


def _degrees_or_none(text: str) -> float | None:
    if text.lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--thumb-zero-elevation must be degrees or 'none', got "
                                         f"{text!r}") from None


def _shard(text: str) -> tuple[int, int]:
    k, n = _two_numbers(text, "/", int, "--shard must look like K/N (e.g. 0/4)")
    if n < 1 or not 0 <= k < n:
        raise argparse.ArgumentTypeError(f"--shard K/N needs 0 <= K < N, got {text!r}")
    return k, n


def _channels(text: str) -> tuple[int, ...]:
    try:
        channels = tuple(int(x) for x in text.split(","))
    except ValueError:
        channels = ()
    if not channels or min(channels) < 1:
        raise argparse.ArgumentTypeError("--channels must be comma-separated positive integers "
                                         f"(e.g. 16,24,32,48,64), got {text!r}")
    return channels


def _out_folder(text: str) -> str:
    """An output folder: ``""`` is refused (it would silently mean the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a folder, got {text!r} (use . for the "
                                         "current folder)")
    long = next((p for p in text.split("/") if len(os.fsencode(p)) > _NAME_MAX), None)
    if long is not None:  # ENAMETOOLONG only once a file is written there
        raise argparse.ArgumentTypeError(f"a folder name is at most {_NAME_MAX} bytes, got one of "
                                         f"{len(os.fsencode(long))} ({long[:24]}...)")
    return text


_NAME_MAX = 255
"""Longest file or folder name, bytes (Linux, macOS and Windows file systems)."""


def _positive_int(text: str) -> int:
    """An integer >= 1 (``--threads``, ``--batch-size``...); argparse names the option."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def _device(text: str) -> str:
    """``auto``, ``cpu``, ``cuda``, ``cuda:N`` or ``mps`` (other torch devices: not trained on)."""
    if not re.fullmatch(r"auto|cpu|cuda(:\d+)?|mps", text):
        raise argparse.ArgumentTypeError(f"must be auto, cpu, cuda, cuda:N or mps, got {text!r}")
    return text


def _tolerant_output() -> None:
    """Let stdout and stderr write any text: a character the terminal's encoding cannot show
    (a folder named ``données`` under ``PYTHONIOENCODING=ascii`` or a C locale) is written as
    an escape (``\\xe9``) instead of ending a finished command with a ``UnicodeEncodeError``."""
    for stream in (sys.stdout, sys.stderr):
        encoding = (getattr(stream, "encoding", None) or "").lower().replace("-", "")
        if hasattr(stream, "reconfigure") and not encoding.startswith("utf") \
                and getattr(stream, "errors", "strict") == "strict":
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a stream that cannot change now: left as it is
                pass
