"""The ``handmesh pretrain`` and ``handmesh pretrain-encoder`` commands (docs pages "The
pretrained model" and "Why the paper starts from pretrained weights"): the makers of the two
shipped weight files, kept apart from the everyday commands of ``handmesh_tutorial.apps.cli``."""

from __future__ import annotations

import argparse

__all__ = ["add_pretrain_commands"]


def _cmd_pretrain(args: argparse.Namespace) -> int:
    from .pretrain_network import PretrainedRecipe, build_pretrained

    fields = ("train_scenes", "val_scenes", "data_seed", "render_size", "image_size", "encoder",
              "recipe", "epochs", "batch_size", "lr", "workers", "loader_workers", "seed",
              "device", "precision", "init", "init_encoder", "freeze_encoder", "encoder_lr_scale",
              "augment")
    recipe = PretrainedRecipe(**{k: getattr(args, k) for k in fields
                                 if getattr(args, k) is not None})
    res = build_pretrained(args.out, recipe, max_generate_seconds=args.max_generate_seconds,
                           max_train_seconds=args.max_train_seconds, install=args.install,
                           progress=not args.no_progress, overwrite=args.overwrite,
                           scenes_from=args.scenes_from)
    info = res["info"]
    print(f"handmesh pretrain: {info['data']['train_scenes']} training scenes, "
          f"{info['epochs_done']} of {info.get('epochs_planned', recipe.epochs)} epochs on "
          f"{info['hardware']}, "
          f"{info['seconds']['generate']:.0f} s generating, {info['seconds']['train']:.0f} s "
          f"training -> {res['file']}")
    return 0


def _cmd_pretrain_encoder(args: argparse.Namespace) -> int:
    from .pose_pretraining import PosePretrainConfig, build_pretrained_encoder

    fields = ("train_scenes", "val_scenes", "data_seed", "render_size", "backbone", "batch_size",
              "lr", "max_steps", "seed", "device", "workers", "precision")
    kw = {k: getattr(args, k) for k in fields if getattr(args, k) is not None}
    if args.image_sizes:
        kw["image_sizes"] = args.image_sizes
    if args.init is not None:
        kw["init"] = None if args.init == "none" else args.init
    res = build_pretrained_encoder(args.out, PosePretrainConfig(**kw),
                                   max_generate_seconds=args.max_generate_seconds,
                                   max_train_seconds=args.max_train_seconds,
                                   stop_after=args.stop_after_steps,
                                   install=args.install, progress=not args.no_progress,
                                   overwrite=args.overwrite, scenes_from=args.scenes_from)
    last = res["history"][-1]
    print(f"handmesh pretrain-encoder: {res['info']['data']['train_scenes']} training scenes, "
          f"{last['step']} steps on {res['info']['hardware']}; val PA-MPJPE "
          f"{last['64']['pa_mpjpe']:.2f} mm at 64 px (mean training hand "
          f"{last['mean training hand']['pa_mpjpe']:.2f}) -> {res['file']}")
    return 0


