"""Training losses and the 2D keypoint head, against independent computations."""

import math

import numpy as np
import pytest
import torch

from handmesh_tutorial.metrics import procrustes_align
from handmesh_tutorial.nn import keypoints as KP
from handmesh_tutorial.nn import losses as L
from handmesh_tutorial.nn.encoder import resnet10
from handmesh_tutorial.render.camera import project

torch.set_num_threads(1)


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_similarity_align_recovers_a_similarity_and_matches_the_numpy_procrustes():
    rng = np.random.default_rng(0)
    target = rng.normal(size=(4, 21, 3))
    moved = np.stack([1.7 * t @ _rotation(i).T + rng.normal(size=3) for i, t in enumerate(target)])
    got = L.similarity_align(torch.tensor(moved), torch.tensor(target)).numpy()
    np.testing.assert_allclose(got, target, atol=1e-9)
    noisy = moved + 0.1 * rng.normal(size=moved.shape)
    got = L.similarity_align(torch.tensor(noisy, dtype=torch.float32),
                             torch.tensor(target, dtype=torch.float32)).numpy()
    want = procrustes_align(noisy, target, allow_reflection=False)
    np.testing.assert_allclose(got, want, atol=2e-5)


def test_aligned_joint_loss_ignores_pose_of_the_whole_hand_and_has_finite_gradients():
    rng = np.random.default_rng(1)
    target = torch.tensor(rng.normal(size=(3, 21, 3)), dtype=torch.float32)
    rot = torch.tensor(_rotation(5), dtype=torch.float32)
    assert float(L.aligned_joint_loss(0.5 * target @ rot.T + 2.0, target)) < 1e-5
    pred = (target + 0.05 * torch.randn(3, 21, 3)).requires_grad_()
    loss = L.aligned_joint_loss(pred, target)
    loss.backward()
    assert float(loss.detach()) > 0.005 and torch.isfinite(pred.grad).all()
    # a mirror image is not a similarity (proper rotations only): it keeps an error
    mirror = target * torch.tensor([-1.0, 1.0, 1.0])
    assert float(L.aligned_joint_loss(mirror, target)) > 0.1


def test_edge_and_normal_losses_on_one_folded_quad():
    # two triangles sharing edge (0, 1); the truth is flat in z = 0
    gt = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, -1, 0]]])
    faces = torch.tensor([[0, 1, 2], [1, 0, 3]])
    assert float(L.edge_length_loss(gt * 1.0, gt, faces)) == 0.0
    assert float(L.normal_loss(gt * 3.0, gt, faces)) == pytest.approx(0.0, abs=1e-7)
    pred = gt.clone()
    pred[0, 3, 2] = 1.0  # vertex 3 lifted: its triangle folds by 45 deg about edge (0, 1)
    # 5 unique edges; (1, 3) and (0, 3) grow from sqrt(2) / 1 to sqrt(3) / sqrt(2)
    want = ((math.sqrt(3) - math.sqrt(2)) + (math.sqrt(2) - 1.0)) / 5
    assert float(L.edge_length_loss(pred, gt, faces)) == pytest.approx(want, rel=1e-6)
    # 6 face edges: triangle 0 lies flat (0); in triangle 1 the edge (1, 0) is still in the
    # plane, (0, 3) and (3, 1) have |cos| = 1/sqrt(3) and 1/sqrt(2) with the normal (0, 0, 1)
    want = (1 / math.sqrt(2) + 1 / math.sqrt(3)) / 6
    assert float(L.normal_loss(pred, gt, faces)) == pytest.approx(want, rel=1e-6)


def test_normalised_keypoints_follow_the_crop_pixel_convention():
    size = 8
    K = torch.tensor([[[10.0, 0, 3.5], [0, 10.0, 3.5], [0, 0, 1]]])
    root = torch.tensor([[0.0, 0.0, 1.0]])
    # a point on the optical axis projects to pixel 3.5 (the crop's centre) -> 0
    joints = torch.zeros(1, 2, 3)
    joints[0, 1] = torch.tensor([-0.35, -0.35, 0.0])  # pixel (0, 0): the first pixel's centre
    uv = KP.normalised_keypoints(joints, root, K, size)
    np.testing.assert_allclose(uv[0, 0].numpy(), [0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(uv[0, 1].numpy(), [1 / size - 1] * 2, atol=1e-6)
    pix = project(joints[0] + root[0], K[0])
    np.testing.assert_allclose(((2 * pix + 1) / size - 1).numpy(), uv[0].numpy(), atol=1e-6)


def test_soft_argmax_of_a_peak_is_its_cell_centre_and_grid_sample_reads_that_cell():
    h = torch.full((1, 2, 4, 8), -1e4)
    h[0, 0, 1, 6] = 0.0
    h[0, 1, 3, 0] = 0.0
    uv = KP.soft_argmax(h)
    np.testing.assert_allclose(uv[0].numpy(), [[(2 * 6 + 1) / 8 - 1, (2 * 1 + 1) / 4 - 1],
                                               [(2 * 0 + 1) / 8 - 1, (2 * 3 + 1) / 4 - 1]],
                               atol=1e-6)
    fmap = torch.arange(32.0).view(1, 1, 4, 8)
    got = torch.nn.functional.grid_sample(fmap, uv.unsqueeze(2), align_corners=False)
    assert got.flatten().tolist() == [fmap[0, 0, 1, 6].item(), fmap[0, 0, 3, 0].item()]


def test_keypoint_encoder_shapes_and_errors():
    enc = KP.KeypointEncoder(resnet10(), num_joints=21, width=16, out_features=32)
    out = enc(torch.randn(2, 3, 64, 64))
    assert out["features"].shape == (2, 32) and out["uv"].shape == (2, 21, 2)
    assert out["uv"].abs().max() <= 1.0
    with pytest.raises(ValueError, match="needs a ResNet backbone"):
        KP.KeypointEncoder(torch.nn.Identity())
    with pytest.raises(ValueError, match=r"pred_uv \(2, 21, 2\) and target_uv \(2, 20, 2\)"):
        KP.keypoint_loss(out["uv"], torch.zeros(2, 20, 2))
