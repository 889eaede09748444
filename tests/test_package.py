import subprocess
import sys

import pytest

import handmesh_tutorial as hmt
from handmesh_tutorial.apps import cli


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no_such_module"):
        hmt.no_such_module  # noqa: B018


def test_import_is_light():
    # `import handmesh_tutorial` must not start OpenGL or load torch: submodules load on demand.
    code = ("import sys, handmesh_tutorial; "
            "print(any(m in sys.modules for m in ('torch', 'pyrender', 'OpenGL')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_cli_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    assert exc.value.code == 0
    assert "demo" in capsys.readouterr().out


def test_cli_without_command_prints_help(capsys):
    assert cli.main([]) == 0
    assert "usage: handmesh" in capsys.readouterr().out


def test_cli_rejects_unknown_command(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["fly"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
