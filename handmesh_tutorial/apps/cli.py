"""The ``handmesh`` command: ``handmesh --help`` lists the sub-commands.

Each sub-command is a thin wrapper: argument parsing here, the work in the library module that owns
the concept, so everything the command does can also be called from Python or a notebook.

Errors: a library error prints one line on stderr (``handmesh COMMAND: error: ...``, naming the
file, key or shape and what to do) and exits with a code that says what kind of problem it was
([`EXIT_CODES`][handmesh_tutorial.apps.cli.EXIT_CODES]); ``handmesh --debug COMMAND ...`` shows the
full traceback instead. The sub-commands import their library modules when they run, so ``handmesh
--help`` starts fast without torch or OpenGL.

One name per concept: ``--dataset intersh|freihand`` is the data format (``train``,
``evaluate``), ``--kind`` the scene kind (``generate``), ``--workers`` generator processes,
``--loader-workers`` DataLoader processes, ``--encoder`` the image encoder and ``--no-progress``
turns progress bars off. Old spellings (``evaluate --kind``, ``train --workers``, ``--quiet``,
``pretrain-encoder --backbone``) still work, hidden from ``--help``, and warn with the new name.

Taught in notebook 00 ("Quickstart") and notebook 08 ("Training").
"""

from __future__ import annotations

import argparse
import errno
import pickle
import sys
import traceback
import zipfile
from pathlib import Path

from ..budget import budget
from ._cli_pretrain import add_pretrain_commands
from ._cli_types import (
    _channels,
    _degrees_or_none,
    _device,
    _out_folder,
    _positive_int,
    _shard,
    _share,
    _tolerant_output,
)

__all__ = ["EXIT_CODES", "build_parser", "main"]

EXIT_CODES = {"ok": 0, "unexpected": 1, "usage": 2, "bad-input": 3, "not-found": 4,
              "exists": 5, "environment": 6, "interrupted": 130}
"""Exit codes of ``handmesh`` (argparse's own usage errors exit with 2). ``environment``: the
run was stopped by its surroundings, not its inputs: a full disk, a read-only or forbidden
folder, another process holding the writer lock, a killed worker process; fix that and rerun the
same command (it resumes)."""

# errnos of an OSError that mean a name the user gave (exit code 3): too long, a loop of links
_INPUT_ERRNOS = {errno.ENAMETOOLONG, errno.ELOOP}
# errnos of an OSError that mean the machine, not the input or the code (exit code 6)
_ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM,
                       errno.EIO, errno.EMFILE, errno.ENFILE, errno.EBUSY, errno.ETXTBSY}


class _DeprecatedAlias(argparse.Action):
    """An old spelling of an option, hidden from ``--help``: stores into the canonical option's
    ``dest`` and prints a warning naming the canonical spelling (one name per concept)."""

    def __init__(self, option_strings, dest, canonical: str, **kwargs):
        self.canonical = canonical
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog}: warning: {option_string} is deprecated and will be removed; use "
              f"{self.canonical}", file=sys.stderr)
        setattr(namespace, self.dest, True if self.nargs == 0 else values)


def _cmd_demo(args: argparse.Namespace) -> int:
    from . import demo

    init = None if args.init_encoder == "none" else args.init_encoder
    if args.pooling == "global" and args.recipe != "paper":  # before minutes of scenes
        raise ValueError("--pooling global is a choice of --recipe paper; the CPU recipe pools "
                         "at the joints")
    cfg = demo.DemoConfig.from_budget(budget(args.budget), recipe=args.recipe, init_encoder=init,
                                      pooling=args.pooling)
    res = demo.run_demo(args.out, seed=args.seed, config=cfg, progress=not args.no_progress,
                        overwrite=args.overwrite)
    print(f"handmesh demo: report written to {res.report} ({res.seconds['total'] / 60:.1f} min "
          f"this run; budget tier {cfg.budget})")
    print(f"held-out: {res.scores['num_samples']} scenes; '{demo.BASELINE_ROW}' = the "
          f"template's open hand and '{demo.MEAN_ROW}' = the Procrustes mean of the training "
          "meshes, each predicted for every image: the bars to clear after alignment")
    print(demo.headline(res.scores, res.baseline_scores, res.mean_hand_scores,
                        res.pretrained_scores))
    for name, d in (res.differences or {}).items():
        print(f"PA-MPJPE minus {name}: {d['difference']:+.2f} mm (95 % interval {d['low']:+.2f} "
              f"to {d['high']:+.2f}; better on {100 * d['a_better']:.0f} % of the scenes)")
    print(res.comparison or res.table)
    for name in ("overlays", "loss", "pck", "vr", "json"):
        if name in res.files:
            print(f"{name}: {res.files[name]}")
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from ..data import verify_dataset

    report = verify_dataset(args.root, remove=args.remove_bad, progress=not args.no_progress)
    print(f"handmesh verify: {report}")
    if report.error is not None:  # a read-only root: the report above, then the file named
        raise report.error
    if report.disagree:
        raise ValueError(report.advice())
    return 0 if report.ok else EXIT_CODES["bad-input"]


