"""Tests of handmesh_tutorial.visibility: VR on hand-made and rendered masks, bins, sampling."""

from __future__ import annotations

import numpy as np
import pytest

from handmesh_tutorial import visibility as V


def _count(mask, value=True):
    """Independent pixel count by plain Python loops."""
    return sum(1 for row in mask.tolist() for x in row if x == value)


def test_vr_hand_made_masks():
    scene = np.zeros((6, 8), np.int32)
    alone1 = np.zeros((6, 8), bool)
    alone1[1:5, 1:6] = True  # 20 pixels
    scene[alone1] = 1
    scene[1:3, 4:7] = 2  # body 2 in front covers 2x2 pixels of body 1 (and 2 of background)
    expected = (_count(alone1) - 4) / _count(alone1)
    assert V.visibility_ratio(scene, alone1, 1) == pytest.approx(expected) == 16 / 20
    # the same with the alone mask given as a label mask
    assert V.visibility_ratio(scene, alone1.astype(np.uint8) * 1, 1) == 16 / 20
    alone2 = scene == 2
    assert V.visibility_ratio(scene, alone2, 2) == 1.0
    assert V.visibility_ratios(scene, {1: alone1, 2: alone2}) == {1: 0.8, 2: 1.0}


def test_vr_alone_is_one_and_in_unit_interval():
    rng = np.random.default_rng(0)
    for _ in range(50):
        alone = {lab: rng.random((12, 15)) < 0.4 for lab in (1, 2, 3)}
        scene = np.zeros((12, 15), np.int64)
        for lab in rng.permutation([1, 2, 3]):  # painter's order: later bodies are in front
            scene[alone[lab]] = lab
        vrs = V.visibility_ratios(scene, alone)
        for lab, vr in vrs.items():
            assert 0.0 <= vr <= 1.0
            assert vr == _count(scene, lab) / _count(alone[lab])
        lab = 2
        only = np.where(alone[lab], lab, 0)
        assert V.visibility_ratio(only, alone[lab], lab) == 1.0


def test_vr_errors():
    scene = np.zeros((4, 4), np.int32)
    alone = np.zeros((4, 4), bool)
    with pytest.raises(ValueError, match="label 5 is empty"):
        V.visibility_ratio(scene, alone, 5)
    with pytest.raises(ValueError, match=r"shape \(4, 4\) != alone_mask shape \(4, 5\)"):
        V.visibility_ratio(scene, np.ones((4, 5), bool), 1)
    with pytest.raises(ValueError, match="integer label mask"):
        V.visibility_ratio(scene.astype(bool), alone, 1)
    with pytest.raises(ValueError, match="2-D"):
        V.visibility_ratio(scene, np.ones(16, bool), 1)
    scene[0, :] = 1
    alone[0, :2] = True
    with pytest.raises(ValueError, match="2 visible scene pixels lie outside"):
        V.visibility_ratio(scene, alone, 1)
    with pytest.warns(RuntimeWarning, match="outside its alone mask"):
        assert V.visibility_ratio(scene, alone, 1, on_outside="warn") == 1.0
    assert V.visibility_ratio(scene, alone, 1, on_outside="ignore") == 1.0
    with pytest.raises(ValueError, match="on_outside"):
        V.visibility_ratio(scene, alone, 1, on_outside="clip")


def test_vr_stray_pixels_pass_as_jitter_up_to_their_share():
    """A GPU rasteriser flips some edge pixels between the scene and alone passes: ``stray``
    lets that share through, counted as hidden; beyond it ``on_outside`` applies."""
    scene = np.zeros((10, 10), np.int32)
    alone = np.zeros((10, 10), bool)
    alone[:5, :] = True  # 50 pixels alone
    scene[:4, :] = 1  # 40 visible inside
    scene[5, :2] = 1  # 2 stray pixels: 4 % of 50
    with pytest.raises(ValueError, match="2 visible scene pixels"):
        V.visibility_ratio(scene, alone, 1)
    assert V.visibility_ratio(scene, alone, 1, stray=0.04) == pytest.approx(40 / 50)
    with pytest.raises(ValueError, match="2 visible scene pixels"):
        V.visibility_ratio(scene, alone, 1, stray=0.03)
    assert V.visibility_ratios(scene, {1: alone}, stray=0.05) == {1: pytest.approx(0.8)}


