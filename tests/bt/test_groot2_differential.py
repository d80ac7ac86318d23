"""Our Groot2 server and ``.btlog`` writer against BehaviorTree.CPP's own (behaviortreepy 0.1.4 = BT.CPP 4.8.2).

The seeded random trees of ``test_btcpp_conformance.py`` (every built-in bt-meta implements, SubTrees with
remapping, autoremap and literals, ``{@key}``, scripted RUNNING/SUCCESS/FAILURE leaves) are loaded into both
engines; BehaviorTree.CPP's ``Groot2Publisher`` and ours serve them on 127.0.0.1, and one client of ours sends both
the same requests between the same ticks. STATUS and BLACKBOARD replies must be byte-identical, reply headers equal
but for the random tree id, FULLTREE equal as XML trees (BehaviorTree.CPP orders ports by hash). ``FileLogger2``
files must hold the same transitions (timestamps aside) and the same tree.
"""

from __future__ import annotations

import gc
import importlib.util
import json
import struct
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from types import ModuleType

import behaviortreepy as btpy
import py_trees
import pytest
import zmq

from bt_meta.bt.groot2.btlog import Btlog, BtlogError, BtlogWriter, read_btlog
from bt_meta.bt.groot2.observer import StatusObserver
from bt_meta.bt.groot2.protocol import ProtocolError
from bt_meta.bt.groot2.published_tree import PublishedTree
from bt_meta.bt.groot2.server import Groot2Server
from bt_meta.bt.groot2.tree_xml import full_tree_xml
from bt_meta.bt.nodes.ticking import tick_exactly_once, tick_once
from bt_meta.bt.registry import NodeType, default_registry
from bt_meta.bt.xml.reader import load_tree_text
from bt_meta.testing import free_groot2_port

pytestmark = pytest.mark.usefixtures("clean_blackboard")
TIMEOUT_MS = 3000


def _conformance() -> ModuleType:
    """The random tree generator and scripted leaves of the BT.CPP conformance test (one source of trees)."""
    name = "bt_meta_tests_btcpp_conformance"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("test_btcpp_conformance.py"))
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


conformance = _conformance()



class Client:
    """A Groot2 client: REQ socket with bounded timeouts (a test can never hang on a silent server)."""

    def __init__(self, context: zmq.Context, port: int) -> None:
        self.socket = context.socket(zmq.REQ)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.setsockopt(zmq.RCVTIMEO, TIMEOUT_MS)
        self.socket.setsockopt(zmq.SNDTIMEO, TIMEOUT_MS)
        self.socket.connect(f"tcp://127.0.0.1:{port}")
        self.next_id = 1000

    def raw(self, parts: list[bytes]) -> list[bytes]:
        self.socket.send_multipart(parts)
        return self.socket.recv_multipart()

    def request(self, letter: str, *extra: bytes) -> list[bytes]:
        self.next_id += 1
        return self.raw([struct.pack("<BBI", 2, ord(letter), self.next_id), *extra])

    def close(self) -> None:
        self.socket.close(linger=0)


def our_tree(generated):
    registry = default_registry()
    log: list = []
    for name, script in generated.leaves.items():
        leaf = conformance.Leaf(name, script)

        def factory(*, name: str, ports: dict, children: list, leaf=leaf) -> py_trees.behaviour.Behaviour:
            return conformance.ScriptedBehaviour(name, leaf, log)

        registry.register(NodeType(name, "Action", [], factory))
    root = load_tree_text(generated.xml, registry)
    root.test_log = log  # what the scripted leaves did (ticks and halts), for the hook tests
    return root, PublishedTree.build(root, registry=registry)


class Pair:
    """The same generated tree in BehaviorTree.CPP (with its Groot2Publisher) and in bt-meta (with ours)."""

    def __init__(self, seed: int, context: zmq.Context, mode: str = "exactly_once") -> None:
        self.generated = conformance.generate(seed, forever=(mode == "exactly_once"), depth=4)
        self.mode = mode
        self.btcpp_step = conformance.btcpp_stepper(self.generated, mode)
        btcpp_port = free_groot2_port()
        self.publisher = btpy.Groot2Publisher(self.btcpp_step.tree, btcpp_port)
        py_trees.blackboard.Blackboard.storage.clear()
        self.root, self.tree = our_tree(self.generated)
        self.observer = StatusObserver(self.tree)
        self.server = Groot2Server(self.tree, self.observer, free_groot2_port(), seed=seed)
        self.btcpp = Client(context, btcpp_port)
        self.ours = Client(context, self.server.port)

    def tick(self) -> tuple[list, list]:
        """Tick both; returns what the scripted leaves did on each side during that tick."""
        _status, btcpp_events = self.btcpp_step()
        self.root.test_log.clear()
        status = tick_exactly_once(self.root) if self.mode == "exactly_once" else tick_once(self.root)
        self.observer.tick_finished(status)
        return btcpp_events, list(self.root.test_log)

    def both(self, letter: str, *extra: bytes) -> tuple[list[bytes], list[bytes]]:
        return self.btcpp.request(letter, *extra), self.ours.request(letter, *extra)

    def close(self) -> None:
        self.btcpp.close()
        self.ours.close()
        self.server.close()
        self.observer.close()
        del self.publisher
        gc.collect()


