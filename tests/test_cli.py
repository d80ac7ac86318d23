"""The CLI's contract: version, usage errors exit 2 with one line and no traceback."""

from __future__ import annotations

import subprocess
import sys

import bt_meta
from bt_meta.cli import main


def test_version_is_printed(capsys):
    try:
        main(["--version"])
    except SystemExit as exit_:
        assert exit_.code == 0
    assert capsys.readouterr().out.strip() == f"bt-meta {bt_meta.__version__}"


def test_unknown_command_exits_2_without_traceback():
    result = subprocess.run(
        [sys.executable, "-m", "bt_meta.cli", "no-such-command"], capture_output=True, text=True, check=False
    )
    assert result.returncode == 2
    assert "invalid choice" in result.stderr
    assert "Traceback" not in result.stderr


def test_no_command_prints_help_and_exits_2(capsys):
    assert main([]) == 2
    assert "COMMAND" in capsys.readouterr().out
