"""A Groot2 monitoring server for a py_trees tree, answering as BehaviorTree.CPP's ``Groot2Publisher`` does.

Two ZeroMQ sockets, as in BehaviorTree.CPP: a REP socket on ``tcp://HOST:PORT`` (``*`` by default) answers
Groot2's requests and a PUB socket on ``PORT+1`` carries breakpoint notifications. Requests are served by a
background thread (100 ms receive timeout, so closing is prompt); the tree ticks in the caller's thread and the
server only reads what the :class:`~bt_meta.bt.groot2.observer.StatusObserver` reports (the status buffer is
updated a byte at a time, the recording under a lock). ``seed`` seeds the ids of breakpoint notifications.

Replies (first part: the request header echoed, protocol 2, the tree's 16-byte id):

* FULLTREE -- the XML of :func:`~bt_meta.bt.groot2.tree_xml.full_tree_xml`
* STATUS -- ``uint16`` uid + ``uint8`` status per node in BehaviorTree.CPP's order; a node reset to IDLE shows
  ``10 + its previous status``
* BLACKBOARD (2 parts: ``name;name;...``) -- MessagePack of ``{subtree: {key: value}}`` for the named subtrees
* TOGGLE_RECORDING (``start``/``stop``), GET_TRANSITIONS -- recorded 9-byte transitions (last 1000)
* HOOK_INSERT / HOOK_REMOVE / BREAKPOINT_UNLOCK / REMOVE_ALL_HOOKS / DISABLE_ALL_HOOKS -- breakpoints and node
  replacement (:mod:`~bt_meta.bt.groot2.hooks`); HOOKS_DUMP -- the hooks as JSON. A breakpoint reached is announced
  on the PUB socket (BREAKPOINT_REACHED header, then the uid as text); ``Node ID not found`` for an unknown hook
* a header that is not 6 bytes -- ``error`` / ``wrong request header``; an unknown letter -- ``error`` /
  ``Request not recognized``; a 1-part BLACKBOARD -- ``error`` / ``must be 2 parts message``

Offers:

* :class:`Groot2Server` -- ``Groot2Server(tree, observer, port, seed=..., host=...)``; :meth:`~Groot2Server.close`
* :class:`Groot2PortError` -- a port that is invalid or in use (user input: the CLI exits 2)
* :func:`check_port`, :func:`probe_ports` -- the checks made before any work starts
"""

from __future__ import annotations

import collections
import contextlib
import errno
import random
import socket
import threading
import time
from typing import Any

import zmq

from bt_meta.bt.groot2 import msgpack
from bt_meta.bt.groot2.hooks import HookError, HookTable
from bt_meta.bt.groot2.observer import StatusObserver, now_usec
from bt_meta.bt.groot2.protocol import (
    DEFAULT_PORT,
    NodeStatus,
    ProtocolError,
    RequestHeader,
    RequestType,
    Transition,
    idle_code,
    pack_reply_header,
    pack_status_buffer,
    pack_transition,
    tree_uuid,
)
from bt_meta.bt.groot2.published_tree import PublishedTree
from bt_meta.bt.groot2.tree_xml import full_tree_xml
from bt_meta.errors import UserInputError

_RECV_TIMEOUT_MS = 100
_SEND_TIMEOUT_MS = 1000
_RECORDED_TRANSITIONS = 1000
_HEARTBEAT_S = 5.0  # BehaviorTree.CPP's max_heartbeat_delay: no request for this long disables every hook


class Groot2PortError(UserInputError):
    """A ``--groot2`` port that is out of range or already in use."""


def check_port(port: int) -> int:
    """Groot2 uses PORT and PORT+1: both must be valid TCP ports."""
    if not isinstance(port, int) or isinstance(port, bool) or not 1 <= port <= 65534:
        raise Groot2PortError(f"Groot2 port {port!r} is invalid: expected 1..65534 (it uses PORT and PORT+1)",
                              "--groot2")
    return port


def probe_ports(port: int, host: str = "*") -> None:
    """Fail early, naming the port, when PORT or PORT+1 cannot be bound now (the server binds them later)."""
    address = "0.0.0.0" if host == "*" else host
    for candidate in (port, port + 1):
        with socket.socket(socket.AF_INET6 if ":" in address else socket.AF_INET) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as ZeroMQ binds its listeners
            try:
                probe.bind((address, candidate))
            except OSError as error:
                reason = "already in use" if error.errno == errno.EADDRINUSE else (error.strerror or str(error))
                raise Groot2PortError(f"Groot2 port {candidate} cannot be opened: {reason} (Groot2 needs PORT and "
                                      "PORT+1)", "--groot2") from None


