"""The URDF folder a simulator process writes is removed even when the process was SIGKILLed (campaign workers)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

from bt_meta.world.simulation import sim

CHILD = """
import os, sys, time
from bt_meta.world.robot.description import load_robot
from bt_meta.world.simulation import sim
path = sim._robot_urdf_file(load_robot("baxter"), "light")
print(path, flush=True)
time.sleep(60)
"""


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_only_folders_of_dead_processes_on_this_host_are_removed(tmp_path: Path) -> None:
    host = socket.gethostname()
    dead = tmp_path / f"bt_meta_sim_{host}_{_dead_pid()}_abc"
    alive = tmp_path / f"bt_meta_sim_{host}_{os.getpid()}_abc"
    other_host = tmp_path / f"bt_meta_sim_{host}x_{_dead_pid()}_abc"
    unnamed = tmp_path / "bt_meta_sim_q1w2e3"
    for folder in (dead, alive, other_host, unnamed):
        (folder / "inner").mkdir(parents=True)
    assert sim._remove_orphaned_urdf_folders(tmp_path) == [dead]
    assert not dead.exists() and alive.is_dir() and other_host.is_dir() and unnamed.is_dir()


def test_a_sigkilled_process_leaves_a_folder_the_next_one_removes() -> None:
    child = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    try:
        urdf = Path(child.stdout.readline().strip())
        assert urdf.is_file()
        folder = urdf.parent.parent
        assert folder.name.startswith(f"bt_meta_sim_{socket.gethostname()}_{child.pid}_")
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    assert folder.is_dir()  # nothing ran at exit
    removed = sim._remove_orphaned_urdf_folders(Path(tempfile.gettempdir()))
    assert folder in removed and not folder.exists()