def test_vr_bins_edges():
    assert V.VR_BINS == ((0.40, 0.60), (0.60, 0.80), (0.80, 0.95), (0.95, 1.00))
    cases = {0.0: -1, 0.3999: -1, 0.40: 0, 0.5999: 0, 0.60: 1, 0.7999: 1, 0.80: 2, 0.9499: 2,
             0.95: 3, 0.99: 3, 1.0: 3, 1.0001: -1, float("nan"): -1}
    for vr, b in cases.items():
        assert V.vr_bin(vr) == b, vr
    # ratios of pixel counts hit the edges exactly
    assert V.vr_bin(3 / 5) == 1 and V.vr_bin(19 / 20) == 3 and V.vr_bin(4 / 5) == 2
    assert V.vr_bin(2 / 5) == 0


def test_balanced_sampler_fills_equal_quotas():
    rng = np.random.default_rng(1)
    stream = rng.beta(5, 1, size=5000)  # skewed to high VR, like real scenes
    s = V.BalancedVRSampler(per_bin=25)
    accepted = [v for v in stream if s.offer(v)]
    assert s.full and s.needed == [0, 0, 0, 0]
    bins = np.array([V.vr_bin(v) for v in accepted])
    assert np.bincount(bins, minlength=4).tolist() == [25, 25, 25, 25]
    assert not s.wants(0.99) and not s.offer(0.5)
    # deterministic, and balanced_indices makes the same decisions
    idx = V.balanced_indices(stream, 25)
    assert [stream[i] for i in idx] == accepted
    assert V.balanced_indices(stream, 25) == idx
    with pytest.raises(ValueError, match="per_bin"):
        V.BalancedVRSampler(0)
    # the docstring example
    s1 = V.BalancedVRSampler(per_bin=1)
    assert [s1.offer(v) for v in (0.99, 0.97, 0.3, 0.5, 0.7, 0.85)] == [
        True, False, False, True, True, True]
    assert s1.full and s1.offered == 6


def test_vr_on_rendered_scene():
    trimesh = pytest.importorskip("trimesh")
    from handmesh_tutorial import render as R

    sph = trimesh.creation.icosphere(2, radius=0.03)
    box = trimesh.creation.box(extents=(0.08, 0.08, 0.02))
    meshes = [(sph.vertices + [0.0, 0.0, 0.4], sph.faces, np.ones((len(sph.vertices), 3)), 1),
              (box.vertices + [0.02, 0.0, 0.5], box.faces, np.ones((len(box.vertices), 3)), 2)]
    K = R.intrinsics(100.0, 100.0, 31.5, 31.5)
    with R.Renderer(64) as r:
        out = r.render(meshes, K, color=False, alone=True)
    vrs = V.visibility_ratios(out.labels, out.alone_masks)
    a1, a2 = out.alone_masks[1], out.alone_masks[2]
    assert vrs[1] == 1.0
    assert vrs[2] == pytest.approx(_count(a2 & ~a1) / _count(a2))
    assert 0.2 < vrs[2] < 0.95


def test_vr_image_masks_labels_and_an_empty_body_among_others():
    # issue 43 item 15: a 0/255 mask read as "not in view", label 0 unchecked, one empty mask
    # failing every body of visibility_ratios
    scene = np.zeros((4, 6), np.int32)
    scene[:, :3] = 1
    alone255 = np.zeros((4, 6), np.uint8)
    alone255[:, :4] = 255
    with pytest.raises(ValueError, match=r"no pixel equal to label 1, but holds the values "
                                         r"\[0, 255\].*pass it as bool \(alone_mask > 0\)"):
        V.visibility_ratio(scene, alone255, 1)
    assert V.visibility_ratio(scene, alone255 > 0, 1) == 0.75
    for bad in (0, -1, 1.5, True, "1"):
        with pytest.raises(ValueError, match=r"label must be an integer >= 1 .* got"):
            V.visibility_ratio(scene, alone255 > 0, bad)
    with pytest.raises(ValueError, match="stray must be a share in"):
        V.visibility_ratio(scene, alone255 > 0, 1, stray=float("nan"))
    masks = {1: alone255 > 0, 2: np.zeros((4, 6), bool)}
    with pytest.warns(RuntimeWarning, match=r"label\(s\) \[2\] is empty"):
        vrs = V.visibility_ratios(scene, masks)
    assert vrs[1] == 0.75 and np.isnan(vrs[2])
    with pytest.raises(ValueError, match=r"label\(s\) \[2\] is empty"):
        V.visibility_ratios(scene, masks, on_empty="raise")
