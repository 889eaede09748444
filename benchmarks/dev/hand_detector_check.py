"""Dev-only check: does a hand detector trained on real photographs find our rendered hands?

Issue criterion: a real-photo detector finds the target hand in >= 90 % of scenes with VR >= 0.95
and >= 60 % of those with VR >= 0.4, and its 3D landmarks agree with our 21 joints to <= 18 mm
after Procrustes alignment with scale (FreiHAND's PA error).

The detector is Google's MediaPipe Hands (legacy ``mediapipe.solutions.hands``: BlazePalm palm
detection + the 21-landmark hand model, both ``.tflite`` files shipped *inside* the wheel, so
nothing is downloaded at run time). ``mediapipe==0.10.21`` is the last release that still has
``solutions.hands`` (0.10.30 dropped it; the Tasks API needs a ``.task`` file from the network).
Licence: Apache-2.0. It is NOT a project dependency: install it in a throw-away venv, never in
the project's.

Two halves, so the two environments never mix:

``generate`` (project venv; ``handmesh_tutorial`` + pyrender, ``PYOPENGL_PLATFORM=egl``) renders
fresh scenes with :func:`handmesh_tutorial.scenes.make_sample` and writes one ``NNNNN.npz``
(+ ``NNNNN.png``) per scene: ``image`` (S,S,3) uint8, ``joints`` (21,3) target hand, camera frame,
metres, FreiHAND order; ``other_joints`` (21,3) of the other hand (hand-hand) or NaN; ``K``;
``vr`` (target); ``side``, ``other_side``, ``kind``, ``seed``, ``tone`` (the target's skin tone,
an index into ``hand.SKIN_TONES``, 0 lightest). ``index.json`` records the seeds.

``detect`` (detector venv; needs only numpy + pillow + mediapipe) runs the detector on every
image and writes ``results.json`` (per scene and summary) and prints the table.

Run (from the repository root, one core): ``generate --num 40`` ~4 min (hand-chain scenes never
reach VR < 0.6, so that kind spends its whole ``--max-candidates``); ``detect`` ~10 s. Baseline
numbers: ``benchmarks/dev/README.md``::

    python3 -m venv /tmp/mpenv && /tmp/mpenv/bin/pip install mediapipe==0.10.21
    PYOPENGL_PLATFORM=egl OMP_NUM_THREADS=1 .venv/bin/python \\
        benchmarks/dev/hand_detector_check.py generate --out /tmp/det --num 40
    OMP_NUM_THREADS=1 /tmp/mpenv/bin/python \\
        benchmarks/dev/hand_detector_check.py detect --data /tmp/det --sheet /tmp/det/sheet.png

Seeds. Scene ``j`` of kind ``k`` (``k`` = position in ``interact.KINDS``: hand-hand 0,
hand-object 1, hand-chain 2) uses ``dataset.sample_seed(seed, 100_000 * k + j)`` with ``--seed``
(default 0); ``j`` runs over candidates (scenes the generator rejects are skipped). With
``--balance-vr`` (default) a candidate is kept only while its VR bin (``visibility.VR_BINS``:
[0.4,0.6) [0.6,0.8) [0.8,0.95) [0.95,1]) has fewer than ``num / 4`` scenes, so every bin is
filled equally (the rarest bin, [0.4,0.6), costs most of the candidates); scenes below 0.4 are
not kept. ``--no-balance-vr`` keeps the first ``num`` scenes, VR as the generator draws it.

Matching rule ("the detector finds the target hand"). For each detection ``d`` and each hand
``h`` in the scene, ``e(d, h)`` = mean over the 21 keypoints of the 2D distance (px) between the
detector's image landmarks and ``h``'s projected joints (same keypoint order, see below). A
detection is assigned to the hand with the smallest ``e``; the target is *found* when a detection
assigned to it has ``e / s <= --match`` (default 0.5), ``s`` = the hand's 2D scale = focal
length x 3D wrist-to-middle-MCP length / depth of the middle MCP (px; a palm length, which does
not shrink when the hand is foreshortened as a 2D bounding box would). Why not "wrist inside the
target's bounding box": our camera crops the target to fill the image (5-15 % margin), so any
detection anywhere would be inside it. The keypoint-wise rule also rejects a detection whose
fingers are assigned wrongly, which a box rule would accept: e.g. the back of our right hand
read as the palm of a left hand (thumb and pinky sides swapped; seen on the clay hand). The
looser ``loc`` diagnostic column ignores finger assignment (a detection's landmark box has IoU
>= 0.5 with the target's projected-joint box, more than with the other hand's); it never enters
the headline rate. The threshold 0.5 is loose on purpose: on the clay-hand baseline correct
detections score 0.07-0.39 and junk ones (a box collapsed on one finger, a wrong
chirality) 0.59-0.64; look at the contact sheet (``--sheet``) when a template or framing changes.

Keypoint order: MediaPipe's ``HandLandmark`` is WRIST, THUMB_CMC, THUMB_MCP, THUMB_IP, THUMB_TIP,
INDEX_MCP..TIP, MIDDLE.., RING.., PINKY.. = FreiHAND's order (0 wrist, 1-4 thumb base to tip, 5-8
index, ... 17-20 pinky) = ours; no permutation. (Our thumb "1" is MANO's thumb base / CMC-ish
joint, MediaPipe's is the CMC: same role.)

3D agreement: ``multi_hand_world_landmarks`` are metric (metres) and hand-centred; they are
aligned to our camera-frame joints by Procrustes with scale, FreiHAND's evaluation
(reflections allowed, as ``metrics.freihand_scores``; re-implemented here in numpy because this
half cannot import the project) and, as a diagnostic, reflection-free. The mean per-keypoint
error after alignment is the PA error (mm).

Per joint: ``detect`` also prints, for the found targets with VR >= 0.4, each joint's error
after alignment and its mean residual (detector minus ours) in the target hand's own frame
(along the palm, across it, along the palm normal); a residual that every scene shares is a
difference of keypoint convention or of our template's anatomy, not noise.

Handedness: MediaPipe labels assume a mirrored (selfie) image; our renders are not mirrored, so
its "Left" means a right hand. We swap its label and report agreement with the scene's ``side``
as a diagnostic only; it is not part of the matching rule.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

VR_BINS = ((0.40, 0.60), (0.60, 0.80), (0.80, 0.95), (0.95, 1.00))  # = visibility.VR_BINS
KIND_NAMES = ("hand-hand", "hand-object", "hand-chain")  # = interact.KINDS
KIND_STRIDE = 100_000
LOC_IOU = 0.5  # the looser "localised" diagnostic: 2D box IoU, finger assignment ignored


def vr_bin(vr: float) -> int:
    """Bin index in :data:`VR_BINS` (half-open, last closed), -1 if none."""
    for i, (lo, hi) in enumerate(VR_BINS):
        if lo <= vr < hi or (i == len(VR_BINS) - 1 and vr == hi):
            return i
    return -1


# ---------------------------------------------------------------------------------------------
# generate (project venv)
# ---------------------------------------------------------------------------------------------
def generate(out: Path, num: int, seed: int, kinds: list[str], image_size: int,
             balance: bool, max_candidates: int, share: tuple[float, float] | None = None,
             photo_prob: float | None = None) -> None:
    """Render ``num`` scenes per kind and write them to ``out`` (see the module docstring)."""
    import torch
    from PIL import Image

    import handmesh_tutorial
    from handmesh_tutorial import scenes as interact
    from handmesh_tutorial.data import SampleRejected, sample_seed
    from handmesh_tutorial.visibility import VR_BINS as PROJECT_BINS

    torch.set_num_threads(1)
    assert tuple(interact.KINDS) == KIND_NAMES, interact.KINDS
    assert tuple(tuple(b) for b in PROJECT_BINS) == VR_BINS, PROJECT_BINS
    out.mkdir(parents=True, exist_ok=True)
    interact.get_renderer(image_size)
    quota = [num // len(VR_BINS) + (i < num % len(VR_BINS)) for i in range(len(VR_BINS))]
    index = []
    t0 = time.perf_counter()
    tried = 0
    drawn = {kind: [0] * (len(VR_BINS) + 1) for kind in kinds}  # candidates per bin, <0.4 first
    for kind in kinds:
        k = KIND_NAMES.index(kind)
        have = [0] * len(VR_BINS)
        kept = 0
        for j in range(max_candidates):
            if kept >= num:
                break
            s_seed = sample_seed(seed, KIND_STRIDE * k + j)
            tried += 1
            try:
                s, scene = interact.make_sample(s_seed, kind=kind, image_size=image_size,
                                                share=share, photo_prob=photo_prob,
                                                return_scene=True)
            except SampleRejected:
                continue
            t = s["target"]
            vr = float(s["vr"][t])
            b = vr_bin(vr)
            drawn[kind][b + 1] += 1
            if balance and (b < 0 or have[b] >= quota[b]):
                continue
            if b >= 0:
                have[b] += 1
            tone = scene.body(t).tone
            others = [lab for lab in s["joints"] if lab != t]
            other = (np.asarray(s["joints"][others[0]], np.float32) if others
                     else np.full((21, 3), np.nan, np.float32))
            name = f"{len(index):05d}"
            np.savez_compressed(
                out / f"{name}.npz", image=s["image"],
                joints=np.asarray(s["joints"][t], np.float32), other_joints=other,
                K=np.asarray(s["K"], np.float64), vr=vr, side=s["sides"][t],
                other_side=s["sides"][others[0]] if others else "", kind=kind, seed=s_seed,
                tone=tone)
            Image.fromarray(s["image"]).save(out / f"{name}.png")
            index.append({"name": name, "kind": kind, "seed": s_seed, "candidate": j, "vr": vr,
                          "side": s["sides"][t], "tone": tone})
            kept += 1
        print(f"{kind}: {kept} scenes from {j + 1} candidates, per VR bin {have} (candidates "
              f"rendered per bin, <0.4 first: {drawn[kind]})"
              + ("" if kept >= num else "  (max_candidates reached)"), flush=True)
    dt = time.perf_counter() - t0
    meta = {"seed": seed, "num_per_kind": num, "kinds": kinds, "image_size": image_size,
            "balance_vr": balance, "frame_share": share, "photo_prob": photo_prob,
            "vr_bins": VR_BINS, "kind_stride": KIND_STRIDE,
            "seed_rule": "dataset.sample_seed(seed, kind_stride * kind_index + candidate)",
            "handmesh_tutorial": getattr(handmesh_tutorial, "__version__", "?"),
            "git": _git_head(), "seconds": round(dt, 1), "candidates": tried,
            "candidate_vr_histogram": {"bins": ["<0.40", *map(str, VR_BINS)], **drawn},
            "scenes": index}
    (out / "index.json").write_text(json.dumps(meta, indent=1))
    print(f"wrote {len(index)} scenes to {out} in {dt:.0f} s ({tried / dt:.1f} candidates/s)")


def _git_head() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=Path(__file__).parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


# ---------------------------------------------------------------------------------------------
# detect (detector venv: numpy + pillow + mediapipe only)
# ---------------------------------------------------------------------------------------------
def procrustes(pred: np.ndarray, gt: np.ndarray, reflection: bool = True) -> np.ndarray:
    """``pred`` (N,3) aligned to ``gt`` (N,3) by rotation, scale and translation.

    FreiHAND's recipe: centre both, divide by their Frobenius norms (+1e-8), orthogonal
    Procrustes via SVD, scale = sum of singular values. ``reflection=False`` forces det(R) = +1.
    """
    mu_p, mu_g = pred.mean(0), gt.mean(0)
    p, g = pred - mu_p, gt - mu_g
    n_p, n_g = np.linalg.norm(p) + 1e-8, np.linalg.norm(g) + 1e-8
    p, g = p / n_p, g / n_g
    u, w, vt = np.linalg.svd(g.T @ p)  # R = argmin ||p R - g||, R = (u vt).T
    if not reflection and np.linalg.det(u @ vt) < 0:
        u[:, -1] *= -1
        w = w.copy()
        w[-1] *= -1
    r = (u @ vt).T
    return (p @ r) * w.sum() * n_g + mu_g


def project(joints: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(21,3) camera-frame points -> (21,2) pixels."""
    x = joints @ K.T
    return x[:, :2] / x[:, 2:3]


