"""Pose probe: how many numbers a hand pose needs; does a CNN trained from scratch read them?

Why the CPU models tie the mean training hand (docs page "Why the paper starts from pretrained
weights", "Where the articulation is lost"). Two measurements on INTER-SH roots:

1. **PCA oracle.** The target joints of the training scenes, aligned to their generalised
   Procrustes mean (rotation, translation, scale; no reflection), are summarised by a PCA. For
   each ``k``, the held-out joints are projected on the first ``k`` components and scored with
   PA-MPJPE: how close a model gets that reads *exactly* ``k`` pose numbers from the image.
2. **Probe.** The simplest model that could read them: a ResNet (``--encoder``) with global
   pooling and one linear layer to the first ``k`` PCA coefficients (standardised), trained with
   an L1 loss on the reconstructed aligned joints (mm), Adam 1e-3 halved after three quarters,
   batch 16, on the 64-px crops of the demo (``InterSHTorchDataset``, no augmentation unless
   ``--augment``: random in-plane rotation, scale +-20 %, shift +-10 %, brightness and colour
   offsets, which leave the aligned pose unchanged). The last ``--val`` training scenes are held
   out (same distribution as the training scenes); the test root is scored too.

The probe's numbers are mean PA-MPJPE (mm) of its predicted aligned joints, beside the mean hand
(the constant answer ``k = 0``) on the same scenes. Dev-only (not run by ``make benchmarks``): a
run takes 3-5 CPU minutes. Example::

    handmesh generate --kind mixed --num 3000 --seed 0 --image-size 128 --workers 2 --out D/train
    handmesh generate --kind mixed --num 200 --seed 1 --image-size 128 --balance-vr --out D/test
    handmesh generate --kind mixed --num 9000 --seed 10 --image-size 128 --workers 2 --out D/more
    python benchmarks/dev/pose_probe.py --train D/train --test D/test --cache D/cache --steps 3000
    python benchmarks/dev/pose_probe.py ... --augment
    python benchmarks/dev/pose_probe.py ... --extra D/more
"""

from __future__ import annotations

import argparse
import hashlib
import time
from pathlib import Path

import numpy as np
import torch

import handmesh_tutorial as hmt
from handmesh_tutorial._io import atomic_savez
from handmesh_tutorial.data.torch_views import InterSHTorchDataset
from handmesh_tutorial.metrics import point_errors, procrustes_align


def crops(root: Path, cache: Path, size: int) -> dict:
    """The deterministic crops and target joints of a root (cached as npz: float16 images; the
    file name carries a hash of the root's absolute path, so two roots never share a cache)."""
    key = hashlib.sha1(str(root.resolve()).encode()).hexdigest()[:10]
    f = cache / f"{root.name}_{key}_{size}.npz"
    if f.exists():
        with np.load(f) as z:
            return {k: z[k] for k in z.files}
    ds = InterSHTorchDataset(root, image_size=size, train=False)
    items = [ds[i] for i in range(len(ds))]
    out = {"images": np.stack([it["image"].numpy().astype(np.float16) for it in items]),
           "joints": np.stack([it["joints"].numpy().astype(np.float64) for it in items])}
    cache.mkdir(parents=True, exist_ok=True)
    atomic_savez(f, compressed=False, **out)  # an interrupted run leaves no half-written cache
    return out


def pa_mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean PA-MPJPE (official FreiHAND alignment), mm. ``(N, 21, 3)`` metres."""
    return 1000 * float(point_errors(procrustes_align(pred, gt), gt).mean())


def aligned_to(joints: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Each ``(21, 3)`` set aligned to ``ref`` by a proper similarity transform."""
    return procrustes_align(joints, np.broadcast_to(ref, joints.shape), allow_reflection=False)


def procrustes_mean(joints: np.ndarray, iterations: int = 5) -> np.ndarray:
    ref = joints[0] - joints[0].mean(0)
    for _ in range(iterations):
        ref = aligned_to(joints, ref).mean(0)
    return ref


