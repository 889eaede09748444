"""Tests of the composable model: ``conv=`` hooks in the blocks and decoders, output modules and
heads one can pass, and ``ModelConfig`` presets, against digests of the networks that
``build_model`` made before these hooks existed (``fixtures/model_reference.json``)."""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from fingerprints import differences, fingerprint

from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn import outputs as O
from handmesh_tutorial.nn.config import ModelConfig
from handmesh_tutorial.nn.decoder import MultiPathDecoder, SinglePathDecoder
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.keypoints import KeypointEncoder
from handmesh_tutorial.nn.spiral import SpiralConv

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
    kw = {**CASES[name], **extra}
    if kw.get("output") == "skinned":  # needs a hand with skinning weights
        from handmesh_tutorial.hand import HandModel

        tmpl, h = HandModel("right"), None
        kw["factors"] = (2, 2)
    torch.manual_seed(0)
    kw.setdefault("encoder", TinyEncoder())
    return M.build_model(template=tmpl, hierarchy=h, channels=(4, 8, 8), latent_channels=8,
                         **kw).eval()


def digest(net) -> dict:
    """SHA-256 of the state dict (keys, dtypes, shapes, bytes, in order) and of the outputs for
    a fixed input; parameter count. Bit for bit: only for comparing two networks built in the
    same process (the recorded reference is compared by ``fingerprints``)."""
    h = hashlib.sha256()
    for k, v in net.state_dict().items():
        h.update(f"{k}{v.dtype}{tuple(v.shape)}".encode())
        h.update(v.detach().contiguous().numpy().tobytes())
    o = hashlib.sha256()
    for k, v in sorted(fixed_outputs(net).items()):
        o.update(k.encode())
        o.update(v.contiguous().numpy().tobytes())
    return {"state_dict": h.hexdigest(), "outputs": o.hexdigest(),
            "parameters": sum(p.numel() for p in net.parameters())}


def fixed_outputs(net) -> dict:
    """The network's outputs for a fixed random input ``(2, 3, 32, 32)``."""
    g = torch.Generator().manual_seed(1)
    x = torch.randn(2, 3, 32, 32, generator=g)
    with torch.no_grad():
        return dict(net(x))


def reference_entry(net) -> dict:
    """What ``fixtures/model_reference.json`` records of a network, in numbers that survive a
    change of CPU (``fingerprints``): the parameter count, the state dict's and the outputs'
    fingerprints."""
    return {"parameters": sum(p.numel() for p in net.parameters()),
            "state_dict": fingerprint(net.state_dict()),
            "outputs": fingerprint(fixed_outputs(net))}


@pytest.fixture(scope="module")
def sphere():
    return sphere_template()


@pytest.mark.recorded
@pytest.mark.parametrize("name", sorted(CASES))
def test_the_default_networks_are_the_recorded_ones(sphere, name):
    """Same parameters, buffers and outputs as the networks ``build_model`` made before the
    hooks existed: names, shapes, dtypes and integer buffers exactly, floats to the spread of
    CPU kernels (``fingerprints.KERNEL_RTOL``), on any x86-64 CPU."""
    ref = json.loads(REFERENCE.read_text())
    if ref["torch"].split("+")[0] != torch.__version__.split("+")[0]:
        pytest.skip(f"reference recorded with torch {ref['torch']}, this is {torch.__version__}")
    got, want = reference_entry(build_case(name, sphere)), ref["cases"][name]
    assert got["parameters"] == want["parameters"], name
    problems = (differences(got["state_dict"], want["state_dict"])
                + differences(got["outputs"], want["outputs"]))
    assert not problems, f"{name}: " + "; ".join(problems[:5])


@pytest.mark.recorded
def test_the_reference_check_sees_a_changed_network(sphere):
    """The fingerprint comparison is not blind: one weight moved by 1 % of its tensor's norm,
    or the outputs of another seed's initialisation, are reported."""
    ref = json.loads(REFERENCE.read_text())["cases"]["default"]
    net = build_case("default", sphere)
    key, w = next((k, v) for k, v in net.state_dict().items() if v.dtype.is_floating_point
                  and v.numel() > 10)
    with torch.no_grad():
        w.view(-1)[0] += 0.01 * w.norm()
    assert any(p.startswith(key) for p in differences(reference_entry(net)["state_dict"],
                                                      ref["state_dict"]))
    # another seed, on a case whose head is not zeroed (the default's outputs are the template)
    torch.manual_seed(1)
    other = M.build_model(template=sphere[0], hierarchy=sphere[1], channels=(4, 8, 8),
                          latent_channels=8, encoder=TinyEncoder(),
                          **CASES["single-xyz-spiral"]).eval()
    recorded = json.loads(REFERENCE.read_text())["cases"]["single-xyz-spiral"]
    assert differences(reference_entry(other)["outputs"], recorded["outputs"])