def hand_scale_px(joints: np.ndarray, K: np.ndarray) -> float:
    """Palm length in pixels: focal x |wrist - middle MCP| / depth of the middle MCP."""
    return float(K[0, 0] * np.linalg.norm(joints[9] - joints[0]) / joints[9, 2])


def hand_frame(joints: np.ndarray, side: str) -> np.ndarray:
    """(3,3) rows: the hand's own axes from its 21 joints. x: wrist -> middle MCP; z: the palm
    normal (from the index and little-finger MCPs, pointing out of the palm for both sides);
    y = z x x (across the palm)."""
    x = joints[9] - joints[0]
    x = x / np.linalg.norm(x)
    z = np.cross(joints[5] - joints[0], joints[17] - joints[0])
    z = z - x * (z @ x)
    z = z / np.linalg.norm(z)
    if side == "left":            # a mirror image: the cross product flips
        z = -z
    return np.stack([x, np.cross(z, x), z])


JOINT_NAMES = ("wrist", "thumb CMC", "thumb MCP", "thumb IP", "thumb tip") + tuple(
    f"{f} {j}" for f in ("index", "middle", "ring", "little") for j in ("MCP", "PIP", "DIP", "tip"))


def per_joint(recs: list[dict]) -> dict:
    """Per joint over the found targets (VR >= 0.4): the mean error after alignment (mm) and the
    mean residual (detector minus ours, mm) in the target's hand frame (`hand_frame`: along the
    palm, across it, along the palm normal). A residual that is the same in every scene is a
    difference of convention or of our template, not noise; ``pa_if_unbiased_mm`` is the PA
    error with each joint's mean residual subtracted (a bound on what changing where a keypoint
    sits could gain; no re-alignment)."""
    res = np.array([r["residual_hand_mm"] for r in recs
                    if r["found"] and r["vr"] >= 0.40 and "residual_hand_mm" in r])
    if not len(res):
        return {}
    bias = res.mean(0)
    return {"n": len(res), "joints": list(JOINT_NAMES),
            "error_mm": np.linalg.norm(res, axis=2).mean(0).tolist(),
            "bias_mm": bias.tolist(),
            "pa_mm": float(np.linalg.norm(res, axis=2).mean()),
            "pa_if_unbiased_mm": float(np.linalg.norm(res - bias, axis=2).mean())}