@pytest.fixture
def context():
    ctx = zmq.Context()
    yield ctx
    ctx.term()


def canonical(element: ET.Element) -> tuple:
    return element.tag, tuple(sorted(element.attrib.items())), tuple(canonical(child) for child in element)


def split_full_tree(text: bytes) -> tuple[dict, list[tuple], dict[str, tuple]]:
    document = ET.fromstring(text)
    trees = [canonical(tree) for tree in document.findall("BehaviorTree")]
    models = {}
    for model in document.find("TreeNodesModel"):
        ports = tuple(sorted((p.tag, p.get("name"), p.get("default"), p.get("type")) for p in model))
        models[model.get("ID")] = (model.tag, ports)
    return document.attrib, trees, models


def assert_same_headers(btcpp: list[bytes], ours: list[bytes]) -> None:
    assert len(btcpp[0]) == len(ours[0]) == 22
    assert btcpp[0][:6] == ours[0][:6]
    assert ours[0][6 + 6] >> 4 == 4  # tree ids are random UUIDs v4 on both sides


def compare_server(seed: int, context: zmq.Context, ticks: int = 6, mode: str = "exactly_once") -> None:
    pair = Pair(seed, context, mode)
    try:
        btcpp, ours = pair.both("T")
        assert_same_headers(btcpp, ours)
        root_b, trees_b, models_b = split_full_tree(btcpp[1])
        root_o, trees_o, models_o = split_full_tree(ours[1])
        assert (root_o, trees_o) == (root_b, trees_b), f"seed {seed}\n{pair.generated.xml}\n{ours[1].decode()}"
        for node_id, (category, ports) in models_o.items():
            assert node_id in models_b, f"we model {node_id}, BT.CPP does not"
            want_category, want_ports = models_b[node_id]
            assert category == want_category, node_id
            # Names, directions and defaults; bt-meta's built-ins spell some port types differently (see docs).
            assert [p[:3] for p in ports] == [p[:3] for p in want_ports], node_id
        names = ";".join(subtree.published_name for subtree in pair.tree.subtrees).encode()
        for tick in range(ticks):
            for letter, extra in (("S", ()), ("B", (names,))):
                btcpp, ours = pair.both(letter, *extra)
                assert_same_headers(btcpp, ours)
                assert ours[1:] == btcpp[1:], f"seed {seed} {mode} tick {tick} {letter}\n{pair.generated.xml}"
            pair.tick()
    finally:
        pair.close()


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_status_full_tree_and_blackboard_replies_equal_btcpp(mode: str, context: zmq.Context) -> None:
    for seed in range(6):
        compare_server(seed, context, mode=mode)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_status_full_tree_and_blackboard_replies_equal_btcpp_sweep(mode: str, context: zmq.Context) -> None:
    for seed in range(6, 150):
        compare_server(seed, context, ticks=10, mode=mode)


def test_error_replies_and_hook_requests_equal_btcpp(context: zmq.Context) -> None:
    pair = Pair(3, context)
    try:
        for parts in ([b"xx"], [b"\x02S\x00\x00\x00\x00\x00"]):
            assert pair.ours.raw(parts) == pair.btcpp.raw(parts) == [b"error", b"wrong request header"]
        btcpp, ours = pair.both("Z")
        assert ours == btcpp == [b"error", b"Request not recognized"]
        btcpp, ours = pair.both("B")
        assert ours == btcpp == [b"error", b"must be 2 parts message"]
        for letter, extra in (("D", ()), ("A", ()), ("X", ()), ("r", (b"stop",)), ("B", (b"NoSuchTree",))):
            btcpp, ours = pair.both(letter, *extra)
            assert_same_headers(btcpp, ours)
            assert ours[1:] == btcpp[1:], letter
    finally:
        pair.close()


def test_recorded_transitions_equal_btcpp(context: zmq.Context) -> None:
    pair = Pair(11, context)
    try:
        btcpp, ours = pair.both("r", b"start")
        assert_same_headers(btcpp, ours)
        assert abs(int(ours[1]) - int(btcpp[1])) < 60_000_000  # both: the server's clock in microseconds
        for _ in range(5):
            pair.tick()
        btcpp, ours = pair.both("t")
        assert_same_headers(btcpp, ours)
        assert len(ours[1]) == len(btcpp[1]) > 0
        assert [ours[1][i + 6 : i + 9] for i in range(0, len(ours[1]), 9)] == [
            btcpp[1][i + 6 : i + 9] for i in range(0, len(btcpp[1]), 9)
        ]
        btcpp, ours = pair.both("t")
        assert ours[1:] == btcpp[1:] == [b""]  # GET_TRANSITIONS hands each transition out once
    finally:
        pair.close()


