"""``sim serve --ros2`` stops with status 0 when SIGTERM lands in the middle of a callback (CI saw exit 1: the
handler shut the context down under a publish, which raised RCLError)."""

from __future__ import annotations

import sys

import pytest

# the served simulator, its state publisher sending SIGTERM to its own process from inside its 5th publish
_SCRIPT = """
import os, signal, sys
import bt_meta.ros2.state_publishers as publishers
original = publishers.StatePublishers.publish
calls = []
def publish(self):
    calls.append(1)
    if len(calls) == 5:
        os.kill(os.getpid(), signal.SIGTERM)
    original(self)
    if len(calls) == 5:
        original(self)  # a second publish after the signal, still inside the same callback
publishers.StatePublishers.publish = publish
from bt_meta.cli import main
sys.exit(main(["sim", "serve", "--ros2", "--scene", "letters_A", "--joint", "left_s0=0.8", "--camera-rate", "0"]))
"""


@pytest.mark.slow
def test_sigterm_inside_a_callback_is_a_clean_stop(loopback_only):
    done = loopback_only(sys.executable, "-c", _SCRIPT)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "bt-meta sim: stopped" in done.stderr and "error" not in done.stderr
