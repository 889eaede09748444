"""Load a user's own ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` without chumpy, safely.

MANO is licence-gated, so the library ships its own hand (the MakeHuman hand,
[`handmesh_tutorial.hand`][handmesh_tutorial.hand]). A user who owns the official files can load
them here and use them anywhere a [`HandModel`][handmesh_tutorial.hand.model.HandModel] is accepted:
[`load_mano`][handmesh_tutorial.mano.load_mano] returns a
[`ManoModel`][handmesh_tutorial.mano.ManoModel] with the same call signature and output (vertices,
21 FreiHAND-order joints, 16 MANO joints, joint transforms) and the same attributes (``faces``,
``template_vertices``, ``skinning_weights``, ``rest_joints``, ``parents``, ``fingertip_vertex_ids``,
``joint_regressor``).

**Safe loading.** The official files are Python-2 pickles that contain numpy arrays, one
``scipy.sparse`` matrix (``J_regressor``) and chumpy ``Ch`` objects (public loaders such as
manopth's call ``.r`` on ``shapedirs``; without chumpy, plain unpickling fails with "No module named
'chumpy'"). Plain ``pickle.load`` would import chumpy (unmaintained, broken on current numpy) and
would execute whatever callable a tampered file names.
[`RestrictedUnpickler`][handmesh_tutorial.mano.RestrictedUnpickler] admits only a whitelist of
classes (numpy array/dtype reconstruction, scipy sparse csc/csr/coo matrices, a few chumpy classes)
and maps chumpy and scipy classes to tiny stand-ins that only *record* their pickled state;
[`read_mano_pickle`][handmesh_tutorial.mano.read_mano_pickle] then turns the stand-ins into plain
arrays. Anything else is refused with
[`UnsafePickleError`][handmesh_tutorial.mano.UnsafePickleError] naming ``module.class`` and the
file, before anything is called.

How chumpy objects pickle (read from chumpy's ``ch.py``): ``Ch.__getstate__`` returns a copy of the
instance ``__dict__`` without its weak-reference caches; the array of a leaf ``Ch`` lives in the
``x`` entry. ``Select`` (``chumpy.reordering``) keeps its input in ``a`` and ``idxs`` /
``preferred_shape``; ``Reshape`` keeps ``a`` and ``newshape``; ``transpose`` keeps ``a`` and
``axes``. The stand-ins evaluate exactly these.

**Conventions verified in public code** (see ``docs/api/mano.md`` for the citations):

* *Left-hand shapedirs.* In the official ``MANO_LEFT.pkl`` the x component of ``shapedirs``
  (``shapedirs[:, 0, :]``) is the same as the right hand's although the left template is mirrored in
  x, so equal ``betas`` give a left hand that is not the mirror image of the right one. The common
  fix flips its sign: ``shapedirs[:, 0, :] *= -1`` (reported in the smplx repository's issue #48;
  applied in InterHand2.6M's ``tool/MANO_render/render.py``, recommended in dex-ycb-toolkit issue
  #28, discussed in arctic issue #50). [`load_mano`][handmesh_tutorial.mano.load_mano] applies it
  for left hands by default (``fix_left_shapedirs``). The library cannot check a file against the
  right one, so if your left file was already corrected, pass ``fix_left_shapedirs=False``.
* *Fingertip vertices.* MANO has 16 joints; the 5 fingertips of the 21 keypoints are mesh
  vertices, and two conventions are in use (thumb, index, middle, ring, pinky):
  ``"smplx"`` = ``(744, 320, 443, 554, 671)`` (``vertex_ids['mano']`` in the smplx package, used
  by HaMeR and the models built on it) and ``"manopth"`` = ``(745, 317, 444, 556, 673)`` for the
  right hand and ``(745, 317, 445, 556, 673)`` for the left (manopth's ``ManoLayer`` and the
  manopth-based code built on it). Both pick vertices at the very tip of each finger; use the
  one your data was annotated with.

Units: the official files are in metres; nothing is rescaled.
"""

from __future__ import annotations

import io
import math
import pickle
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch

from . import hand as _hand  # joint orders, HandOutput and LBS live in hand.py (one place)

