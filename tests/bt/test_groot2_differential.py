"""Our Groot2 server and ``.btlog`` writer against BehaviorTree.CPP's own (behaviortreepy 0.1.4 = BT.CPP 4.8.2).

The seeded random trees of ``test_btcpp_conformance.py`` (every built-in bt-meta implements, SubTrees with
remapping, autoremap and literals, ``{@key}``, scripted RUNNING/SUCCESS/FAILURE leaves), those of
``test_btcpp_scripting.py`` (every pre/post-condition attribute) and one tree where every such attribute fires are
loaded into both engines; BehaviorTree.CPP's ``Groot2Publisher`` and ours serve them on 127.0.0.1, and one client
of ours sends both the same requests between the same ticks. STATUS and BLACKBOARD replies must be byte-identical,
reply headers equal but for the random tree id, FULLTREE equal as XML trees (BehaviorTree.CPP orders ports by hash;
pre/post conditions in its enum order). ``FileLogger2`` files must hold the same transitions (timestamps aside) and
the same tree.
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


def _test_module(filename: str) -> ModuleType:
    """A sibling test module (its tree generator and scripted leaves: one source of trees)."""
    name = "bt_meta_tests_" + Path(filename).stem
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(filename))
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


conformance = _test_module("test_btcpp_conformance.py")
# Trees with every pre/post-condition attribute (``_skipIf`` ... ``_post``), scripts and the newer built-ins.
scripting = _test_module("test_btcpp_scripting.py")
CONDITIONS = (*scripting.PRE, *scripting.POST)


# Every pre/post-condition attribute, on controls, decorators, leaves and a SubTree (evaluated in the parent's
# blackboard), firing over a few ticks: a skip, an imposed SUCCESS and FAILURE, a halt (``_onHalted``), a ``_while``
# that turns false on a RUNNING node, post scripts writing entries the BLACKBOARD reply shows. ``_onHalted`` reads
# no entry: BT.CPP's Tree destructor halts every node, idle or not, before any entry may exist.
EVERY_CONDITION = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence name="top">
      <Script code="a := 0; b := 0; t := 0; halted := -1"/>
      <KeepRunningUntilFailure>
       <Repeat num_cycles="3" _onSuccess="b := b + 100">
        <ForceSuccess>
        <ReactiveSequence name="watched" _onSuccess="b += 1" _onFailure="b += 10" _post="a += 1">
          <Script name="count" code="t += 1"/>
          <ScriptCondition name="gate" code="t != 9 &amp;&amp; t != 20"/>
          <AlwaysSuccess name="skipped_leaf" _skipIf="true"/>
          <AlwaysFailure name="made_to_succeed" _successIf="a &gt;= 0"/>
          <Fallback name="halted_here" _failureIf="a == 5" _onHalted="halted := 1">
            <L0 _while="t != 2 &amp;&amp; t != 7"/>
            <L1 _onFailure="b += 2"/>
          </Fallback>
          <SubTree ID="Sub" name="sub" _skipIf="a == 3" _post="a := a" v="{a}"/>
          <SkipUnlessUpdated entry="{@a}"><L2/></SkipUnlessUpdated>
        </ReactiveSequence>
        </ForceSuccess>
       </Repeat>
      </KeepRunningUntilFailure>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Sub">
    <Inverter _onSuccess="w := 1" _onFailure="w := 2">
      <ScriptCondition code="v &gt; 1" _while="true"/>
    </Inverter>
  </BehaviorTree>
</root>
"""
EVERY_CONDITION_LEAVES = {"L0": ["RUNNING", "RUNNING", "FAILURE", "RUNNING", "SUCCESS"], "L1": ["FAILURE", "SUCCESS"],
                          "L2": ["SUCCESS", "RUNNING"]}


