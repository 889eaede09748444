"""Tests of handmesh_tutorial.nn.decoder: single- vs multi-path shapes, depth, gradients,
equivariance and overfitting posed hands."""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
import torch
import trimesh

from handmesh_tutorial.nn import decoder as dec
from handmesh_tutorial.nn.blocks import compose_up
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.spiral import SpiralConv

torch.set_num_threads(1)

SMALL = (4, 4, 8, 8, 8)  # smoke-size channels per level, finest first


@pytest.fixture(scope="module")
def hier():
    """A 5-level hierarchy of an icosphere (642 -> 321 -> 161 -> 81 -> 41) and its spirals."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    h = mesh_hierarchy(mesh.vertices, mesh.faces, use_cache=False)
    return SimpleNamespace(down=h.down, up=h.up, faces=h.faces, spirals=dec.hierarchy_spirals(h, 9),
                           sizes=h.num_vertices)


def _make(kind, hier, channels=SMALL, **kw):
    cls = dec.MultiPathDecoder if kind == "multi" else dec.SinglePathDecoder
    return cls(hier, hier.spirals, channels, **kw)


@pytest.mark.parametrize("kind,kw", [("single", {}), ("multi", {}), ("multi", {"fuse_head": True}),
                                     ("single", {"in_channels": 5, "num_blocks": 2}),
                                     ("single", {"head": "spiral"}), ("multi", {"head": "pyramid"}),
                                     ("single", {"head": "pyramid", "out_channels": 12})])
def test_forward_backward_shapes_and_finite_grads(hier, kind, kw):
    torch.manual_seed(0)
    d = _make(kind, hier, zero_head=False, **kw)
    x = torch.randn(2, hier.sizes[-1], kw.get("in_channels", SMALL[-1]), requires_grad=True)
    y = d(x)
    assert y.shape == (2, hier.sizes[0], kw.get("out_channels", 3))
    y.square().mean().backward()
    grads = [p.grad for p in d.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    # every parameter receives gradient (no dead branch, e.g. unused last-stage fusion outputs)
    assert all(g.abs().sum() > 0 for g in grads)


def test_multi_path_structure_follows_the_paper(hier):
    d = _make("multi", hier)
    n = len(hier.sizes)
    assert len(d.stages) == n  # five stages for a 5-level hierarchy
    # stage s holds the s coarsest levels, finest first; each adds the next finer resolution
    assert [st.levels for st in d.stages] == [list(range(n - 1 - s, n)) for s in range(n)]
    assert d.stages[0].fusion is None
    assert all(st.fusion is not None for st in d.stages[1:])
    assert d.stages[-1].out_levels == [0]  # last fusion only feeds the finest branch
    assert len(d.transitions) == n - 1


@pytest.mark.parametrize("num_blocks,head", [(1, "linear"), (2, "linear"), (1, "spiral")])
def test_single_and_multi_have_the_same_depth(hier, num_blocks, head):
    single = _make("single", hier, num_blocks=num_blocks, head=head)
    multi = _make("multi", hier, num_blocks=num_blocks, head=head)
    n = len(hier.sizes)
    assert single.depth == multi.depth == 2 * num_blocks * n + (head == "spiral")
    # Independent check for the single path: count SpiralConv calls in one forward pass.
    calls = []
    hooks = [m.register_forward_hook(lambda *a: calls.append(1))
             for m in single.modules() if isinstance(m, SpiralConv)]
    single(torch.randn(1, hier.sizes[-1], SMALL[-1]))
    for h in hooks:
        h.remove()
    assert len(calls) == single.depth
    # The multi path runs more convs in total (parallel branches) but not in sequence.
    assert dec.count_spiral_convs(multi) > multi.depth


def _permuted(hier, seed=0):
    rng = np.random.default_rng(seed)
    perms = [rng.permutation(n) for n in hier.sizes]
    invs = [np.argsort(p) for p in perms]
    down = [sp.csr_matrix(d)[perms[l + 1]][:, perms[l]] for l, d in enumerate(hier.down)]
    up = [sp.csr_matrix(u)[perms[l]][:, perms[l + 1]] for l, u in enumerate(hier.up)]
    spirals = [inv[s[p]] for s, p, inv in zip(hier.spirals, perms, invs, strict=True)]
    return SimpleNamespace(down=down, up=up, spirals=spirals, sizes=hier.sizes), perms


@pytest.mark.parametrize("kind", ["single", "multi"])
def test_decoders_are_equivariant_to_vertex_relabelling(hier, kind):
    perm_h, perms = _permuted(hier, seed=4)
    torch.manual_seed(0)
    kw = {"fuse_head": True} if kind == "multi" else {"head": "spiral"}
    d = _make(kind, hier, zero_head=False, **kw)
    d_p = _make(kind, perm_h, zero_head=False, **kw)
    d_p.load_state_dict(d.state_dict())
    x = torch.randn(2, hier.sizes[-1], SMALL[-1])
    y = d(x)
    y_p = d_p(x[:, torch.from_numpy(perms[-1])])
    torch.testing.assert_close(y_p, y[:, torch.from_numpy(perms[0])], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("kind", ["single", "multi"])
@pytest.mark.parametrize("head", dec.HEADS)
def test_zero_head_outputs_zero_and_still_learns(hier, kind, head):
    torch.manual_seed(0)
    d = _make(kind, hier, head=head)
    x = torch.randn(2, hier.sizes[-1], SMALL[-1])
    y = d(x)
    assert torch.equal(y, torch.zeros_like(y))
    y.sum().backward()
    head_grads = [p.grad for p in d.head.parameters()]
    assert any(g is not None and g.abs().sum() > 0 for g in head_grads)


def test_pyramid_head_sums_upsampled_levels(hier):
    torch.manual_seed(0)
    d = _make("single", hier, head="pyramid", zero_head=False)
    feats = [torch.randn(1, n, c) for n, c in zip(hier.sizes, SMALL, strict=True)]
    want = d.head.linears[0](feats[0])
    for lv in range(1, len(feats)):
        up = torch.from_numpy(compose_up(hier.up, 0, lv).toarray()).float()
        want = want + up @ d.head.linears[lv](feats[lv])
    torch.testing.assert_close(d.head(feats), want, rtol=1e-4, atol=1e-5)


def test_decoder_input_and_config_errors(hier):
    d = _make("single", hier)
    with pytest.raises(ValueError, match=r"expected coarse features \(B, 41, 8\)"):
        d(torch.zeros(1, 40, 8))
    with pytest.raises(ValueError, match="channels has 4 entries but there are 5 levels"):
        _make("multi", hier, channels=(4, 4, 8, 8))
    bad = SimpleNamespace(down=hier.down, up=hier.up[:1] + hier.up[2:] + hier.up[1:2],
                          spirals=hier.spirals)
    with pytest.raises(ValueError, match=r"up\[1\] has shape"):
        dec.MultiPathDecoder(bad, hier.spirals, SMALL)
    with pytest.raises(ValueError, match="head must be one of"):
        _make("single", hier, head="conv")
    with pytest.raises(ValueError, match="exclude each other"):
        _make("multi", hier, head="pyramid", fuse_head=True)


# ----------------------------------------------------------------------------------------------
# Overfitting: latent codes -> posed hands of the library's hand model
# ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def hand_targets():
    from handmesh_tutorial.hand import HandModel

    hand = HandModel("right")
    rng = np.random.default_rng(0)
    pose = torch.from_numpy(rng.normal(scale=0.25, size=(4, 15, 3))).float()
    verts = hand(pose=pose).vertices
    verts = verts - verts.mean(1, keepdim=True)
    h = mesh_hierarchy(hand.template_vertices, hand.faces)
    spirals = dec.hierarchy_spirals(h, 9)
    return SimpleNamespace(h=h, spirals=spirals, verts=verts)


def _overfit(kind, data, steps=120, seed=0):
    torch.manual_seed(seed)
    channels = (8, 8, 16, 16, 16)
    cls = dec.MultiPathDecoder if kind == "multi" else dec.SinglePathDecoder
    decoder = cls(data.h, data.spirals, channels, in_channels=8)
    n, vc = len(data.verts), len(data.spirals[-1])
    codes = torch.randn(n, 16)
    fc = torch.nn.Linear(16, vc * 8)
    params = [*decoder.parameters(), *fc.parameters()]
    opt = torch.optim.Adam(params, lr=3e-3)
    losses = []
    for _ in range(steps):
        pred = decoder(fc(codes).reshape(n, vc, 8)) * 0.1
        loss = (pred - data.verts).abs().mean()  # the paper's L1 vertex loss, metres
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    return losses


@pytest.mark.parametrize("kind", ["single", "multi"])
def test_decoders_overfit_posed_hands(hand_targets, kind):
    losses = _overfit(kind, hand_targets)
    assert np.isfinite(losses).all()
    assert losses[-1] < losses[0] / 10, f"{kind}: loss {losses[0]:.4f} -> {losses[-1]:.4f}"
