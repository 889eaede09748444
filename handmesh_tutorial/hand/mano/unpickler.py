"""Read MANO-format pickles safely: a whitelist unpickler and stand-ins for chumpy and scipy.

The official MANO files are Python-2 pickles holding numpy arrays, one ``scipy.sparse`` matrix and
chumpy ``Ch`` objects.
[`RestrictedUnpickler`][handmesh_tutorial.hand.mano.unpickler.RestrictedUnpickler] resolves only
whitelisted globals (numpy array reconstruction, scipy sparse matrices, a few chumpy
classes mapped to stand-ins that only record their state) and refuses anything else with
[`UnsafePickleError`][handmesh_tutorial.hand.mano.unpickler.UnsafePickleError] before it is called;
[`read_mano_pickle`][handmesh_tutorial.hand.mano.unpickler.read_mano_pickle] returns plain
numpy/scipy objects. numpy arrays and dtypes are rebuilt from checked shapes, numeric dtypes and
exact byte
counts (numpy's own ``__setstate__`` never sees a pickled state), and sizes and nesting are bounded
before anything is allocated
([`MAX_PICKLE_ELEMENTS`][handmesh_tutorial.hand.mano.unpickler.MAX_PICKLE_ELEMENTS],
[`MAX_PICKLE_BYTES`][handmesh_tutorial.hand.mano.unpickler.MAX_PICKLE_BYTES],
[`MAX_PICKLE_DEPTH`][handmesh_tutorial.hand.mano.unpickler.MAX_PICKLE_DEPTH]). See
[`handmesh_tutorial.hand.mano`][handmesh_tutorial.hand.mano] for how chumpy objects pickle.

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
           "MAX_PICKLE_BYTES", "MAX_PICKLE_DEPTH"]


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
        s = _plain(self._state)
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
        s = _plain(self._state)
        shape = tuple(int(n) for n in s.get("_shape", s.get("shape")))
        _check_size(shape, f"sparse matrix {self.qualname}")
        data = np.asarray(s["data"])
        if self.fmt == "coo":
            row = np.asarray(s.get("row", s.get("coords", (None, None))[0]))
            col = np.asarray(s.get("col", s.get("coords", (None, None))[1]))
            return sp.coo_matrix((data, (row, col)), shape=shape)
        cls = sp.csc_matrix if self.fmt == "csc" else sp.csr_matrix
        m = cls((data, np.asarray(s["indices"]), np.asarray(s["indptr"])), shape=shape)
        try:  # indices beyond the shape made scipy's toarray write out of bounds (SIGSEGV)
            m.check_format(full_check=True)
        except ValueError as e:
            raise ValueError(f"sparse matrix {self.qualname}: inconsistent arrays ({e})") from None
        return m


def _make_chumpy(name: str, kind: str) -> type:
    return type(f"Chumpy{name}", (_ChumpyStandIn,), {"qualname": name, "kind": kind})


def _make_sparse(name: str, fmt: str) -> type:
    return type(f"Sparse{name.rsplit('.', 1)[-1]}", (_SparseStandIn,),
                {"qualname": name, "fmt": fmt})


def _plain(obj, memo: dict | None = None):
    """Replace stand-ins by arrays, recursively through dicts, lists and tuples (each shared
    object once: ``memo`` maps ``id`` to its plain value)."""
    memo = {} if memo is None else memo
    key = id(obj)
    if key in memo:
        return memo[key]
    if isinstance(obj, _ArrayStandIn):
        out = obj.value()
    elif isinstance(obj, _DtypeStandIn):
        out = obj.dtype()
    elif isinstance(obj, _ChumpyStandIn):
        out = obj.to_array()
    elif isinstance(obj, _SparseStandIn):
        out = obj.to_sparse()
    elif isinstance(obj, dict):
        out = {k: _plain(v, memo) for k, v in obj.items()}
    elif isinstance(obj, list):
        out = [_plain(v, memo) for v in obj]
    elif isinstance(obj, tuple):
        out = tuple(_plain(v, memo) for v in obj)
    else:
        out = obj
    memo[key] = out
    return out


MAX_PICKLE_ELEMENTS = 20_000_000
"""Largest array (elements) or sparse matrix (rows x columns) a MANO pickle may ask for, and the
most elements its whole contents may expand to, a shared list or array counted at every place it
is used: MANO's largest array, ``posedirs``, has 315,090 elements; a crafted shape or a few hundred
bytes of nested shared lists must not allocate gigabytes.
"""
MAX_PICKLE_BYTES = 256 * 2**20
"""Largest MANO file read, bytes (the official files are about 4 MB)."""
MAX_PICKLE_DEPTH = 32
"""Deepest nesting of lists, tuples, dicts and objects in a MANO pickle (the official files nest
three levels deep)."""
_ARRAY_KINDS = "biufc"  # bool, integers, floats, complex: the only dtypes a MANO file holds


def _check_size(shape, what: str) -> tuple[int, ...]:
    dims = (shape,) if isinstance(shape, int | np.integer) else shape
    if not isinstance(dims, tuple) or len(dims) > 32 \
            or not all(isinstance(n, int | np.integer) and n >= 0 for n in dims):
        raise UnsafePickleError(f"refusing {what} with shape {dims!r}")
    dims = tuple(int(n) for n in dims)
    if math.prod(dims) > MAX_PICKLE_ELEMENTS:
        raise UnsafePickleError(f"refusing {what} of shape {dims} (more than "
                                f"{MAX_PICKLE_ELEMENTS:,} elements)")
    return dims


class _DtypeStandIn(_StandIn):
    """Stand-in for a pickled ``numpy.dtype``: its state is checked here, never by numpy's
    ``dtype.__setstate__`` (which trusts the flags it is given, e.g. an object dtype without its
    object flag, whose bytes numpy then reads as pointers)."""

    qualname = "numpy.dtype"

    def __setstate__(self, state):
        # (version, byte order, subarray, names, fields, elsize, alignment, flags[, metadata])
        if not (isinstance(state, tuple) and len(state) in (8, 9) and state[2:5] == (None,) * 3
                and state[1] in ("<", ">", "|", "=")):
            raise UnsafePickleError(f"refusing a numpy.dtype state {state!r:.200}: only plain "
                                    "numeric dtypes are allowed")
        self.__dict__["_state"] = {"byteorder": state[1]}

    def dtype(self) -> np.dtype:
        """The numpy dtype, if it is a plain numeric one."""
        spec = self._args[0] if self._args else None
        dt = _safe_dtype(spec, "numpy.dtype")
        order = self._state.get("byteorder")
        return dt.newbyteorder(order) if order in ("<", ">") and dt.itemsize > 1 else dt


def _safe_dtype(spec, what: str) -> np.dtype:
    """A plain numeric dtype from a pickled dtype or dtype string, or `UnsafePickleError`."""
    if isinstance(spec, _DtypeStandIn):
        return spec.dtype()
    if isinstance(spec, bytes):  # protocol-0 pickles of Python 3 store the type code as bytes
        spec = spec.decode("latin1")
    try:
        dt = np.dtype(spec) if isinstance(spec, str | np.dtype) else None
    except (TypeError, ValueError):
        dt = None
    if dt is None or dt.kind not in _ARRAY_KINDS or dt.subdtype is not None \
            or dt.names is not None or dt.hasobject:
        raise UnsafePickleError(f"refusing {what} of dtype {spec!r:.100}: a MANO file holds only "
                                "numeric arrays (no object, structured or sub-array dtypes)")
    return dt


def _array_from_bytes(shape, dtype, raw, order: str, what: str) -> np.ndarray:
    """A new array of ``shape`` and ``dtype`` from exactly as many bytes as it needs."""
    dims = _check_size(shape, what)
    dt = _safe_dtype(dtype, what)
    if isinstance(raw, str):  # Python-2 byte strings, read with encoding="latin1"
        raw = raw.encode("latin1")
    if not isinstance(raw, bytes | bytearray | memoryview):
        raise UnsafePickleError(f"refusing {what}: data of type {type(raw).__name__}, not bytes")
    raw = memoryview(raw).cast("B")
    need = math.prod(dims) * dt.itemsize
    if raw.nbytes != need:
        raise UnsafePickleError(f"refusing {what} of shape {dims} and dtype {dt}: it needs "
                                f"{need:,} bytes, the file gives {raw.nbytes:,}")
    if order not in ("C", "F"):
        raise UnsafePickleError(f"refusing {what} with order {order!r}")
    return np.frombuffer(raw, dtype=dt).reshape(dims, order=order).copy(order="K")


class _ArrayStandIn(_StandIn):
    """A numpy array under construction: numpy's ``ndarray.__setstate__`` never sees the pickled
    state; `__setstate__` checks shape, dtype and the byte count, then builds a new array."""

    qualname = "numpy.ndarray"

    def __setstate__(self, state):
        # (version, shape, dtype, is_fortran, data) or without the version
        if not (isinstance(state, tuple) and len(state) in (4, 5)):
            raise UnsafePickleError(f"refusing a numpy array state of type {type(state).__name__}")
        shape, dtype, fortran, raw = state[-4:]
        self.__dict__["array"] = _array_from_bytes(shape, dtype, raw, "F" if fortran else "C",
                                                   "numpy array")

    def value(self):
        """The array (a numpy scalar for a pickled scalar)."""
        if "array" not in self.__dict__:
            raise UnsafePickleError("refusing a numpy array stand-in that was never built")
        return self.array[()] if self.__dict__.get("scalar") else self.array

    @classmethod
    def holding(cls, array: np.ndarray, scalar: bool = False) -> _ArrayStandIn:
        obj = cls.__new__(cls)
        obj.__dict__.update(array=array, scalar=scalar)
        return obj


def _numpy_functions() -> dict[tuple[str, str], object]:
    """numpy's pickle helpers, re-implemented on checked shapes, dtypes and byte counts: each
    returns an `_ArrayStandIn`, so no real numpy object ever receives a pickled state."""
    out: dict[tuple[str, str], object] = {}

    # "numpy.ndarray" resolves to bounded_ndarray, which pickles of arrays pass to _reconstruct
    # as the subtype
    def bounded_reconstruct(subtype, shape, dtype):
        dims = _check_size(shape, "numpy _reconstruct")
        if subtype is not bounded_ndarray:
            raise UnsafePickleError(f"refusing numpy _reconstruct of {subtype!r:.100}")
        return _ArrayStandIn.holding(np.zeros(dims, _safe_dtype(dtype, "numpy _reconstruct")))

    def bounded_ndarray(shape, dtype=float, *args, **kwargs):
        dims = _check_size(shape, "numpy.ndarray")
        if args or kwargs:
            raise UnsafePickleError("refusing numpy.ndarray with a buffer, offset or strides")
        return _ArrayStandIn.holding(np.zeros(dims, _safe_dtype(dtype, "numpy.ndarray")))

    def bounded_scalar(dtype, data=None):
        dt = _safe_dtype(dtype, "numpy scalar")
        array = _array_from_bytes((), dt, data, "C", "numpy scalar")
        return _ArrayStandIn.holding(array, scalar=True)

    def bounded_frombuffer(buf, dtype, shape, order):
        return _ArrayStandIn.holding(_array_from_bytes(shape, dtype, buf, order, "numpy buffer"))

    for core in ("numpy.core", "numpy._core"):
        out[(f"{core}.multiarray", "_reconstruct")] = bounded_reconstruct
        out[(f"{core}.multiarray", "scalar")] = bounded_scalar
        out[(f"{core}.numeric", "_frombuffer")] = bounded_frombuffer
    out[("numpy", "ndarray")] = bounded_ndarray
    out[("numpy", "dtype")] = _DtypeStandIn
    return out


def _check_expansion(data, source: str) -> None:
    """Refuse contents nested deeper than `MAX_PICKLE_DEPTH`, a container that holds itself, or
    more than `MAX_PICKLE_ELEMENTS` elements once shared objects are expanded; counted with a
    memo, in time linear in the number of distinct objects, before anything is converted."""
    sizes: dict[int, int] = {}
    active: set[int] = set()

    def size(obj, depth: int) -> int:
        key = id(obj)
        if key in sizes:
            return sizes[key]
        if depth > MAX_PICKLE_DEPTH:
            raise UnsafePickleError(f"{source}: refusing contents nested more than "
                                    f"{MAX_PICKLE_DEPTH} levels deep")
        if isinstance(obj, _ArrayStandIn):
            children, n = None, (obj.array.size if "array" in obj.__dict__ else 1)
        elif isinstance(obj, dict):
            children = (*obj.keys(), *obj.values())
        elif isinstance(obj, list | tuple | set | frozenset):
            children = obj
        elif isinstance(obj, _StandIn):
            children = (*obj._args, *obj._state.values())
        else:
            children, n = None, 1
        if children is not None:
            if key in active:
                raise UnsafePickleError(f"{source}: refusing a container that contains itself")
            active.add(key)
            n = 1 + sum(size(child, depth + 1) for child in children)
            active.discard(key)
        if n > MAX_PICKLE_ELEMENTS:
            raise UnsafePickleError(f"{source}: refusing contents that expand to more than "
                                    f"{MAX_PICKLE_ELEMENTS:,} elements (objects shared many "
                                    "times, e.g. nested lists)")
        sizes[key] = n
        return n

    size(data, 0)


def _safe_reconstructor(cls, base, state):
    """``copyreg._reconstructor`` restricted to stand-ins built on ``object`` (protocol 0/1)."""
    if not (isinstance(cls, type) and issubclass(cls, _ChumpyStandIn | _SparseStandIn)) \
            or base is not object:
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

    Admitted: numpy ``ndarray``/``dtype`` and numpy's array/scalar reconstruction helpers (as
    checked re-implementations that return stand-ins, which
    [`read_mano_pickle`][handmesh_tutorial.hand.mano.unpickler.read_mano_pickle] turns into arrays),
    scipy sparse csc/csr/coo matrices (as `_SparseStandIn`), chumpy ``Ch``, ``Select``,
    ``Reshape`` and ``transpose`` (as `_ChumpyStandIn`), ``set``/``frozenset``/``slice``/
    ``object`` and a restricted ``copyreg._reconstructor``. Every other global raises
    [`UnsafePickleError`][handmesh_tutorial.hand.mano.unpickler.UnsafePickleError] when the
    unpickler *looks it up*, i.e. before it could be called.

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


def _check_lengths(raw: bytes, path: Path) -> None:
    """Walk the file's opcodes (``pickletools.genops``, which reads, never allocates, what an
    opcode declares) before the unpickler runs: a string or bytes opcode that declares more
    bytes than the file holds (14 bytes claiming 2^45) would make the unpickler allocate them.

    Raises:
        ValueError: naming the file and what the opcode declares.
    """
    import pickletools

    try:
        for _ in pickletools.genops(raw):
            pass
    except ValueError as err:  # "expected N bytes in a bytes8, but only M remain"
        if "remain" in str(err):
            raise ValueError(f"{path}: not a readable MANO pickle ({str(err)[:200]}); refused "
                             "before reading") from None
        # other complaints (genops decodes protocol-0 strings more strictly than the
        # unpickler): the unpickler decides, and a MemoryError it raises is named too


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
            ``module.name`` and the file are in the message; nothing was executed), or asks for
            an object, structured or sub-array dtype, an array over `MAX_PICKLE_ELEMENTS`,
            contents that expand past it, nesting deeper than `MAX_PICKLE_DEPTH` or a container
            that holds itself (refused before numpy allocates or reads anything).
        ValueError: the file is not a pickled dict of string keys, is damaged, or declares a
            string longer than the file (checked before anything is allocated); the message
            names it.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MANO file not found: {path}")
    size = path.stat().st_size
    if size > MAX_PICKLE_BYTES:
        raise ValueError(f"{path}: {size:,} bytes; a MANO file is a few MB (limit "
                         f"{MAX_PICKLE_BYTES:,})")
    with open(path, "rb") as fh:
        raw = fh.read()
    _check_lengths(raw, path)
    try:
        data = RestrictedUnpickler(io.BytesIO(raw), source=str(path)).load()
        if not isinstance(data, dict):
            raise ValueError(f"{path}: expected a pickled dict, got {type(data).__name__}")
        odd = [k for k in data if not isinstance(k, str)]
        if odd:  # load_mano sorts and names the keys: a TypeError about '<' otherwise
            raise ValueError(f"{path}: a MANO file's keys are strings, got "
                             f"{type(odd[0]).__name__} key {str(odd[0])[:40]!r}")
        _check_expansion(data, str(path))
        return {k: _plain(v) for k, v in data.items()}
    except UnsafePickleError as err:
        if str(path) in str(err):
            raise
        raise UnsafePickleError(f"{path}: {err}") from None
    except ValueError as err:
        if str(path) in str(err):
            raise
        raise ValueError(f"{path}: {err}") from None
    except (pickle.UnpicklingError, EOFError, TypeError, AttributeError, IndexError, KeyError,
            OverflowError, MemoryError) as err:  # a damaged or crafted file: name it
        raise ValueError(f"{path}: not a readable MANO pickle ({type(err).__name__}: "
                         f"{str(err)[:200]})") from None
