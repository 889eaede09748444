"""Read MANO-format pickles safely: a whitelist unpickler and stand-ins for chumpy and scipy.

The official MANO files are Python-2 pickles holding numpy arrays, one ``scipy.sparse`` matrix and
chumpy ``Ch`` objects. [`RestrictedUnpickler`][handmesh_tutorial.mano.unpickler.RestrictedUnpickler]
resolves only whitelisted globals (numpy array reconstruction, scipy sparse matrices, a few chumpy
classes mapped to stand-ins that only record their state) and refuses anything else with
[`UnsafePickleError`][handmesh_tutorial.mano.unpickler.UnsafePickleError] before it is called;
[`read_mano_pickle`][handmesh_tutorial.mano.unpickler.read_mano_pickle] returns plain numpy/scipy
objects. Sizes are bounded
([`MAX_PICKLE_ELEMENTS`][handmesh_tutorial.mano.unpickler.MAX_PICKLE_ELEMENTS],
[`MAX_PICKLE_BYTES`][handmesh_tutorial.mano.unpickler.MAX_PICKLE_BYTES]). See
[`handmesh_tutorial.mano`][handmesh_tutorial.mano] for how chumpy objects pickle.

Taught in notebook 01 (the hand model); notebook 02 shows a refused pickle.
"""

from __future__ import annotations

import io
import math
import pickle
from pathlib import Path

import numpy as np
import scipy.sparse as sp

__all__ = ["UnsafePickleError", "RestrictedUnpickler", "read_mano_pickle", "MAX_PICKLE_ELEMENTS",
           "MAX_PICKLE_BYTES"]


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
    [`UnsafePickleError`][handmesh_tutorial.mano.unpickler.UnsafePickleError] when the unpickler
    *looks it up*, i.e. before it could be called.

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
