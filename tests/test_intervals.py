"""Paired differences, Welch intervals and detectable differences (hmt.metrics.intervals)."""

import numpy as np
import pytest
from scipy import stats

from handmesh_tutorial.metrics.intervals import (
    detectable_difference,
    format_interval,
    paired_difference,
    seed_difference,
)


def test_the_paired_t_interval_equals_scipys_paired_test():
    rng = np.random.default_rng(3)
    b = rng.normal(8.0, 2.0, 100)
    a = b - 0.4 + rng.normal(0, 0.7, 100)
    got = paired_difference(a, b)
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert got["difference"] == pytest.approx(np.mean(a - b), abs=1e-12)
    assert (got["low"], got["high"]) == pytest.approx((ci.low, ci.high), abs=1e-10)
    assert got["a_better"] == pytest.approx(np.mean(a < b))
    assert got["n"] == 100 and got["sd"] == pytest.approx(np.std(a - b, ddof=1))


def test_the_bootstrap_interval_agrees_with_t_on_normal_differences_and_is_seeded():
    rng = np.random.default_rng(5)
    d = rng.normal(-1.0, 1.0, 400)
    t = paired_difference(d, np.zeros_like(d))
    bs = paired_difference(d, np.zeros_like(d), method="bootstrap", resamples=4000, seed=1)
    assert bs["low"] == pytest.approx(t["low"], abs=0.03)
    assert bs["high"] == pytest.approx(t["high"], abs=0.03)
    again = paired_difference(d, np.zeros_like(d), method="bootstrap", resamples=4000, seed=1)
    assert again == bs


def test_welch_interval_equals_scipys_unequal_variance_test():
    a, b = np.array([5.53, 5.40, 5.66]), np.array([5.51, 5.70, 5.32, 5.48])
    got = seed_difference(a, b)
    ci = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert (got["low"], got["high"]) == pytest.approx((ci.low, ci.high), abs=1e-10)
    same = seed_difference([1.0, 1.0], [2.0, 2.0])
    assert (same["low"], same["high"]) == (-1.0, -1.0)


def test_the_detectable_difference_is_found_with_the_stated_power():
    sd, n = 0.6, 100
    delta = detectable_difference(sd, n)
    rng = np.random.default_rng(0)
    found = np.mean([stats.ttest_1samp(rng.normal(delta, sd, n), 0).pvalue < 0.05
                     for _ in range(2000)])
    assert 0.76 < found < 0.84
    # two independent groups need sqrt(2) times the paired difference
    assert detectable_difference(sd, n, paired=False) == pytest.approx(delta * np.sqrt(2))


@pytest.mark.parametrize("call, match", [
    (lambda: paired_difference([1, 2, 3], [1, 2]), "same samples"),
    (lambda: paired_difference([1.0], [2.0]), "at least 2"),
    (lambda: paired_difference([1, np.nan], [1, 2]), "non-finite"),
    (lambda: paired_difference([[1, 2]], [[1, 2]]), r"shape \(N,\)"),
    (lambda: paired_difference([1, 2], [2, 3], confidence=1.5), "confidence"),
    (lambda: paired_difference([1, 2], [2, 3], method="x"), "method"),
    (lambda: paired_difference([1, 2], [2, 3], method="bootstrap", resamples=5), "resamples"),
    (lambda: seed_difference([1.0], [1.0, 2.0]), "at least 2 seeds"),
    (lambda: detectable_difference(-1, 10), "sd"),
    (lambda: detectable_difference(1, 1), "n must"),
    (lambda: detectable_difference(1, 10, power=1.0), "power"),
])
def test_bad_arguments_are_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_format_interval_keeps_signs_readable():
    assert format_interval({"difference": -4.3, "low": -6.09, "high": -2.56}) == \
        "-4.30 (-6.09 to -2.56)"


def test_the_lazy_submodules_are_the_right_modules():
    import subprocess
    import sys

    code = ("import handmesh_tutorial as hmt; "
            "assert hmt.metrics.intervals.__name__.endswith('.intervals'); "
            "assert hmt.metrics.surface.__name__.endswith('.surface')")
    subprocess.run([sys.executable, "-c", code], check=True)