__all__ = [
    "FINGERTIP_VERTEX_IDS",
    "MANO_KEYS",
    "ManoModel",
    "RestrictedUnpickler",
    "UnsafePickleError",
    "load_mano",
    "read_mano_pickle",
]

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
"""Arrays [`load_mano`][handmesh_tutorial.mano.load_mano] needs, with their expected shapes:
``"V"`` = the number of vertices of ``v_template`` (778 in the official files; other meshes in MANO
format also load), ``None`` = any size.
"""


class UnsafePickleError(pickle.UnpicklingError, ValueError):
    """A pickle names a class or function outside the whitelist (nothing was executed)."""


# --------------------------------------------------------------------------------------------
# Stand-ins: record pickled state, never run third-party code
# --------------------------------------------------------------------------------------------
class _StandIn:
    """Base of the stand-ins: accepts any constructor call and stores the pickled state."""

    qualname = "?"

    def __new__(cls, *args, **kwargs):
        obj = object.__new__(cls)
        obj.__dict__["_args"] = args
        obj.__dict__["_state"] = {}
        return obj

    def __setstate__(self, state):
        # Ch.__getstate__ returns a dict; objects with __slots__ give (dict, slotstate).
        if isinstance(state, tuple) and len(state) == 2:
            merged = dict(state[0] or {})
            merged.update(state[1] or {})
            state = merged
        if not isinstance(state, dict):
            raise UnsafePickleError(f"unexpected pickled state of {self.qualname}: "
                                    f"{type(state).__name__}")
        self.__dict__["_state"] = state

    def __repr__(self):
        return f"<stand-in for {self.qualname} with keys {sorted(self._state)}>"


class _ChumpyStandIn(_StandIn):
    """Stand-in for a chumpy object; `to_array` evaluates the few array-valued kinds."""

    kind = "Ch"

    def to_array(self) -> np.ndarray:
        """The array this chumpy object stands for (numpy float64)."""
        s = self._state
        if self.kind == "Ch" or (self.kind not in ("Select", "Reshape", "transpose") and "x" in s):
            if "x" not in s:
                raise ValueError(f"chumpy {self.qualname} object has no 'x' array in its state "
                                 f"(keys {sorted(s)})")
            return np.asarray(_plain(s["x"]), dtype=np.float64)
        a = np.asarray(_plain(s["a"]), dtype=np.float64)
        if self.kind == "Select":
            out = a.ravel()[np.asarray(_plain(s["idxs"])).ravel()].copy()
            shape = s.get("preferred_shape")
            return out.reshape(shape) if shape is not None else out
        if self.kind == "Reshape":
            return a.reshape(s["newshape"])
        return np.ascontiguousarray(np.transpose(a, axes=s.get("axes")))


class _SparseStandIn(_StandIn):
    """Stand-in for a scipy sparse matrix; `to_sparse` rebuilds it from its arrays."""

    fmt = "csc"

    def to_sparse(self) -> sp.spmatrix:
        """A current-scipy sparse matrix equal to the pickled one."""
        s = self._state
        shape = tuple(int(n) for n in s.get("_shape", s.get("shape")))
        _check_size(shape, f"sparse matrix {self.qualname}")
        data = np.asarray(s["data"])
        if self.fmt == "coo":
            row = np.asarray(s.get("row", s.get("coords", (None, None))[0]))
            col = np.asarray(s.get("col", s.get("coords", (None, None))[1]))
            return sp.coo_matrix((data, (row, col)), shape=shape)
        cls = sp.csc_matrix if self.fmt == "csc" else sp.csr_matrix
        return cls((data, np.asarray(s["indices"]), np.asarray(s["indptr"])), shape=shape)


def _make_chumpy(name: str, kind: str) -> type:
    return type(f"Chumpy{name}", (_ChumpyStandIn,), {"qualname": name, "kind": kind})


def _make_sparse(name: str, fmt: str) -> type:
    return type(f"Sparse{name.rsplit('.', 1)[-1]}", (_SparseStandIn,),
                {"qualname": name, "fmt": fmt})


