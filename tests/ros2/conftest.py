"""Real rclpy processes for the ROS 2 tests, each process tree in a network namespace with only loopback.

The served simulator starts under ``unshare -n`` (loopback up, nothing else), and the ROS 2 world joins its
namespace with ``nsenter --net``: DDS can reach nothing but this machine's loopback in there. Every test has a
``ROS_DOMAIN_ID`` of its own and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``. Without the ``[ros2]`` extra, or
without ``unshare``/``nsenter``/``ip`` and the right to make a namespace (root), the tests skip and say why.
"""

from __future__ import annotations

import importlib.util
import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BT_META = [sys.executable, "-m", "bt_meta.cli"]
_DOMAINS = itertools.count(100 + (os.getpid() % 50) * 2)


def _skip_reason() -> str | None:
    try:
        found = importlib.util.find_spec("rclpy") is not None
    except (ImportError, ValueError):  # blocked in sys.modules
        found = False
    if not found:
        return "needs the [ros2] extra: pip install 'bt-meta[ros2]'"
    for tool in ("unshare", "nsenter", "ip"):
        if shutil.which(tool) is None:
            return f"needs {tool} (util-linux, iproute2) to keep DDS in a loopback-only network namespace"
    probe = subprocess.run(["unshare", "-n", "true"], capture_output=True, check=False)
    if probe.returncode != 0:
        return "cannot create a network namespace here (unshare -n needs root)"
    return None


REASON = _skip_reason()


def default_sigint() -> None:
    """A child's SIGINT as a terminal gives it, whatever this pytest inherited (a background job ignores SIGINT,
    and an ignored SIGINT is kept across exec): the tests that send Ctrl-C assert on what the default does."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def pytest_collection_modifyitems(config, items):
    """Every test here that starts ROS 2 processes (uses ``serve`` or ``loopback_only``) skips with the reason."""
    if REASON is None:
        return
    for item in items:
        if {"serve", "loopback_only"} & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.skip(reason=REASON))


def _environment(domain: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    env.pop("ROS_STATIC_PEERS", None)
    return env


class Served:
    """``bt-meta sim serve --ros2`` in a fresh loopback-only network namespace; ``run()`` starts bt-meta in it."""

    def __init__(self, tmp_path: Path, *args: str) -> None:
        self.domain = next(_DOMAINS)
        self.env = _environment(self.domain)
        self.log = tmp_path / f"serve-{self.domain}.log"
        command = " ".join(["ip link set lo up && exec", *(_quote(a) for a in [*BT_META, "sim", "serve", "--ros2",
                                                                                 *args])])
        self.process = subprocess.Popen(["unshare", "-n", "sh", "-c", command], cwd=ROOT, env=self.env,
                                        stdout=subprocess.DEVNULL, stderr=open(self.log, "w"))  # noqa: SIM115
        deadline = time.monotonic() + 240  # the first start generates control_msgs (about a minute)
        while "ready" not in self.log.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise AssertionError(f"sim serve did not start: {self.log.read_text()[-2000:]}")
            time.sleep(0.2)

    def command(self, *args: str) -> list[str]:
        return ["nsenter", f"--net=/proc/{self.process.pid}/ns/net", *BT_META, *args]

    def run(self, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
        return subprocess.run(self.command(*args), cwd=ROOT, env=self.env, capture_output=True, text=True,
                              timeout=timeout, check=False)

    def start(self, *args: str) -> subprocess.Popen:
        return subprocess.Popen(self.command(*args), cwd=ROOT, env=self.env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)

    def stop(self) -> int | None:
        return stop_process(self.process)


def stop_process(process: subprocess.Popen) -> int | None:
    """SIGTERM, then SIGKILL after 20 s: a served process stopped as its users stop it, never left behind."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def _quote(text: str) -> str:
    import shlex

    return shlex.quote(text)


@pytest.fixture
def serve(tmp_path):
    """``serve(*args)`` -> a :class:`Served`; stopped after the test."""
    started: list[Served] = []

    def start(*args: str) -> Served:
        served = Served(tmp_path, *args)
        started.append(served)
        return served

    yield start
    for served in started:
        served.stop()


@pytest.fixture
def loopback_only():
    """``loopback_only(*command)`` runs a command in a fresh loopback-only namespace (for the no-server case)."""

    def run(*command: str, domain: int | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
        env = _environment(domain if domain is not None else next(_DOMAINS))
        script = " ".join(["ip link set lo up && exec", *(_quote(a) for a in command)])
        return subprocess.run(["unshare", "-n", "sh", "-c", script], cwd=ROOT, env=env, capture_output=True,
                              text=True, timeout=timeout, check=False)

    return run
