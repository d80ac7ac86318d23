"""Groot2 log files (``.btlog``): BehaviorTree.CPP's ``FileLogger2`` format, for Groot2's log replay.

Layout (``loggers/bt_file_logger_v2.cpp``): the ASCII text ``BTCPP4-FileLogger2``, a protocol byte (1), the full
tree XML's length as ``int32`` little endian and the XML itself (with ``_uid`` attributes), the time the log starts
as ``int64`` microseconds since the epoch, then one 9-byte transition per status change (microseconds since the
start in 48 bits, ``uint16`` uid, ``uint8`` new status; transitions to IDLE included).

Offers:

* :class:`BtlogWriter` -- ``BtlogWriter(path, tree_xml)``; :meth:`~BtlogWriter.record` (a
  :class:`~bt_meta.bt.groot2.observer.StatusObserver` callback), :meth:`~BtlogWriter.flush`,
  :meth:`~BtlogWriter.close`
* :func:`check_btlog_path` -- the checks BehaviorTree.CPP makes (suffix ``.btlog``) plus a writable folder, before
  any work starts
* :func:`read_btlog` -- header XML, start time and transitions of a file (for tests and tools)
* :class:`BtlogError` -- a path that cannot be a Groot2 log (user input: the CLI exits 2)
"""

from __future__ import annotations

import os
import struct
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from bt_meta.bt.groot2.observer import now_usec
from bt_meta.bt.groot2.protocol import NodeStatus, Transition, unpack_transitions
from bt_meta.errors import UserInputError

MAGIC = b"BTCPP4-FileLogger2"
PROTOCOL = 1
# A transition record is 48 bits of time, 16 of uid, 8 of status: one uint64 (time | uid << 48) and one byte.
_RECORD = struct.Struct("<QB").pack
_TIME_MASK = (1 << 48) - 1


class BtlogError(UserInputError):
    """A ``--btlog`` path that cannot be written as a Groot2 log."""


def check_btlog_path(path: str | Path) -> Path:
    """Refuse a path Groot2 cannot replay or we cannot write, naming it (no file is created)."""
    path = Path(path)
    if path.suffix != ".btlog":
        raise BtlogError("a Groot2 log file must end in .btlog (BehaviorTree.CPP's FileLogger2 requires it)", path)
    if path.is_dir():
        raise BtlogError("is a directory, not a .btlog file", path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise BtlogError(f"cannot write the log: folder {str(folder)!r} does not exist", path)
    if not os.access(folder, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise BtlogError("cannot write the log: permission denied", path)
    return path


class BtlogWriter:
    """Writes one tree's header on creation, then each transition as it is recorded."""

    def __init__(self, path: str | Path, tree_xml: str, start_usec: int | None = None) -> None:
        self.path = check_btlog_path(path)
        try:
            self._file: BinaryIO | None = open(self.path, "wb")  # noqa: SIM115 - kept open for the whole run
        except OSError as error:
            raise BtlogError(f"cannot write the log: {error.strerror}", self.path) from None
        xml = tree_xml.encode("utf-8")
        self.start_usec = now_usec() if start_usec is None else start_usec
        self._lock = threading.Lock()
        self._pending = bytearray()
        self._file.write(MAGIC + bytes([PROTOCOL]) + struct.pack("<i", len(xml)) + xml
                         + struct.pack("<q", self.start_usec))
        self.count = 0

    def record(self, timestamp_usec: int, uid: int, _previous: NodeStatus, status: NodeStatus) -> None:
        """Queue one transition (the ticking thread calls this; :meth:`flush` writes the queue)."""
        self._pending += _RECORD(((timestamp_usec - self.start_usec) & _TIME_MASK) | (uid << 48), status)
        self.count += 1

    def flush(self) -> None:
        with self._lock:
            if self._file is not None:
                pending, self._pending = self._pending, bytearray()
                self._file.write(pending)
                self._file.flush()

    def close(self) -> None:
        self.flush()
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def __enter__(self) -> BtlogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Btlog:
    """A parsed ``.btlog`` file."""

    tree_xml: str
    start_usec: int
    transitions: list[Transition]


def read_btlog(path: str | Path) -> Btlog:
    data = Path(path).read_bytes()
    head = len(MAGIC) + 1
    if data[: len(MAGIC)] != MAGIC or len(data) < head + 4:
        raise BtlogError("not a BehaviorTree.CPP FileLogger2 log", path)
    (size,) = struct.unpack_from("<i", data, head)
    xml_end = head + 4 + size
    if len(data) < xml_end + 8:
        raise BtlogError("truncated FileLogger2 header", path)
    xml = data[head + 4 : xml_end].decode("utf-8")
    (start,) = struct.unpack_from("<q", data, xml_end)
    return Btlog(xml, start, unpack_transitions(data[xml_end + 8 :]))
