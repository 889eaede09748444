"""Write the 3D views of the docs page *3D views* (``docs/concepts/views/*.bin``) and their
static pictures (``*.jpg``, shown where JavaScript or WebGL is missing).

Usage: ``PYOPENGL_PLATFORM=egl python tools/draw_3d_views.py [docs/concepts/views]``.
Three payloads of ``handmesh_tutorial.viz.web3d`` (meshcat commands): the right hand in the
"point" pose with its skeleton (template frame, the shared hand camera); one generated
hand-object scene (``make_sample(data.sample_seed(21, i), "hand-object")``, the first seed the
generator accepts) in its camera's frame turned y-up; and the shipped pretrained network's
prediction on that scene's image over the ground truth, the prediction placed at the true root
joint (as the metrics do). The outputs are committed; rerun this script when the hand, the
generator or the shipped network change. Same code, same bytes. Prints each file's size and the
MPJPE of the prediction.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

import handmesh_tutorial as hmt

#: camera-frame data (OpenCV: y down, z forward) turned y-up, seen from near the image's camera
SCENE_VIEW = {"elev": 15.0, "azim": 30.0, "vertical_axis": "y"}
Y_UP = np.array([1.0, -1.0, -1.0])


def hand_view() -> hmt.viz.View3D:
    model = hmt.hand.HandModel("right")
    with torch.no_grad():
        out = model(pose=torch.as_tensor(hmt.hand.example_pose("point", "right"))[None])
    return hmt.viz.view_hand(out.vertices[0], model.faces, colors=model.vertex_colors(),
                             joints=out.joints[0])


def scene_sample() -> dict:
    i = 0
    while True:
        try:
            sample = hmt.scenes.make_sample(hmt.data.sample_seed(21, i), "hand-object", 224)
            sample["seed_index"] = i
            return sample
        except hmt.scenes.InteractionError:
            i += 1


def scene_view(sample: dict) -> hmt.viz.View3D:
    colours = {sample["target"]: "#d9ad94"}
    meshes = {}
    for label, (v, f) in sample["meshes"].items():
        name = sample["names"][label] if "names" in sample else f"body {label}"
        meshes[str(name)] = (np.asarray(v) * Y_UP, f, colours.get(label, "#7f9fbf"))
    return hmt.viz.view_meshes(meshes, view=SCENE_VIEW)


def prediction_view(sample: dict) -> tuple[hmt.viz.View3D, float]:
    t = sample["target"]
    joints = np.asarray(sample["joints"][t], dtype=float)
    uv = joints @ np.asarray(sample["K"]).T
    uv = uv[:, :2] / uv[:, 2:]
    lo, hi = uv.min(0), uv.max(0)
    pred = hmt.inference.predict_hand(sample["image"], (*lo, *hi), sample["sides"][t],
                                      K=sample["K"])
    shift = joints[9] - pred.joints[9]            # root-relative, as the metrics compare
    pv, pj = pred.vertices + shift, pred.joints + shift
    gv = np.asarray(sample["meshes"][t][0], dtype=float)
    if gv.shape != pv.shape:
        raise ValueError(f"ground truth {gv.shape} and prediction {pv.shape} differ in vertices")
    mpjpe = float(np.linalg.norm(pj - joints, axis=1).mean() * 1000)
    view = hmt.viz.view_prediction(pv * Y_UP, gv * Y_UP, pred.faces, pred_joints=pj * Y_UP,
                                   gt_joints=joints * Y_UP, view=SCENE_VIEW)
    return view, mpjpe


def main(argv: list[str]) -> None:
    out = Path(argv[0] if argv else "docs/concepts/views")
    sample = scene_sample()
    pred, mpjpe = prediction_view(sample)
    for name, view in (("hand", hand_view()), ("scene", scene_view(sample)), ("prediction", pred)):
        path = view.save(out / f"{name}.bin")
        picture = view.save_picture(out / f"{name}.jpg")
        print(f"wrote {path} ({path.stat().st_size / 1e3:.0f} kB) and {picture.name} "
              f"({picture.stat().st_size / 1e3:.0f} kB)")
    print(f"prediction: MPJPE {mpjpe:.1f} mm (root-aligned), sample_seed(21, {sample['seed_index']})")


if __name__ == "__main__":
    main(sys.argv[1:])
