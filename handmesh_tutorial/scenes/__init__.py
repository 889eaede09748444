"""The INTER-SH interaction generator: the paper's six-step algorithm (supplementary,
"Generating Mesh Interactions"), for hand-hand, hand-object and hand-chain scenes.

1. **Centre body.** A hand at a random valid pose (LCS angles inside the limits, no self-collision)
   and random rotation, a static object
   ([`objects.make_object`][handmesh_tutorial.objects.static.make_object]) or an articulated
   chain of rings ([`objects.make_chain`][handmesh_tutorial.objects.chain.make_chain]), at the
   scene centre.
2. **Second hand.** A hand in the neutral (flat) pose whose palm faces the centre body, far
   enough along a random approach direction ``u`` that the two cannot collide.
3. **Approach.** The second hand moves towards the centre in steps of ``approach_step``
   (2 mm) until its cylinders first collide; it backs off to the last valid position.
4. **Joint moves.** Every joint of every dynamic body (both hands, the chain links) gets a random
   direction in its LCS-angle space and turns along it in increments of ``joint_step_deg`` (2
   degrees) until a collision with another body, a self-collision, or its limit stops it, backing
   off to the last valid angle. The default limits are anatomical (``limits="anatomical"``,
   [`handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG`][handmesh_tutorial.lcs.ANATOMICAL_LIMITS_DEG]:
   one-sided flexion, little abduction and twist), which give natural poses; the paper's ±60 degrees
   about every axis (fingers bent backwards and twisted) is ``limits="paper"``
   (``handmesh generate --limits paper``).
5. **Repeat.** Joints move in turn, at most ``sweep_deg`` per round, until no joint can make a
   valid move (stop reason ``"no valid move"``) or ``max_rounds`` rounds have run
   (``"max rounds"``).
6. **Render** ([`make_sample`][handmesh_tutorial.scenes.sample.make_sample]): a camera framed on
   the target hand like a FreiHAND crop
   ([`frame_camera`][handmesh_tutorial.scenes.framing.frame_camera]: the hand wholly inside,
   45-75 % of the image side), random lights of random colour temperature
   ([`scene_lights`][handmesh_tutorial.render.lights.scene_lights]), a natural photograph or a
   procedural texture behind
   ([`handmesh_tutorial.render.scene_background`][handmesh_tutorial.render.scene_background]); scene
   image, label mask, every body alone, visibility ratios.

Validity is decided on the collision cylinders
([`handmesh_tutorial.collision`][handmesh_tutorial.collision]), as in the paper; each body is a rig
of rigid cylinders attached to the nodes of its kinematic tree, and all candidate angles of one
joint are tested in one vectorised call of
[`collision.cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect] (infinite
cylinders, then capsules, then the exact Ketchel-Larochelle test on the survivors); the approach
uses [`collision.bodies_collide`][handmesh_tutorial.collision.bodies_collide].

**Deviations from the paper.** (a) *Settle (step 5b)*: cylinders approximate the meshes only to a
few millimetres (radii are the 95th percentile of the vertex distances, see
[`collision.hand_cylinders`][handmesh_tutorial.collision.hand_cylinders]; round palm cylinders stick
out of the flat palm), so after step 5 the generator measures the *meshes*
([`mesh_contact`][handmesh_tutorial.scenes.contact.mesh_contact]: vertex-to-surface distances with
exact inside/outside signs) and translates the second body along ``u`` until the meshes touch (gap
<= ``contact_tol``) without interpenetrating by more than ``penetration_tol``. Both numbers end up
in the scene ``stats`` (mm). (b) *Re-approach* (``reapproach``): after every round of joint moves
the second hand is pushed towards the centre again until its cylinders touch (step 3 repeated), so
contacts lost by joint moves are restored. (c) *Natural poses* (``poses="natural"``, the default
with anatomical limits): the paper's random directions send every joint that meets nothing to a
limit, so hands end up as claws (a straight knuckle under a fully bent middle joint) and with
neighbouring fingers bent in opposite ways. Instead each hand draws a target pose from a
flexion-synergy prior
([`lcs.natural_hand_angles`][handmesh_tutorial.lcs.synergy.natural_hand_angles]: the fingers of a
hand close together, MCP with PIP, neighbours alike); the centre hand starts part of the way there
(step 1), the second hand flat (step 2), and in step 4 every joint moves straight towards its
target until it gets there or touches the other body, so a grasp wraps around the object where they
meet. ``limits="paper"`` restores the paper's rule (``poses="uniform"``).

Further choices the paper leaves open, all in
[`InteractionConfig`][handmesh_tutorial.scenes.config.InteractionConfig]: with
``poses="uniform"``, a joint's random direction has per-axis weights ``axis_weights`` (abduction,
flexion, twist) and flexes rather than extends with probability ``flexion_bias``; the centre hand's
random pose uses ``init_pose_scale`` of the range; a joint stops for good once it is blocked (by
contact or limit), which is what makes "no valid move" reachable.

Everything is seeded: the same seed gives the same scene, to the byte.

**Submodules** (each concept in one file):

* [`config`][handmesh_tutorial.scenes.config]: `InteractionConfig`, `InteractionError`,
  `STOP_REASONS` (notebook 04).
* [`rig`][handmesh_tutorial.scenes.rig]: rigid cylinders on a kinematic tree, posed by LCS angles,
  and their collision queries (notebook 04).
* [`bodies`][handmesh_tutorial.scenes.bodies]: hands, static objects and the chain during
  generation (notebook 04).
* [`scene`][handmesh_tutorial.scenes.scene]: the result, `Scene` and `SceneBody` (notebook 04).
* [`contact`][handmesh_tutorial.scenes.contact]: signed distances to meshes, `mesh_contact`
  (notebook 04); ``_contact_numba`` (private) holds their compiled kernel, selected like the
  cylinder test's by [`hmt.collision.BACKEND`][handmesh_tutorial.collision.BACKEND].
* [`generator`][handmesh_tutorial.scenes.generator]: steps 1-5 and the settle, `build_scene`
  (notebook 04).
* [`framing`][handmesh_tutorial.scenes.framing]: the camera of step 6, `frame_camera`,
  `camera_pose` (notebook 05).
* [`sample`][handmesh_tutorial.scenes.sample]: step 6, `make_sample`, `make_samples` (retries
  a seed whose scene cannot be made), `render_scene` (lit by
  `render.scene_lights`), the per-process renderer (notebook 05).
* [`generate`][handmesh_tutorial.scenes.generate]: the dataset driver `generate_interactions`
  (``handmesh generate``, notebook 05).

Every public name is importable from ``handmesh_tutorial.scenes`` itself.
"""

