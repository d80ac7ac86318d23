"""The bytes of BehaviorTree.CPP's Groot2 protocol (``loggers/groot2_protocol.h``, protocol 2) and node statuses.

Every Groot2 exchange is a multipart ZeroMQ request/reply. The first part of a request is a 6-byte header:
protocol (``uint8``, 2), request type (one ASCII letter), request id (``uint32`` little endian). The first part of a
reply repeats that header (protocol set to 2) and appends the 16-byte id of the tree (a random UUID v4). An error
reply is the two parts ``b"error"`` and the message. Node statuses travel as BehaviorTree.CPP's ``NodeStatus``
numbers; a node that went back to IDLE is shown as ``10 + previous status`` so Groot2 can grey out what ran.

Offers:

* :class:`RequestType` -- the request letters (FULLTREE ``T``, STATUS ``S``, BLACKBOARD ``B``, hooks, recording)
* :data:`PROTOCOL_ID`, :data:`DEFAULT_PORT`, :data:`REQUEST_HEADER_SIZE`, :data:`REPLY_HEADER_SIZE`
* :class:`RequestHeader` -- :meth:`~RequestHeader.pack` / :meth:`~RequestHeader.unpack`
* :func:`pack_reply_header` -- request header + tree id
* :func:`tree_uuid` -- the 16 bytes identifying one published tree (a UUID v4 derived from its XML)
* :class:`NodeStatus` -- BehaviorTree.CPP's status numbers; :func:`status_code` maps py_trees statuses onto them
* :func:`idle_code` -- the ``IDLE_FROM_*`` code of a transition to IDLE
* :func:`pack_status_buffer` -- the STATUS reply body (``uint16`` uid + ``uint8`` status per node)
* :class:`Transition`, :func:`pack_transition` -- the 9-byte transition records of ``.btlog`` files and
  GET_TRANSITIONS replies (48-bit microseconds, ``uint16`` uid, ``uint8`` status)
"""

from __future__ import annotations

import enum
import hashlib
import struct
from collections.abc import Iterable
from dataclasses import dataclass

from py_trees.common import Status

from bt_meta.errors import BtMetaError

PROTOCOL_ID = 2
DEFAULT_PORT = 1667  # Groot2's and BehaviorTree.CPP's default server port
REQUEST_HEADER_SIZE = 6
REPLY_HEADER_SIZE = REQUEST_HEADER_SIZE + 16
_HEADER = struct.Struct("<BBI")
_TRANSITION_TIME_MAX = (1 << 48) - 1


class ProtocolError(BtMetaError):
    """Bytes that are not a Groot2 message (the server answers them with an error reply)."""


class RequestType(enum.IntEnum):
    """Request letters of ``BT::Monitor::RequestType``."""

    FULLTREE = ord("T")
    STATUS = ord("S")
    BLACKBOARD = ord("B")
    HOOK_INSERT = ord("I")
    HOOK_REMOVE = ord("R")
    BREAKPOINT_REACHED = ord("N")
    BREAKPOINT_UNLOCK = ord("U")
    HOOKS_DUMP = ord("D")
    REMOVE_ALL_HOOKS = ord("A")
    DISABLE_ALL_HOOKS = ord("X")
    TOGGLE_RECORDING = ord("r")
    GET_TRANSITIONS = ord("t")
    UNDEFINED = 0


@dataclass(frozen=True)
class RequestHeader:
    """``BT::Monitor::RequestHeader``; ``type`` is kept as a raw byte so unknown letters can be answered."""

    unique_id: int
    type: int
    protocol: int = PROTOCOL_ID

    def pack(self) -> bytes:
        return _HEADER.pack(self.protocol, self.type, self.unique_id)

    @classmethod
    def unpack(cls, data: bytes) -> RequestHeader:
        if len(data) != REQUEST_HEADER_SIZE:
            raise ProtocolError("wrong request header")
        protocol, kind, unique_id = _HEADER.unpack(data)
        return cls(unique_id, kind, protocol)


