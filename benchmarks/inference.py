"""The inference helper on rendered scenes: its errors with the right inputs and with the mistakes.

For every sample of an INTER-SH root (default: 24 mixed-kind scenes of seed 500, the test seed of
the shipped network, generated into ``--data`` when it is missing), the target hand's box is the
box of its projected mesh (what the evaluation crops use) and its side the annotated one. Rows:

* ``correct``: :func:`hmt.inference.predict_hands` with the image, box, side and ``K``;
* ``float in [0, 1]``: the image divided by 255 but read as 0-255 (what the network saw before
  the helper refused it);
* ``BGR``: the channels reversed (the helper cannot detect it; the docs say so);
* ``wrong side``: every hand passed with the other side (a left hand not mirrored, a right hand
  mirrored);
* ``box_scale 1.0``: a tight crop instead of the training crops' 1.5 margin;
* ``160-px crop``: a crop of another size than the network's 128 px (refused for checkpoints).

Baselines on the same samples: the rest hand and the mean training hand (the Procrustes mean of
48 scenes of seed ``--seed + 1``, ``train.mean_hand``), each predicted for every image; PA-MPJPE
with a 95 % interval over the samples and the network's paired difference to each baseline.

Columns: MPJPE (root-relative, as ``handmesh evaluate``), PA-MPJPE, and, for the ``correct`` row,
the camera-frame error of the placed hand (MPJPE with ``K``) and its root error split into the
image plane (x, y) and depth (z), medians and means, mm.

Run: ``python benchmarks/inference.py [--data /tmp/infer_scenes] [--num 24]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

import handmesh_tutorial as hmt
from handmesh_tutorial import inference as I
from handmesh_tutorial.data.augment import unmirror
from handmesh_tutorial.render.camera import project


def _scores(pred, gt) -> tuple[float, float]:
    s = hmt.metrics.freihand_scores(pred_joints=np.stack(pred), gt_joints=np.stack(gt))
    return s["mpjpe"], s["pa_mpjpe"]


def _raw(net, images: list[torch.Tensor], mirrored: list[bool]) -> list[np.ndarray]:
    """Root-relative joints of crops the helper would refuse, un-mirrored like the helper."""
    with torch.no_grad():
        j = net(torch.stack(images))["joints"].double().numpy()
    return [unmirror(x, m) for x, m in zip(j, mirrored, strict=True)]


def _interval(x) -> str:
    x = np.asarray(x, dtype=float)
    h = 1.96 * x.std(ddof=1) / np.sqrt(len(x))
    return f"{x.mean():.2f} ({x.mean() - h:.2f}, {x.mean() + h:.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/tmp/infer_scenes")
    ap.add_argument("--num", type=int, default=24)
    ap.add_argument("--seed", type=int, default=500)
    args = ap.parse_args()
    torch.set_num_threads(1)
    if not (Path(args.data) / "meta.json").is_file():
        from handmesh_tutorial.apps.cli import main as cli

        cli(["generate", "--kind", "mixed", "--num", str(args.num), "--seed", str(args.seed),
             "--out", args.data, "--no-progress"])
    ds = hmt.data.InterSHDataset(args.data)
    net = hmt.pretrained.pretrained()
    rows: dict[str, list] = {k: [] for k in (
        "correct", "float in [0, 1]", "BGR", "wrong side", "box_scale 1.0", "160-px crop")}
    gt, cam_err, root_xy, root_z = [], [], [], []
    for i in range(min(args.num, len(ds))):
        s = ds[i]
        t = s["target"]
        uv = project(s["meshes"][t][0], s["K"])
        box, side, img, gj = (*uv.min(0), *uv.max(0)), s["sides"][t], s["image"], s["joints"][t]
        gt.append(gj - gj[hmt.metrics.ROOT_INDEX])
        p = I.predict_hand(img, box, side, K=s["K"], model=net, image_size=128)
        q = I.predict_hand(img, box, side, model=net, image_size=128)
        rows["correct"].append(q.joints)
        cam_err.append(1000 * np.linalg.norm(p.joints - gj, axis=1).mean())
        d = 1000 * (p.root - gj[hmt.metrics.ROOT_INDEX])
        root_xy.append(np.linalg.norm(d[:2]))
        root_z.append(abs(d[2]))
        rows["BGR"].append(I.predict_hand(img[..., ::-1], box, side, model=net,
                                          image_size=128).joints)
        other = "right" if side == "left" else "left"
        rows["wrong side"].append(I.predict_hand(img, box, other, model=net,
                                                 image_size=128).joints)
        rows["box_scale 1.0"].append(I.predict_hand(img, box, side, model=net, image_size=128,
                                                    box_scale=1.0).joints)
        rows["160-px crop"].append(I.predict_hand(img, box, side, model=net,
                                                  image_size=160).joints)
        c = q.crop.image
        rows["float in [0, 1]"] += _raw(net, [(c + 0.5) / 255.0 - 0.5], [q.crop.mirrored])
    train_root = Path(f"{args.data}_mean_hand")
    if not (train_root / "meta.json").is_file():
        from handmesh_tutorial.apps.cli import main as cli

        cli(["generate", "--kind", "mixed", "--num", "48", "--seed", str(args.seed + 1),
             "--out", str(train_root), "--no-progress"])
    tmpl = hmt.train.resolve_template(None)
    consts = {"rest hand (no network)": hmt.train.baselines._rest_template(tmpl),
              "mean training hand (no network)": hmt.train.mean_hand(
                  hmt.data.InterSHTorchDataset(train_root, train=False))}
    pa = {"correct": rows["correct"]}
    for name, verts in consts.items():
        _, joints = hmt.train.constant_hand_predictions(verts, tmpl.joint_regressor, len(gt))
        pa[name] = list(joints.double().numpy())
    per = {k: 1000 * hmt.metrics.per_sample_scores(
        pred_joints=np.stack(v), gt_joints=np.stack(gt))["joint_err_pa"].mean(1)
        for k, v in pa.items()}
    print("PA-MPJPE per sample, mean (95 % interval), mm:")
    for k, v in per.items():
        print(f"  {k}: {_interval(v)}")
    for k in consts:
        print(f"  correct minus {k}: {_interval(per['correct'] - per[k])}")
    print(f"{len(gt)} samples of {args.data}; mm")
    print("| input | MPJPE | PA-MPJPE |\n|---|---|---|")
    for name, pred in rows.items():
        m, pa = _scores(pred, gt)
        print(f"| {name} | {m:.1f} | {pa:.1f} |")
    for name, v in (("camera-frame MPJPE (K given)", cam_err), ("root error, x-y", root_xy),
                    ("root error, depth", root_z)):
        print(f"{name}: median {np.median(v):.0f}, mean {np.mean(v):.0f}, max {np.max(v):.0f}")
    depth = np.array([ds[i]["joints"][ds[i]["target"]][9, 2] for i in range(len(gt))])
    print(f"depth of the roots: {depth.min():.2f}-{depth.max():.2f} m; depth error / depth: "
          f"median {np.median(np.array(root_z) / 1000 / depth):.1%}")


if __name__ == "__main__":
    main()
