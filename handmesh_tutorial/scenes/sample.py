"""Step 6, the dataset sample: `make_sample` (build a scene, then `render_scene` under
[`scene_lights`][handmesh_tutorial.render.lights.scene_lights]), and the per-process renderer
(`get_renderer`, `init_worker`).

Camera frame OpenCV, metres; images ``(S, S, 3)`` uint8. Taught in notebook 05 ("Rendering and
visibility").
"""

from __future__ import annotations

import numpy as np

from ..data import KINDS
from ..render.backgrounds import PHOTO_PROB
from ..render.lights import scene_lights
from ..visibility import visibility_ratios
from .bodies import _hand_assets
from .config import InteractionConfig, InteractionError
from .framing import FRAME_FOCAL, FRAME_MARGIN, FRAME_SHARE, frame_camera
from .generator import build_scene
from .scene import Scene

__all__ = ["get_renderer", "init_worker", "make_sample", "make_samples", "render_scene"]


_RENDERERS: dict = {}


def get_renderer(image_size: int = 224):
    """The per-process [`Renderer`][handmesh_tutorial.render.Renderer] of this image size (created
    on first use and then reused: one OpenGL context per process)."""
    key = int(image_size)
    if key not in _RENDERERS:
        from ..render import Renderer

        _RENDERERS[key] = Renderer(key)
    return _RENDERERS[key]


def init_worker(image_size: int = 224, threads: int = 1) -> None:
    """``worker_init`` for
    [`handmesh_tutorial.data.generate_dataset`][handmesh_tutorial.data.generate_dataset]: one
    renderer and the hand models per process, torch limited to ``threads`` threads.

    Use ``functools.partial(init_worker, image_size)``.
    """
    import torch

    torch.set_num_threads(int(threads))
    get_renderer(image_size)
    for side in ("left", "right"):
        _hand_assets(side)


def _choose_kind(seed: int) -> str:
    g = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(3)[2])
    return KINDS[int(g.integers(len(KINDS)))]


def make_sample(sample_seed: int, kind: str = "hand-hand", image_size: int = 224,
                renderer=None, config: InteractionConfig | None = None, *,
                limits: str | None = None, share: tuple[float, float] | None = None,
                photo_prob: float | None = None, return_scene: bool = False):
    """One INTER-SH sample: [`build_scene`][handmesh_tutorial.scenes.generator.build_scene] then
    [`render_scene`][handmesh_tutorial.scenes.sample.render_scene].

    The scene and the view draw from independent streams of ``sample_seed``
    (``numpy.random.SeedSequence(sample_seed).spawn(3)``: scene, view, kind), so the same seed
    always gives the same bytes.

    Args:
        sample_seed: the sample's seed (from
            [`handmesh_tutorial.data.sample_seed`][handmesh_tutorial.data.sample_seed]).
        kind: ``"hand-hand"``, ``"hand-object"``, ``"hand-chain"`` or ``"mixed"`` (one of the
            three drawn from the seed).
        image_size: square image side, pixels.
        renderer: a [`Renderer`][handmesh_tutorial.render.Renderer] of that size; ``None`` uses the
            per-process one ([`get_renderer`][handmesh_tutorial.scenes.sample.get_renderer]).
        config: generator parameters
            ([`InteractionConfig`][handmesh_tutorial.scenes.config.InteractionConfig]).
        limits: shortcut for ``config.limits``: ``"anatomical"`` (the default config's, with
            natural poses) or ``"paper"`` (±60° on every axis, with the paper's uniform poses).
        share: (min, max) share of the image side covered by the target hand's bounding box;
            ``None`` = [`FRAME_SHARE`][handmesh_tutorial.scenes.framing.FRAME_SHARE] (see
            [`render_scene`][handmesh_tutorial.scenes.sample.render_scene]).
        photo_prob: probability of a photograph as background (else a procedural texture);
            ``None`` = [`PHOTO_PROB`][handmesh_tutorial.render.backgrounds.PHOTO_PROB] (0.75).
        return_scene: also return the [`Scene`][handmesh_tutorial.scenes.scene.Scene] (what
            the sample does not store, e.g. each hand's skin ``tone``).

    Returns:
        The sample dict of [`render_scene`][handmesh_tutorial.scenes.sample.render_scene];
        ``(sample, scene)`` with ``return_scene=True``.

    Raises:
        ValueError: unknown kind or limits.
        InteractionError: the scene could not be generated.
    """
    if kind == "mixed":
        kind = _choose_kind(sample_seed)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS} or 'mixed', got {kind!r}")
    cfg = config or InteractionConfig()
    # build_scene's limits override selects a whole generator (those limits with their poses)
    overrides = {} if limits is None or limits == cfg.limits else {"limits": limits}
    scene_ss, view_ss, _ = np.random.SeedSequence(int(sample_seed)).spawn(3)
    try:
        scene = build_scene(kind, np.random.default_rng(scene_ss), cfg, **overrides)
    except InteractionError as e:
        raise InteractionError(kind, int(sample_seed), e.reason) from None
    scene.seed = int(sample_seed)
    sample = render_scene(scene, np.random.default_rng(view_ss), image_size, renderer,
                          share=FRAME_SHARE if share is None else share,
                          photo_prob=PHOTO_PROB if photo_prob is None else photo_prob)
    return (sample, scene) if return_scene else sample