def generate(seed: int, kind: str, mode: str = "exactly_once"):
    """A tree and its scripted leaves: seeded ``plain`` (built-ins, SubTree remapping) or ``conditions`` trees, or
    the ``every_condition`` tree above."""
    if kind == "every_condition":
        return conformance.Generated(EVERY_CONDITION, EVERY_CONDITION_LEAVES)
    if kind == "conditions":
        xml, leaves, _kinds = scripting.generate_tree(seed)
        return conformance.Generated(xml, leaves)
    return conformance.generate(seed, forever=(mode == "exactly_once"), depth=4)


def condition_seeds(count: int, mode: str, ticks: int, start: int = 0) -> list[int]:
    """Seeds of ``conditions`` trees that BehaviorTree.CPP ticks ``ticks`` times without a script error (a tree
    that throws has nothing to publish after the throw)."""
    seeds: list[int] = []
    seed = start
    while len(seeds) < count:
        xml, leaves, _kinds = scripting.generate_tree(seed)
        step = scripting._btcpp_steps(xml, leaves, mode)
        if all(step()[0] != "error" for _ in range(ticks)):
            seeds.append(seed)
        seed += 1
    return seeds


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


def our_tree(generated, kind: str = "plain"):
    registry = default_registry()
    log: list = []
    for name, script in generated.leaves.items():
        leaf = conformance.Leaf(name, script)

        def factory(*, name: str, ports: dict, children: list, leaf=leaf) -> py_trees.behaviour.Behaviour:
            if kind != "plain":  # WhileDoElse re-ticks a finished condition: answer as BT.CPP's leaf does
                return scripting._Leaf(name, leaf.script, log)
            return conformance.ScriptedBehaviour(name, leaf, log)

        registry.register(NodeType(name, "Action", [], factory))
    root = load_tree_text(generated.xml, registry)
    root.test_log = log  # what the scripted leaves did (ticks and halts), for the hook tests
    return root, PublishedTree.build(root, registry=registry)


class Pair:
    """The same generated tree in BehaviorTree.CPP (with its Groot2Publisher) and in bt-meta (with ours)."""

    def __init__(self, seed: int, context: zmq.Context, mode: str = "exactly_once", kind: str = "plain") -> None:
        self.generated = generate(seed, kind, mode)
        self.mode = mode
        self.btcpp_step = conformance.btcpp_stepper(self.generated, mode)
        btcpp_port = free_groot2_port()
        self.publisher = btpy.Groot2Publisher(self.btcpp_step.tree, btcpp_port)
        py_trees.blackboard.Blackboard.storage.clear()
        self.root, self.tree = our_tree(self.generated, kind)
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
    """Attributes as a set (BT.CPP orders ports by hash) but pre/post conditions in order (BT.CPP's enum order)."""
    conditions = tuple(name for name in element.attrib if name in CONDITIONS)
    return (element.tag, tuple(sorted(element.attrib.items())), conditions,
            tuple(canonical(child) for child in element))


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


def compare_server(seed: int, context: zmq.Context, ticks: int = 6, mode: str = "exactly_once",
                   kind: str = "plain") -> None:
    pair = Pair(seed, context, mode, kind)
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


# The sweeps: a slow share in every full run, the whole sweep behind ``-m fuzz`` (each tree costs about 0.4 s,
# most of it the two servers' 100 ms receive timeouts on close).
SWEEP = [pytest.param(40, marks=pytest.mark.slow, id="40"),
         pytest.param(144, marks=[pytest.mark.slow, pytest.mark.fuzz], id="144")]


@pytest.mark.parametrize("size", SWEEP)
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_status_full_tree_and_blackboard_replies_equal_btcpp_sweep(mode: str, size: int,
                                                                   context: zmq.Context) -> None:
    for seed in range(6, 6 + size):
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