def record_reference(path: Path = REFERENCE) -> None:
    """Write ``fixtures/model_reference.json`` from the networks built now (run this file as a
    script, only when a change of the networks is intended)."""
    tmpl_h = sphere_template()
    cases = {name: reference_entry(build_case(name, tmpl_h)) for name in sorted(CASES)}
    lines = [f'{{"torch": {json.dumps(torch.__version__)}, "cases": {{']
    for i, (name, entry) in enumerate(cases.items()):
        lines.append(f' {json.dumps(name)}: {{"parameters": {entry["parameters"]},')
        for j, part in enumerate(("state_dict", "outputs")):
            rows = [f"   {json.dumps(k)}: {json.dumps(v)}" for k, v in entry[part].items()]
            lines.append(f'  {json.dumps(part)}: {{\n' + ",\n".join(rows)
                         + ("},", "}}" + ("," if i < len(cases) - 1 else ""))[j])
    path.write_text("\n".join(lines) + "}}\n")  # one array per line: a change reads in a diff


# --- conv= hooks ----------------------------------------------------------------------------


class DepthwiseSpiralConv(torch.nn.Module):
    """A depthwise-separable spiral convolution (HandMesh's DSConv idea, written here): one weight
    per spiral position and input channel, summed over the spiral, then a per-vertex Linear."""

    def __init__(self, in_channels, out_channels, indices):
        super().__init__()
        idx = torch.as_tensor(np.asarray(indices), dtype=torch.long)
        self.register_buffer("indices", idx, persistent=False)
        self.depthwise = torch.nn.Parameter(torch.randn(idx.shape[1], in_channels) * 0.3)
        self.pointwise = torch.nn.Linear(in_channels, out_channels)

    def forward(self, x):
        b, v, c = x.shape
        g = x.index_select(1, self.indices.reshape(-1)).view(b, v, -1, c)
        return self.pointwise((g * self.depthwise).sum(2))


@pytest.mark.parametrize("name", ["default", "single-xyz-spiral", "multi-offset-fuse-2blocks"])
def test_the_default_conv_is_spiralconv_bit_for_bit(sphere, name):
    assert digest(build_case(name, sphere, conv=SpiralConv)) == digest(build_case(name, sphere))


@pytest.mark.parametrize("name", ["single-xyz-spiral", "multi-offset-fuse-2blocks"])
def test_a_custom_conv_is_used_everywhere_and_trains(sphere, name):
    made = []

    def conv(cin, cout, indices):
        made.append((cin, cout, np.shape(indices)))
        return DepthwiseSpiralConv(cin, cout, indices)

    plain = build_case(name, sphere)
    net = build_case(name, sphere, conv=conv).train()
    n_spiral = sum(isinstance(m, SpiralConv) for m in plain.modules())
    customs = [m for m in net.modules() if isinstance(m, DepthwiseSpiralConv)]
    # every spiral convolution (blocks, spiral head) became the custom one, none is left
    assert n_spiral > 0 and len(customs) == len(made) == n_spiral
    assert not any(isinstance(m, SpiralConv) for m in net.modules())
    assert isinstance(net.decoder.head, DepthwiseSpiralConv)
    assert net.decoder.depth == plain.decoder.depth > 0
    levels = {len(v) for v in sphere[1].vertices}
    assert {shape[0] for _, _, shape in made} <= levels and {s[1] for _, _, s in made} == {9}
    # a training step moves every custom conv's weights, through finite gradients
    before = [m.depthwise.detach().clone() for m in customs]
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    x = torch.randn(2, 3, 32, 32, generator=torch.Generator().manual_seed(2))
    out = net(x)
    (out["vertices"].pow(2).mean() + out["joints"].abs().mean()).backward()
    assert all(torch.isfinite(m.depthwise.grad).all() for m in customs)
    opt.step()
    assert all(not torch.equal(b, m.depthwise) for b, m in zip(before, customs, strict=True))


# --- ModelConfig ------------------------------------------------------------------------------


def test_a_config_builds_the_same_network_as_the_keywords(sphere):
    tmpl, h = sphere
    kw = dict(CASES["multi-pyramid-rotation"], channels=(4, 8, 8), latent_channels=8)
    torch.manual_seed(0)
    cfg = ModelConfig(encoder=TinyEncoder(), **kw)
    by_config = M.build_model(config=cfg, template=tmpl, hierarchy=h).eval()
    ref = digest(build_case("multi-pyramid-rotation", sphere))
    assert digest(by_config) == ref and by_config.config is cfg
    torch.manual_seed(0)
    positional = M.build_model(cfg.replace(encoder=TinyEncoder()), template=tmpl, hierarchy=h)
    assert digest(positional.eval()) == ref
    # the plain form round-trips through JSON into build_model's keywords
    plain = cfg.replace(encoder="resnet10").to_dict()
    assert ModelConfig(**json.loads(json.dumps(plain))) == cfg.replace(encoder="resnet10")
    with pytest.raises(ValueError, match=r"\['encoder'\] hold modules"):
        cfg.to_dict()