def make_samples(num: int, seed: int, kind: str = "mixed", image_size: int = 224, *,
                 max_attempts: int = 20, **kwargs) -> list[dict]:
    """``num`` samples in memory, each retried on a new seed when its scene cannot be made.

    Sample ``i`` is ``make_sample(sample_seed(seed, i, attempt))`` for the first ``attempt``
    that raises no [`InteractionError`][handmesh_tutorial.scenes.config.InteractionError]: the
    seeds ``generate_dataset`` draws (it also rejects implausible candidates and balances VR,
    so its samples can differ; for a set on disk use it or ``handmesh generate``). Wrap the
    list in [`InterSHTorchDataset`][handmesh_tutorial.data.torch_views.InterSHTorchDataset] to
    train on it.

    Args:
        num: number of samples, >= 1.
        seed: base seed, a non-negative integer.
        kind: see [`make_sample`][handmesh_tutorial.scenes.sample.make_sample].
        image_size: square image side, pixels.
        max_attempts: seeds tried per sample before giving up.
        **kwargs: more options of ``make_sample`` (``config``, ``limits``, ``share``, ...).

    Returns:
        The sample dicts; each has ``seed`` and ``attempt`` entries.

    Raises:
        InteractionError: a sample failed ``max_attempts`` times.
    """
    from ..data import sample_seed

    if isinstance(num, bool) or not isinstance(num, int) or num < 1 or max_attempts < 1:
        raise ValueError(f"num and max_attempts must be integers >= 1, got {num!r}, "
                         f"{max_attempts!r}")
    out = []
    for i in range(num):
        for attempt in range(max_attempts):
            s = sample_seed(seed, i, attempt)
            try:
                sample = make_sample(s, kind, image_size, **kwargs)
            except InteractionError as e:
                last = e
                continue
            out.append({**sample, "seed": s, "attempt": attempt})
            break
        else:
            raise InteractionError(kind, seed, f"sample {i}: {max_attempts} seeds failed, the "
                                   f"last with: {last.reason}")
    return out


