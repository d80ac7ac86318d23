"""Groot2 breakpoints on our server: the tick stops at the node, Groot2 is told on the PUB socket, unlock decides.

BehaviorTree.CPP's own breakpoints block inside its C++ tick, which behaviortreepy runs holding Python's lock, so
these are checked against the protocol as ``groot2_publisher.cpp`` implements it (BREAKPOINT_REACHED header + uid
text on PORT+1; unlock JSON ``{uid, position, desired_status, remove_when_done}``); replace hooks are compared
with BehaviorTree.CPP in ``test_groot2_differential.py``.
"""

from __future__ import annotations

import json
import struct
import threading
import time

import py_trees
import pytest
import zmq
from py_trees.common import Status

from bt_meta.bt.groot2 import server as server_module
from bt_meta.bt.groot2.observer import StatusObserver
from bt_meta.bt.groot2.published_tree import PublishedTree
from bt_meta.bt.groot2.server import Groot2Server
from bt_meta.bt.nodes.ticking import tick_exactly_once
from bt_meta.bt.registry import NodeType, default_registry
from bt_meta.bt.xml.reader import load_tree_text
from bt_meta.testing import free_groot2_port

pytestmark = pytest.mark.usefixtures("clean_blackboard")
TREE = """<root BTCPP_format="4"><BehaviorTree ID="MainTree">
  <Sequence><Step name="first"/><Step name="second"/></Sequence>
</BehaviorTree></root>"""



class Setup:
    def __init__(self, context: zmq.Context) -> None:
        self.ticked: list[str] = []
        registry = default_registry()
        ticked = self.ticked

        class Step(py_trees.behaviour.Behaviour):
            def update(self) -> Status:
                ticked.append(self.name)
                return Status.SUCCESS

        registry.register(NodeType("Step", "Action", [], lambda *, name, ports, children: Step(name)))
        self.root = load_tree_text(TREE, registry)
        self.tree = PublishedTree.build(self.root, registry=registry)
        self.observer = StatusObserver(self.tree)
        self.server = Groot2Server(self.tree, self.observer, free_groot2_port(), host="127.0.0.1", seed=1)
        self.req = context.socket(zmq.REQ)
        self.sub = context.socket(zmq.SUB)
        for sock in (self.req, self.sub):
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.RCVTIMEO, 3000)
        self.req.connect(f"tcp://127.0.0.1:{self.server.port}")
        self.sub.setsockopt(zmq.SUBSCRIBE, b"")
        self.sub.connect(f"tcp://127.0.0.1:{self.server.port + 1}")
        time.sleep(0.3)  # a PUB socket drops what it sends before the subscription arrives
        self.result: list[Status] = []

    def request(self, letter: str, payload: dict | None = None) -> list[bytes]:
        parts = [struct.pack("<BBI", 2, ord(letter), 5)]
        if payload is not None:
            parts.append(json.dumps(payload).encode())
        self.req.send_multipart(parts)
        return self.req.recv_multipart()

    def tick_in_background(self) -> threading.Thread:
        thread = threading.Thread(target=lambda: self.result.append(tick_exactly_once(self.root)), daemon=True)
        thread.start()
        return thread

    def close(self) -> None:
        self.req.close(linger=0)
        self.sub.close(linger=0)
        self.server.close()
        self.observer.close()


@pytest.fixture
def setup():
    context = zmq.Context()
    made = Setup(context)
    yield made
    made.close()
    context.term()


def breakpoint_hook(uid: int) -> dict:
    return {"uid": uid, "position": 0, "mode": 0, "enabled": True, "once": False, "desired_status": "SKIPPED"}


def reached(setup: Setup) -> tuple[bytes, bytes]:
    """The BREAKPOINT_REACHED message Groot2 gets on PORT+1 (3 s timeout)."""
    header, uid = setup.sub.recv_multipart()
    return header, uid


def test_breakpoint_stops_the_tick_until_unlocked_with_a_status(setup: Setup) -> None:
    assert setup.request("I", breakpoint_hook(3))[1:] == []
    thread = setup.tick_in_background()
    header, uid = reached(setup)
    assert header[0] == 2 and header[1] == ord("N") and len(header) == 6 and uid == b"3"
    thread.join(0.3)
    assert thread.is_alive() and setup.ticked == ["first"]  # waiting at "second"
    status = setup.request("S")[1]
    assert status[:3] == bytes([1, 0, 1])  # the Sequence is RUNNING while the breakpoint holds
    hooks = json.loads(setup.request("D")[1])
    assert hooks == [{"desired_status": "SKIPPED", "enabled": True, "mode": 0, "once": False, "position": 0,
                      "uid": 3}]
    unlock = {"uid": 3, "position": 0, "desired_status": "FAILURE", "remove_when_done": True}
    assert setup.request("U", unlock)[1:] == []
    thread.join(5)
    assert not thread.is_alive()
    assert setup.result == [Status.FAILURE] and setup.ticked == ["first"]  # "second" answered FAILURE, unticked
    assert setup.request("D")[1] == b"[]"  # remove_when_done
    assert setup.request("U", unlock) == [b"error", b"Node ID not found"]


def test_unlock_with_skipped_lets_the_node_tick(setup: Setup) -> None:
    setup.request("I", breakpoint_hook(2))
    thread = setup.tick_in_background()
    reached(setup)
    setup.request("U", {"uid": 2, "position": 0, "desired_status": "SKIPPED", "remove_when_done": False})
    thread.join(5)
    assert setup.result == [Status.SUCCESS] and setup.ticked == ["first", "second"]


@pytest.mark.parametrize("release", ["R", "A", "X"])
def test_removing_or_disabling_hooks_releases_a_waiting_breakpoint(release: str, setup: Setup) -> None:
    setup.request("I", breakpoint_hook(2))
    thread = setup.tick_in_background()
    reached(setup)
    payload = {"uid": 2, "position": 0} if release == "R" else None
    assert setup.request(release, payload)[1:] == []
    thread.join(5)
    assert setup.result == [Status.SUCCESS] and setup.ticked == ["first", "second"]


def test_a_silent_groot2_releases_breakpoints(setup: Setup, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(server_module, "_HEARTBEAT_S", 0.3)
    setup.request("I", breakpoint_hook(2))
    thread = setup.tick_in_background()
    reached(setup)
    thread.join(5)  # no request for 0.3 s: every hook is disabled, the tick goes on
    assert setup.result == [Status.SUCCESS]


def test_bad_hook_requests_get_error_replies(setup: Setup) -> None:
    assert setup.request("I", {"uid": 2})[0] == b"error"
    setup.req.send_multipart([struct.pack("<BBI", 2, ord("I"), 5), b"{not json"])
    assert setup.req.recv_multipart()[0] == b"error"
    assert setup.request("R", {"uid": 2, "position": 0}) == [b"error", b"Node ID not found"]
    assert setup.request("I", breakpoint_hook(77))[1:] == []  # unknown node: ignored, as BehaviorTree.CPP does
    assert setup.request("D")[1] == b"[]"
