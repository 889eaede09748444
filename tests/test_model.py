"""Tests of handmesh_tutorial.nn.model: MSMRNet assembly, outputs, templates, state-dict round
trip."""

import numpy as np
import pytest
import torch
import trimesh

from handmesh_tutorial.nn import model as M
from handmesh_tutorial.nn.blocks import CoarseMeshTransformer
from handmesh_tutorial.nn.decoder import MultiPathDecoder, SinglePathDecoder
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy

torch.set_num_threads(1)

SMALL = (4, 4, 8, 8, 8)


@pytest.fixture(scope="module")
def sphere():
    """An icosphere template with a random row-stochastic 21-joint regressor, and its hierarchy."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(0)
    jr = rng.random((21, len(mesh.vertices)))
    jr /= jr.sum(1, keepdims=True)
    tmpl = M.MeshTemplate(np.asarray(mesh.vertices) * 0.05, np.asarray(mesh.faces), jr)
    h = mesh_hierarchy(tmpl.vertices, tmpl.faces, use_cache=False)
    return tmpl, h


def _build(sphere, **kw):
    tmpl, h = sphere
    kw.setdefault("channels", SMALL)
    kw.setdefault("latent_channels", 8)
    return M.build_model(template=tmpl, hierarchy=h, **kw)


@pytest.mark.parametrize("decoder,attention", [("multi", True), ("single", False)])
def test_model_forward_shapes_joints_and_names(sphere, decoder, attention):
    torch.manual_seed(0)
    net = _build(sphere, decoder=decoder, attention=attention).eval()
    names = dict(net.named_children())
    assert {"encoder", "latent_to_mesh", "transformer", "decoder"} <= set(names)
    assert isinstance(net.decoder, MultiPathDecoder if decoder == "multi" else SinglePathDecoder)
    assert isinstance(net.transformer, CoarseMeshTransformer if attention else torch.nn.Identity)
    with torch.no_grad():
        out = net(torch.randn(2, 3, 64, 64))
        big = net(torch.randn(1, 3, 224, 224))
    v = len(sphere[0].vertices)
    assert out["vertices"].shape == (2, v, 3) and out["joints"].shape == (2, 21, 3)
    assert big["vertices"].shape == (1, v, 3) and big["joints"].shape == (1, 21, 3)
    jr = torch.from_numpy(sphere[0].joint_regressor).float()
    torch.testing.assert_close(out["joints"], torch.einsum("jv,bvc->bjc", jr, out["vertices"]))
    assert torch.isfinite(out["vertices"]).all()


def test_model_backward_reaches_every_part(sphere):
    net = _build(sphere, zero_head=False)
    out = net(torch.randn(2, 3, 64, 64))
    (out["vertices"].abs().mean() + out["joints"].abs().mean()).backward()
    for part in ("encoder", "latent_to_mesh", "transformer", "decoder"):
        grads = [p.grad for p in getattr(net, part).parameters()]
        assert all(g is not None and torch.isfinite(g).all() for g in grads), part
        assert sum(g.abs().sum() for g in grads) > 0, part


def test_fc_output_matches_coarse_mesh(sphere):
    tmpl, h = sphere
    net = _build(sphere)
    assert net.coarse_vertices == h.num_vertices[-1]
    assert net.latent_to_mesh.out_features == h.num_vertices[-1] * 8
    assert net.latent_to_mesh.in_features == net.encoder.out_features == 512


def test_weights_only_state_dict_round_trip(sphere, tmp_path):
    torch.manual_seed(0)
    net = _build(sphere, zero_head=False).eval()
    path = tmp_path / "model.pt"
    torch.save(net.state_dict(), path)
    sd = torch.load(path, weights_only=True)
    assert not any("index" in k or "indices" in k or "joint_regressor" in k
                   or k.startswith("template") for k in sd)
    torch.manual_seed(1)
    other = _build(sphere, zero_head=False).eval()
    x = torch.randn(1, 3, 64, 64)
    with torch.no_grad():
        assert not torch.allclose(other(x)["vertices"], net(x)["vertices"])
        other.load_state_dict(sd)
        torch.testing.assert_close(other(x)["vertices"], net(x)["vertices"])


def test_parameter_table_and_counts(sphere):
    net = _build(sphere)
    c = M.parameter_counts(net)
    assert c["total"] == sum(p.numel() for p in net.parameters())
    assert c["encoder"] + c["latent_to_mesh"] + c["transformer"] + c["decoder"] == c["total"]
    assert c["latent_to_mesh"] == 512 * net.coarse_vertices * 8 + net.coarse_vertices * 8
    table = M.parameter_table(net)
    for part in ("encoder", "latent_to_mesh", "transformer", "decoder", "total", "FC / decoder"):
        assert part in table
    assert f"{c['decoder']:,}" in table
    no_att = M.parameter_counts(_build(sphere, attention=False))
    assert no_att["transformer"] == 0 and no_att["decoder"] == c["decoder"]


def test_templates_in_every_form(sphere):
    tmpl, h = sphere
    as_dict = {"vertices": tmpl.vertices, "faces": tmpl.faces,
               "joint_regressor": tmpl.joint_regressor}
    for form in (as_dict, (tmpl.vertices, tmpl.faces, tmpl.joint_regressor)):
        t = M.as_template(form)
        np.testing.assert_array_equal(t.faces, tmpl.faces)
    with pytest.raises(ValueError, match="lacks keys"):
        M.as_template({"vertices": tmpl.vertices})
    with pytest.raises(ValueError, match=r"joint_regressor must be \(J, 642\)"):
        M.as_template((tmpl.vertices, tmpl.faces, tmpl.joint_regressor[:, :10]))
    with pytest.raises(ValueError, match="face ids"):
        M.as_template((tmpl.vertices, tmpl.faces + 1000, tmpl.joint_regressor))
    with pytest.raises(ValueError, match="decoder must be 'multi' or 'single'"):
        _build(sphere, decoder="double")


def test_custom_encoder_module(sphere):
    class Tiny(torch.nn.Module):
        out_features = 6

        def forward(self, x):
            return x.mean((2, 3)).repeat(1, 2)

    net = _build(sphere, encoder=Tiny())
    assert net(torch.randn(2, 3, 32, 32))["vertices"].shape == (2, 642, 3)
    with pytest.raises(ValueError, match="out_features"):
        _build(sphere, encoder=torch.nn.Identity())


def test_default_template_is_the_open_hand():
    from handmesh_tutorial.hand import HandModel

    hand = HandModel("right")
    net = M.build_model(channels=SMALL, latent_channels=8).eval()
    assert net.faces.shape == hand.faces.shape
    with torch.no_grad():
        out = net(torch.randn(1, 3, 64, 64))
    assert out["vertices"].shape == (1, hand.num_vertices, 3)
    assert out["joints"].shape == (1, 21, 3)


@pytest.mark.parametrize("decoder", ["multi", "single"])
@pytest.mark.parametrize("output", ["affine", "offset"])
def test_output_at_initialisation_is_the_root_centred_template(sphere, decoder, output):
    tmpl, _ = sphere
    net = _build(sphere, decoder=decoder, output=output).eval()
    with torch.no_grad():
        out = net(torch.randn(2, 3, 64, 64))
    want = torch.as_tensor(M.root_centred_template(tmpl), dtype=torch.float32)
    torch.testing.assert_close(out["vertices"], want.expand(2, -1, -1))
    # centred on the template's joint 9 (the root of the training targets)
    torch.testing.assert_close(out["joints"][:, 9], torch.zeros(2, 3), atol=1e-6, rtol=0)


def test_vertices_from_field_parameterisations(sphere):
    tmpl, _ = sphere
    p = torch.as_tensor(M.root_centred_template(tmpl), dtype=torch.float32)
    v = len(p)
    rot = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    shift = torch.tensor([0.01, -0.02, 0.03])
    affine = _build(sphere, output="affine", smoothing_length=0.0)
    raw = torch.cat([(rot - torch.eye(3)).reshape(9), shift / affine.output_scale])
    got = affine.vertices_from_field(raw.expand(1, v, 12))
    # a constant field is a rigid motion of the whole template
    torch.testing.assert_close(got[0], p @ rot.T + shift)
    offset = _build(sphere, output="offset")
    d = torch.randn(1, v, 3)
    torch.testing.assert_close(offset.vertices_from_field(d), p + 0.1 * d)
    xyz = _build(sphere, output="xyz")
    torch.testing.assert_close(xyz.vertices_from_field(d), 0.1 * d)
    assert affine.decoder.head.out_features == 12 and xyz.decoder.head.out_features == 3
    with pytest.raises(ValueError, match="output must be one of"):
        _build(sphere, output="mesh")


def test_output_smoothing_follows_the_length(sphere):
    tmpl, _ = sphere
    from handmesh_tutorial.nn.smoothing import mean_edge_length

    e = mean_edge_length(tmpl.vertices, tmpl.faces)
    assert isinstance(_build(sphere, smoothing_length=0.0).smoothing, torch.nn.Identity)
    net = _build(sphere, smoothing_length=e)  # sigma = e: two steps, applied one by one
    assert len(net.smoothing) == 2
    dense = (net.smoothing[1].to_dense() @ net.smoothing[0].to_dense()).double()
    from handmesh_tutorial.nn.smoothing import smoothing_matrix

    want = torch.from_numpy(smoothing_matrix(tmpl.faces, 2).toarray())
    torch.testing.assert_close(dense, want, rtol=1e-6, atol=1e-7)
    # a smoothed constant (rigid) field is unchanged: the template still comes out at init
    torch.testing.assert_close(dense.sum(1), torch.ones(len(dense), dtype=torch.float64))


def _set_sparse_method(net, method):
    from handmesh_tutorial.nn.blocks import SparseVertexMap
    maps = [m for m in net.modules() if isinstance(m, SparseVertexMap) and not m.is_selection]
    for m in maps:
        m.method = method
    return len(maps)


@pytest.mark.parametrize("decoder", ["multi", "single"])
def test_fast_sparse_maps_give_the_reference_outputs_and_gradients(sphere, decoder):
    # the CSR products (default) against the original gather-and-sum formulation, through the
    # whole network (decoder maps, fusion, output smoothing), forward and backward, float64
    torch.manual_seed(0)
    net = _build(sphere, decoder=decoder, zero_head=False, keypoints=True,
                 global_rotation=True).double()
    x = torch.randn(2, 3, 64, 64, dtype=torch.float64)
    results = {}
    for method in ("gather", "csr"):
        assert _set_sparse_method(net, method) > 0
        net.zero_grad()
        out = net(x)
        (out["vertices"].pow(2).mean() + out["joints"].abs().mean() + out["uv"].mean()).backward()
        results[method] = ({k: v.detach() for k, v in out.items()},
                           {n: p.grad.clone() for n, p in net.named_parameters()})
    (out_g, grad_g), (out_c, grad_c) = results["gather"], results["csr"]
    for k in out_g:
        torch.testing.assert_close(out_c[k], out_g[k], rtol=1e-12, atol=1e-14)
    for n in grad_g:
        torch.testing.assert_close(grad_c[n], grad_g[n], rtol=1e-10, atol=1e-14, msg=n)
    # float32 and bfloat16 autocast (the training option) run through the CSR path too
    net = net.float()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out16 = net(x.float())
    assert torch.isfinite(out16["vertices"].float()).all()
    err = (out16["vertices"].float() - out_g["vertices"].float()).norm()
    # bfloat16 keeps 8 significant bits; through ~20 random layers about 7 % here
    assert err < 0.2 * out_g["vertices"].float().norm()