class Groot2Server:
    """Serves a published tree until :meth:`close`; :meth:`publish` swaps in another (a repaired run's next one)."""

    def __init__(self, tree: PublishedTree, observer: StatusObserver, port: int = DEFAULT_PORT,
                 *, seed: int | None = None, host: str = "*") -> None:
        self.port = check_port(port)
        self._lock = threading.Lock()
        self._recording = False
        self._recording_start = 0
        self._recorded: collections.deque[Transition] = collections.deque(maxlen=_RECORDED_TRANSITIONS)
        self._context = zmq.Context()
        self._server = self._context.socket(zmq.REP)
        self._publisher = self._context.socket(zmq.PUB)
        for sock in (self._server, self._publisher):
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RCVTIMEO, _RECV_TIMEOUT_MS)
            sock.setsockopt(zmq.SNDTIMEO, _SEND_TIMEOUT_MS)
        try:
            self._bind(self._server, host, port)
            self._bind(self._publisher, host, port + 1)
        except Groot2PortError:
            self._shutdown_sockets()
            raise
        self._active = True
        self._last_request = time.monotonic()
        self._heartbeat = True
        self._rng = random.Random(seed)
        self.hooks: HookTable | None = None
        self.publish(tree, observer)
        self._thread = threading.Thread(target=self._serve, name=f"groot2-server-{port}", daemon=True)
        self._thread.start()

    def _bind(self, sock: zmq.Socket, host: str, port: int) -> None:
        try:
            sock.bind(f"tcp://{host}:{port}")
        except zmq.ZMQError as error:
            reason = "already in use" if error.errno == zmq.EADDRINUSE else error.strerror
            raise Groot2PortError(f"Groot2 port {port} cannot be opened: {reason} (Groot2 needs PORT and PORT+1)",
                                  "--groot2") from None

    def publish(self, tree: PublishedTree, observer: StatusObserver) -> None:
        """Serve ``tree`` (reported by ``observer``) from now on; its new tree id tells Groot2 to fetch it again."""
        if self.hooks is not None:
            self.hooks.close()  # a breakpoint of the old tree must not hold the new one
            if self._observer.hooks is self.hooks:
                self._observer.hooks = None
        order = [node.uid for node in tree.status_order()]
        # BehaviorTree.CPP's status buffer: uid + status per node; the status byte of each uid is updated in place.
        self._offset = {uid: 3 * index + 2 for index, uid in enumerate(order)}
        self._buffer = bytearray(pack_status_buffer((uid, int(NodeStatus.IDLE)) for uid in order))
        self.tree = tree
        self.tree_xml = full_tree_xml(tree)
        self.tree_id = tree_uuid(self.tree_xml)
        self.hooks = HookTable({node.uid for node in tree.nodes}, self._announce_breakpoint, observer.hook_node)
        observer.hooks = self.hooks
        self._observer = observer
        observer.subscribe(self.record)

    # -- what the tree reports ----------------------------------------------------------------------------------

    def record(self, timestamp_usec: int, uid: int, previous: NodeStatus, status: NodeStatus) -> None:
        """A :class:`StatusObserver` callback (BehaviorTree.CPP's ``Groot2Publisher::callback``)."""
        # One byte store: atomic for the server thread copying the buffer, so no lock on the hot path.
        self._buffer[self._offset[uid]] = idle_code(previous) if status == NodeStatus.IDLE else status
        if self._recording:
            with self._lock:
                self._recorded.append(Transition(timestamp_usec - self._recording_start, uid, status))

    def status_buffer(self) -> bytes:
        return bytes(self._buffer)

    def blackboard_dump(self, names: str) -> bytes:
        dump: dict[str, Any] = {}
        for name in names.split(";"):
            subtree = self.tree.subtree_named(name)
            if subtree is None:
                continue
            for _attempt in range(5):  # the tree may write the blackboard while we read it
                try:
                    entries = self.tree.blackboard(subtree)
                    break
                except RuntimeError:
                    continue
            else:
                entries = {}
            dump[name] = entries or None
        return msgpack.packb(dump or None)

    # -- the request loop ---------------------------------------------------------------------------------------

    def _announce_breakpoint(self, uid: int) -> None:
        """BREAKPOINT_REACHED on the PUB socket (called by the ticking thread, the only one using that socket)."""
        header = RequestHeader(self._rng.getrandbits(32), RequestType.BREAKPOINT_REACHED).pack()
        with contextlib.suppress(zmq.ZMQError):  # the breakpoint still waits for its unlock
            self._publisher.send_multipart([header, str(uid).encode()])

    def _check_heartbeat(self) -> None:
        alive = time.monotonic() - self._last_request < _HEARTBEAT_S
        if alive != self._heartbeat:
            self._heartbeat = alive
            self.hooks.enable_all(alive)

    def _serve(self) -> None:
        while self._active:
            try:
                request = self._server.recv_multipart()
            except zmq.Again:
                self._check_heartbeat()
                continue
            except zmq.ZMQError:
                break
            self._last_request = time.monotonic()
            self._check_heartbeat()
            reply = self.answer(request)
            try:
                self._server.send_multipart(reply)
            except zmq.ZMQError:
                if not self._active:
                    break

    def answer(self, request: list[bytes]) -> list[bytes]:
        """The reply parts for one request (also usable without sockets)."""
        try:
            header = RequestHeader.unpack(request[0])
        except ProtocolError as error:
            return [b"error", str(error).encode()]
        head = pack_reply_header(header, self.tree_id)
        try:
            kind = RequestType(header.type)
        except ValueError:
            kind = RequestType.UNDEFINED
        try:
            return self._answer(kind, head, request)
        except Exception as error:  # a reply must always go out on a REP socket; BT.CPP sends what() back
            return [b"error", str(error).encode()]

    def _answer(self, kind: RequestType, head: bytes, request: list[bytes]) -> list[bytes]:
        two_parts = kind in (RequestType.BLACKBOARD, RequestType.HOOK_INSERT, RequestType.HOOK_REMOVE,
                             RequestType.BREAKPOINT_UNLOCK, RequestType.TOGGLE_RECORDING)
        if two_parts and len(request) != 2:
            return [b"error", b"must be 2 parts message"]
        if kind == RequestType.FULLTREE:
            return [head, self.tree_xml.encode("utf-8")]
        if kind == RequestType.STATUS:
            return [head, self.status_buffer()]
        if kind == RequestType.BLACKBOARD:
            return [head, self.blackboard_dump(request[1].decode("utf-8", errors="replace"))]
        if kind in (RequestType.HOOK_INSERT, RequestType.HOOK_REMOVE, RequestType.BREAKPOINT_UNLOCK):
            change = {RequestType.HOOK_INSERT: self.hooks.insert, RequestType.HOOK_REMOVE: self.hooks.remove,
                      RequestType.BREAKPOINT_UNLOCK: self.hooks.unlock}[kind]
            try:
                change(request[1])
            except HookError as error:
                return [b"error", str(error).encode()]
            return [head]
        if kind == RequestType.HOOKS_DUMP:
            return [head, self.hooks.dump()]
        if kind == RequestType.REMOVE_ALL_HOOKS:
            self.hooks.remove_all()
            return [head]
        if kind == RequestType.DISABLE_ALL_HOOKS:
            self.hooks.enable_all(False)
            return [head]
        if kind == RequestType.TOGGLE_RECORDING:
            command = request[1].decode("utf-8", errors="replace")
            if command == "start":
                with self._lock:
                    self._recording_start = now_usec()
                    self._recorded.clear()
                    self._recording = True
                return [head, str(now_usec()).encode()]
            if command == "stop":
                with self._lock:
                    self._recording = False
            return [head]
        if kind == RequestType.GET_TRANSITIONS:
            with self._lock:
                recorded, self._recorded = self._recorded, collections.deque(maxlen=_RECORDED_TRANSITIONS)
            return [head, b"".join(pack_transition(t) for t in recorded)]
        return [b"error", b"Request not recognized"]

    # -- lifetime -----------------------------------------------------------------------------------------------

    def _shutdown_sockets(self) -> None:
        self._server.close(linger=0)
        self._publisher.close(linger=0)
        self._context.term()

    def close(self) -> None:
        """Stop serving and release both ports (within about 100 ms)."""
        if not getattr(self, "_active", False):
            return
        self._active = False
        self.hooks.close()
        if self._observer.hooks is self.hooks:
            self._observer.hooks = None
        self._thread.join(timeout=5)
        self._shutdown_sockets()

    def __enter__(self) -> Groot2Server:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

