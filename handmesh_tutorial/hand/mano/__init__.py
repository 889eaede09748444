"""Load a user's own ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` without chumpy, safely.

MANO is licence-gated, so the library ships its own hand (the MakeHuman hand,
[`handmesh_tutorial.hand`][handmesh_tutorial.hand]). A user who owns the official files can load
them here and use them anywhere a [`HandModel`][handmesh_tutorial.hand.model.HandModel] is accepted:
[`load_mano`][handmesh_tutorial.hand.mano.model.load_mano] returns a
[`ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel] with the same call signature and output
(vertices, 21 FreiHAND-order joints, 16 MANO joints, joint transforms) and the same attributes
(``faces``, ``template_vertices``, ``skinning_weights``, ``rest_joints``, ``parents``,
``fingertip_vertex_ids``, ``joint_regressor``).

**Safe loading.** The official files are Python-2 pickles that contain numpy arrays, one
``scipy.sparse`` matrix (``J_regressor``) and chumpy ``Ch`` objects (public loaders such as
manopth's call ``.r`` on ``shapedirs``; without chumpy, plain unpickling fails with "No module named
'chumpy'"). Plain ``pickle.load`` would import chumpy (unmaintained, broken on current numpy) and
would execute whatever callable a tampered file names.
[`RestrictedUnpickler`][handmesh_tutorial.hand.mano.unpickler.RestrictedUnpickler] admits only a
whitelist of classes
(numpy array/dtype reconstruction, scipy sparse csc/csr/coo matrices, a few chumpy classes) and maps
chumpy and scipy classes to tiny stand-ins that only *record* their pickled state;
[`read_mano_pickle`][handmesh_tutorial.hand.mano.unpickler.read_mano_pickle] then turns the
stand-ins into plain arrays. Anything else is refused with
[`UnsafePickleError`][handmesh_tutorial.hand.mano.unpickler.UnsafePickleError] naming
``module.class`` and the file, before anything is called.

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
  #28, discussed in arctic issue #50).
  [`load_mano`][handmesh_tutorial.hand.mano.model.load_mano] applies it for left hands by default
  (``fix_left_shapedirs``). The library cannot check a file against the right one, so if your left
  file was already corrected, pass ``fix_left_shapedirs=False``.
* *Fingertip vertices.* MANO has 16 joints; the 5 fingertips of the 21 keypoints are mesh
  vertices, and two conventions are in use (thumb, index, middle, ring, pinky):
  ``"smplx"`` = ``(744, 320, 443, 554, 671)`` (``vertex_ids['mano']`` in the smplx package, used
  by HaMeR and the models built on it) and ``"manopth"`` = ``(745, 317, 444, 556, 673)`` for the
  right hand and ``(745, 317, 445, 556, 673)`` for the left (manopth's ``ManoLayer`` and the
  manopth-based code built on it). Both pick vertices at the very tip of each finger; use the
  one your data was annotated with.

Units: the official files are in metres; nothing is rescaled.

Submodules (each name below is re-exported here, so ``hmt.hand.mano.load_mano`` etc. keep working):

* [`unpickler`][handmesh_tutorial.hand.mano.unpickler]: the restricted unpickler and
  ``read_mano_pickle`` (notebooks 01, 02).
* [`model`][handmesh_tutorial.hand.mano.model]: ``ManoModel`` and ``load_mano`` (notebooks 01, 02).

Taught in notebook 01 (the hand model); notebook 02 builds the LCS of a MANO-format hand.
"""

from __future__ import annotations

from .model import FINGERTIP_VERTEX_IDS, MANO_KEYS, ManoModel, load_mano
from .unpickler import RestrictedUnpickler, UnsafePickleError, read_mano_pickle

__all__ = [
    "FINGERTIP_VERTEX_IDS",
    "MANO_KEYS",
    "ManoModel",
    "RestrictedUnpickler",
    "UnsafePickleError",
    "load_mano",
    "read_mano_pickle",
]
