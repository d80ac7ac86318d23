"""A ``--json`` command's stdout is its JSON document alone, whatever the engines print meanwhile (pybullet's C
code writes URDF warnings to file descriptor 1; Ray's driver prints a lost node's log on ``sys.stdout``)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bt_meta.cli import main
from bt_meta.commands._common import json_document_stdout, print_json

NOISY = """
import os
from bt_meta.commands._common import json_document_stdout, print_json
with json_document_stdout():
    os.write(1, b"b3Warning from C on fd 1\\n")
    print("a Python print")
    print_json({"answer": 42})
print("after the command")
"""


def test_output_on_file_descriptor_1_goes_to_stderr_and_the_document_to_stdout():
    done = subprocess.run([sys.executable, "-c", NOISY], capture_output=True, text=True, timeout=60, check=True)
    document, after = done.stdout.split("}\n", 1)
    assert json.loads(document + "}") == {"answer": 42}
    assert after == "after the command\n"  # stdout is given back when the command ends
    assert "b3Warning from C on fd 1" in done.stderr and "a Python print" in done.stderr


def test_a_captured_stdout_without_a_descriptor_still_gets_the_document_alone(capsys):
    with json_document_stdout():
        print("a Python print")
        print_json({"answer": 42})
    captured = capsys.readouterr()
    assert json.loads(captured.out) == {"answer": 42}
    assert "a Python print" in captured.err


@pytest.mark.slow
def test_a_simulating_command_s_json_parses():
    """A real command that loads URDFs (pybullet prints warnings for links without inertia) through the CLI."""
    done = subprocess.run([sys.executable, "-m", "bt_meta.cli", "run", "trees/letters.yaml", "--problem", "A",
                           "--json"], capture_output=True, text=True, timeout=600, cwd=_repo())
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout)["status"] == "SUCCESS"


def test_main_in_process_prints_the_document_alone(capsys):
    assert main(["plugins", "--json"]) == 0
    assert isinstance(json.loads(capsys.readouterr().out), (list, dict))


def _repo():
    from pathlib import Path

    return Path(__file__).resolve().parents[1]