def _cmd_generate(args: argparse.Namespace) -> int:
    from .. import scenes as interact
    from ..data import META_FILE, verify_dataset

    if args.verify and (Path(args.out) / META_FILE).exists():
        report = verify_dataset(args.out, remove=True, progress=not args.no_progress)
        print(f"handmesh generate --verify: {report}")
        # nothing generated while a bad entry is left where a planned sample belongs (it would
        # count as done); entries of indices the set does not plan are listed and left
        in_the_way = [n for n, _ in report.kept if n not in report.unplanned]
        if report.error or report.disagree or in_the_way:
            raise report.error or ValueError(report.advice() or (
                f"{', '.join(in_the_way[:8])} could not be removed (see above), where samples "
                "this set plans belong: move them away, then rerun this command"))

    s = interact.generate_interactions(
        args.out, args.kind, args.num, args.seed, image_size=args.image_size,
        workers=args.workers, balance_vr=args.balance_vr, shard=args.shard, limits=args.limits,
        durable=not args.no_fsync, progress=not args.no_progress, vr_probe=args.vr_probe,
        frame_share=args.frame_share, thumb_zero_elevation=args.thumb_zero_elevation)
    print(f"handmesh generate: {s.written} samples written, {s.skipped} already present "
          f"(skipped), {s.attempts} candidates, {s.samples_per_second:.2f} samples/s, "
          f"{s.seconds:.1f} s -> {s.root}")
    print("target-hand VR histogram:")
    for (lo, hi), n in zip(s.vr_bins, s.vr_histogram, strict=True):
        print(f"  [{lo:.2f}, {hi:.2f}{']' if hi >= 1 else ')'}: {n}")
    print(f"  outside the bins (VR < {s.vr_bins[0][0]:.2f}): {s.vr_outside}")
    if s.vr_probe:
        gone = ", ".join(f"[{lo:.2f}, {hi:.2f}{']' if hi >= 1 else ')'}"
                         for lo, hi in s.vr_unreachable) or "none"
        print(f"VR balancing over the reachable bins; left out: {gone} (probe of "
              f"{s.vr_probe['candidates']} candidates, hits per bin {s.vr_probe['hits']}); "
              f"samples written outside their bin: {s.off_bin}")
    return 0


_TRAIN_OPTIONS = ("data", "dataset", "val_data", "val_fraction", "epochs", "batch_size",
                  "image_size", "lr", "lr_step", "micro_batches", "encoder", "decoder",
                  "channels", "latent_channels", "template", "seed", "device", "threads",
                  "num_workers", "val_every", "checkpoint_every", "precision", "init",
                  "init_encoder", "freeze_encoder", "encoder_lr_scale")


def _cmd_train(args: argparse.Namespace) -> int:
    from .. import train

    overrides = {k: getattr(args, k) for k in _TRAIN_OPTIONS if getattr(args, k) is not None}
    overrides.update(out_dir=args.out, attention=not args.no_attention,
                     augment=not args.no_augment, progress=not args.no_progress,
                     durable=not args.no_fsync, skip_bad=args.skip_bad)
    from .demo.config import RECIPES

    for k, v in RECIPES[args.recipe].items():
        overrides.setdefault(k, v)
    cfg = train.TrainConfig.from_budget(budget(args.budget), **overrides)
    res = train.train(cfg, resume=args.resume, overwrite=args.overwrite)
    if res.rank != 0:
        return 0
    print(f"handmesh train: {res.epochs} epochs, {res.steps} steps, {res.seconds:.1f} s, "
          f"world size {res.world_size}")
    print(f"{'epoch':>5} {'loss (mm)':>10} {'val PA-MPJPE':>13} {'val PA-MPVPE':>13} {'lr':>9}")
    for r in res.history[-10:]:
        print(f"{r['epoch']:>5} {1000 * r['train_loss']:>10.2f} {r['val_pa_mpjpe']:>13.2f} "
              f"{r['val_pa_mpvpe']:>13.2f} {r['lr']:>9.2g}")
    print(f"checkpoint: {res.checkpoint}")
    if res.best_checkpoint is not None:
        print(f"best checkpoint (val PA-MPVPE): {res.best_checkpoint}")
    print(f"metrics: {res.metrics_csv}")
    _print_skipped("train", res.skipped)
    return 0


