"""One name per concept on the ``handmesh`` command line; old spellings are hidden and warn."""

from __future__ import annotations

import argparse

import pytest

from handmesh_tutorial.apps import cli


def _help(parser, command: str) -> str:
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices[command].format_help()


def test_data_format_is_dataset_in_train_and_evaluate_and_kind_only_the_scene_kind():
    parser = cli.build_parser()
    for command in ("train", "evaluate"):
        assert "--dataset {intersh,freihand}" in _help(parser, command), command
        assert "--kind" not in _help(parser, command), command
    assert "--kind {hand-hand,hand-object,hand-chain,mixed}" in _help(parser, "generate")
    assert "--dataset" not in _help(parser, "generate")


def test_evaluate_kind_is_a_deprecated_alias_of_dataset(capsys):
    parser = cli.build_parser()
    base = ["evaluate", "--checkpoint", "ck.pt", "--data", "root"]
    args = parser.parse_args([*base, "--dataset", "freihand"])
    assert args.dataset == "freihand" and "deprecated" not in capsys.readouterr().err
    args = parser.parse_args([*base, "--kind", "freihand"])
    assert args.dataset == "freihand"
    err = capsys.readouterr().err
    assert "handmesh evaluate: warning: --kind is deprecated" in err and "use --dataset" in err
    with pytest.raises(SystemExit):  # the alias keeps the choices
        parser.parse_args([*base, "--kind", "coco"])


def test_train_dataloader_workers_are_loader_workers_as_in_pretrain(capsys):
    parser = cli.build_parser()
    assert "--loader-workers" in _help(parser, "train") and "--loader-workers" in _help(
        parser, "pretrain")
    assert parser.parse_args(["train", "--loader-workers", "3"]).num_workers == 3
    assert "deprecated" not in capsys.readouterr().err
    assert parser.parse_args(["train", "--workers", "2"]).num_workers == 2
    assert "--workers is deprecated and will be removed; use --loader-workers" in \
        capsys.readouterr().err
    # --workers keeps its one meaning elsewhere: generator processes
    assert "--workers WORKERS" in _help(parser, "generate")
    assert "--workers WORKERS" not in _help(parser, "train")


def _visible_options(parser) -> dict[str, set[str]]:
    """Each sub-command's option strings shown by ``--help`` (hidden aliases left out)."""
    sub = next(a for a in parser._actions if a.dest == "command")
    return {name: {s for a in p._actions if a.help != argparse.SUPPRESS for s in a.option_strings}
            for name, p in sub.choices.items()}


def test_progress_bars_are_no_progress_and_the_encoder_is_encoder_in_every_command():
    shown = _visible_options(cli.build_parser())
    assert set(shown) == {"demo", "generate", "verify", "train", "pretrain", "pretrain-encoder",
                          "evaluate"}
    for command, options in shown.items():
        assert "--no-progress" in options, command
        assert not options & {"--quiet", "--backbone"}, (command, options & {"--quiet",
                                                                             "--backbone"})
    for command in ("train", "pretrain", "pretrain-encoder"):
        assert "--encoder" in shown[command], command


@pytest.mark.parametrize("argv", [["generate", "--kind", "hand-hand", "--num", "1", "--out", "r"],
                                  ["verify", "r"]])
def test_quiet_is_a_deprecated_alias_of_no_progress(argv, capsys):
    parser = cli.build_parser()
    assert parser.parse_args(argv).no_progress is False
    assert parser.parse_args([*argv, "--no-progress"]).no_progress is True
    assert "deprecated" not in capsys.readouterr().err
    assert parser.parse_args([*argv, "--quiet"]).no_progress is True
    err = capsys.readouterr().err
    assert f"handmesh {argv[0]}: warning: --quiet is deprecated and will be removed; use " \
           "--no-progress" in err


def test_pretrain_encoder_backbone_is_a_deprecated_alias_of_encoder(capsys):
    parser = cli.build_parser()
    assert parser.parse_args(["pretrain-encoder"]).backbone is None  # the recipe's default
    assert parser.parse_args(["pretrain-encoder", "--encoder", "resnet18"]).backbone == "resnet18"
    assert "deprecated" not in capsys.readouterr().err
    assert parser.parse_args(["pretrain-encoder", "--backbone", "resnet34"]).backbone == "resnet34"
    assert "handmesh pretrain-encoder: warning: --backbone is deprecated and will be removed; " \
           "use --encoder" in capsys.readouterr().err