def print_per_joint(pj: dict) -> None:
    if not pj:
        return
    print("\n" f"per joint, found targets with VR >= 0.4 (N {pj['n']}): error after alignment and "
          "the mean residual (detector minus ours) in the hand's frame, mm")
    print(f"{'joint':<12} {'error':>6} {'along':>6} {'across':>6} {'normal':>6} {'|mean|':>6}")
    for name, e, b in zip(pj["joints"], pj["error_mm"], pj["bias_mm"], strict=True):
        print(f"{name:<12} {e:6.1f} {b[0]:6.1f} {b[1]:6.1f} {b[2]:6.1f} "
              f"{np.linalg.norm(b):6.1f}")
    print(f"PA {pj['pa_mm']:.1f} mm; with each joint's mean residual removed "
          f"{pj['pa_if_unbiased_mm']:.1f} mm")


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of the axis-aligned 2D boxes of point sets ``a`` and ``b`` (N,2)."""
    lo, hi = np.maximum(a.min(0), b.min(0)), np.minimum(a.max(0), b.max(0))
    inter = float(np.prod(np.clip(hi - lo, 0, None)))
    area = float(np.prod(a.max(0) - a.min(0)) + np.prod(b.max(0) - b.min(0)))
    return inter / (area - inter) if area > inter else 0.0


def _load(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _pad(image: np.ndarray, frac: float) -> tuple[np.ndarray, int]:
    """Image with a border of ``frac`` x its side on every side (mean colour of the image edge)."""
    if frac <= 0:
        return image, 0
    p = int(round(frac * image.shape[0]))
    edge = np.concatenate([image[0], image[-1], image[:, 0], image[:, -1]]).mean(0)
    out = np.empty((image.shape[0] + 2 * p, image.shape[1] + 2 * p, 3), np.uint8)
    out[:] = edge.astype(np.uint8)
    out[p:p + image.shape[0], p:p + image.shape[1]] = image
    return out, p


def run_detector(hands, image: np.ndarray, pad: float) -> list[dict]:
    """Detections on one RGB image: 2D landmarks (21,2) px in the unpadded image, world
    landmarks (21,3) m, handedness as the hand really is (label swapped, see docstring), score."""
    img, p = _pad(image, pad)
    res = hands.process(img)
    dets = []
    if not res.multi_hand_landmarks:
        return dets
    h, w = img.shape[:2]
    for i, lms in enumerate(res.multi_hand_landmarks):
        uv = np.array([[lm.x * w - p, lm.y * h - p] for lm in lms.landmark])
        world = np.array([[lm.x, lm.y, lm.z]
                          for lm in res.multi_hand_world_landmarks[i].landmark])
        cls = res.multi_handedness[i].classification[0]
        side = {"Left": "right", "Right": "left"}[cls.label]  # mirrored-image convention
        dets.append({"uv": uv, "world": world, "side": side, "score": float(cls.score)})
    return dets


def evaluate_scene(scene: dict, dets: list[dict], match: float) -> dict:
    """Match detections to the scene's hands and score the target (see the module docstring)."""
    K = scene["K"]
    hands = [("target", scene["joints"])]
    if not np.isnan(scene["other_joints"]).any():
        hands.append(("other", scene["other_joints"]))
    proj = [project(j, K) for _, j in hands]
    scale = hand_scale_px(scene["joints"], K)
    best = None
    other_found = localised = False
    for d in dets:
        iou = [box_iou(d["uv"], q) for q in proj]
        localised |= int(np.argmax(iou)) == 0 and iou[0] >= LOC_IOU
        e = [float(np.linalg.norm(d["uv"] - q, axis=1).mean()) for q in proj]
        if int(np.argmin(e)) == 0 and (best is None or e[0] < best[0]):
            best = (e[0], d)
        if int(np.argmin(e)) == 1 and e[1] <= match * hand_scale_px(hands[1][1], K):
            other_found = True
    rec = {"num_detections": len(dets), "scale_px": scale, "found": False,
           "other_found": other_found, "localised": localised}
    if best is None:
        return rec
    e2d, d = best
    rec["err2d_px"] = e2d
    rec["err2d_rel"] = e2d / scale
    if e2d / scale > match:
        return rec
    gt = scene["joints"].astype(np.float64)
    aligned = procrustes(d["world"], gt)
    pa = np.linalg.norm(aligned - gt, axis=1).mean() * 1e3
    rec["residual_hand_mm"] = ((aligned - gt) @ hand_frame(gt, str(scene["side"])).T
                               * 1e3).round(3).tolist()
    pa_rot = np.linalg.norm(procrustes(d["world"], gt, reflection=False) - gt, axis=1).mean()
    rec.update(found=True, pa_mm=float(pa), pa_noreflect_mm=float(pa_rot * 1e3),
               side_ok=d["side"] == str(scene["side"]), score=d["score"])
    return rec


