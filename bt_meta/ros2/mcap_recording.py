"""``bt-meta run --world ros2 --record-mcap FILE.mcap``: the messages of a ROS-driven run as MCAP, ROS 2 encoded.

What the world receives and sends is written as it happens, CDR-serialized by rclpy with ``ros2msg`` schemas (the
message definitions the installed interface packages ship, dependencies appended as rosbag2 does), so Foxglove,
``rosbag2`` and ``mcap-ros2-support`` read it: the joint states and object poses received, and every
FollowJointTrajectory goal's trajectory on ``<action>/goal_trajectory`` (``trajectory_msgs/msg/JointTrajectory``;
actions themselves are not topics). ``log_time`` is the receiving (or sending) wall clock, ``publish_time`` the
message's stamp where it has one.

Offers:

* :class:`McapRecording` -- ``write(topic, message)``, thread-safe; ``close()`` finishes the file
* :func:`message_definition` -- the ``ros2msg`` schema text of a message type
"""

from __future__ import annotations

import os
import re
import sys
import threading
import time
from pathlib import Path
from typing import Any

from bt_meta.errors import BtMetaError, UserInputError

__all__ = ["McapRecording", "message_definition"]

_BUILTIN = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
            "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def _share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    return [Path(p) / "share" for p in prefixes]


def _msg_text(package: str, name: str) -> str:
    for share in _share_dirs():
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text()
    raise BtMetaError(f"no definition of {package}/msg/{name} (.msg) under {', '.join(map(str, _share_dirs()))}")


def _dependencies(package: str, text: str) -> list[tuple[str, str]]:
    """``(package, name)`` of the message types ``text``'s fields use, in order of appearance."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        kind = line.split()[0]
        if "=" in line.split(None, 1)[-1] and kind.split("<=")[0] in _BUILTIN:
            continue  # a constant
        base = re.sub(r"\[.*\]$", "", kind).split("<=")[0]
        if base in _BUILTIN:
            continue
        if base == "Header":
            out.append(("std_msgs", "Header"))
        elif "/" in base:
            parts = base.split("/")
            out.append((parts[0], parts[-1]))
        else:
            out.append((package, base))
    return out


def message_definition(kind: str) -> str:
    """``pkg/msg/Name``'s definition followed by every type it uses (``MSG: pkg/Name`` sections)."""
    package, _msg, name = kind.split("/")
    main = _msg_text(package, name)
    seen: set[tuple[str, str]] = set()
    sections: list[str] = []
    pending = _dependencies(package, main)
    while pending:
        dep = pending.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_text(*dep)
        sections.append(f"{_SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{text}")
        pending.extend(_dependencies(dep[0], text))
    return "\n".join([main, *sections])


class McapRecording:
    def __init__(self, path: str | Path) -> None:
        from mcap.writer import Writer

        self.path = Path(path)
        if self.path.suffix != ".mcap":
            raise UserInputError(f"--record-mcap {path}: the file must end in .mcap", "--record-mcap")
        try:
            self._file = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        except OSError as error:
            raise UserInputError(f"--record-mcap {path}: {error.strerror}", "--record-mcap") from None
        self._writer = Writer(self._file)
        self._writer.start(profile="ros2", library="bt-meta")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.messages = 0

    def _channel(self, topic: str, message: Any) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            module = type(message).__module__.split(".")[0]
            kind = f"{module}/msg/{type(message).__name__}"
            schema = self._schemas.get(kind)
            if schema is None:
                schema = self._writer.register_schema(kind, "ros2msg", message_definition(kind).encode())
                self._schemas[kind] = schema
            channel = self._writer.register_channel(topic, "cdr", schema)
            self._channels[topic] = channel
        return channel

    def write(self, topic: str, message: Any) -> None:
        from rclpy.serialization import serialize_message

        from bt_meta.ros2.messages import nanoseconds

        now = time.time_ns()
        header = getattr(message, "header", None)
        stamp = nanoseconds(header.stamp) if header is not None else now
        data = serialize_message(message)
        with self._lock:
            if self._file.closed:
                return
            channel = self._channel(topic, message)
            self._sequence += 1
            self._writer.add_message(channel, log_time=now, data=data, publish_time=stamp, sequence=self._sequence)
            self.messages += 1

    def close(self) -> None:
        with self._lock:
            if self._file.closed:
                return
            try:
                self._writer.finish()
            finally:
                self._file.close()
