"""Differences between two methods scored on the same samples, with 95 % intervals and power.

Two networks evaluated on the same test scenes give paired errors: the question "is A better
than B?" is about the per-scene differences, whose spread is much smaller than that of either
score. [`paired_difference`][handmesh_tutorial.metrics.intervals.paired_difference] gives the mean
difference with a Student-t or bootstrap interval;
[`seed_difference`][handmesh_tutorial.metrics.intervals.seed_difference] compares two training
recipes over independent seeds (Welch), which counts the run-to-run spread; and
[`detectable_difference`][handmesh_tutorial.metrics.intervals.detectable_difference] says the
smallest true difference a design finds with a given power (how many scenes or seeds a 0.1 mm
claim needs). Used by the demo's report and notebook 10's ablation.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

__all__ = ["paired_difference", "seed_difference", "detectable_difference", "format_interval"]


def _vector(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"{name} must be one score per sample, shape (N,), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds {int((~np.isfinite(a)).sum())} non-finite values")
    return a


def _check_confidence(confidence: float) -> None:
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")


def paired_difference(a, b, *, confidence: float = 0.95, method: str = "t",
                      resamples: int = 10_000, seed: int = 0) -> dict:
    """Mean of ``a - b`` over paired samples, with a confidence interval.

    Args:
        a: (N,) scores of method A per sample (e.g. PA-MPJPE in mm per test scene).
        b: (N,) scores of method B on the same samples, in the same order.
        confidence: interval coverage in (0, 1).
        method: ``"t"`` (Student t on the differences) or ``"bootstrap"`` (percentile interval of
            ``resamples`` resamplings of the samples, seeded).
        resamples: bootstrap resamplings (``method="bootstrap"``), at least 100.
        seed: bootstrap seed.

    Returns:
        ``{"difference", "low", "high", "sd", "n", "a_better"}``: the mean difference, its
        interval, the standard deviation of the per-sample differences, the sample count and the
        share of samples where ``a < b`` (lower is better for errors). Same units as the scores.

    Raises:
        ValueError: shapes differ, fewer than 2 samples, non-finite scores, or a bad option.
    """
    a, b = _vector(a, "a"), _vector(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a and b must score the same samples: shapes {a.shape} and {b.shape}")
    if len(a) < 2:
        raise ValueError(f"a paired interval needs at least 2 samples, got {len(a)}")
    _check_confidence(confidence)
    d = a - b
    mean, sd = float(d.mean()), float(d.std(ddof=1))
    if method == "t":
        half = float(stats.t.ppf(0.5 + confidence / 2, len(d) - 1)) * sd / math.sqrt(len(d))
        low, high = mean - half, mean + half
    elif method == "bootstrap":
        if int(resamples) < 100:
            raise ValueError(f"resamples must be at least 100, got {resamples}")
        rng = np.random.default_rng(seed)
        means = d[rng.integers(0, len(d), size=(int(resamples), len(d)))].mean(axis=1)
        low, high = (float(q) for q in np.quantile(means, [0.5 - confidence / 2,
                                                             0.5 + confidence / 2]))
    else:
        raise ValueError(f"method must be 't' or 'bootstrap', got {method!r}")
    return {"difference": mean, "low": low, "high": high, "sd": sd, "n": len(d),
            "a_better": float((d < 0).mean())}


def seed_difference(a, b, *, confidence: float = 0.95) -> dict:
    """Difference of two recipes' mean scores over independent training seeds (Welch's t).

    Args:
        a: (Ka,) one score per seed of recipe A (e.g. test PA-MPJPE of each run), Ka >= 2.
        b: (Kb,) the same for recipe B, Kb >= 2.
        confidence: interval coverage in (0, 1).

    Returns:
        ``{"difference", "low", "high", "df"}``: ``mean(a) - mean(b)``, its Welch interval and
        the Welch-Satterthwaite degrees of freedom. When both spreads are zero the interval is
        the point itself.

    Raises:
        ValueError: fewer than 2 seeds on a side, non-finite scores, a bad confidence.
    """
    a, b = _vector(a, "a"), _vector(b, "b")
    if len(a) < 2 or len(b) < 2:
        raise ValueError(f"Welch's interval needs at least 2 seeds per side, got {len(a)} and "
                         f"{len(b)}")
    _check_confidence(confidence)
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    d = float(a.mean() - b.mean())
    if va + vb == 0:
        return {"difference": d, "low": d, "high": d, "df": float("inf")}
    df = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1))
    half = float(stats.t.ppf(0.5 + confidence / 2, df)) * math.sqrt(va + vb)
    return {"difference": d, "low": d - half, "high": d + half, "df": float(df)}


def detectable_difference(sd: float, n: int, *, alpha: float = 0.05, power: float = 0.8,
                          paired: bool = True) -> float:
    """The smallest true difference a two-sided test at level ``alpha`` finds with ``power``.

    Normal approximation: ``(z(1 - alpha/2) + z(power)) * sd * sqrt(k / n)`` with ``k = 1`` for
    paired samples (``sd``: of the per-sample differences) and ``k = 2`` for two independent
    groups of ``n`` each (``sd``: of one group's values, e.g. the run-to-run spread over seeds).

    Args:
        sd: standard deviation (see above), >= 0, in the scores' units.
        n: pairs (paired) or values per group, >= 2.
        alpha: test level in (0, 1).
        power: probability of finding a true difference of the returned size, in (0, 1).
        paired: paired design (else two independent groups).

    Returns:
        The difference, in the units of ``sd``.

    Raises:
        ValueError: an argument out of its range.
    """
    if not (math.isfinite(sd) and sd >= 0):
        raise ValueError(f"sd must be finite and >= 0, got {sd}")
    if int(n) != n or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n}")
    if not 0 < alpha < 1 or not 0 < power < 1:
        raise ValueError(f"alpha and power must be in (0, 1), got {alpha} and {power}")
    z = stats.norm.ppf(1 - alpha / 2) + stats.norm.ppf(power)
    return float(z * sd * math.sqrt((1 if paired else 2) / n))


def format_interval(result: dict, digits: int = 2) -> str:
    """``"-1.16 (-1.63 to -0.64)"`` from a result of `paired_difference` or `seed_difference`."""
    f = f"{{:+.{digits}f}}"
    return (f"{f.format(result['difference'])} ({f.format(result['low'])} to "
            f"{f.format(result['high'])})")
