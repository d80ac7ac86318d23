"""control_msgs, generated at first use from the Jazzy definitions kept in this package (no network needed).

``control_msgs`` (FollowJointTrajectory, GripperCommand) is not on PyPI, but the interface generators are (the
``[ros2]`` extra installs them). The few definitions bt-meta uses are kept in ``interfaces/control_msgs/`` exactly
as in ros-controls/control_msgs, branch ``jazzy`` (5.8.0, BSD-3-Clause, its LICENSE beside them). At first use
they are generated with cmake and the C/C++ compiler into a cache folder keyed by the definitions and the Python
environment, under a file lock (a server and a client starting together generate once), then imported from there.
Interfaces must match the robot's distro: Jazzy's FollowJointTrajectory feedback differs from later distros', and
mismatched definitions lose feedback silently (docs/ros2.md).

Offers:

* :func:`cache_root` -- ``$BT_META_ROS2_CACHE``, else ``$XDG_CACHE_HOME/bt-meta/ros2`` (``~/.cache``)
* :func:`generated_prefix` -- the install prefix of the generated package, generating it when absent
* :func:`load_control_msgs` -- import path and shared libraries in place; returns the ``control_msgs`` module
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

from bt_meta.ros2.errors import InterfaceGenerationError, Ros2Unavailable

__all__ = ["DEFINITIONS", "cache_root", "generated_prefix", "load_control_msgs"]

DEFINITIONS = Path(__file__).parent / "interfaces" / "control_msgs"
_PACKAGE = "control_msgs"
_loaded: ModuleType | None = None


def cache_root() -> Path:
    explicit = os.environ.get("BT_META_ROS2_CACHE")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "bt-meta" / "ros2"


def _key() -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in DEFINITIONS.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(DEFINITIONS)).encode())
        digest.update(path.read_bytes())
    digest.update(f"{sys.prefix}|{sys.version_info[:2]}".encode())
    return digest.hexdigest()[:16]


def _site_packages(prefix: Path) -> Path:
    return prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"


def generated_prefix() -> Path:
    """The install prefix of the generated package (``lib/``, ``share/``), generated under a lock when absent."""
    root = cache_root()
    prefix = root / f"{_PACKAGE}-{_key()}"
    if (_site_packages(prefix) / _PACKAGE / "__init__.py").is_file():
        return prefix
    root.mkdir(parents=True, exist_ok=True)
    with open(root / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (_site_packages(prefix) / _PACKAGE / "__init__.py").is_file():
            _generate(prefix)
    return prefix


def _generate(prefix: Path) -> None:
    for tool in ("cmake", "cc", "c++"):
        if shutil.which(tool) is None:
            raise InterfaceGenerationError(f"generating {_PACKAGE} needs {tool!r} on PATH (cmake and a C/C++ "
                                           "compiler: apt-get install cmake g++)")
    env_prefix = Path(sys.prefix)
    if not (env_prefix / "share" / "rosidl_default_generators").is_dir():
        raise Ros2Unavailable("generating control_msgs needs the interface generators of the extra: "
                              "pip install 'bt-meta[ros2]'")
    partial = prefix.with_name(prefix.name + ".partial")
    build = prefix.with_name(prefix.name + ".build")
    for folder in (partial, build):
        shutil.rmtree(folder, ignore_errors=True)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(p for p in (str(env_prefix), env.get("AMENT_PREFIX_PATH")) if p)
    env["PATH"] = os.pathsep.join((str(env_prefix / "bin"), env.get("PATH", "")))
    started = time.monotonic()
    steps = [
        ["cmake", "-S", str(DEFINITIONS), "-B", str(build), f"-DCMAKE_PREFIX_PATH={env_prefix}",
         f"-DCMAKE_INSTALL_PREFIX={partial}", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
         "-DCMAKE_BUILD_TYPE=Release", f"-DCMAKE_INSTALL_RPATH={prefix / 'lib'};{env_prefix / 'lib'}"],
        ["cmake", "--build", str(build), "-j", str(max(1, min(4, os.cpu_count() or 1)))],
        ["cmake", "--install", str(build)],
    ]
    log = build.with_suffix(".log")
    build.mkdir(parents=True)
    with open(log, "w") as out:
        for step in steps:
            done = subprocess.run(step, env=env, stdout=out, stderr=subprocess.STDOUT, check=False)
            if done.returncode != 0:
                raise InterfaceGenerationError(f"generating {_PACKAGE} failed at `{' '.join(step[:3])}` "
                                               f"(exit {done.returncode}); the log: {log}")
        out.write(f"generated in {time.monotonic() - started:.1f} s\n")
    os.replace(partial, prefix)  # the RPATH names the final prefix: the libraries resolve only after this
    shutil.rmtree(build, ignore_errors=True)


def load_control_msgs() -> ModuleType:
    """``control_msgs`` importable, its typesupport libraries loaded (found by soname when rmw asks for them)."""
    global _loaded
    if _loaded is not None:
        return _loaded
    prefix = generated_prefix()
    site = str(_site_packages(prefix))
    if site not in sys.path:
        sys.path.insert(0, site)
    for library in sorted((prefix / "lib").glob(f"lib{_PACKAGE}__*.so")):
        with contextlib.suppress(OSError):  # one that fails is reported by the import below
            ctypes.CDLL(str(library), mode=ctypes.RTLD_GLOBAL)
    import control_msgs.action  # noqa: F401

    _loaded = sys.modules[_PACKAGE]
    return _loaded
