"""Fingerprints of arrays that survive a change of CPU, for tests that compare against a recorded
reference.

Floating point is reproducible bit for bit on one machine and library build, not across CPUs:
torch (MKL, its own vectorised kernels) and numpy pick SIMD code paths by CPU, and sums round
differently. A fingerprint therefore keeps what is exact by construction exactly (names, dtypes,
shapes, integer and boolean arrays by SHA-256) and summarises each floating-point array by three
float64 numbers, compared with a tolerance relative to the array's norm:

- ``sum``: the plain sum;
- ``signed``: the sum with a fixed +-1 pattern per element (drawn from integers, so the same on
  every machine): a change that keeps the sum (a permutation, a sign flip) moves it;
- ``norm``: the Euclidean norm.

A real change (another initialisation, layer or sample) moves them by a share of the norm of
order one; the kernel paths of one x86-64 machine move them by at most about 3e-5 of it
(``make unit-kernels`` runs the tests that use this under reduced MKL, ATen and numpy paths).
"""

from __future__ import annotations

import hashlib

import numpy as np

# The largest change of a fingerprint, as a share of the array's norm, that a change of CPU
# kernels may cause. Measured on an AMD EPYC (AVX-512) against MKL_CBWR=COMPATIBLE,
# ATEN_CPU_CAPABILITY=default/avx2, NPY_DISABLE_CPU_FEATURES and NUMBA_CPU_NAME=generic:
# at most 2.7e-5 for a freshly initialised network's weights and outputs, 6e-7 for a generated
# scene's geometry. 1e-3 leaves a margin of 30x over the worst, far below a real change.
KERNEL_RTOL = 1e-3


def _signs(n: int) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 2, n).astype(np.float64) * 2.0 - 1.0


def fingerprint(arrays: dict) -> dict:
    """``{name: entry}`` for ``{name: array}`` (numpy or torch, any shape): ``dtype`` and
    ``shape`` always; ``sha256`` of the bytes for integer and boolean arrays; ``sum``,
    ``signed``, ``norm`` (float64) for floating-point ones. JSON-ready."""
    out = {}
    for name, value in arrays.items():
        a = value.detach().cpu().numpy() if hasattr(value, "detach") else np.asarray(value)
        entry = {"dtype": str(a.dtype), "shape": list(a.shape)}
        if a.dtype.kind in "fc":
            x = a.astype(np.float64).ravel()
            entry.update(sum=float(x.sum()), signed=float(_signs(x.size) @ x),
                         norm=float(np.sqrt(x @ x)))
        else:
            entry["sha256"] = hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()
        out[name] = entry
    return out


def differences(got: dict, want: dict, rtol: float = KERNEL_RTOL) -> list[str]:
    """Where fingerprint ``got`` is not ``want``: names missing or added, dtype, shape or integer
    bytes that differ, float summaries further apart than ``rtol`` of the array's norm (plus a
    tiny absolute floor for all-zero arrays). Empty when they match."""
    problems = []
    if list(got) != list(want):
        problems.append(f"names differ: only got {sorted(set(got) - set(want))}, only "
                        f"recorded {sorted(set(want) - set(got))}" if set(got) != set(want)
                        else "same names in another order")
    for name in [n for n in want if n in got]:
        g, w = got[name], want[name]
        for key in ("dtype", "shape", "sha256"):
            if g.get(key) != w.get(key):
                problems.append(f"{name}: {key} {g.get(key)} != recorded {w.get(key)}")
        if "norm" in w and "norm" in g:
            bound = rtol * w["norm"] + 1e-12
            for key in ("sum", "signed", "norm"):
                if abs(g[key] - w[key]) > bound:
                    problems.append(f"{name}: {key} {g[key]!r} differs from recorded {w[key]!r} "
                                    f"by more than {bound:.3g} ({rtol:g} of its norm)")
    return problems