from __future__ import annotations

from ..data import KINDS
from ..render.lights import scene_lights
from .bodies import FOREARM_LENGTH
from .config import STOP_REASONS, InteractionConfig, InteractionError
from .contact import closest_points_on_triangles, mesh_contact, signed_distance
from .framing import FRAME_FOCAL, FRAME_MARGIN, FRAME_SHARE, camera_pose, frame_camera
from .generate import MAX_IMAGE_SIZE, MIN_IMAGE_SIZE, generate_interactions
from .generator import build_scene
from .sample import get_renderer, init_worker, make_sample, make_samples, render_scene
from .scene import Scene, SceneBody

# A dataset's meta.json records its make_sample as "<module>.<name>" and a resumed run must
# record the same string: keep the name it had before interact became a package (pickling by
# reference still finds it here).
make_sample.__module__ = __name__

__all__ = [
    "FOREARM_LENGTH",
    "FRAME_FOCAL",
    "FRAME_MARGIN",
    "FRAME_SHARE",
    "KINDS",
    "MAX_IMAGE_SIZE",
    "MIN_IMAGE_SIZE",
    "STOP_REASONS",
    "InteractionConfig",
    "InteractionError",
    "Scene",
    "SceneBody",
    "build_scene",
    "camera_pose",
    "frame_camera",
    "closest_points_on_triangles",
    "generate_interactions",
    "get_renderer",
    "init_worker",
    "make_sample",
    "make_samples",
    "mesh_contact",
    "render_scene",
    "scene_lights",
    "signed_distance",
]
