"""``bt-meta run --world ros2 --record-mcap FILE.mcap``: the messages of a ROS-driven run as MCAP, ROS 2 encoded.

What the world receives and sends is written as it happens, CDR-serialized by rclpy with ``ros2msg`` schemas (the
message definitions the installed interface packages ship, dependencies appended as rosbag2 does), so Foxglove,
``rosbag2`` and ``mcap-ros2-support`` read it: the joint states and object poses received, and every
FollowJointTrajectory goal's trajectory on ``<action>/goal_trajectory`` (``trajectory_msgs/msg/JointTrajectory``;
actions themselves are not topics). ``log_time`` is the receiving (or sending) wall clock, ``publish_time`` the
message's stamp where it has one.

What the tree did goes in as ``std_msgs/msg/String`` messages holding one JSON object each (:class:`McapTreeLog`;
rosbag2 and Foxglove read the type without any definition of ours, and JSON keeps the records as open as the trace
events they come from): the node statuses of every tick on :data:`TREE_TOPIC`, every failure on
:data:`FAILURE_TOPIC`, every repair decision on :data:`REPAIR_TOPIC`.

Offers:

* :class:`McapRecording` -- ``write(topic, message)``, thread-safe; ``close()`` finishes the file
* :class:`McapTreeLog` -- a plugin writing the tree's statuses, failures and repairs into a recording
* :func:`message_definition` -- the ``ros2msg`` schema text of a message type
"""

from __future__ import annotations

import json
import os
import re
import sys
import threading
import time
from pathlib import Path
from typing import Any

from bt_meta.errors import BtMetaError, UserInputError
from bt_meta.hookspecs import hookimpl

__all__ = ["FAILURE_TOPIC", "REPAIR_TOPIC", "TREE_TOPIC", "McapRecording", "McapTreeLog", "message_definition"]

TREE_TOPIC = "/bt_meta/tree/status"
"""Per tick: ``{"tick", "status" (the root's), "nodes": [[name, status], ...]}``: every node the tick visited, in
the order they finished their part of it."""
FAILURE_TOPIC = "/bt_meta/failures"
"""Per failure: ``{"tick", "failure"}`` -- the failure as the run reports it (``Failure.to_dict``)."""
REPAIR_TOPIC = "/bt_meta/repairs"
"""Per repair decision: the executor's ``repair`` trace event (``tick``, ``outcome``: applied, refused, stopped,
...; ``attempt`` or ``proposal``, ``reason``)."""

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


class McapTreeLog:
    """Writes what the tree does into a :class:`McapRecording`: ``watch(run)`` each run context that ticks a tree
    (the statuses of the nodes each tick visits), and, registered as a plugin, failures and repairs from the trace
    events."""

    def __init__(self, recording: McapRecording) -> None:
        self.recording = recording
        self.ticks = 0

    def watch(self, run: Any) -> None:
        """Route ``run.tick`` through the log (once per run context)."""
        if getattr(run, "_mcap_watched", False):
            return
        original = run.tick

        def tick(root: Any, visit: Any = None) -> Any:
            nodes: list[list[str]] = []

            def seen(behaviour: Any) -> None:
                nodes.append([behaviour.name, behaviour.status.value])
                if visit is not None:
                    visit(behaviour)

            status = original(root, seen)
            self.ticks += 1
            self._write(TREE_TOPIC, {"tick": run.tick_count, "status": status.value, "nodes": nodes})
            return status

        run.tick = tick
        run._mcap_watched = True

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        kind = event.get("type")
        if kind == "failure":
            self._write(FAILURE_TOPIC, {"tick": event.get("tick"), "failure": event.get("failure")})
        elif kind == "repair":
            self._write(REPAIR_TOPIC, {k: v for k, v in event.items() if k != "type"})

    def _write(self, topic: str, record: dict[str, Any]) -> None:
        from std_msgs.msg import String

        self.recording.write(topic, String(data=json.dumps(record, default=str, sort_keys=True)))