def _print_skipped(command: str, skipped: list) -> None:
    """The bad samples ``--skip-bad`` left out, one line each (stdout: part of the result)."""
    if not skipped:
        return
    print(f"handmesh {command}: skipped {len(skipped)} bad sample(s) (--skip-bad):")
    for s in skipped:
        where = f"{s['split']} " if "split" in s else ""
        print(f"  {where}sample {s.get('sample', s['index'])}: {s['error']}")


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .. import train

    ev = train.evaluate(args.checkpoint, args.data, kind=args.dataset, split=args.split,
                        image_size=args.image_size, batch_size=args.batch_size,
                        device=args.device, out_dir=args.out, num_samples=args.num,
                        template=args.template, progress=not args.no_progress,
                        threads=args.threads, camera_frame=not args.network_frame,
                        skip_bad=args.skip_bad, overwrite=args.overwrite)
    from .demo import BASELINE_ROW, headline

    sc = ev["scores"]
    n, planned = ev["num_samples"], ev.get("planned")
    scored = (f"scored {n} of {planned} planned samples" if planned not in (None, n)
              else f"{n} samples")
    print(f"handmesh evaluate: {scored} of {args.data} (targets centred at "
          f"joint 9; '{BASELINE_ROW}' = the template's open hand for every image)")
    print(headline(sc, ev["baseline"]["scores"]))
    if "mpvpe" in sc:  # joints only when the network's mesh is not the data's (a note says so)
        print(f"MPVPE {sc['mpvpe']:.2f} mm, AUC vertices {sc['auc_verts']:.3f} (0-50 mm)")
    print(ev["comparison"])
    for name, path in ev["files"].items():
        print(f"{name}: {path}")
    for note in ev.get("notes", []):
        print(f"note: {note}")
    _print_skipped("evaluate", ev["skipped"])
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of the ``handmesh`` command (sub-commands included)."""
    parser = argparse.ArgumentParser(prog="handmesh", description="MSMR-Net tutorial toolkit: "
                                     "generate INTER-SH scenes, train, evaluate, demo.")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error instead of one line")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser("demo", help="generate a VR-balanced INTER-SH set, train MSMR-Net on "
                          "CPU, evaluate on held-out scenes, write OUT/report.md (resumable)")
    demo.add_argument("--out", type=_out_folder, default="runs/demo",
                      help="output folder (default: runs/demo); a folder holding files the demo "
                      "did not write is refused unless --overwrite")
    demo.add_argument("--overwrite", action="store_true",
                      help="write into an --out that holds other files (the demo's files of "
                      "the same names are replaced, the others left)")
    demo.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    demo.add_argument("--budget", choices=("smoke", "default", "full"), default=None,
                      help="size tier (default: HANDMESH_BUDGET, else default)")
    demo.add_argument("--recipe", choices=("cpu", "paper"), default="cpu",
                      help="training recipe: 'cpu' (default: 2D keypoint head, global-rotation "
                      "head, skinned output, keypoint and aligned-joint losses beside L1) or "
                      "'paper' (the paper's network and loss: the decoder regresses the vertex "
                      "coordinates, one L1 loss on them)")
    demo.add_argument("--pooling", choices=("joints", "global"), default="joints",
                      help="--recipe paper only: read the pretrained encoder at its own 2D joints "
                      "(default) or its ResNet part globally pooled, as the paper's encoder")
    demo.add_argument("--init-encoder", default="pretrained",
                      metavar="pretrained|neutral|none|FILE",
                      help="where the encoder starts: the shipped pretrained hand encoder "
                      "(default, the paper's protocol), the shipped decoder-neutral one, none "
                      "(random weights) or a pose-encoder file; the rest of the network starts "
                      "from random weights")
    demo.add_argument("--no-progress", action="store_true", help="no progress bars")
    demo.set_defaults(func=_cmd_demo)

    gen = sub.add_parser("generate", help="generate (or resume) an INTER-SH dataset of rendered "
                         "hand-hand / hand-object / hand-chain interactions")
    gen.add_argument("--kind", required=True,
                     choices=("hand-hand", "hand-object", "hand-chain", "mixed"),
                     help="scene kind; mixed draws one per sample")
    gen.add_argument("--num", type=int, required=True, help="samples in the whole dataset")
    gen.add_argument("--seed", type=int, default=0, help="base seed (default: 0)")
    gen.add_argument("--out", type=_out_folder, required=True,
                     help="output folder (rerun to resume)")
    gen.add_argument("--image-size", type=int, default=224, help="image side in pixels "
                     "(default: 224)")
    gen.add_argument("--workers", type=int, default=1, help="worker processes (default: 1)")
    gen.add_argument("--balance-vr", action="store_true",
                     help="equal numbers of samples per VR bin of the target hand; bins that a "
                     "probe of candidates (almost) never reaches, e.g. [0.40, 0.60) for "
                     "hand-chain, are reported up front and left out")
    gen.add_argument("--vr-probe", type=int, default=64, metavar="N",
                     help="candidates of the --balance-vr probe (default: 64)")
    gen.add_argument("--shard", type=_shard, default=None, metavar="K/N",
                     help="make only shard K of N (merge with dataset.merge_shards)")
    gen.add_argument("--limits", choices=("anatomical", "paper"), default="anatomical",
                     help="joint limits of the hands: anatomical (default: natural poses) or "
                     "paper (+-60 deg about every LCS axis, the paper's generator)")
    gen.add_argument("--frame-share", type=_share, default=None, metavar="MIN,MAX",
                     help="share of the image side covered by the target hand's bounding box "
                     "(default: 0.45,0.75, FreiHAND-like crops; smaller shows more arm and "
                     "surroundings)")
    gen.add_argument("--thumb-zero-elevation", type=_degrees_or_none,
                     default=5.0, metavar="DEG|none",  # = lcs.THUMB_ZERO_ELEVATION_DEG (tested)
                     help="degrees out of the palm plane that the thumb's zero angles mean "
                     "(default: 5, a thumb near the palm plane as anatomical ranges assume; "
                     "'none': the template's half-opposed rest thumb, the generator before "
                     "this option)")
    gen.add_argument("--no-fsync", action="store_true",
                     help="skip fsync of every file (faster, not safe against power cuts)")
    gen.add_argument("--verify", action="store_true",
                     help="before resuming, re-read every sample already in OUT and remove "
                     "the unreadable ones, so that this run writes them again (a meta.json "
                     "that disagrees with the samples stops it: nothing removed)")
    gen.set_defaults(func=_cmd_generate)

    ver = sub.add_parser("verify", help="re-read every sample of an INTER-SH root and list the "
                         "unreadable ones and those that disagree with meta.json (exit code 3 "
                         "if any)")
    ver.add_argument("root", help="the dataset folder (with meta.json)")
    ver.add_argument("--remove-bad", action="store_true",
                     help="delete the unreadable sample folders meta.json plans (their "
                     "sample files only: anything else is listed and left); the generate "
                     "command that made ROOT then writes them again, byte for byte")
    ver.set_defaults(func=_cmd_verify)
    for p in (gen, ver):  # --quiet: their old spelling
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
        p.add_argument("--quiet", action=_DeprecatedAlias, nargs=0, dest="no_progress",
                       canonical="--no-progress")

    tr = sub.add_parser("train", help="train MSMR-Net on an INTER-SH (or FreiHAND) root; "
                        "sizes default to the HANDMESH_BUDGET tier; works under torchrun")
    tr.add_argument("--data", help="training data root (with --resume: may name where the "
                    "run's data moved; the same data is checked by its fingerprint)")
    tr.add_argument("--dataset", choices=("intersh", "freihand"), help="data format "
                    "(default: intersh)")
    tr.add_argument("--val-data", help="separate validation root (default: hold out "
                    "--val-fraction of --data)")
    tr.add_argument("--val-fraction", type=float, help="held-out share (default: 0.1)")
    tr.add_argument("--out", type=_out_folder, default="runs/train",
                    help="output folder (default: runs/train); a folder holding files train did "
                    "not write is refused unless --overwrite")
    tr.add_argument("--budget", choices=("smoke", "default", "full"), default=None,
                    help="size tier for epochs / batch / image size / threads (default: "
                    "HANDMESH_BUDGET)")
    tr.add_argument("--epochs", type=_positive_int)
    tr.add_argument("--batch-size", type=_positive_int, help="global batch size")
    tr.add_argument("--image-size", type=int)
    tr.add_argument("--lr", type=float, help="Adam learning rate (default: 1e-4)")
    tr.add_argument("--lr-step", type=int, help="epochs between halvings (default: epochs/4)")
    tr.add_argument("--micro-batches", type=int, help="gradient-accumulation chunks per rank")
    tr.add_argument("--encoder", help="resnet18 | resnet34 | resnet50 | hrnet18")
    tr.add_argument("--decoder", choices=("multi", "single"))
    tr.add_argument("--no-attention", action="store_true", help="no coarse-mesh transformer")
    tr.add_argument("--channels", type=_channels, help="decoder channels, finest first")
    tr.add_argument("--latent-channels", type=int)
    tr.add_argument("--template", help="mesh template: a .npz of train.save_template or your "
                    "MANO_RIGHT.pkl (default: the MakeHuman hand)")
    tr.add_argument("--seed", type=int)
    tr.add_argument("--device", type=_device, help="auto | cpu | cuda | cuda:N | mps")
    tr.add_argument("--threads", type=_positive_int, help="torch threads")
    tr.add_argument("--precision", choices=("float32", "bfloat16"),
                    help="bfloat16: autocast forward pass (faster on CPUs with bf16 units)")
    tr.add_argument("--loader-workers", dest="num_workers", type=int,
                    help="DataLoader worker processes (as in handmesh pretrain; --workers of "
                    "generate and pretrain are generator processes)")
    tr.add_argument("--workers", action=_DeprecatedAlias, dest="num_workers", type=int,
                    canonical="--loader-workers")
    tr.add_argument("--init", help="start from these weights: a checkpoint, or 'pretrained'")
    tr.add_argument("--recipe", choices=("paper", "cpu"), default="paper",
                    help="loss terms and heads (default: paper, the L1 vertex loss; cpu: the "
                    "demo's keypoint encoder, rotation head, skinned output and extra losses)")
    tr.add_argument("--init-encoder", metavar="pretrained|FILE",
                    help="start the encoder from the shipped pretrained hand encoder or a "
                    "pose-encoder file (needs --recipe cpu --encoder resnet10)")
    tr.add_argument("--freeze-encoder", type=int, metavar="EPOCHS",
                    help="keep the encoder fixed for the first EPOCHS epochs (default: 0)")
    tr.add_argument("--encoder-lr-scale", type=float,
                    help="the encoder's learning rate as a share of --lr (default: 1)")
    tr.add_argument("--val-every", type=int, help="validate every N epochs")
    tr.add_argument("--checkpoint-every", type=int, help="checkpoint every N epochs")
    tr.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint_last.pt")
    tr.add_argument("--overwrite", action="store_true",
                    help="start afresh in an OUT that already holds a run (all its files are "
                    "removed first: checkpoints, logs, config.json); without --resume or "
                    "--overwrite such an OUT is refused. Also writes into an OUT holding files "
                    "train did not write (those are left)")
    tr.add_argument("--skip-bad", action="store_true",
                    help="load every sample once first, leave out those that cannot be read and "
                    "list them at the end (default: the first bad sample stops the run, named)")
    tr.add_argument("--no-augment", action="store_true", help="no data augmentation")
    tr.add_argument("--no-progress", action="store_true", help="no progress bars")
    tr.add_argument("--no-fsync", action="store_true",
                    help="skip fsync of checkpoints and logs (faster, not safe against power cuts)")
    tr.set_defaults(func=_cmd_train)

    add_pretrain_commands(sub)

    ev = sub.add_parser("evaluate", help="evaluate a checkpoint: FreiHAND-style scores and the "
                        "table per visibility-ratio bin")
    ev.add_argument("--checkpoint", required=True,
                    help="a checkpoint_*.pt of handmesh train, or 'pretrained' (the shipped "
                    "network)")
    ev.add_argument("--data", required=True, help="INTER-SH root (or FreiHAND root)")
    ev.add_argument("--dataset", choices=("intersh", "freihand"), default=None,
                    help="data format (default: the format the checkpoint was trained on)")
    ev.add_argument("--kind", action=_DeprecatedAlias, dest="dataset", canonical="--dataset",
                    choices=("intersh", "freihand"))
    ev.add_argument("--split", default="evaluation", help="FreiHAND split (default: evaluation)")
    ev.add_argument("--out", type=_out_folder, default=None,
                    help="write eval.json, predictions.npz and figures (an earlier evaluation's "
                    "files there are replaced as a set; a folder holding files evaluate did not "
                    "write is refused unless --overwrite)")
    ev.add_argument("--overwrite", action="store_true",
                    help="write into an --out that holds other files (evaluate's files of the "
                    "same names are replaced, the others left)")
    ev.add_argument("--image-size", type=int, default=None, help="default: the checkpoint's")
    ev.add_argument("--batch-size", type=_positive_int, default=16)
    ev.add_argument("--num", type=int, default=None, help="only the first N samples")
    ev.add_argument("--device", type=_device, default="auto")
    ev.add_argument("--threads", type=_positive_int, default=None)
    ev.add_argument("--template", default=None, help="the template used for training (.npz "
                    "or MANO_RIGHT.pkl; default: the one the checkpoint names)")
    ev.add_argument("--network-frame", action="store_true",
                    help="store predictions in the network frame, not the camera frame")
    ev.add_argument("--skip-bad", action="store_true",
                    help="load every sample once first, leave out those that cannot be read and "
                    "list them at the end (default: the first bad sample stops, named)")
    ev.add_argument("--no-progress", action="store_true", help="no progress bar")
    ev.set_defaults(func=_cmd_evaluate)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``handmesh`` console script; returns the exit code."""
    _tolerant_output()
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    from .._io import claim_state, release_claim

    before = claim_state(getattr(args, "out", None))
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"handmesh {args.command}: interrupted (rerun the same command to resume)",
              file=sys.stderr)
        return EXIT_CODES["interrupted"]
    except Exception as err:  # noqa: BLE001 - every error becomes one line + an exit code
        release_claim(before)  # a refused command leaves no marker, lock or empty --out
        if args.debug:
            traceback.print_exc()
        kind = error_kind(err)
        print(f"handmesh {args.command}: error: {error_message(err)}", file=sys.stderr)
        if not args.debug:
            print(f"(exit code {EXIT_CODES[kind]}: {kind}; run `handmesh --debug "
                  f"{args.command} ...` for the traceback)", file=sys.stderr)
        return EXIT_CODES[kind]