def augment(x: torch.Tensor) -> torch.Tensor:
    """Random rotation, scale, shift and colour of a batch of normalised crops."""
    b = len(x)
    ang = torch.empty(b).uniform_(-np.pi, np.pi)
    sc = torch.exp(torch.empty(b).uniform_(-0.2, 0.2))
    theta = torch.zeros(b, 2, 3)
    theta[:, 0, 0], theta[:, 0, 1] = torch.cos(ang) * sc, -torch.sin(ang) * sc
    theta[:, 1, 0], theta[:, 1, 1] = torch.sin(ang) * sc, torch.cos(ang) * sc
    theta[:, :, 2] = torch.empty(b, 2).uniform_(-0.1, 0.1)
    grid = torch.nn.functional.affine_grid(theta, x.shape, align_corners=False)
    x = torch.nn.functional.grid_sample(x, grid, align_corners=False, padding_mode="border")
    gain = torch.empty(b, 1, 1, 1).uniform_(0.7, 1.3)
    return x * gain + torch.empty(b, 3, 1, 1).uniform_(-0.1, 0.1)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=Path, required=True)
    ap.add_argument("--test", type=Path, required=True)
    ap.add_argument("--extra", type=Path, help="more training scenes (another root)")
    ap.add_argument("--cache", type=Path, required=True, help="folder for the cached crops")
    ap.add_argument("--image-size", type=int, default=64)
    ap.add_argument("--components", type=int, default=12, help="k, PCA coefficients predicted")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--val", type=int, default=300, help="training scenes held out")
    ap.add_argument("--limit", type=int, help="use only the first N training scenes")
    ap.add_argument("--augment", action="store_true")
    ap.add_argument("--encoder", default="resnet10")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    tr, te = crops(args.train, args.cache, args.image_size), crops(args.test, args.cache,
                                                                   args.image_size)
    n_fit = len(tr["joints"]) - args.val
    ref = procrustes_mean(tr["joints"][:n_fit])
    flat = aligned_to(tr["joints"], ref).reshape(len(tr["joints"]), -1)
    mu = flat[:n_fit].mean(0)
    _, s, vt = np.linalg.svd(flat[:n_fit] - mu, full_matrices=False)
    explained = np.cumsum(s ** 2) / (s ** 2).sum()

    gt, val_gt = te["joints"], tr["joints"][n_fit:]
    print(f"training scenes {n_fit}, validation {args.val}, test {len(gt)}")
    print("explained variance of the first 1..5 components:", np.round(explained[:5], 3))
    template = hmt.nn.model.as_template()
    rest_j = np.asarray(template.joint_regressor) @ hmt.nn.model.root_centred_template(template)
    for name, joints in (("validation", val_gt), ("test", gt)):
        print(f"{name}: rest hand {pa_mpjpe_mm(np.broadcast_to(rest_j, joints.shape), joints):.2f}"
              f" mm, mean hand (k=0) {pa_mpjpe_mm(np.broadcast_to(ref, joints.shape), joints):.2f}"
              " mm")
    test_aligned = aligned_to(gt, ref).reshape(len(gt), -1)
    for k in (1, 2, 3, 5, 8, 12, 20):
        rec = mu + ((test_aligned - mu) @ vt[:k].T) @ vt[:k]
        print(f"  PCA oracle k={k:2d}: {pa_mpjpe_mm(rec.reshape(-1, 21, 3), gt):.2f} mm")

    k = args.components
    coef = (flat - mu) @ vt[:k].T
    sd = coef[:n_fit].std(0)
    images = tr["images"][:n_fit] if args.limit is None else tr["images"][:min(args.limit, n_fit)]
    targets = coef[:len(images)] / sd
    if args.extra is not None:
        more = crops(args.extra, args.cache, args.image_size)
        images = np.concatenate([images, more["images"]])
        extra_flat = aligned_to(more["joints"], ref).reshape(len(more["joints"]), -1)
        targets = np.concatenate([targets, ((extra_flat - mu) @ vt[:k].T) / sd])
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    x_train = torch.from_numpy(images.astype(np.float32))
    y_train = torch.from_numpy(targets.astype(np.float32))
    basis = torch.from_numpy((vt[:k] * sd[:, None]).astype(np.float32))  # coefficient -> m
    mean = torch.from_numpy(mu.astype(np.float32))
    enc = hmt.nn.encoder.build_encoder(args.encoder)
    net = torch.nn.Sequential(enc, torch.nn.Linear(enc.out_features, k))
    opt = torch.optim.Adam(net.parameters(), 1e-3)

    def predict(x: np.ndarray) -> np.ndarray:
        net.eval()
        with torch.no_grad():
            c = torch.cat([net(torch.from_numpy(x[i:i + 64].astype(np.float32)))
                           for i in range(0, len(x), 64)])
        return (mean + c @ basis).numpy().astype(np.float64).reshape(-1, 21, 3)

    print(f"probe: {args.encoder} -> {k} coefficients, {len(x_train)} training crops, "
          f"augment {args.augment}")
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    for step in range(1, args.steps + 1):
        if step == int(0.75 * args.steps) + 1:
            for g in opt.param_groups:
                g["lr"] = 5e-4
        idx = torch.from_numpy(rng.integers(0, len(x_train), 16))
        x = augment(x_train[idx]) if args.augment else x_train[idx]
        net.train()
        loss = (1000 * ((net(x) - y_train[idx]) @ basis)).abs().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 500 == 0 or step == args.steps:
            fit = pa_mpjpe_mm(predict(tr["images"][:300]), tr["joints"][:300])
            val = pa_mpjpe_mm(predict(tr["images"][n_fit:]), val_gt)
            test = pa_mpjpe_mm(predict(te["images"]), gt)
            print(f"  step {step:5d}: training scenes {fit:.2f} mm, validation {val:.2f} mm, "
                  f"test {test:.2f} mm ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
