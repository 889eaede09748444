"""MANO as a torch module with the [`HandModel`][handmesh_tutorial.hand.model.HandModel] interface.

[`load_mano`][handmesh_tutorial.hand.mano.model.load_mano] reads a user's own ``MANO_RIGHT.pkl`` /
``MANO_LEFT.pkl`` (through
[`read_mano_pickle`][handmesh_tutorial.hand.mano.unpickler.read_mano_pickle]) and returns a
[`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]: same call signature, same
output type ([`HandOutput`][handmesh_tutorial.hand.model.HandOutput]: vertices (B,778,3), 21
FreiHAND-order joints, 16 MANO joints, joint transforms; float32, metres) and the same numpy
attributes. The skinning, joint orders, input checks and skin colours are the hand package's
(one copy for both models); the left-hand ``shapedirs`` fix and the fingertip conventions are
described in [`handmesh_tutorial.hand.mano`][handmesh_tutorial.hand.mano].

Taught in notebook 01 (the hand model); notebook 02 uses it for the LCS of a MANO hand.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch

from .._common import (
    _as_batch,
    _batch_size,
    _check_side,
    _keypoints21,
    _rest_keypoints,
    _translate,
)
from ..appearance import plain_skin_colors
from ..joints import _KEYPOINT_OF_MANO, MANO_TO_FREIHAND
from ..model import HandOutput
from ..skinning import axis_angle_to_matrix, lbs
from .unpickler import read_mano_pickle

__all__ = ["FINGERTIP_VERTEX_IDS", "MANO_KEYS", "ManoModel", "load_mano"]

FINGERTIP_VERTEX_IDS: dict[str, dict[str, tuple[int, ...]]] = {
    # smplx/vertex_ids.py, key 'mano' (same ids for both sides; HaMeR-family code).
    "smplx": {"right": (744, 320, 443, 554, 671), "left": (744, 320, 443, 554, 671)},
    # manopth/manolayer.py (hassony2/manopth): the left middle tip is 445.
    "manopth": {"right": (745, 317, 444, 556, 673), "left": (745, 317, 445, 556, 673)},
}
"""Fingertip vertex ids (thumb, index, middle, ring, pinky) per convention and side."""

MANO_KEYS: dict[str, tuple] = {
    "v_template": ("V", 3),
    "shapedirs": ("V", 3, None),
    "posedirs": ("V", 3, 135),
    "J_regressor": (16, "V"),
    "weights": ("V", 16),
    "kintree_table": (2, 16),
    "f": (None, 3),
}
"""Arrays [`load_mano`][handmesh_tutorial.hand.mano.model.load_mano] needs, with their expected
shapes: ``"V"`` = the number of vertices of ``v_template`` (778 in the official files; other meshes
in MANO
format also load), ``None`` = any size.
"""


def _check_shape(key: str, arr, expected: tuple, source: str) -> None:
    shape = tuple(arr.shape)
    if len(shape) != len(expected) or any(e is not None and e != s
                                         for e, s in zip(expected, shape, strict=True)):
        want = "x".join("*" if e is None else str(e) for e in expected)
        raise ValueError(f"{source}: key '{key}' has shape {shape}, expected {want}")


MAX_EXTENT_M = 1.0
"""Largest coordinate of a MANO file's rest hand, and largest shape or pose displacement per
unit parameter, metres: a hand is about 0.2 m long (a file in millimetres is refused)."""


def _checked_arrays(params: Mapping, source: str) -> dict:
    """The `MANO_KEYS` arrays of ``params`` as numeric numpy arrays (``J_regressor`` dense),
    refused by name unless their shapes fit, floats are finite and values plausible: the rest
    hand and the shape and pose displacements within `MAX_EXTENT_M`, skinning weights in
    [0, 1], faces indexing the vertices."""
    out = dict(params)
    for key in MANO_KEYS:
        if key not in params:
            raise ValueError(f"{source}: missing key '{key}' (keys: {sorted(params)})")
        a = params[key]
        a = a.toarray() if sp.issparse(a) else np.asarray(a)
        if a.dtype.kind not in "fiu":
            raise ValueError(f"{source}: key '{key}' must be a numeric array, got "
                             f"{type(params[key]).__name__} of dtype {a.dtype}")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ValueError(f"{source}: key '{key}' holds NaN or infinity")
        out[key] = a
    for key in ("hands_components", "hands_mean"):  # optional (PCA poses, the mean pose)
        if key in params:
            try:
                out[key] = np.asarray(params[key], dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise ValueError(f"{source}: key '{key}' must be a numeric array, got "
                                 f"{type(params[key]).__name__} ({e})") from None
            if not np.isfinite(out[key]).all():
                raise ValueError(f"{source}: key '{key}' holds NaN or infinity")
    if out["v_template"].ndim != 2:
        raise ValueError(f"{source}: key 'v_template' has shape {out['v_template'].shape}, "
                         "expected Vx3")
    nv = len(out["v_template"])
    for key, shape in MANO_KEYS.items():
        _check_shape(key, out[key], tuple(nv if e == "V" else e for e in shape), source)
    for key in ("v_template", "shapedirs", "posedirs"):
        big = float(np.abs(out[key]).max(initial=0.0))
        if big > MAX_EXTENT_M:
            raise ValueError(f"{source}: key '{key}' holds {big:.3g}, beyond +-{MAX_EXTENT_M:g} m "
                             "(MAX_EXTENT_M): MANO files store metres; a damaged or foreign file")
    w = out["weights"]
    if w.size and (w.min() < -1e-6 or w.max() > 1 + 1e-6):
        raise ValueError(f"{source}: key 'weights' holds values in [{w.min():.3g}, "
                         f"{w.max():.3g}], expected skinning weights in [0, 1]")
    rest = np.abs(out["J_regressor"] @ out["v_template"]).max(initial=0.0)
    if not rest <= MAX_EXTENT_M:
        raise ValueError(f"{source}: key 'J_regressor' puts a rest joint {rest:.3g} m from the "
                         f"origin, beyond {MAX_EXTENT_M:g} m (MAX_EXTENT_M)")
    f = out["f"]
    if f.dtype.kind not in "iu" or (f.size and (f.min() < 0 or f.max() >= nv)):
        raise ValueError(f"{source}: key 'f' must hold vertex ids in [0, {nv}), got dtype "
                         f"{f.dtype}, values {f.min(initial=0)}..{f.max(initial=0)}")
    return out


def _infer_side(path: Path) -> str | None:
    name = path.name.lower()
    if re.search(r"left", name):
        return "left"
    if re.search(r"right", name):
        return "right"
    return None


class ManoModel(torch.nn.Module):
    """MANO (Romero et al. 2017) as a torch module with the
    [`HandModel`][handmesh_tutorial.hand.model.HandModel] interface.

    Forward pass (all in metres, float32):

    1. shape blend: ``v_shaped = v_template + shapedirs · betas`` (778x3x10 · 10);
    2. joints: ``J = J_regressor @ v_shaped`` (16x778 · 778x3);
    3. pose blend: ``v_posed = v_shaped + posedirs · vec(R_k - I)`` over the 15 non-root joints
       (135 values, joint-major, row-major 3x3);
    4. linear blend skinning with ``weights`` (778x16) along ``kintree_table`` parents:
       ``G_k = G_parent(k) · [R_k | J_k - J_parent(k)]``, ``v = Σ_k w_k G_k [v_posed - J_k]``;
    5. ``transl`` is added; ``joints_mano`` are the posed joint centres ``G_k[:3, 3]``; the 21
       keypoints are these 16 plus the 5 fingertip vertices, in FreiHAND order.

    Usually built with [`load_mano`][handmesh_tutorial.hand.mano.model.load_mano]. Attributes mirror
    [`HandModel`][handmesh_tutorial.hand.model.HandModel].

    Args:
        params: dict with the [`MANO_KEYS`][handmesh_tutorial.hand.mano.model.MANO_KEYS] arrays (as
            returned by
            [`read_mano_pickle`][handmesh_tutorial.hand.mano.unpickler.read_mano_pickle]);
            ``hands_components`` (45x45) and ``hands_mean`` (45,) are needed for PCA poses or
            ``flat_hand_mean=False``.
        side: ``"right"`` or ``"left"``.
        use_pca: if True, ``pose`` holds ``num_pca_comps`` PCA coefficients (B, num_pca_comps) and
            the full pose is ``coeffs @ hands_components[:num_pca_comps]``.
        num_pca_comps: number of PCA components used when ``use_pca`` (1..45).
        flat_hand_mean: if True (default), zero pose is the flat template hand; if False, MANO's
            mean pose ``hands_mean`` is added to the 45 pose values (as smplx and manopth do with
            ``flat_hand_mean=False``), so zero pose is the relaxed, slightly curled mean hand.
        fingertips: ``"smplx"`` (default) or ``"manopth"`` fingertip vertex convention (see
            [`FINGERTIP_VERTEX_IDS`][handmesh_tutorial.hand.mano.model.FINGERTIP_VERTEX_IDS]), or an
            explicit 5-tuple (thumb, index, middle, ring, pinky).
        fix_left_shapedirs: flip ``shapedirs[:, 0, :]`` (left-hand fix, see the module text);
            ``None`` = do it for ``side="left"`` only.
        source: name used in error messages.

    Raises:
        ValueError: a key is missing or has the wrong shape, or an option is invalid.
    """

    def __init__(self, params: Mapping, side: str = "right", *, use_pca: bool = False,
                 num_pca_comps: int = 45, flat_hand_mean: bool = True,
                 fingertips: str | tuple = "smplx", fix_left_shapedirs: bool | None = None,
                 source: str = "<MANO params>"):
        super().__init__()
        _check_side(side)
        params = _checked_arrays(params, source)
        self.side = side
        self.source = source
        self.use_pca = bool(use_pca)
        self.flat_hand_mean = bool(flat_hand_mean)

        shapedirs = np.array(params["shapedirs"], dtype=np.float64)
        if fix_left_shapedirs is None:
            fix_left_shapedirs = side == "left"
        if fix_left_shapedirs:
            shapedirs[:, 0, :] *= -1
        self.fix_left_shapedirs = bool(fix_left_shapedirs)
        self.num_betas = shapedirs.shape[-1]

        j_reg = params["J_regressor"]
        j_reg = j_reg.toarray() if sp.issparse(j_reg) else np.asarray(j_reg)
        kintree = np.asarray(params["kintree_table"]).astype(np.int64)
        parents = kintree[0].copy()
        parents[0] = -1  # MANO stores 4294967295 (uint32 -1) for the root
        if np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, 16)):
            raise ValueError(f"{source}: kintree_table parents {parents.tolist()} are not a tree "
                             "with parents before children")

        if isinstance(fingertips, str):
            if fingertips not in FINGERTIP_VERTEX_IDS:
                raise ValueError(f"fingertips must be one of {sorted(FINGERTIP_VERTEX_IDS)} or a "
                                 f"5-tuple of vertex ids, got {fingertips!r}")
            tips = FINGERTIP_VERTEX_IDS[fingertips][side]
        else:
            tips = tuple(int(t) for t in fingertips)
            if len(tips) != 5:
                raise ValueError(f"fingertips needs 5 vertex ids, got {len(tips)}")
        nv = len(params["v_template"])
        if not all(0 <= t < nv for t in tips):
            raise ValueError(f"{source}: fingertip vertex ids {tips} are not all vertices of its "
                             f"{nv}-vertex mesh (fingertips={fingertips!r})")
        self.fingertip_convention = fingertips if isinstance(fingertips, str) else "custom"

        hands_mean = np.zeros(45)
        comps = None
        if "hands_components" in params:
            comps = np.asarray(params["hands_components"], dtype=np.float64)
            _check_shape("hands_components", comps, (None, 45), source)
        if not self.flat_hand_mean:
            if "hands_mean" not in params:
                raise ValueError(f"{source}: flat_hand_mean=False needs key 'hands_mean'")
            hands_mean = params["hands_mean"]
            if hands_mean.size != 45:
                raise ValueError(f"{source}: key 'hands_mean' has shape {hands_mean.shape}, "
                                 "expected 45 numbers")
            hands_mean = hands_mean.reshape(45)
        if self.use_pca:
            if comps is None:
                raise ValueError(f"{source}: use_pca=True needs key 'hands_components'")
            if not 1 <= num_pca_comps <= comps.shape[0]:
                raise ValueError(f"num_pca_comps must be in 1..{comps.shape[0]}, "
                                 f"got {num_pca_comps}")
            comps = comps[:num_pca_comps]
        self.num_pca_comps = int(num_pca_comps) if self.use_pca else 0

        f32 = torch.float32
        self.register_buffer("v_template", torch.as_tensor(
            np.asarray(params["v_template"], dtype=np.float64), dtype=f32))
        self.register_buffer("shapedirs", torch.as_tensor(shapedirs, dtype=f32))
        posedirs = np.asarray(params["posedirs"], dtype=np.float64).reshape(-1, 135)
        self.register_buffer("posedirs", torch.as_tensor(posedirs.T.copy(), dtype=f32))  # 135xV3
        self.register_buffer("J_regressor", torch.as_tensor(j_reg, dtype=f32))
        self.register_buffer("weights", torch.as_tensor(
            np.asarray(params["weights"], dtype=np.float64), dtype=f32))
        self.register_buffer("hands_mean", torch.as_tensor(hands_mean, dtype=f32))
        if comps is not None:
            self.register_buffer("hands_components", torch.as_tensor(comps, dtype=f32))
        else:
            self.hands_components = None
        self.register_buffer("_tips", torch.as_tensor(tips, dtype=torch.long))
        self.register_buffer("_to_freihand", torch.as_tensor(
            np.asarray(MANO_TO_FREIHAND), dtype=torch.long))

        # HandModel-compatible attributes (numpy, like HandModel).
        self.faces = np.asarray(params["f"]).astype(np.int64)
        self.parents = parents
        self.fingertip_vertex_ids = np.asarray(tips, dtype=np.int64)
        self.template_vertices = self.v_template.numpy().copy()
        self.skinning_weights = self.weights.numpy().copy()
        self.rest_joints = (self.J_regressor @ self.v_template).numpy().copy()
        tip_rows = np.zeros((5, j_reg.shape[1]))
        tip_rows[np.arange(5), list(tips)] = 1.0
        self.joint_regressor = np.concatenate([j_reg, tip_rows])[
            self._to_freihand.numpy()].astype(np.float32)

    @property
    def num_vertices(self) -> int:
        """Number of mesh vertices V (778 for the official files)."""
        return int(self.v_template.shape[0])

    @property
    def num_joints(self) -> int:
        """Number of skinning joints (16)."""
        return int(self.weights.shape[1])

    @property
    def num_shape_params(self) -> int:
        """Number of shape parameters (MANO's betas, 10)."""
        return int(self.num_betas)

    @property
    def rest_keypoints(self) -> np.ndarray:
        """(21,3) float32 rest keypoints in FreiHAND order (joints + tip vertices), metres."""
        return _rest_keypoints(self.rest_joints, self.template_vertices,
                               self.fingertip_vertex_ids, MANO_TO_FREIHAND)

    @property
    def bone_radii(self) -> np.ndarray:
        """(16,) float32 estimated limb radius per joint's bone, metres.

        Mean distance of the vertices skinned mostly to joint k from its bone segment (joint k to
        its child joint, or to its fingertip for the last joint of a finger); for the wrist, the
        palm's half-thickness (mean distance of the palm vertices from the plane through the wrist
        and the knuckles). An estimate for collision proxies, like `HandModel.bone_radii` (on the
        MakeHuman hand written in MANO format the two agree to about 10 %).
        """
        v = self.template_vertices.astype(np.float64)
        j = self.rest_joints.astype(np.float64)
        kp = self.rest_keypoints.astype(np.float64)
        owner = self.skinning_weights.argmax(1)
        radii = np.zeros(16)
        for k in range(16):
            children = np.flatnonzero(self.parents == k)
            pts = v[owner == k]
            if len(pts) == 0:
                continue
            if k == 0:                                       # palm: half-thickness
                normal = np.cross(kp[5] - kp[17], kp[9] - kp[0])
                normal /= np.linalg.norm(normal)
                plane = (kp[0] + kp[5] + kp[9] + kp[13] + kp[17]) / 5
                radii[0] = np.abs((pts - plane) @ normal).mean()
                continue
            if len(children):
                end = j[children[0]]
            else:
                end = kp[_KEYPOINT_OF_MANO[k] + 1]                   # the finger's tip keypoint
            d = end - j[k]
            t = np.clip((pts - j[k]) @ d / (d @ d), 0.0, 1.0)
            radii[k] = np.linalg.norm(pts - (j[k] + t[:, None] * d), axis=1).mean()
        return radii.astype(np.float32)

    def vertex_colors(self, tone=None, rng=None, variation: float = 0.04) -> np.ndarray:
        """Per-vertex skin colour
        (a tone of [`SKIN_TONES`][handmesh_tutorial.hand.appearance.SKIN_TONES]).

        MANO files carry no palm or nail labels, so the colour is one tone with a little
        per-vertex brightness noise.

        Args:
            tone: index into ``SKIN_TONES`` or an RGB triple in [0,1]; ``None``: a random tone
                when ``rng`` is given, else tone 1.
            rng: ``numpy.random.Generator`` or seed; ``None`` = seed 0.
            variation: amplitude of the brightness noise.

        Returns:
            (V,3) float32 RGB in [0,1].
        """
        return plain_skin_colors(self.num_vertices, tone, rng, variation)

    # -- forward ------------------------------------------------------------------------------
    def _hand_pose(self, pose):
        """(B,45) axis-angle of the 15 finger joints from ``pose`` (before ``hands_mean``)."""
        like = self.v_template
        if self.use_pca:
            pose = _as_batch(pose, "pose (PCA coefficients, use_pca=True)",
                             ((self.num_pca_comps,),), like, unbatched=True)
            return None if pose is None else pose @ self.hands_components
        pose = _as_batch(pose, "pose", ((15, 3), (45,)), like, unbatched=True)
        return None if pose is None else pose.reshape(pose.shape[0], 45)

    def _betas(self, shape):
        if shape is None:
            return None
        betas = torch.as_tensor(shape, device=self.v_template.device).to(self.v_template.dtype)
        if betas.dim() == 1:
            betas = betas.unsqueeze(0)
        if betas.dim() != 2 or betas.shape[1] > self.num_betas:
            raise ValueError(f"shape (betas) must have shape (B,k) with k <= {self.num_betas}, "
                             f"got {tuple(betas.shape)}")
        return torch.nn.functional.pad(betas, (0, self.num_betas - betas.shape[1]))

    def full_pose(self, pose=None, global_orient=None) -> torch.Tensor:
        """The 16 axis-angle rotations MANO skins with (root first).

        Args:
            pose: (B,15,3) or (B,45) axis-angle (radians), or (B,num_pca_comps) PCA
                coefficients when ``use_pca``; ``None`` = zeros.
            global_orient: (B,3) axis-angle of the root (wrist), or ``None``.

        Returns:
            (B,16,3) axis-angle, radians; ``hands_mean`` already added unless ``flat_hand_mean``.
        """
        hand = self._hand_pose(pose)
        go = _as_batch(global_orient, "global_orient", ((3,),), self.v_template, unbatched=True)
        batch = _batch_size(hand, go, broadcast=True)
        dev = self.v_template.device
        hand = torch.zeros(1, 45, device=dev) if hand is None else hand
        go = torch.zeros(1, 3, device=dev) if go is None else go
        hand = hand.expand(batch, 45) + self.hands_mean
        return torch.cat([go.expand(batch, 3), hand], 1).reshape(batch, 16, 3)

    def forward(self, pose=None, shape=None, global_orient=None, transl=None):
        """Pose and shape the hand.

        Args:
            pose: (B,15,3) axis-angle per non-root joint in MANO order (radians; the rotation of
                joint k in its parent's frame, rest-pose axes), or (B,45); with ``use_pca`` (B,n)
                PCA coefficients. ``None`` = zeros.
            shape: (B,k) betas, k <= 10 (missing ones are 0); ``None`` = mean shape.
            global_orient: (B,3) axis-angle rotation of the whole hand about the wrist joint.
            transl: (B,3) translation in metres, added last.

        Returns:
            The same output type as [`HandModel`][handmesh_tutorial.hand.model.HandModel]:
            ``vertices``
            (B,778,3), ``joints`` (B,21,3) FreiHAND order, ``joints_mano`` (B,16,3), ``transforms``
            (B,16,4,4) global rigid transforms of the joints, all metres, float32.

        Raises:
            ValueError: an input has the wrong shape or the batch sizes disagree.
        """
        fp = self.full_pose(pose, global_orient)
        betas = self._betas(shape)
        tr = _as_batch(transl, "transl", ((3,),), self.v_template, unbatched=True)
        batch = _batch_size(fp, betas, tr, broadcast=True)
        fp = fp.expand(batch, 16, 3)

        v_shaped = self.v_template.expand(batch, -1, -1)
        if betas is not None:
            v_shaped = v_shaped + torch.einsum("vcl,bl->bvc", self.shapedirs,
                                               betas.expand(batch, -1))
        joints = torch.einsum("jv,bvc->bjc", self.J_regressor, v_shaped)        # (B,16,3)
        rots = axis_angle_to_matrix(fp)                                  # (B,16,3,3)
        eye = torch.eye(3, dtype=rots.dtype, device=rots.device)
        pose_feat = (rots[:, 1:] - eye).reshape(batch, 135)
        v_posed = v_shaped + (pose_feat @ self.posedirs).reshape(batch, -1, 3)
        # Same skinning as HandModel: G_k = G_parent [R_k | J_k - J_parent], blended.
        verts, transforms = lbs(v_posed, joints, rots, self.weights, self.parents)
        if tr is not None:
            verts, transforms = _translate(verts, transforms, tr)
        posed_joints = transforms[:, :, :3, 3]
        joints21 = _keypoints21(posed_joints, verts, self._tips, self._to_freihand)
        return HandOutput(vertices=verts, joints=joints21, joints_mano=posed_joints,
                                transforms=transforms)



def load_mano(path: str | Path, side: str | None = None, *, use_pca: bool = False,
              num_pca_comps: int = 45, flat_hand_mean: bool = True,
              fingertips: str | tuple = "smplx",
              fix_left_shapedirs: bool | None = None) -> ManoModel:
    """Load an official MANO pickle (or a file in its format) as a
    [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel].

    Args:
        path: ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` (your own licensed copy).
        side: ``"right"`` or ``"left"``; ``None`` infers it from the file name.
        use_pca: pose given as PCA coefficients (see
            [`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel]).
        num_pca_comps: number of PCA components when ``use_pca``.
        flat_hand_mean: zero pose = flat template (True, default) or MANO's mean pose (False).
        fingertips: ``"smplx"`` (744, 320, 443, 554, 671) or ``"manopth"``
            (745, 317, 444/445, 556, 673) fingertip vertices, or an explicit 5-tuple.
        fix_left_shapedirs: flip the sign of ``shapedirs[:, 0, :]``; ``None`` = on for left
            hands (the official left file needs it), off for right.

    Returns:
        The model; call it like [`HandModel`][handmesh_tutorial.hand.model.HandModel].

    Raises:
        FileNotFoundError: no such file.
        UnsafePickleError: the file contains a class or function outside the whitelist.
        ValueError: side cannot be inferred, a key is missing or has the wrong shape.

    Examples:
        >>> mano = load_mano("models/MANO_RIGHT.pkl")            # doctest: +SKIP
        >>> out = mano(pose=torch.zeros(1, 15, 3))               # doctest: +SKIP
        >>> out.vertices.shape, out.joints.shape                 # doctest: +SKIP
        (torch.Size([1, 778, 3]), torch.Size([1, 21, 3]))
    """
    path = Path(path)
    params = read_mano_pickle(path)
    if side is None:
        side = _infer_side(path)
        if side is None:
            raise ValueError(f"cannot infer the side from the file name {path.name!r}; "
                             "pass side='right' or side='left'")
    return ManoModel(params, side, use_pca=use_pca, num_pca_comps=num_pca_comps,
                     flat_hand_mean=flat_hand_mean, fingertips=fingertips,
                     fix_left_shapedirs=fix_left_shapedirs, source=str(path))