def error_kind(err: BaseException) -> str:
    """The [`EXIT_CODES`][handmesh_tutorial.apps.cli.EXIT_CODES] key of an exception raised by a
    sub-command: bad input (3, 4, 5) vs the environment (6: disk, permissions, lock, a killed
    worker) vs a bug (1)."""
    from .._io import EnvironmentFailure

    if isinstance(err, FileExistsError):
        return "exists"
    if isinstance(err, FileNotFoundError | NotADirectoryError | IsADirectoryError):
        return "not-found"
    if isinstance(err, EnvironmentFailure) or (isinstance(err, OSError)
                                               and err.errno in _ENVIRONMENT_ERRNOS):
        return "environment"
    if isinstance(err, ValueError | KeyError | pickle.UnpicklingError | zipfile.BadZipFile
                  | EOFError | FloatingPointError) or (isinstance(err, OSError)
                                                       and err.errno in _INPUT_ERRNOS):
        return "bad-input"
    return "unexpected"  # TypeError, IndexError, ...: most likely a bug of ours


_ENVIRONMENT_HINTS = {
    errno.ENOSPC: "free some space or choose another output folder",
    errno.EDQUOT: "free some space or choose another output folder",
    errno.EROFS: "the file system is read-only: choose another output folder",
    errno.EACCES: "no permission: choose another output folder or fix its permissions",
    errno.EPERM: "no permission: choose another output folder or fix its permissions",
}


def error_message(err: BaseException) -> str:
    """One line for a user: the library's message (at most its first three lines joined)."""
    text = str(err) if str(err) else type(err).__name__
    if isinstance(err, OSError) and err.errno in _ENVIRONMENT_ERRNOS and err.strerror:
        where = f": {err.filename}" if err.filename is not None else ""
        text = f"{err.strerror}{where} ({_ENVIRONMENT_HINTS.get(err.errno, 'fix that')}, then " \
               "rerun the same command: it resumes)"
    if isinstance(err, KeyError) and err.args:
        text = f"missing key {err.args[0]!r}"
    if text.startswith("Caught ") and "Original Traceback" in text:
        # re-raised from a DataLoader worker: the original error is the traceback's last line
        last = text.strip().splitlines()[-1].strip()
        text = last.split(": ", 1)[1] if ": " in last else last
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return " ".join(lines) if len(lines) <= 3 else " ".join(lines[:3]) + " ..."


if __name__ == "__main__":
    sys.exit(main())
