"""Write ``tests/fixtures/spiralnet_spirals.npz``: spirals made by SpiralNet++'s own function.

Usage::

    python tools/spiralnet_reference.py --spiralnet-plus PATH/TO/spiralnet_plus [--out FILE]

``PATH/TO/spiralnet_plus`` is a checkout of ``github.com/sw-gong/spiralnet_plus``; its
``utils/generate_spiral_seq.py`` (``extract_spirals``) is imported from there, never copied, and
run on OpenMesh meshes built from the faces in their stored order, as its ``preprocess_spiral``
does. Needs ``openmesh`` (PyPI, built from source: a C++ compiler and cmake), ``scikit-learn``,
``trimesh`` and numpy, in any environment (the library is not imported).

Meshes: an icosphere (42 vertices, closed) and a 7 x 7 grid patch (49 vertices, open, with
boundary and corner vertices), each with its faces in a shuffled order (SpiralNet++ spirals depend
on it). Spirals: length 9 (MobRecon) and length 12 with dilation 2. No vertex's rings run out at
these sizes, so SpiralNet++'s nearest-vertex fallback is never used (checked: no repeated ids).
The file (a few KB) stores ``<mesh>_faces`` and ``<mesh>_L<length>_d<dilation>`` arrays; the
test ``tests/test_spiral.py::test_spiralnet_convention_equals_their_construction`` compares
``spiral_indices(faces, L, d, convention="spiralnet")`` with them.
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np

SETTINGS = ((9, 1), (12, 2))


def meshes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    import trimesh

    rng = np.random.default_rng(0)
    ico = trimesh.creation.icosphere(subdivisions=1)
    n = 7
    ij = np.arange(n * n).reshape(n, n)
    a, b, c, d = ij[:-1, :-1].ravel(), ij[:-1, 1:].ravel(), ij[1:, :-1].ravel(), ij[1:, 1:].ravel()
    grid_faces = np.concatenate([np.stack([a, c, d], 1), np.stack([a, d, b], 1)])
    yy, xx = np.divmod(np.arange(n * n), n)
    grid_vertices = np.stack([xx, yy, np.zeros(n * n)], 1).astype(np.float64)
    out = {}
    for name, (v, f) in {"icosphere": (np.asarray(ico.vertices), np.asarray(ico.faces)),
                         "grid": (grid_vertices, grid_faces)}.items():
        out[name] = (v, f[rng.permutation(len(f))].astype(np.int64))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spiralnet-plus", required=True, help="a spiralnet_plus checkout")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "tests" /
                                             "fixtures" / "spiralnet_spirals.npz"))
    args = parser.parse_args()
    import openmesh as om

    src = Path(args.spiralnet_plus) / "utils" / "generate_spiral_seq.py"
    spec = importlib.util.spec_from_file_location("generate_spiral_seq", src)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    arrays = {}
    for name, (v, f) in meshes().items():
        mesh = om.TriMesh(v, f)
        assert mesh.n_faces() == len(f), f"OpenMesh dropped faces of {name}"
        arrays[f"{name}_faces"] = f
        for length, dilation in SETTINGS:
            s = np.asarray(module.extract_spirals(mesh, length, dilation), dtype=np.int16)
            assert all(len(set(row)) == length for row in s.tolist()), (name, length, dilation)
            arrays[f"{name}_L{length}_d{dilation}"] = s
    np.savez_compressed(args.out, **arrays)
    print(f"wrote {args.out}: {sorted(arrays)}")


if __name__ == "__main__":
    main()