def wilson_interval(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a rate ``k / n`` (how far a rate on N scenes can be from
    the generator's true rate: about +-6 points at N = 246)."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return float(centre - half), float(centre + half)


def _summary(recs: list[dict]) -> dict:
    found = [r for r in recs if r["found"]]
    n = len(recs)
    out = {"n": n, "found": len(found), "rate": len(found) / n if n else float("nan"),
           "rate_ci95": wilson_interval(len(found), n),
           "any_detection": sum(r["num_detections"] > 0 for r in recs) / n if n else float("nan"),
           "localised": sum(r["localised"] for r in recs) / n if n else float("nan")}
    if found:
        out["pa_mm"] = float(np.mean([r["pa_mm"] for r in found]))
        out["pa_noreflect_mm"] = float(np.mean([r["pa_noreflect_mm"] for r in found]))
        out["err2d_px"] = float(np.mean([r["err2d_px"] for r in found]))
        out["side_ok"] = float(np.mean([r["side_ok"] for r in found]))
    return out


def summarise(recs: list[dict]) -> dict:
    """Per kind x VR bin, per kind, the headline figures (VR >= 0.95, VR >= 0.4), and those per
    skin tone of the target hand (``tone k``; scenes from ``generate`` record it)."""
    groups = {}
    for kind in [*KIND_NAMES, "all"]:
        rk = [r for r in recs if kind == "all" or r["kind"] == kind]
        if not rk:
            continue
        g = {f"[{lo:.2f},{hi:.2f}{']' if hi == 1 else ')'}":
             _summary([r for r in rk if vr_bin(r["vr"]) == b])
             for b, (lo, hi) in enumerate(VR_BINS)}
        g["<0.40"] = _summary([r for r in rk if r["vr"] < VR_BINS[0][0]])
        g["VR>=0.95"] = _summary([r for r in rk if r["vr"] >= 0.95])
        g["VR>=0.40"] = _summary([r for r in rk if r["vr"] >= 0.40])
        groups[kind] = g
    tones = sorted({r["tone"] for r in recs if r.get("tone") is not None})
    for tone in tones:   # the target's skin tone (SKIN_TONES index, 0 lightest), all kinds
        rt = [r for r in recs if r.get("tone") == tone]
        groups[f"tone {tone}"] = {"VR>=0.95": _summary([r for r in rt if r["vr"] >= 0.95]),
                                  "VR>=0.40": _summary([r for r in rt if r["vr"] >= 0.40])}
    return groups


def _fmt(s: dict) -> str:
    if not s["n"]:
        return f"{'-':>4}"
    pa = f"{s['pa_mm']:7.1f}" if "pa_mm" in s else f"{'-':>7}"
    par = f"{s['pa_noreflect_mm']:7.1f}" if "pa_mm" in s else f"{'-':>7}"
    e2 = f"{s['err2d_px']:6.1f}" if "pa_mm" in s else f"{'-':>6}"
    sd = f"{s['side_ok']:5.2f}" if "pa_mm" in s else f"{'-':>5}"
    return (f"{s['n']:4d} {s['rate']:6.1%} {pa} {par} {e2} {sd} {s['localised']:6.1%} "
            f"{s['any_detection']:6.1%}")


LEGEND = ("found: target found (matching rule); PA / PA+: mean 3D landmark error after "
          "Procrustes with scale, reflections allowed (FreiHAND) / not, over found targets, mm; "
          "2D px: mean 2D landmark error of found targets; side: handedness agreement (label "
          "swapped for unmirrored images); loc: looser diagnostic, a detection's landmark box has "
          f"IoU >= {LOC_IOU} with the target's joint box (finger assignment ignored); any: images "
          "with at least one detection")


def print_table(groups: dict, conf: float) -> None:
    print(f"\nmin_detection_confidence = {conf}")
    print(f"{'kind':<12} {'VR':<13} {'N':>4} {'found':>6} {'PA mm':>7} {'PA+ mm':>7} "
          f"{'2D px':>6} {'side':>5} {'loc':>6} {'any':>6}")
    for kind, g in groups.items():
        for key, s in g.items():
            print(f"{kind:<12} {key:<13} {_fmt(s)}")
        print()


def contact_sheet(data: Path, scenes: list[dict], recs: list[dict], dets: list[list[dict]],
                  path: Path, n: int = 12, zoom: int = 2) -> None:
    """A grid of ``n`` scenes (missed and found, all kinds): target joints green (other hand
    blue), detections red (matched to the target) or orange (not), VR / kind / PA in the title."""
    from PIL import Image, ImageDraw

    per = n // len(KIND_NAMES)
    order = []
    for kind in KIND_NAMES:  # per kind: up to half missed, the rest found, spread over VR
        ks = sorted((i for i, r in enumerate(recs) if r["kind"] == kind),
                    key=lambda i: recs[i]["vr"])
        miss = [i for i in ks if not recs[i]["found"]]
        hit = [i for i in ks if recs[i]["found"]]
        n_hit = min(len(hit), per - min(len(miss), per // 2))
        n_miss = min(len(miss), per - n_hit)
        order += [miss[k] for k in np.linspace(0, len(miss) - 1, n_miss).round().astype(int)]
        order += [hit[k] for k in np.linspace(0, len(hit) - 1, n_hit).round().astype(int)]
    bones = [(0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (0, 9), (9, 10),
             (10, 11), (11, 12), (0, 13), (13, 14), (14, 15), (15, 16), (0, 17), (17, 18),
             (18, 19), (19, 20)]
    tiles = []
    for i in order:
        sc = scenes[i]
        img = Image.fromarray(sc["image"]).resize((sc["image"].shape[1] * zoom,) * 2)
        dr = ImageDraw.Draw(img)

        def skel(uv, colour, width=2, dr=dr):
            for a, b in bones:
                dr.line([tuple(uv[a] * zoom), tuple(uv[b] * zoom)], fill=colour, width=width)
            for q in uv:
                x, y = q * zoom
                dr.ellipse([x - 2, y - 2, x + 2, y + 2], fill=colour)

        skel(project(sc["joints"], sc["K"]), (0, 220, 0))
        if not np.isnan(sc["other_joints"]).any():
            skel(project(sc["other_joints"], sc["K"]), (60, 120, 255))
        for d in dets[i]:
            matched = recs[i]["found"] and abs(
                np.linalg.norm(d["uv"] - project(sc["joints"], sc["K"]), axis=1).mean()
                - recs[i]["err2d_px"]) < 1e-6
            skel(d["uv"], (255, 0, 0) if matched else (255, 150, 0), 1)
        r = recs[i]
        txt = f"{r['kind']} vr={r['vr']:.2f} {'FOUND' if r['found'] else 'miss'}"
        if r["found"]:
            txt += f" PA={r['pa_mm']:.0f}mm"
        dr.rectangle([0, 0, img.width, 14], fill=(0, 0, 0))
        dr.text((3, 1), txt, fill=(255, 255, 255))
        tiles.append(img)
    if not tiles:
        return
    cols = 4
    rows = (len(tiles) + cols - 1) // cols
    w, h = tiles[0].size
    sheet = Image.new("RGB", (cols * w, rows * h), (255, 255, 255))
    for k, t in enumerate(tiles):
        sheet.paste(t, ((k % cols) * w, (k // cols) * h))
    sheet.save(path)
    print(f"contact sheet: {path}")


def detect(data: Path, confs: list[float], match: float, pad: float, model_complexity: int,
           sheet: Path | None, out: Path | None) -> dict:
    """Run MediaPipe Hands on every scene of ``data`` and score it (see the module docstring)."""
    try:
        import mediapipe as mp
    except ImportError:
        sys.exit("detect needs mediapipe: python3 -m venv /tmp/mpenv && "
                 "/tmp/mpenv/bin/pip install mediapipe==0.10.21, then run with /tmp/mpenv")
    names = sorted(p.stem for p in data.glob("*.npz"))
    scenes = [_load(data / f"{n}.npz") for n in names]
    if not scenes:
        sys.exit(f"no scenes in {data}")
    meta = {}
    if (data / "index.json").exists():
        meta = {k: v for k, v in json.loads((data / "index.json").read_text()).items()
                if k != "scenes"}
    result = {"detector": f"mediapipe {mp.__version__} solutions.hands", "data": str(data),
              "generate": meta, "match_rel": match, "pad": pad,
              "model_complexity": model_complexity, "by_confidence": {}}
    for conf in confs:
        t0 = time.perf_counter()
        with mp.solutions.hands.Hands(static_image_mode=True, max_num_hands=2,
                                      model_complexity=model_complexity,
                                      min_detection_confidence=conf) as hands:
            all_dets = [run_detector(hands, sc["image"], pad) for sc in scenes]
        dt = time.perf_counter() - t0
        recs = []
        for n, sc, ds in zip(names, scenes, all_dets, strict=True):
            rec = evaluate_scene(sc, ds, match)
            rec.update(name=n, kind=str(sc["kind"]), vr=float(sc["vr"]), seed=int(sc["seed"]),
                       side=str(sc["side"]),
                       tone=int(sc["tone"]) if "tone" in sc else None)   # older sets: none
            recs.append(rec)
        groups = summarise(recs)
        print_table(groups, conf)
        print(f"({len(scenes)} images in {dt:.1f} s)")
        pj = per_joint(recs)
        print_per_joint(pj)
        result["by_confidence"][str(conf)] = {"summary": groups, "per_joint": pj,
                                              "scenes": recs}
        if sheet is not None and conf == confs[-1]:
            contact_sheet(data, scenes, recs, all_dets, sheet)
    print(LEGEND)
    head = result["by_confidence"][str(confs[-1])]["summary"]["all"]
    ci = {k: "-".join(f"{x:.1%}" for x in head[k]["rate_ci95"]) for k in ("VR>=0.95", "VR>=0.40")}
    print(f"headline (conf {confs[-1]}): found VR>=0.95 {head['VR>=0.95']['rate']:.1%} "
          f"(95 % CI {ci['VR>=0.95']}; target >= 90 %), VR>=0.4 {head['VR>=0.40']['rate']:.1%} "
          f"(95 % CI {ci['VR>=0.40']}; target >= 60 %), "
          f"PA {head['VR>=0.40'].get('pa_mm', float('nan')):.1f} mm (target <= 18 mm)")
    path = out or data / "results.json"
    path.write_text(json.dumps(result, indent=1))
    print(f"wrote {path}")
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd")
    g = sub.add_parser("generate", help="render scenes (project venv)")
    g.add_argument("--out", type=Path, required=True)
    g.add_argument("--num", type=int, default=40, help="scenes per kind")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--kinds", default=",".join(KIND_NAMES))
    g.add_argument("--image-size", type=int, default=224)
    g.add_argument("--frame-share", default=None, metavar="MIN,MAX",
                   help="target hand's box / image side (default: the generator's 0.45,0.75)")
    g.add_argument("--photo-prob", type=float, default=None, metavar="P",
                   help="probability of a photograph as background (default: the generator's "
                        "0.75; 0 = procedural textures only)")
    g.add_argument("--balance-vr", action=argparse.BooleanOptionalAction, default=True)
    g.add_argument("--max-candidates", type=int, default=None,
                   help="per kind (default 15 x num with --balance-vr, else 3 x num)")
    d = sub.add_parser("detect", help="run MediaPipe Hands (detector venv)")
    d.add_argument("--data", type=Path, required=True)
    d.add_argument("--conf", default="0.3,0.5",
                   help="min_detection_confidence values; the last gives the headline")
    d.add_argument("--match", type=float, default=0.5,
                   help="max mean 2D landmark error / palm length (px/px) to count as found")
    d.add_argument("--pad", type=float, default=0.0,
                   help="border added around the image, fraction of its side (0 = as rendered)")
    d.add_argument("--model-complexity", type=int, default=1, choices=(0, 1))
    d.add_argument("--sheet", type=Path, default=None, help="contact sheet PNG")
    d.add_argument("--json", type=Path, default=None, help="default DATA/results.json")
    a = ap.parse_args(argv)
    if a.cmd is None:  # e.g. a loop over benchmarks: nothing to do without arguments
        ap.print_help()
        return 0
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    if a.cmd == "generate":
        if a.max_candidates is None:
            a.max_candidates = (15 if a.balance_vr else 3) * a.num
        kinds = [k.strip() for k in a.kinds.split(",") if k.strip()]
        bad = [k for k in kinds if k not in KIND_NAMES]
        if bad:
            ap.error(f"unknown kinds {bad}")
        share = None if a.frame_share is None else tuple(float(x) for x in a.frame_share.split(","))
        generate(a.out, a.num, a.seed, kinds, a.image_size, a.balance_vr, a.max_candidates,
                 share, a.photo_prob)
    else:
        detect(a.data, [float(c) for c in a.conf.split(",")], a.match, a.pad,
               a.model_complexity, a.sheet, a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
