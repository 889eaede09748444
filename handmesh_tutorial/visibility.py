r"""The visibility ratio (VR) of the paper, its bins, and balanced sampling across the bins.

For a body ``o`` (a hand or an object) of a rendered scene the paper defines

$$
VR_o = \frac{\sum_{i=1}^N 1_o(M^{scene}_i)}{\sum_{i=1}^N 1_o(M^{alone}_i)}
$$

where ``M^scene`` is the label mask of the complete scene, ``M^alone`` the mask of ``o`` rendered
alone with the same camera, ``N`` the number of pixels and ``1_o`` the indicator "this pixel shows
``o``". ``VR = 1``: nothing hides ``o``; ``VR = 0.5``: half of its pixels are covered by other
bodies. The masks come from `handmesh_tutorial.render.Renderer` (``labels`` and
``alone_masks``); both use the same rasterisation, so a body's visible pixels are a subset of its
alone mask and ``VR`` lies in ``[0, 1]``.

This module is the one place that defines the VR bins of the paper (`VR_BINS`).

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

__all__ = [
    "VR_BINS",
    "BalancedVRSampler",
    "balanced_indices",
    "visibility_ratio",
    "visibility_ratios",
    "vr_bin",
    "vr_bin_index",
]

VR_BINS: tuple[tuple[float, float], ...] = ((0.40, 0.60), (0.60, 0.80), (0.80, 0.95), (0.95, 1.00))
"""The four VR categories of the paper (Table "Results on INTER-SH"): each is ``[low, high)``
except the last, ``[0.95, 1.00]``, which is closed. A VR below 0.40 is in no bin.
"""

_ON_OUTSIDE = ("raise", "warn", "ignore")


def _check_label(label) -> int:
    """``label`` as an int >= 1, or a ValueError (0 is the background of a label mask)."""
    if isinstance(label, bool | np.bool_) or not isinstance(label, int | np.integer) \
            or int(label) < 1:
        raise ValueError(f"label must be an integer >= 1 (a body's label; 0 is the background "
                         f"of a label mask), got {label!r}")
    return int(label)


def _indicator(mask: Any, label: int, name: str) -> np.ndarray:
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H, W) mask, got shape {m.shape}")
    if m.dtype == np.bool_:
        return m
    if not np.issubdtype(m.dtype, np.integer):
        raise ValueError(f"{name} must be a bool mask or an integer label mask, "
                         f"got dtype {m.dtype}")
    ind = m == label
    if not ind.any() and m.any():
        values = np.unique(m)
        shown = ", ".join(str(int(v)) for v in values[:6]) + (", ..." if len(values) > 6 else "")
        raise ValueError(f"{name} has no pixel equal to label {label}, but holds the values "
                         f"[{shown}]: an integer mask is read as a label mask; for a 0/255 or "
                         f"0/1 image mask pass it as bool ({name} > 0), else give the label its "
                         "pixels carry")
    return ind


def visibility_ratio(scene_mask: Any, alone_mask: Any, label: int,
                     on_outside: str = "raise", stray: float = 0.0) -> float:
    """Visibility ratio of one body: visible pixels in the scene / pixels when rendered alone.

    Args:
        scene_mask: (H, W) integer label mask of the complete scene (0 = background, each body
            its label), e.g. ``RenderResult.labels``.
        alone_mask: (H, W) mask of the body rendered alone: either a bool mask (``True`` = the
            body) or an integer label mask, whose pixels equal to ``label`` count (a 0/255
            image mask is not a label mask: pass ``mask > 0``).
        label: the body's label, an integer ``>= 1`` (0 is the background).
        on_outside: what to do when some pixels labelled ``label`` in the scene lie outside the
            alone mask (impossible for masks from the same camera and rasteriser, so it means a
            rendering or bookkeeping bug): ``"raise"`` (default) a ValueError, ``"warn"`` a
            RuntimeWarning, or ``"ignore"``. With ``"warn"``/``"ignore"`` only the visible pixels
            inside the alone mask are counted, which keeps the result in ``[0, 1]``.
        stray: share of the alone mask's pixel count that may lie outside it and still pass
            as rasteriser jitter (counted as hidden, ``on_outside`` not applied). 0 (default):
            none, right for Mesa, which rasterises a body identically in both passes; NVIDIA's
            EGL flips some edge pixels between them (docs page "Rendering", "The passes and the
            label mask"), and the generator allows 3 %.

    Returns:
        VR in ``[0, 1]`` (a Python float).

    Raises:
        ValueError: a mask is not 2-D, the shapes differ, ``scene_mask`` is not an integer label
            mask, ``label`` is not an integer >= 1, ``stray`` is outside [0, 1], an integer
            ``alone_mask`` has pixels but none equal to ``label`` (a 0/255 image mask: the
            message says to pass ``mask > 0``), the alone mask of ``label`` is empty (VR
            undefined), or visible pixels lie outside the alone mask with
            ``on_outside="raise"``.

    Examples:
        >>> import numpy as np
        >>> from handmesh_tutorial.visibility import visibility_ratio
        >>> alone = np.zeros((4, 6), bool)
        >>> alone[:, :4] = True  # body 1 rendered alone covers 4 columns
        >>> scene = np.zeros((4, 6), int)
        >>> scene[:, :3], scene[:, 3:] = 1, 2  # in the scene, body 2 hides its 4th column
        >>> visibility_ratio(scene, alone, 1)
        0.75
    """
    if on_outside not in _ON_OUTSIDE:
        raise ValueError(f"on_outside must be one of {_ON_OUTSIDE}, got {on_outside!r}")
    label = _check_label(label)
    if not 0.0 <= stray <= 1.0:
        raise ValueError(f"stray must be a share in [0, 1], got {stray!r}")
    scene = np.asarray(scene_mask)
    if scene.ndim != 2 or not np.issubdtype(scene.dtype, np.integer) or scene.dtype == np.bool_:
        raise ValueError(f"scene_mask must be a 2-D integer label mask, got dtype {scene.dtype} "
                         f"shape {scene.shape}")
    alone = _indicator(alone_mask, label, "alone_mask")
    if scene.shape != alone.shape:
        raise ValueError(f"scene_mask shape {scene.shape} != alone_mask shape {alone.shape} "
                         f"(label {label})")
    visible = scene == label
    denom = int(np.count_nonzero(alone))
    if denom == 0:
        raise ValueError(f"alone mask of label {label} is empty: the body is not in view, "
                         "its visibility ratio is undefined")
    outside = int(np.count_nonzero(visible & ~alone))
    if outside > stray * denom:
        msg = (f"label {label}: {outside} visible scene pixels lie outside its alone mask "
               "(the masks do not come from the same camera/rasteriser?)")
        if on_outside == "raise":
            raise ValueError(msg)
        if on_outside == "warn":
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
    num = int(np.count_nonzero(visible & alone))
    return num / denom


def visibility_ratios(scene_mask: Any, alone_masks: Mapping[int, Any],
                      on_outside: str = "raise", stray: float = 0.0,
                      on_empty: str = "nan") -> dict[int, float]:
    """Visibility ratios of several bodies of one scene.

    Args:
        scene_mask: (H, W) integer label mask of the scene.
        alone_masks: ``{label: (H, W) mask}`` of each body alone (bool or label masks), e.g.
            ``RenderResult.alone_masks``; labels are integers >= 1.
        on_outside: as in `visibility_ratio`.
        stray: as in `visibility_ratio`.
        on_empty: a body whose alone mask is empty (out of view: its VR is undefined):
            ``"nan"`` (default) gives it NaN with a RuntimeWarning that names it, and the other
            bodies keep their ratios (NaN falls in no VR bin); ``"raise"``: a ValueError that
            names every such body.

    Returns:
        ``{label: VR}`` with the same keys as ``alone_masks``.

    Raises:
        ValueError: as `visibility_ratio`; an unknown ``on_empty``; empty alone masks with
            ``on_empty="raise"``.
    """
    if on_empty not in ("nan", "raise"):
        raise ValueError(f"on_empty must be 'nan' or 'raise', got {on_empty!r}")
    empty = [int(_check_label(lab)) for lab, m in alone_masks.items()
             if np.asarray(m).ndim == 2 and not np.asarray(m).any()]
    if empty:
        msg = (f"alone mask of label(s) {empty} is empty: those bodies are not in view, their "
               "visibility ratio is undefined")
        if on_empty == "raise":
            raise ValueError(msg)
        warnings.warn(msg + " (NaN)", RuntimeWarning, stacklevel=2)
    return {int(lab): (math.nan if int(lab) in empty else
                       visibility_ratio(scene_mask, m, int(lab), on_outside, stray))
            for lab, m in alone_masks.items()}


def vr_bin_index(vr, bins=VR_BINS):
    """Index of the visibility-ratio bin of each value, -1 when it falls in none (vectorised).

    The one definition of the bin rule. Bins are half open ``[low, high)`` except the last, which
    is closed ``[low, high]``: with the paper's bins 0.4 -> 0, 0.6 -> 1, 0.95 -> 3, 1.0 -> 3,
    0.39 -> -1, NaN -> -1. Because a VR is a ratio of pixel counts computed in float64, values
    such as ``3/5`` or ``19/20`` equal the literals ``0.6`` and ``0.95`` exactly and fall in the
    upper bin.

    Args:
        vr: a float or an array of visibility ratios in [0, 1].
        bins: increasing, non-overlapping ``(low, high)`` pairs (default `VR_BINS`).

    Returns:
        An int for a scalar input, else an int64 array of the input's shape.
    """
    v = np.asarray(vr, dtype=np.float64)
    idx = np.full(v.shape, -1, dtype=np.int64)
    last = len(bins) - 1
    for k, (lo, hi) in enumerate(bins):
        inside = (v >= lo) & ((v <= hi) if k == last else (v < hi))
        idx[inside & (idx < 0)] = k
    return int(idx) if idx.ndim == 0 else idx


def vr_bin(vr: float, bins: tuple[tuple[float, float], ...] = VR_BINS) -> int:
    """Index of the VR bin holding one ``vr``, or -1 when it is in none (below 0.40, above 1,
    NaN); the scalar form of `vr_bin_index`."""
    return int(vr_bin_index(float(vr), bins))


class BalancedVRSampler:
    """Accept or reject a stream of candidate scenes so that every VR bin gets the same quota.

    The generator draws scenes whose target-hand VR it cannot choose in advance; most land in the
    high-VR bins. The sampler accepts a candidate when its bin still has room and rejects it
    otherwise (greedy, first come first served), so the accepted set is balanced as in the paper
    (equal numbers per bin). The decision depends only on the sequence of VRs offered: the same
    stream gives the same decisions.

    Args:
        per_bin: quota of each bin (``> 0``).
        bins: VR bins (default `VR_BINS`).

    Examples:
        >>> from handmesh_tutorial.visibility import BalancedVRSampler
        >>> s = BalancedVRSampler(per_bin=1)
        >>> [s.offer(v) for v in (0.99, 0.97, 0.3, 0.5, 0.7, 0.85)]  # 0.3 is in no bin
        [True, False, False, True, True, True]
        >>> s.full
        True
    """

    def __init__(self, per_bin: int, bins: tuple[tuple[float, float], ...] = VR_BINS):
        if int(per_bin) < 1:
            raise ValueError(f"per_bin must be >= 1, got {per_bin}")
        self.per_bin = int(per_bin)
        self.bins = tuple(bins)
        self.counts = [0] * len(self.bins)
        self.offered = 0

    def offer(self, vr: float) -> bool:
        """Decide about one candidate.

        Args:
            vr: the candidate's visibility ratio.

        Returns:
            ``True`` (accept; its bin count goes up) or ``False`` (reject: no bin, or bin full).
        """
        self.offered += 1
        b = vr_bin(vr, self.bins)
        if b < 0 or self.counts[b] >= self.per_bin:
            return False
        self.counts[b] += 1
        return True

    def wants(self, vr: float) -> bool:
        """Whether `offer` would accept ``vr`` now (no state change)."""
        b = vr_bin(vr, self.bins)
        return b >= 0 and self.counts[b] < self.per_bin

    @property
    def needed(self) -> list[int]:
        """Remaining places per bin."""
        return [self.per_bin - c for c in self.counts]

    @property
    def full(self) -> bool:
        """``True`` when every bin has reached its quota."""
        return all(c >= self.per_bin for c in self.counts)

    def __repr__(self) -> str:
        return (f"BalancedVRSampler(per_bin={self.per_bin}, counts={self.counts}, "
                f"offered={self.offered})")


def balanced_indices(vrs: Iterable[float], per_bin: int,
                     bins: tuple[tuple[float, float], ...] = VR_BINS) -> list[int]:
    """Indices of a balanced subset of a list of VRs (the first ``per_bin`` of each bin).

    Args:
        vrs: candidate visibility ratios, in stream order.
        per_bin: quota of each bin.
        bins: VR bins (default `VR_BINS`).

    Returns:
        Increasing indices of the accepted candidates (fewer than ``per_bin`` in a bin when the
        stream did not hold enough).
    """
    s = BalancedVRSampler(per_bin, bins)
    return [i for i, v in enumerate(vrs) if s.offer(v)]