def _sides(text: str) -> tuple[int, ...]:
    """``"64,96,128"`` -> ``(64, 96, 128)``; argparse's error names the option and the form."""
    try:
        return tuple(int(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be comma-separated crop sides in pixels (e.g. "
                                         f"64,96,128), got {text!r}") from None


def add_pretrain_commands(sub) -> None:
    """Add ``pretrain`` and ``pretrain-encoder`` to the ``handmesh`` sub-parsers."""
    from ._cli_types import _out_folder
    from .cli import _DeprecatedAlias  # at call time: cli imports this module
    pre = sub.add_parser("pretrain", help="make the pretrained MSMR-Net: generate scenes, train "
                         "(a GPU when there is one), export a small int8 file (resumable)")
    pre.add_argument("--out", type=_out_folder, default="runs/pretrained",
                     help="output folder (default: runs/pretrained; rerun to resume); a folder "
                     "holding other files is refused unless --overwrite")
    pre.add_argument("--overwrite", action="store_true",
                     help="write into an --out that holds other files (pretrain's files of the "
                     "same names are then replaced, the others left)")
    pre.add_argument("--install", action="store_true",
                     help="copy the result into the package, where hmt.pretrained.pretrained() and "
                     "--checkpoint pretrained find it")
    pre.add_argument("--train-scenes", type=int, help="training scenes (default: 20000)")
    pre.add_argument("--val-scenes", type=int, help="validation scenes (default: 300)")
    pre.add_argument("--data-seed", type=int, help="seed of the training scenes (default: 100; "
                     "validation: the next)")
    pre.add_argument("--render-size", type=int, help="scene image side (default: 224)")
    pre.add_argument("--image-size", type=int, help="network crop side (default: 128)")
    pre.add_argument("--encoder", help="image encoder (default: resnet10)")
    pre.add_argument("--recipe", choices=("cpu", "paper"), help="loss recipe (default: cpu)")
    pre.add_argument("--epochs", type=int, help="training epochs (default: 16)")
    pre.add_argument("--batch-size", type=int, help="batch size (default: 128)")
    pre.add_argument("--lr", type=float, help="Adam learning rate (default: 1e-3)")
    pre.add_argument("--workers", type=int, help="generator processes (default: one per CPU)")
    pre.add_argument("--loader-workers", type=int,
                     help="data-loader processes (default: one per CPU, less one)")
    pre.add_argument("--seed", type=int, help="initialisation / order / augmentation seed")
    pre.add_argument("--device", help="auto | cpu | cuda (default: auto)")
    pre.add_argument("--precision", choices=("float32", "bfloat16"),
                     help="autocast precision (default: bfloat16)")
    pre.add_argument("--init", help="start from these weights: 'pretrained' (the shipped network; "
                     "use new --data-seed values so each run adds scenes) or a checkpoint")
    pre.add_argument("--init-encoder", help="start only the encoder from a pose-encoder file "
                     "(handmesh pretrain-encoder) or a shipped one: neutral, pretrained")
    pre.add_argument("--freeze-encoder", type=int, help="epochs at the start with the encoder "
                     "fixed (>= --epochs without augmentation: each crop encoded once)")
    pre.add_argument("--encoder-lr-scale", type=float,
                     help="the encoder's learning rate as a share of --lr once unfrozen")
    pre.add_argument("--no-augment", dest="augment", action="store_false", default=None,
                     help="no random crop rotation, scale, shift or colour (with a frozen "
                     "encoder: features computed once)")
    pre.add_argument("--max-generate-seconds", type=float, default=None,
                     help="stop generating training scenes when the next shard would end past "
                     "this budget")
    pre.add_argument("--max-train-seconds", type=float, default=None,
                     help="fit training to this budget: the first epoch is timed, then the "
                     "epochs that fit are planned (learning-rate schedule included)")
    pre.add_argument("--scenes-from", metavar="RUN", default=None,
                     help="train on the scenes of another pretrain run, read in its --out folder "
                     "RUN instead of generating them (the same --data-seed, --train-scenes, "
                     "--val-scenes, --render-size): a later stage of a chain, with --init")
    pre.add_argument("--no-progress", action="store_true", help="no progress bars")
    pre.set_defaults(func=_cmd_pretrain)

    pe = sub.add_parser("pretrain-encoder", help="make the pretrained hand image encoder: generate "
                        "scenes, train on 2D keypoints and 3D joints (no mesh decoder), export a "
                        "small int8 file (resumable)")
    pe.add_argument("--out", type=_out_folder, default="runs/pretrained_encoder",
                    help="output folder (default: runs/pretrained_encoder; rerun to resume); a "
                    "folder holding other files is refused unless --overwrite")
    pe.add_argument("--overwrite", action="store_true",
                    help="write into an --out that holds other files (pretrain-encoder's files "
                    "of the same names are then replaced, the others left)")
    pe.add_argument("--install", nargs="?", const="pretrained", default=False,
                    choices=("pretrained", "neutral"),
                    help="copy the result into the package: as the demo's encoder "
                    "(pretrained, the default) or as the decoder-neutral one (neutral), where "
                    "init_encoder='pretrained' / 'neutral' find it")
    pe.add_argument("--train-scenes", type=int, help="training scenes (default: 40000)")
    pe.add_argument("--val-scenes", type=int, help="validation scenes (default: 400)")
    pe.add_argument("--data-seed", type=int, help="seed of the training scenes (default: 900; "
                    "validation: the next)")
    pe.add_argument("--render-size", type=int, help="scene image side (default: 224)")
    pe.add_argument("--image-sizes", type=_sides, help="crop sides trained on, "
                    "comma-separated (default: 64,96,128)")
    pe.add_argument("--encoder", dest="backbone", help="image encoder, a ResNet (default: "
                    "resnet10)")
    pe.add_argument("--backbone", action=_DeprecatedAlias, dest="backbone", canonical="--encoder")
    pe.add_argument("--batch-size", type=int, help="batch size (default: 256)")
    pe.add_argument("--lr", type=float, help="AdamW peak learning rate (default: 2e-3)")
    pe.add_argument("--max-steps", type=int, help="the most training steps (default: 60000)")
    pe.add_argument("--init", help="start from: none (random weights, the default), network (the "
                    "encoder of the shipped MSMR-Net) or a pose-encoder file")
    pe.add_argument("--seed", type=int, help="initialisation / order / augmentation seed")
    pe.add_argument("--device", help="auto | cpu | cuda (default: auto)")
    pe.add_argument("--precision", choices=("float32", "bfloat16"),
                    help="autocast precision (default: bfloat16)")
    pe.add_argument("--workers", type=int, help="generator processes (default: one per CPU)")
    pe.add_argument("--max-generate-seconds", type=float, default=None,
                    help="stop generating training scenes when the next shard would end past "
                    "this budget")
    pe.add_argument("--max-train-seconds", type=float, default=None,
                    help="training budget: the first steps are timed and the steps that fit are "
                    "planned (learning-rate schedule included)")
    pe.add_argument("--scenes-from", metavar="RUN", default=None,
                    help="train on the scenes (and crops) of another pretrain-encoder run, read "
                    "in its --out folder RUN instead of generating them (the same --data-seed, "
                    "--train-scenes, --val-scenes): a later stage of a chain")
    pe.add_argument("--stop-after-steps", type=int, default=None,
                    help="stop after this many steps of the planned --max-steps schedule (the "
                    "learning rate where the plan has it); a rerun without it continues")
    pe.add_argument("--no-progress", action="store_true", help="no progress bars")
    pe.set_defaults(func=_cmd_pretrain_encoder)