def pack_reply_header(request: RequestHeader, tree_id: bytes) -> bytes:
    """The first part of a reply: the request's id and type, protocol 2, then the tree's 16-byte id."""
    if len(tree_id) != 16:
        raise ValueError("a Groot2 tree id has 16 bytes")
    return RequestHeader(request.unique_id, request.type, PROTOCOL_ID).pack() + tree_id


def tree_uuid(tree_xml: str) -> bytes:
    """The tree id of the reply headers, shaped as the random UUID v4 BehaviorTree.CPP draws per publisher.

    Groot2 fetches the tree again when this id changes. Deriving it from the tree's XML (instead of drawing it)
    gives a new id exactly when the tree differs -- also across runs -- and needs no random draw.
    """
    raw = bytearray(hashlib.sha256(tree_xml.encode("utf-8")).digest()[:16])
    raw[8] = (raw[8] & 0xBF) | 0x80  # variant 10xxxxxx
    raw[6] = (raw[6] & 0x4F) | 0x40  # version 0100xxxx
    return bytes(raw)


class NodeStatus(enum.IntEnum):
    """``BT::NodeStatus``."""

    IDLE = 0
    RUNNING = 1
    SUCCESS = 2
    FAILURE = 3
    SKIPPED = 4


_FROM_PY_TREES = {
    Status.INVALID: NodeStatus.IDLE,
    Status.RUNNING: NodeStatus.RUNNING,
    Status.SUCCESS: NodeStatus.SUCCESS,
    Status.FAILURE: NodeStatus.FAILURE,
}


# Keyed by identity: py_trees' Status members hash in Python, which is slow on the per-transition path.
_BY_IDENTITY = {id(status): code for status, code in _FROM_PY_TREES.items()}


def status_code(status: object) -> NodeStatus:
    """BehaviorTree.CPP's number for a py_trees status (INVALID is IDLE); a status named SKIPPED maps to 4."""
    code = _BY_IDENTITY.get(id(status))
    if code is not None:
        return code
    name = str(getattr(status, "name", status)).upper()
    if name in NodeStatus.__members__:
        return NodeStatus[name]
    raise ProtocolError(f"status {status!r} has no BehaviorTree.CPP equivalent")


def idle_code(previous: NodeStatus) -> int:
    """What the STATUS reply shows for a node that went from ``previous`` back to IDLE (``IDLE_FROM_*``)."""
    return 10 + int(previous)


def pack_status_buffer(entries: Iterable[tuple[int, int]]) -> bytes:
    """The STATUS reply body: ``(uid, code)`` pairs as ``uint16`` + ``uint8``, in the publisher's node order."""
    return b"".join(struct.pack("<HB", uid, code) for uid, code in entries)


@dataclass(frozen=True)
class Transition:
    """One status change: microseconds since the log or recording started, node uid, new status."""

    timestamp_usec: int
    uid: int
    status: NodeStatus


def pack_transition(transition: Transition) -> bytes:
    """9 bytes: the low 48 bits of the timestamp, the uid, the status (as BT.CPP's ``memcpy`` of 6+2+1 bytes)."""
    stamp = transition.timestamp_usec & _TRANSITION_TIME_MAX
    return stamp.to_bytes(6, "little") + struct.pack("<HB", transition.uid, int(transition.status))


def unpack_transitions(data: bytes) -> list[Transition]:
    """The inverse of :func:`pack_transition` over a run of 9-byte records."""
    if len(data) % 9:
        raise ProtocolError(f"transition records are 9 bytes each; got {len(data)} bytes")
    out = []
    for offset in range(0, len(data), 9):
        stamp = int.from_bytes(data[offset : offset + 6], "little")
        uid, code = struct.unpack_from("<HB", data, offset + 6)
        out.append(Transition(stamp, uid, NodeStatus(code)))
    return out