def render_scene(scene: Scene, rng, image_size: int = 224, renderer=None,
                 occluder_view: float = 0.4, *, share: tuple[float, float] = FRAME_SHARE,
                 focal: tuple[float, float] = FRAME_FOCAL, margin: float = FRAME_MARGIN,
                 photo_prob: float = PHOTO_PROB, camera=None) -> dict:
    """Step 6: place a camera, render a scene and measure visibility; the dataset sample dict.

    **Camera** ([`frame_camera`][handmesh_tutorial.scenes.framing.frame_camera]): it looks at the
    target hand from a uniformly random direction (or, with probability ``occluder_view``, from
    around the other body's side), with a random roll, at the distance where the hand covers a
    random share (``share``, 45-75 %) of the image side with a focal length of 1.8-3.6 times the
    side; the whole target hand stays at least ``margin`` (8 %) of the side inside the border, like
    a FreiHAND 224-px crop. The other body may leave the frame.
    **Light** ([`scene_lights`][handmesh_tutorial.render.lights.scene_lights]): key, fill,
    sometimes rim and point lights of random colour temperature and exposure, plus an ambient term
    tinted by the background. **Background**
    ([`handmesh_tutorial.render.scene_background`][handmesh_tutorial.render.scene_background]): a
    natural photograph (random crop, flip, defocus, colour jitter; ``photo_prob``) or a procedural
    texture. The renderer draws the scene (image, label mask) and each body alone (the VR
    denominators);
    the image gets a little sensor noise (0-2 grey levels).

    Args:
        scene: a [`Scene`][handmesh_tutorial.scenes.scene.Scene].
        rng: ``numpy.random.Generator`` or seed of the view.
        image_size: square image side, pixels.
        renderer: a [`Renderer`][handmesh_tutorial.render.Renderer] of that size, or ``None`` for
            the per-process one.
        occluder_view: probability of a view from the side of the other body (camera direction
            around ``other centre - target centre``), which makes low VRs (occlusion) common.
        share: (min, max) share of the image side covered by the target hand's bounding box.
        focal: (min, max) focal length as a multiple of the image side.
        margin: free border around the target hand, as a fraction of the image side.
        photo_prob: probability of a photograph (else a procedural texture) as background.
        camera: ``(R, t, K)``, a camera of one's own instead of the drawn one: world to camera
            ``x -> R x + t`` (OpenCV frame, metres) and the (3, 3) intrinsics of the
            ``image_size`` image (e.g. for a scene of
            [`Scene.compose`][handmesh_tutorial.scenes.scene.Scene.compose]); lights and
            background are still drawn from ``rng``.

    Returns:
        A sample for
        [`handmesh_tutorial.data.write_sample`][handmesh_tutorial.data.write_sample]:
        ``image`` (S,S,3) uint8, ``scene_mask`` (S,S) int32, ``alone_masks`` {label: (S,S) bool},
        ``meshes`` {label: (vertices (V,3) float32 camera frame metres, faces (F,3) int32)},
        ``joints`` {hand label: (21,3) float32 camera frame}, ``pose`` {hand label: (15,3)}, ``K``
        (3,3), ``vr`` {label: float}, ``kind``, ``target`` (label 1; the left hand in hand-hand
        scenes), ``sides``, ``names``, ``stats`` (`Scene.stats` plus ``camera_distance_m`` (camera
        to scene centre), ``target_distance_m`` (camera to the target hand's box centre),
        ``focal_px`` and ``target_share`` (the hand's box over the image side)).

    Raises:
        InteractionError: a body is not in view.
    """
    from ..render import framing, scene_background, srgb_to_linear

    rng = np.random.default_rng(rng)
    r = renderer if renderer is not None else get_renderer(image_size)
    if (r.width, r.height) != (image_size, image_size):
        raise ValueError(f"renderer is {r.width}x{r.height}, image_size is {image_size}")
    tb = scene.body(scene.target)
    centre = 0.5 * (tb.vertices.min(0) + tb.vertices.max(0))
    # a uniformly random view hides the target rarely; with probability occluder_view look from
    # behind the other body, so all VR bins of the paper get filled
    toward = None
    if rng.random() < occluder_view:
        other = [b for b in scene.bodies if b.label != scene.target][0]
        toward = other.vertices.mean(0) - centre
    # never look along the target's forearm from the elbow: the forearm would hide the hand
    avoid = None
    if tb.forearm is not None:
        fv = tb.forearm[0]   # every ring's centroid and the far end (last vertex) are on the axis
        avoid = (fv[-1] - fv.mean(0), np.cos(np.deg2rad(50)))
    # Up to 10 views: a view fails when a body sits behind the camera or ends up entirely out of
    # view (or behind its own forearm); the first good view is used (same bytes as long as it
    # is the first one).
    missing = None
    for _ in range(1 if camera is not None else 10):
        if camera is None:
            R, t, K = frame_camera(tb.vertices, rng, image_size, toward=toward, share=share,
                                   focal=focal, margin=margin, avoid=avoid)
        else:
            R, t, K = (np.asarray(c, np.float64) for c in camera)
        meshes = scene.render_meshes(R, t)
        if min(m[0][:, 2].min() for m in meshes) <= 0.05:  # something behind the camera
            continue
        target_v = tb.vertices @ R.T + t
        depth = float(np.linalg.norm(centre @ R.T + t))
        lights = scene_lights(rng, depth)
        bg = scene_background(rng, image_size, image_size, photo_prob=photo_prob)
        # ambient light: bounced off the surroundings, so tinted by the background's mean colour
        tint = srgb_to_linear(bg.reshape(-1, 3).mean(0) / 255.0)
        tint = 0.6 + 0.4 * tint / max(float(tint.mean()), 1e-3)
        ambient = float(rng.uniform(0.06, 0.2)) * tint
        out = r.render(meshes, K, lights=lights, background=bg, ambient=ambient, alone=True,
                       occluders=scene.scenery_meshes(R, t))
        alone = dict(out.alone_masks)
        missing = [lab for lab, m in alone.items() if not m.any()]
        if not missing:
            break
    else:
        what = f"body {missing[0]} is not in view" if missing else "no view in front of all bodies"
        raise InteractionError(scene.kind, scene.seed, f"{what} (10 camera draws)")
    noise = rng.uniform(0.0, 2.0)
    image = np.clip(out.image + rng.normal(0.0, noise, out.image.shape) + 0.5, 0, 255)
    image = image.astype(np.uint8)
    # NVIDIA's EGL flips a few edge pixels between the scene and alone passes (Mesa never does)
    vr = visibility_ratios(out.labels, alone, stray=0.03)
    hands = [b for b in scene.bodies if b.kind == "hand"]
    return {
        "image": image,
        "scene_mask": out.labels.astype(np.int32),
        "alone_masks": alone,
        "meshes": {b.label: ((b.vertices @ R.T + t).astype(np.float32), b.faces.astype(np.int32))
                   for b in scene.bodies},
        "joints": {b.label: (b.joints @ R.T + t).astype(np.float32) for b in hands},
        "pose": {b.label: b.pose.astype(np.float32) for b in hands if b.pose is not None},
        "K": K,
        "vr": vr,
        "kind": scene.kind,
        "target": scene.target,
        "sides": {b.label: b.side for b in hands},
        "names": {b.label: b.name for b in scene.bodies},
        "stats": {**scene.stats, "camera_distance_m": float(np.linalg.norm(t)),
                  "target_distance_m": depth, "focal_px": float(K[0, 0]),
                  "target_share": framing(target_v, K, image_size, margin)["share"]},
    }