def _plain(obj):
    """Replace stand-ins by arrays, recursively through dicts, lists and tuples."""
    if isinstance(obj, _ChumpyStandIn):
        return obj.to_array()
    if isinstance(obj, _SparseStandIn):
        return obj.to_sparse()
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_plain(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(_plain(v) for v in obj)
    return obj


MAX_PICKLE_ELEMENTS = 20_000_000
"""Largest array (elements) or sparse matrix (rows x columns) a MANO pickle may ask for: MANO's
largest array, ``posedirs``, has 315,090 elements; a crafted shape must not allocate gigabytes.
"""
MAX_PICKLE_BYTES = 256 * 2**20
"""Largest MANO file read, bytes (the official files are about 4 MB)."""


def _check_size(shape, what: str) -> None:
    dims = (shape,) if isinstance(shape, int | np.integer) else tuple(shape)
    if not all(isinstance(n, int | np.integer) and n >= 0 for n in dims):
        raise UnsafePickleError(f"refusing {what} with shape {dims!r}")
    if math.prod(int(n) for n in dims) > MAX_PICKLE_ELEMENTS:
        raise UnsafePickleError(f"refusing {what} of shape {dims} (more than "
                                f"{MAX_PICKLE_ELEMENTS:,} elements)")


def _numpy_functions() -> dict[tuple[str, str], object]:
    """numpy's own pickle helpers, found through numpy's reduce protocol (no private imports)."""
    reconstruct = np.zeros(1).__reduce__()[0]          # multiarray._reconstruct
    scalar = np.float64(1.0).__reduce__()[0]           # multiarray.scalar
    frombuffer = np.zeros(1).__reduce_ex__(5)[0]       # numeric._frombuffer (protocol 5)
    out: dict[tuple[str, str], object] = {}

    # "numpy.ndarray" resolves to bounded_ndarray, which pickles of arrays pass to _reconstruct
    # as the subtype: map it back
    def bounded_reconstruct(subtype, shape, dtype):
        _check_size(shape, "numpy _reconstruct")
        return reconstruct(np.ndarray if subtype is bounded_ndarray else subtype, shape, dtype)

    def bounded_ndarray(shape, *args, **kwargs):
        _check_size(shape, "numpy.ndarray")
        return np.ndarray(shape, *args, **kwargs)

    for core in ("numpy.core", "numpy._core"):
        out[(f"{core}.multiarray", "_reconstruct")] = bounded_reconstruct
        out[(f"{core}.multiarray", "scalar")] = scalar
        out[(f"{core}.numeric", "_frombuffer")] = frombuffer
    out[("numpy", "ndarray")] = bounded_ndarray
    out[("numpy", "dtype")] = np.dtype
    return out


def _safe_reconstructor(cls, base, state):
    """``copyreg._reconstructor`` restricted to stand-ins built on ``object`` (protocol 0/1)."""
    if not (isinstance(cls, type) and issubclass(cls, _StandIn)) or base is not object:
        raise UnsafePickleError(f"refusing copyreg._reconstructor({cls!r}, {base!r})")
    if state is not None:
        raise UnsafePickleError("refusing copyreg._reconstructor with a non-empty base state")
    return cls.__new__(cls)


def _safe_encode(text, encoding="utf-8", errors="strict"):
    """``_codecs.encode`` as Python 3 uses it to store bytes in protocol 0-2 pickles."""
    if not isinstance(text, str) or encoding not in ("latin1", "latin-1", "utf-8", "utf8"):
        raise UnsafePickleError(f"refusing _codecs.encode with encoding {encoding!r}")
    return text.encode(encoding, errors)


_CHUMPY = {
    ("chumpy.ch", "Ch"): "Ch", ("chumpy", "Ch"): "Ch",
    ("chumpy.reordering", "Select"): "Select",
    ("chumpy.reordering", "Reshape"): "Reshape",
    ("chumpy.reordering", "transpose"): "transpose",
}
_SPARSE_FORMATS = {"csc_matrix": "csc", "csr_matrix": "csr", "coo_matrix": "coo",
                   "csc_array": "csc", "csr_array": "csr", "coo_array": "coo"}
_SPARSE_MODULES = ("scipy.sparse", "scipy.sparse.csc", "scipy.sparse.csr", "scipy.sparse.coo",
                   "scipy.sparse._csc", "scipy.sparse._csr", "scipy.sparse._coo")
_PY2_MODULES = {"__builtin__": "builtins", "copy_reg": "copyreg"}


def _build_whitelist() -> dict[tuple[str, str], object]:
    allowed: dict[tuple[str, str], object] = dict(_numpy_functions())
    for (module, name), kind in _CHUMPY.items():
        allowed[(module, name)] = _make_chumpy(f"{module}.{name}", kind)
    for module in _SPARSE_MODULES:
        for name, fmt in _SPARSE_FORMATS.items():
            allowed[(module, name)] = _make_sparse(f"{module}.{name}", fmt)
    allowed[("builtins", "object")] = object
    allowed[("builtins", "set")] = set
    allowed[("builtins", "frozenset")] = frozenset
    allowed[("builtins", "slice")] = slice
    allowed[("copyreg", "_reconstructor")] = _safe_reconstructor
    allowed[("_codecs", "encode")] = _safe_encode
    return allowed


_WHITELIST = _build_whitelist()


class RestrictedUnpickler(pickle.Unpickler):
    """A `pickle.Unpickler` that resolves only whitelisted globals.

    Admitted: numpy ``ndarray``/``dtype`` and numpy's array/scalar reconstruction helpers, scipy
    sparse csc/csr/coo matrices (as `_SparseStandIn`), chumpy ``Ch``, ``Select``, ``Reshape`` and
    ``transpose`` (as `_ChumpyStandIn`), ``set``/``frozenset``/``slice``/ ``object`` and a
    restricted ``copyreg._reconstructor``. Every other global raises
    [`UnsafePickleError`][handmesh_tutorial.mano.UnsafePickleError] when the unpickler *looks it
    up*, i.e. before it could be called.

    Args:
        file: a binary file object.
        source: a name for messages (usually the file path).
        **kwargs: passed to `pickle.Unpickler` (``encoding="latin1"`` reads Python-2 pickles such as
            the official MANO files).
    """

    def __init__(self, file, *, source: str = "<pickle>", **kwargs):
        kwargs.setdefault("encoding", "latin1")
        super().__init__(file, **kwargs)
        self.source = source

    def find_class(self, module: str, name: str):  # noqa: D102 - documented on the class
        module = _PY2_MODULES.get(module, module)
        found = _WHITELIST.get((module, name))
        if found is None:
            raise UnsafePickleError(
                f"{self.source}: refusing to load global '{module}.{name}'; a MANO file may only "
                "contain numpy arrays, scipy sparse matrices and chumpy arrays")
        return found

    def persistent_load(self, pid):  # noqa: D102
        raise UnsafePickleError(f"{self.source}: persistent ids are not allowed ({pid!r})")


def read_mano_pickle(path: str | Path) -> dict:
    """Read a MANO-format pickle into plain numpy / scipy objects, safely.

    Args:
        path: ``MANO_RIGHT.pkl``, ``MANO_LEFT.pkl`` or any pickle of a dict in that format.

    Returns:
        The dict stored in the file, with chumpy objects replaced by ``numpy.ndarray`` (float64)
        and sparse matrices rebuilt with the installed scipy. Other values (strings such as
        ``bs_style``) are returned as stored.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        UnsafePickleError: the file names a class or function outside the whitelist (its
            ``module.name`` and the file are in the message; nothing was executed).
        ValueError: the file is not a pickled dict.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MANO file not found: {path}")
    size = path.stat().st_size
    if size > MAX_PICKLE_BYTES:
        raise ValueError(f"{path}: {size:,} bytes; a MANO file is a few MB (limit "
                         f"{MAX_PICKLE_BYTES:,})")
    with open(path, "rb") as fh:
        data = RestrictedUnpickler(io.BytesIO(fh.read()), source=str(path)).load()
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a pickled dict, got {type(data).__name__}")
    return {k: _plain(v) for k, v in data.items()}


# --------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------
def _check_shape(key: str, arr, expected: tuple, source: str) -> None:
    shape = tuple(arr.shape)
    if len(shape) != len(expected) or any(e is not None and e != s
                                         for e, s in zip(expected, shape, strict=True)):
        want = "x".join("*" if e is None else str(e) for e in expected)
        raise ValueError(f"{source}: key '{key}' has shape {shape}, expected {want}")


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

    Usually built with [`load_mano`][handmesh_tutorial.mano.load_mano]. Attributes mirror
    [`HandModel`][handmesh_tutorial.hand.model.HandModel].

    Args:
        params: dict with the [`MANO_KEYS`][handmesh_tutorial.mano.MANO_KEYS] arrays (as returned by
            [`read_mano_pickle`][handmesh_tutorial.mano.read_mano_pickle]); ``hands_components``
            (45x45) and ``hands_mean`` (45,) are needed for PCA poses or ``flat_hand_mean=False``.
        side: ``"right"`` or ``"left"``.
        use_pca: if True, ``pose`` holds ``num_pca_comps`` PCA coefficients (B, num_pca_comps) and
            the full pose is ``coeffs @ hands_components[:num_pca_comps]``.
        num_pca_comps: number of PCA components used when ``use_pca`` (1..45).
        flat_hand_mean: if True (default), zero pose is the flat template hand; if False, MANO's
            mean pose ``hands_mean`` is added to the 45 pose values (as smplx and manopth do with
            ``flat_hand_mean=False``), so zero pose is the relaxed, slightly curled mean hand.
        fingertips: ``"smplx"`` (default) or ``"manopth"`` fingertip vertex convention (see
            [`FINGERTIP_VERTEX_IDS`][handmesh_tutorial.mano.FINGERTIP_VERTEX_IDS]), or an explicit
            5-tuple (thumb, index, middle, ring, pinky).
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
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        for key in MANO_KEYS:
            if key not in params:
                raise ValueError(f"{source}: missing key '{key}' (keys: {sorted(params)})")
        nv = np.shape(params["v_template"])[0]
        for key, shape in MANO_KEYS.items():
            _check_shape(key, params[key], tuple(nv if e == "V" else e for e in shape), source)
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
        self.fingertip_convention = fingertips if isinstance(fingertips, str) else "custom"

        hands_mean = np.zeros(45)
        comps = None
        if "hands_components" in params:
            comps = np.asarray(params["hands_components"], dtype=np.float64)
            _check_shape("hands_components", comps, (None, 45), source)
        if not self.flat_hand_mean:
            if "hands_mean" not in params:
                raise ValueError(f"{source}: flat_hand_mean=False needs key 'hands_mean'")
            hands_mean = np.asarray(params["hands_mean"], dtype=np.float64).reshape(45)
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
            np.asarray(_hand.MANO_TO_FREIHAND), dtype=torch.long))

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
        tips = self.template_vertices[self.fingertip_vertex_ids]
        return np.concatenate([self.rest_joints, tips])[list(_hand.MANO_TO_FREIHAND)]

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
        m2f = np.asarray(_hand.MANO_TO_FREIHAND)
        mano_to_kp = {int(r): i for i, r in enumerate(m2f) if r < 16}
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
                end = kp[mano_to_kp[k] + 1]                   # the finger's tip keypoint
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
        gen = np.random.default_rng(0 if rng is None else rng)
        if tone is None:
            tone = int(gen.integers(len(_hand.SKIN_TONES))) if rng is not None else 1
        if isinstance(tone, (int, np.integer)):
            if not 0 <= int(tone) < len(_hand.SKIN_TONES):
                raise ValueError(f"tone index must be in [0,{len(_hand.SKIN_TONES) - 1}], "
                                 f"got {tone}")
            base = np.asarray(_hand.SKIN_TONES[int(tone)])
        else:
            base = np.asarray(tone, dtype=float).reshape(-1)
            if base.shape != (3,) or base.min() < 0 or base.max() > 1:
                raise ValueError(f"tone must be an index or an RGB triple in [0,1], got {tone!r}")
        noise = 1.0 + variation * gen.standard_normal((self.num_vertices, 1))
        return np.clip(base * noise, 0.0, 1.0).astype(np.float32)

    # -- forward ------------------------------------------------------------------------------
    def _vec(self, x, name: str, width: int):
        """(B,width) float32 tensor on the model's device, or None."""
        if x is None:
            return None
        x = torch.as_tensor(x, dtype=torch.float32, device=self.v_template.device)
        if x.dim() == 1:
            x = x.unsqueeze(0)
        if x.dim() != 2 or x.shape[1] != width:
            raise ValueError(f"{name} must have shape (B,{width}), got {tuple(x.shape)}")
        return x

    def _hand_pose(self, pose):
        """(B,45) axis-angle of the 15 finger joints from ``pose`` (before ``hands_mean``)."""
        if pose is None:
            return None
        pose = torch.as_tensor(pose, dtype=torch.float32, device=self.v_template.device)
        if self.use_pca:
            pose = self._vec(pose, "pose (PCA coefficients, use_pca=True)", self.num_pca_comps)
            return pose @ self.hands_components
        if pose.shape[-2:] == (15, 3):
            pose = pose.reshape(-1, 45) if pose.dim() in (2, 3) else pose
        if pose.dim() == 1 or pose.dim() == 2 and pose.shape[-1] == 45:
            return self._vec(pose, "pose", 45)
        raise ValueError(f"pose must have shape (B,15,3) or (B,45), got {tuple(pose.shape)}")

    def _betas(self, shape):
        if shape is None:
            return None
        betas = torch.as_tensor(shape, dtype=torch.float32, device=self.v_template.device)
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
        go = self._vec(global_orient, "global_orient", 3)
        batch = _common_batch(hand, go)
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
        tr = self._vec(transl, "transl", 3)
        batch = _common_batch(fp, betas, tr)
        fp = fp.expand(batch, 16, 3)

        v_shaped = self.v_template.expand(batch, -1, -1)
        if betas is not None:
            v_shaped = v_shaped + torch.einsum("vcl,bl->bvc", self.shapedirs,
                                               betas.expand(batch, -1))
        joints = torch.einsum("jv,bvc->bjc", self.J_regressor, v_shaped)        # (B,16,3)
        rots = _hand.axis_angle_to_matrix(fp)                                  # (B,16,3,3)
        eye = torch.eye(3, dtype=rots.dtype, device=rots.device)
        pose_feat = (rots[:, 1:] - eye).reshape(batch, 135)
        v_posed = v_shaped + (pose_feat @ self.posedirs).reshape(batch, -1, 3)
        # Same skinning as HandModel: G_k = G_parent [R_k | J_k - J_parent], blended.
        verts, transforms = _hand.lbs(v_posed, joints, rots, self.weights, self.parents)
        posed_joints = transforms[:, :, :3, 3]
        if tr is not None:
            verts = verts + tr[:, None]
            posed_joints = posed_joints + tr[:, None]
            transforms = torch.cat([transforms[:, :, :3, :3], posed_joints[..., None]], -1)
            transforms = torch.cat([transforms, _bottom_row(transforms)], -2)
        tips = verts[:, self._tips]
        joints21 = torch.cat([posed_joints, tips], 1)[:, self._to_freihand]
        return _hand.HandOutput(vertices=verts, joints=joints21, joints_mano=posed_joints,
                                transforms=transforms)


def _common_batch(*tensors) -> int:
    """The batch size shared by the given (B,...) tensors (None ignored, 1 broadcasts)."""
    sizes = {t.shape[0] for t in tensors if t is not None} or {1}
    batch = max(sizes)
    if any(s not in (1, batch) for s in sizes):
        raise ValueError(f"inconsistent batch sizes {sorted(sizes)} among the inputs")
    return batch


def _bottom_row(t: torch.Tensor) -> torch.Tensor:
    row = torch.zeros(*t.shape[:-2], 1, 4, dtype=t.dtype, device=t.device)
    row[..., 0, 3] = 1
    return row


def load_mano(path: str | Path, side: str | None = None, *, use_pca: bool = False,
              num_pca_comps: int = 45, flat_hand_mean: bool = True,
              fingertips: str | tuple = "smplx",
              fix_left_shapedirs: bool | None = None) -> ManoModel:
    """Load an official MANO pickle (or a file in its format) as a
    [`ManoModel`][handmesh_tutorial.mano.ManoModel].

    Args:
        path: ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` (your own licensed copy).
        side: ``"right"`` or ``"left"``; ``None`` infers it from the file name.
        use_pca: pose given as PCA coefficients (see
            [`ManoModel`][handmesh_tutorial.mano.ManoModel]).
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

    Example:
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