def read_flushed(path: Path, transitions: int) -> Btlog:
    """BT.CPP's log once its writer thread (flushing every 10 ms) has written ``transitions`` records, or 2 s. A
    read in the middle of a flush sees a torn last record (``ProtocolError``: not a whole number of 9-byte
    records) and is tried again."""
    deadline = time.monotonic() + 2
    while True:
        try:
            log = read_btlog(path)
        except (BtlogError, ProtocolError):
            log = None
        if (log is not None and len(log.transitions) >= transitions) or time.monotonic() > deadline:
            return log if log is not None else read_btlog(path)
        time.sleep(0.01)


def compare_btlog(seed: int, mode: str, folder: Path, ticks: int = 10) -> None:
    generated = conformance.generate(seed, forever=(mode == "exactly_once"), depth=4)
    step = conformance.btcpp_stepper(generated, mode)
    theirs_path, ours_path = folder / f"btcpp{seed}{mode}.btlog", folder / f"ours{seed}{mode}.btlog"
    logger = btpy.FileLogger(step.tree, str(theirs_path))
    time.sleep(0.02)  # BT.CPP 4.8.2 drops transitions queued before its writer thread runs
    py_trees.blackboard.Blackboard.storage.clear()
    root, tree = our_tree(generated)
    tick = tick_exactly_once if mode == "exactly_once" else tick_once
    with StatusObserver(tree) as observer, BtlogWriter(ours_path, full_tree_xml(tree)) as writer:
        observer.subscribe(writer.record)
        for _ in range(ticks):
            step()
            observer.tick_finished(tick(root))
    ours = read_btlog(ours_path)
    theirs = read_flushed(theirs_path, len(ours.transitions))
    del logger
    assert [(t.uid, t.status) for t in ours.transitions] == [(t.uid, t.status) for t in theirs.transitions], (
        f"seed {seed} {mode}\n{generated.xml}"
    )
    assert split_full_tree(ours.tree_xml.encode())[:2] == split_full_tree(theirs.tree_xml.encode())[:2]
    stamps = [t.timestamp_usec for t in ours.transitions]
    assert stamps == sorted(stamps) and abs(ours.start_usec - theirs.start_usec) < 60_000_000


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_transitions_equal_btcpp_file_logger(mode: str, tmp_path: Path) -> None:
    for seed in range(8):
        compare_btlog(seed, mode, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_transitions_equal_btcpp_file_logger_sweep(mode: str, tmp_path: Path) -> None:
    for seed in range(8, 200):
        compare_btlog(seed, mode, tmp_path)


def replace_hook(uid: int, status: str, once: bool = False) -> bytes:
    return json.dumps({"uid": uid, "position": 0, "mode": 1, "enabled": True, "once": once,
                       "desired_status": status}).encode()


def test_replace_hooks_change_ticks_as_in_btcpp(context: zmq.Context) -> None:
    """Groot2's "replace" hook (mode 1): the node returns the given status without ticking, on both engines."""
    for seed in (0, 4, 7, 10):
        pair = Pair(seed, context)
        try:
            leaves = [node.uid for node in pair.tree.nodes if not node.children and node.name.startswith("L")]
            assert len(leaves) >= 2, pair.generated.xml
            for uid, status, once in ((leaves[0], "FAILURE", False), (leaves[1], "SUCCESS", True)):
                btcpp, ours = pair.both("I", replace_hook(uid, status, once))
                assert ours[1:] == btcpp[1:] == []
            btcpp, ours = pair.both("D")
            assert json.loads(ours[1]) == sorted(json.loads(btcpp[1]), key=lambda h: h["uid"])
            hooked = pair.tree.nodes[leaves[0] - 1].name
            for tick in range(6):
                btcpp_events, our_events = pair.tick()
                assert our_events == btcpp_events
                assert hooked not in {name for name, _event in our_events}  # replaced: never ticked
                btcpp, ours = pair.both("S")
                assert ours[1] == btcpp[1], f"seed {seed} tick {tick}\n{pair.generated.xml}"
            for letter, payload in (("R", {"uid": leaves[0], "position": 0}), ("R", {"uid": leaves[0], "position": 0}),
                                    ("U", {"uid": 999, "position": 0, "desired_status": "SUCCESS",
                                           "remove_when_done": True})):
                btcpp, ours = pair.both(letter, json.dumps(payload).encode())
                assert ours[1:] == btcpp[1:] if ours[0] != b"error" else ours == btcpp, letter
            btcpp, ours = pair.both("D")
            assert ours[1:] == btcpp[1:]
        finally:
            pair.close()