def test_presets_name_whole_architectures(sphere):
    tmpl, h = sphere
    assert ModelConfig.preset("default") == ModelConfig()
    paper = ModelConfig.preset("paper")
    assert paper.output == "xyz" and paper.smoothing_length == 0.0 and paper.decoder == "multi"
    cpu = ModelConfig.preset("cpu", global_rotation=False)
    assert (cpu.encoder, cpu.keypoints, cpu.output, cpu.global_rotation) == (
        "resnet10", True, "skinned", False)
    small = dict(encoder=TinyEncoder(), channels=(4, 8, 8), latent_channels=8)
    single = M.build_model(ModelConfig.preset("single-path", **small), template=tmpl, hierarchy=h)
    assert isinstance(single.decoder, SinglePathDecoder)
    assert isinstance(single.transformer, torch.nn.Identity)
    multi = M.build_model(ModelConfig.preset("multi-path", **small), template=tmpl, hierarchy=h)
    assert isinstance(multi.decoder, MultiPathDecoder)
    assert isinstance(multi.transformer, torch.nn.Identity)
    with pytest.raises(ValueError, match=r"unknown model preset 'tiny'; presets: \['cpu'"):
        ModelConfig.preset("tiny")


def test_config_values_are_checked_and_do_not_mix_with_keywords(sphere):
    with pytest.raises(ValueError, match="num_blocks must be a positive integer, got 0"):
        ModelConfig(num_blocks=0)
    with pytest.raises(ValueError, match="decoder must be 'multi' or 'single', got 'double'"):
        ModelConfig(decoder="double")
    with pytest.raises(ValueError, match="head must be one of"):
        ModelConfig(head="conv")
    with pytest.raises(ValueError, match="output must be one of"):
        ModelConfig(output="mesh")
    assert ModelConfig(channels=[4, 8]).channels == (4, 8)
    with pytest.raises(TypeError, match=r"config= and the keywords \['decoder'\].*replace"):
        M.build_model(config=ModelConfig(), decoder="single", template=sphere[0])


# --- output modules and heads one can pass ---------------------------------------------------


def test_an_output_module_passed_in_equals_the_named_output(sphere):
    tmpl, _ = sphere
    for kind, case in (("offset", "multi-offset-fuse-2blocks"), ("xyz", "single-xyz-spiral")):
        module = O.make_output(kind, tmpl, scale=0.1)
        net = build_case(case, sphere, output=module)
        assert net.vertex_output is module and net.output == kind
        assert digest(net) == digest(build_case(case, sphere))


def test_a_custom_output_module_sets_the_field_width_and_its_smoothing(sphere):
    class Scaled(torch.nn.Module):
        channels = 4  # xyz and a per-vertex gain

        def forward(self, field):
            return field[..., :3] * torch.sigmoid(field[..., 3:])

    net = build_case("default", sphere, output=Scaled())
    assert net.decoder.head.out_features == 4 and net.output == "Scaled"
    assert not isinstance(net.smoothing, torch.nn.Identity)  # smoothed by default
    Scaled.smooth_field = False
    assert isinstance(build_case("default", sphere, output=Scaled()).smoothing, torch.nn.Identity)
    out = net(torch.randn(1, 3, 32, 32))
    assert out["vertices"].shape == (1, len(sphere[0].vertices), 3)
    with pytest.raises(ValueError, match="needs an integer attribute channels"):
        build_case("default", sphere, output=torch.nn.Identity())
    with pytest.raises(ValueError, match=r"field must be \(B, 162, 12\), got \(1, 162, 3\)"):
        O.make_output("affine", sphere[0])(torch.zeros(1, 162, 3))


def test_a_rotation_head_and_a_keypoint_head_can_be_passed(sphere):
    class Quarter(torch.nn.Module):  # a fixed quarter turn about z
        def forward(self, features):
            r = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
            return r.expand(len(features), 3, 3)

    plain = build_case("single-xyz-spiral", sphere)
    turned = build_case("single-xyz-spiral", sphere, global_rotation=Quarter())
    assert isinstance(turned.rotation, Quarter)
    f = torch.randn(2, TinyEncoder.out_features)
    with torch.no_grad():
        a, b = plain.decode(f)["vertices"], turned.decode(f)["vertices"]
    torch.testing.assert_close(b, a @ Quarter()(f).transpose(1, 2))
    tmpl, h = sphere
    narrow = functools.partial(KeypointEncoder, width=32)
    net = M.build_model("resnet10", keypoints=narrow, template=tmpl, hierarchy=h,
                        channels=(4, 8, 8), latent_channels=8)
    assert isinstance(net.encoder, KeypointEncoder) and net.encoder.heatmaps.in_channels == 32
    assert net(torch.randn(1, 3, 64, 64))["uv"].shape == (1, 21, 2)


if __name__ == "__main__":  # record the reference (run once, at a commit whose networks it pins)
    th = sphere_template()
    ref = {"torch": torch.__version__, "cases": {n: digest(build_case(n, th)) for n in CASES}}
    REFERENCE.write_text(json.dumps(ref, indent=1) + "\n")
    print(json.dumps(ref, indent=1))


if __name__ == "__main__":
    record_reference()
