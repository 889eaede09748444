"""The global-rotation head: 6D <-> matrix, and the model turning its mesh by the head's R."""

import numpy as np
import pytest
import torch

from handmesh_tutorial.nn import rotation as R
from handmesh_tutorial.nn.model import build_model
from handmesh_tutorial.train.fit_probe import CodeEncoder

torch.set_num_threads(1)


def test_6d_gives_proper_rotations_and_round_trips():
    d6 = torch.randn(50, 6, dtype=torch.float64)
    m = R.rotation_6d_to_matrix(d6)
    eye = torch.eye(3, dtype=torch.float64).expand(50, 3, 3)
    torch.testing.assert_close(m.transpose(1, 2) @ m, eye)
    torch.testing.assert_close(torch.det(m), torch.ones(50, dtype=torch.float64))
    # the first column is the normalised first vector; the second lies in span(a, b)
    torch.testing.assert_close(m[:, :, 0], d6[:, :3] / d6[:, :3].norm(dim=1, keepdim=True))
    normal = torch.cross(d6[:, :3], d6[:, 3:], dim=1)
    assert float((m[:, :, 1] * normal).sum(1).abs().max()) < 1e-9
    torch.testing.assert_close(R.rotation_6d_to_matrix(R.matrix_to_rotation_6d(m)), m)
    with pytest.raises(ValueError, match=r"expected \(\.\.\., 6\), got \(2, 5\)"):
        R.rotation_6d_to_matrix(torch.zeros(2, 5))


def test_model_turns_its_mesh_about_the_root_by_the_heads_rotation():
    torch.manual_seed(0)
    net = build_model(CodeEncoder(8), "single", attention=False, global_rotation=True)
    codes = torch.randn(3, 8)
    out = net.decode(codes)
    tmpl = net.template
    torch.testing.assert_close(out["vertices"], tmpl.expand(3, -1, -1))  # identity at start
    q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    rot = torch.tensor(q * np.sign(np.linalg.det(q)), dtype=torch.float32)
    with torch.no_grad():
        net.rotation.linear.bias.copy_(R.matrix_to_rotation_6d(rot))
    out = net.decode(codes)
    torch.testing.assert_close(out["vertices"], (tmpl @ rot.T).expand(3, -1, -1), atol=1e-6,
                               rtol=1e-5)
    torch.testing.assert_close(out["joints"], (net.joint_regressor @ tmpl @ rot.T).expand(
        3, -1, -1), atol=1e-6, rtol=1e-5)
    plain = build_model(CodeEncoder(8), "single", attention=False)
    assert plain.rotation is None