def compare_btlog(seed: int, mode: str, folder: Path, ticks: int = 10, kind: str = "plain") -> tuple[Btlog, Btlog]:
    generated = generate(seed, kind, mode)
    step = conformance.btcpp_stepper(generated, mode)
    theirs_path, ours_path = folder / f"btcpp{seed}{mode}{kind}.btlog", folder / f"ours{seed}{mode}{kind}.btlog"
    logger = btpy.FileLogger(step.tree, str(theirs_path))
    time.sleep(0.02)  # BT.CPP 4.8.2 drops transitions queued before its writer thread runs
    py_trees.blackboard.Blackboard.storage.clear()
    root, tree = our_tree(generated, kind)
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
    return ours, theirs


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_transitions_equal_btcpp_file_logger(mode: str, tmp_path: Path) -> None:
    for seed in range(8):
        compare_btlog(seed, mode, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_transitions_equal_btcpp_file_logger_sweep(mode: str, tmp_path: Path) -> None:
    for seed in range(8, 200):
        compare_btlog(seed, mode, tmp_path)


def tree_part(text: bytes | str) -> bytes:
    """The ``<BehaviorTree>`` elements of a full-tree XML, as bytes (its ``<TreeNodesModel>`` cut off)."""
    data = text.encode() if isinstance(text, str) else text
    return data.split(b"<TreeNodesModel")[0]


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_a_tree_with_every_condition_attribute_is_served_and_logged_as_btcpp_does(mode: str, context: zmq.Context,
                                                                                  tmp_path: Path) -> None:
    """Skips, imposed statuses, a ``_while`` that halts a RUNNING leaf, ``_onHalted`` after a ReactiveSequence
    halts a Fallback: FULLTREE byte for byte (no node has two ports, so BT.CPP's hash order cannot differ),
    STATUS and BLACKBOARD after each of 24 ticks, and the ``.btlog`` (transitions and header)."""
    assert used_conditions([0], "every_condition") == set(CONDITIONS)
    compare_server(0, context, ticks=24, mode=mode, kind="every_condition")
    ours, theirs = compare_btlog(0, mode, tmp_path, ticks=24, kind="every_condition")
    assert tree_part(ours.tree_xml) == tree_part(theirs.tree_xml)
    assert {t.status.name for t in ours.transitions} >= {"RUNNING", "SUCCESS", "FAILURE", "IDLE"}
    pair = Pair(0, context, mode, "every_condition")
    try:
        btcpp, ours_reply = pair.both("T")
        assert tree_part(ours_reply[1]) == tree_part(btcpp[1])
        assert b' _skipIf="true"' in ours_reply[1]  # the case: Groot2 sees why the node was skipped
    finally:
        pair.close()


def used_conditions(seeds: list[int], kind: str = "conditions") -> set[str]:
    return {name for seed in seeds for name in CONDITIONS if f" {name}=" in generate(seed, kind).xml}


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_trees_with_every_condition_attribute_serve_what_btcpp_serves(mode: str, context: zmq.Context) -> None:
    """FULLTREE keeps ``_skipIf`` ... ``_post`` as BT.CPP's publisher does; STATUS shows what they made of the
    ticks (SKIPPED included), BLACKBOARD the entries their scripts wrote."""
    seeds = condition_seeds(8, mode, ticks=6)
    for seed in seeds:
        compare_server(seed, context, mode=mode, kind="conditions")
    assert used_conditions(seeds) == set(CONDITIONS)


@pytest.mark.parametrize("size", [pytest.param(20, marks=pytest.mark.slow, id="20"),
                                  pytest.param(60, marks=[pytest.mark.slow, pytest.mark.fuzz], id="60")])
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_trees_with_every_condition_attribute_serve_what_btcpp_serves_sweep(mode: str, size: int,
                                                                            context: zmq.Context) -> None:
    for seed in condition_seeds(size, mode, ticks=10, start=1000):
        compare_server(seed, context, ticks=10, mode=mode, kind="conditions")


@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_of_trees_with_every_condition_attribute_equals_btcpp_file_logger(mode: str, tmp_path: Path) -> None:
    seeds = condition_seeds(8, mode, ticks=10)
    for seed in seeds:
        compare_btlog(seed, mode, tmp_path, kind="conditions")
    assert used_conditions(seeds) == set(CONDITIONS)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_btlog_of_trees_with_every_condition_attribute_sweep(mode: str, tmp_path: Path) -> None:
    for seed in condition_seeds(60, mode, ticks=10, start=1000):
        compare_btlog(seed, mode, tmp_path, kind="conditions")


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
