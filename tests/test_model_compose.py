"""Tests of the composable model: ``conv=`` hooks in the blocks and decoders, output modules and
heads one can pass, and ``ModelConfig`` presets, against digests of the networks that
``build_model`` made before these hooks existed (``fixtures/model_reference.json``)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy

torch.set_num_threads(1)

REFERENCE = Path(__file__).parent / "fixtures" / "model_reference.json"


class TinyEncoder(torch.nn.Module):
    """A small learned image encoder: conv, global pooling, ``(B, 3, H, W) -> (B, 16)``."""

    out_features = 16

    def __init__(self):
        super().__init__()
        self.conv = torch.nn.Conv2d(3, 16, 3, stride=2)

    def forward(self, x):
        return self.conv(x).mean((2, 3))


def sphere_template():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(0)
    jr = rng.random((21, len(mesh.vertices)))
    jr /= jr.sum(1, keepdims=True)
    tmpl = M.MeshTemplate(np.asarray(mesh.vertices) * 0.05, np.asarray(mesh.faces), jr)
    return tmpl, mesh_hierarchy(tmpl.vertices, tmpl.faces, factors=(2, 2), use_cache=False)


# build_model arguments of each reference network (the encoder is TinyEncoder unless named)
CASES = {
    "default": {},
    "single-xyz-spiral": {"decoder": "single", "attention": False, "output": "xyz",
                          "head": "spiral", "zero_head": False},
    "multi-offset-fuse-2blocks": {"output": "offset", "fuse_head": True, "head": "spiral",
                                  "num_blocks": 2, "zero_head": False},
    "multi-pyramid-rotation": {"head": "pyramid", "global_rotation": True, "zero_head": False,
                               "spiral_length": 7, "dilation": 2},
    "resnet10-keypoints": {"encoder": "resnet10", "keypoints": True, "zero_head": False},
    "hand-skinned": {"output": "skinned", "zero_head": False},
}


def build_case(name: str, tmpl_h, **extra):
    tmpl, h = tmpl_h
    kw = dict(CASES[name])
    if kw.get("output") == "skinned":  # needs a hand with skinning weights
        from handmesh_tutorial.hand import HandModel

        tmpl, h = HandModel("right"), None
        kw["factors"] = (2, 2)
    torch.manual_seed(0)
    kw.setdefault("encoder", TinyEncoder())
    return M.build_model(template=tmpl, hierarchy=h, channels=(4, 8, 8), latent_channels=8,
                         **kw, **extra).eval()


def digest(net) -> dict:
    """SHA-256 of the state dict (keys, dtypes, shapes, bytes, in order) and of the outputs for
    a fixed input; parameter count."""
    h = hashlib.sha256()
    for k, v in net.state_dict().items():
        h.update(f"{k}{v.dtype}{tuple(v.shape)}".encode())
        h.update(v.detach().contiguous().numpy().tobytes())
    g = torch.Generator().manual_seed(1)
    x = torch.randn(2, 3, 32, 32, generator=g)
    with torch.no_grad():
        out = net(x)
    o = hashlib.sha256()
    for k in sorted(out):
        o.update(k.encode())
        o.update(out[k].contiguous().numpy().tobytes())
    return {"state_dict": h.hexdigest(), "outputs": o.hexdigest(),
            "parameters": sum(p.numel() for p in net.parameters())}


@pytest.fixture(scope="module")
def sphere():
    return sphere_template()


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_default_networks_are_bit_identical_to_the_recorded_ones(sphere, name):
    ref = json.loads(REFERENCE.read_text())
    if ref["torch"].split("+")[0] != torch.__version__.split("+")[0]:
        pytest.skip(f"reference recorded with torch {ref['torch']}, this is {torch.__version__}")
    assert digest(build_case(name, sphere)) == ref["cases"][name], name


if __name__ == "__main__":  # record the reference (run once, at a commit whose networks it pins)
    th = sphere_template()
    ref = {"torch": torch.__version__, "cases": {n: digest(build_case(n, th)) for n in CASES}}
    REFERENCE.write_text(json.dumps(ref, indent=1) + "\n")
    print(json.dumps(ref, indent=1))
