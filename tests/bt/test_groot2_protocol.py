"""Groot2 protocol bytes, tree numbering and XML, against golden values derived from BehaviorTree.CPP's source.

``groot2_protocol.h`` (header layout), ``groot2_publisher.cpp`` (IDLE_FROM_* codes, transitions), nlohmann::json's
``to_msgpack`` (blackboard replies) and ``xml_parsing.cpp`` (uids, ``_fullpath``). The live comparison with
BehaviorTree.CPP's own publisher is in ``test_groot2_differential.py``.
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET

import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.groot2 import msgpack
from bt_meta.bt.groot2.observer import StatusObserver
from bt_meta.bt.groot2.protocol import (
    NodeStatus,
    ProtocolError,
    RequestHeader,
    RequestType,
    Transition,
    idle_code,
    pack_reply_header,
    pack_status_buffer,
    pack_transition,
    status_code,
    tree_uuid,
    unpack_transitions,
)
from bt_meta.bt.groot2.published_tree import PublishedTree, json_value
from bt_meta.bt.groot2.tree_xml import full_tree_xml
from bt_meta.bt.nodes.ticking import tick_exactly_once
from bt_meta.bt.registry import NodeType, default_registry
from bt_meta.bt.xml.reader import load_tree_text

pytestmark = pytest.mark.usefixtures("clean_blackboard")

TREE = """<root BTCPP_format="4" main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <Sequence name="seq">
      <SetBlackboard output_key="x" value="3"/>
      <Work/>
      <SubTree ID="Sub" x="{x}"/>
      <SubTree ID="Sub" name="second" _autoremap="true"/>
      <Inverter><AlwaysFailure/></Inverter>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Sub">
    <Fallback><Work name="inner"/><Repeat num_cycles="{x}"><AlwaysSuccess name="ok"/></Repeat></Fallback>
  </BehaviorTree>
</root>"""


def registry_with_work(script: list[Status]):
    registry = default_registry()
    calls = {"n": 0}

    class Work(py_trees.behaviour.Behaviour):
        def update(self) -> Status:
            status = script[calls["n"] % len(script)]
            calls["n"] += 1
            return status

    registry.register(NodeType("Work", "Action", [], lambda *, name, ports, children: Work(name)))
    return registry


def test_request_header_layout_is_protocol_type_then_little_endian_id() -> None:
    header = RequestHeader(0x01020304, RequestType.STATUS)
    assert header.pack() == bytes([2, ord("S"), 4, 3, 2, 1])
    assert RequestHeader.unpack(header.pack()) == header
    with pytest.raises(ProtocolError, match="wrong request header"):
        RequestHeader.unpack(b"\x02S\x00")


def test_reply_header_echoes_the_request_with_protocol_2_and_the_tree_id() -> None:
    tree_id = bytes(range(16))
    reply = pack_reply_header(RequestHeader(7, ord("T"), protocol=9), tree_id)
    assert reply == bytes([2, ord("T"), 7, 0, 0, 0]) + tree_id
    assert len(reply) == 22


def test_tree_uuid_is_a_version_4_uuid_that_changes_with_the_tree() -> None:
    first = tree_uuid("<root/>")
    assert first == tree_uuid("<root/>") and first != tree_uuid("<root BTCPP_format='4'/>")
    assert first[6] >> 4 == 4 and first[8] >> 6 == 0b10 and len(first) == 16


def test_status_codes_and_idle_after_a_status() -> None:
    assert [status_code(s) for s in (Status.INVALID, Status.RUNNING, Status.SUCCESS, Status.FAILURE)] == [0, 1, 2, 3]
    assert [idle_code(s) for s in (NodeStatus.RUNNING, NodeStatus.SUCCESS, NodeStatus.FAILURE)] == [11, 12, 13]
    assert pack_status_buffer([(1, 2), (258, 13)]) == bytes([1, 0, 2, 2, 1, 13])
    with pytest.raises(ProtocolError, match=r"no BehaviorTree\.CPP equivalent"):
        status_code("DONE")


def test_transitions_are_48_bit_time_uid_status() -> None:
    transition = Transition((1 << 40) + 5, 0x0102, NodeStatus.FAILURE)
    packed = pack_transition(transition)
    assert packed == (5).to_bytes(1, "little") + bytes([0, 0, 0, 0, 1]) + bytes([2, 1, 3])
    assert unpack_transitions(packed * 2) == [transition, transition]
    with pytest.raises(ProtocolError, match="9 bytes"):
        unpack_transitions(packed[:5])


def test_msgpack_matches_nlohmann_json() -> None:
    # BehaviorTree.CPP 4.8.2's reply to BLACKBOARD "MainTree;Sub::4" after SetBlackboard x=3 (read off the wire).
    golden = "82a84d61696e5472656581a178a133a65375623a3a34c0"
    assert msgpack.packb({"MainTree": {"x": "3"}, "Sub::4": None}).hex() == golden
    assert msgpack.packb(None) == b"\xc0"
    assert msgpack.packb([True, False, 127, 128, -32, -33, 65536]) == bytes.fromhex("97c3c27fcc80e0d0dfce00010000")
    assert msgpack.packb(0.5) == b"\xca" + struct.pack(">f", 0.5)  # float32 when exact, as nlohmann does
    assert msgpack.packb(0.1) == b"\xcb" + struct.pack(">d", 0.1)
    assert msgpack.packb("x" * 40)[:2] == b"\xd9\x28"
    assert msgpack.packb({"b": 1, "a": 2}) == b"\x82\xa1a\x02\xa1b\x01"  # keys sorted like std::map
    with pytest.raises(TypeError, match="cannot encode"):
        msgpack.packb(object())


def test_json_values_follow_behaviortree_cpp_exporter() -> None:
    assert json_value("a") == "a" and json_value(True) == 1 and json_value(2.5) == 2.5
    assert json_value([1, 2]) == [1, 2] and json_value([1, "a"]) is None and json_value(object()) is None


def test_uids_are_preorder_over_the_expanded_tree_and_subtrees_are_named_as_in_btcpp() -> None:
    root = load_tree_text(TREE, registry_with_work([Status.SUCCESS]))
    tree = PublishedTree.build(root, registry=registry_with_work([Status.SUCCESS]))
    names = [(n.uid, n.registration_name, n.name) for n in tree.nodes]
    assert names == [
        (1, "Sequence", "seq"), (2, "SetBlackboard", "SetBlackboard"), (3, "Work", "Work"), (4, "SubTree", "Sub"),
        (5, "Fallback", "Fallback"), (6, "Work", "inner"), (7, "Repeat", "Repeat"), (8, "AlwaysSuccess", "ok"),
        (9, "SubTree", "second"), (10, "Fallback", "Fallback"), (11, "Work", "inner"), (12, "Repeat", "Repeat"),
        (13, "AlwaysSuccess", "ok"), (14, "Inverter", "Inverter"), (15, "AlwaysFailure", "AlwaysFailure"),
    ]
    assert [s.published_name for s in tree.subtrees] == ["MainTree", "Sub::4", "second"]
    assert [n.uid for n in tree.status_order()] == [1, 2, 3, 4, 9, 14, 15, 5, 6, 7, 8, 10, 11, 12, 13]
    assert tree.nodes[3].path == "Sub::4" and tree.nodes[8].path == "second"
    assert tree.nodes[1].path == "SetBlackboard::2"


def test_full_tree_xml_carries_uids_fullpaths_and_models() -> None:
    registry = registry_with_work([Status.SUCCESS])
    tree = PublishedTree.build(load_tree_text(TREE, registry), registry=registry)
    text = full_tree_xml(tree)
    assert text.startswith('<root BTCPP_format="4">\n    <BehaviorTree ID="MainTree" _fullpath="">\n')
    assert '        <Sequence name="seq" _uid="1">\n' in text
    assert '<SubTree ID="Sub" _fullpath="Sub::4" _uid="4" x="{x}"/>' in text
    document = ET.fromstring(text)
    assert [(b.get("ID"), b.get("_fullpath")) for b in document.findall("BehaviorTree")] == [
        ("MainTree", ""), ("Sub", "Sub::4"), ("Sub", "second")]
    models = {m.get("ID"): m for m in document.find("TreeNodesModel")}
    assert models["Work"].tag == "Action"
    assert models["SubTree"].find("input_port").attrib == {"name": "_autoremap", "type": "bool", "default": "false"}
    assert document.find(".//Repeat").get("num_cycles") == "{x}"


def test_observer_reports_resets_to_idle_that_a_later_read_would_miss() -> None:
    registry = registry_with_work([Status.SUCCESS])
    root = load_tree_text(TREE, registry)
    tree = PublishedTree.build(root, registry=registry)
    seen: list[tuple[int, NodeStatus]] = []
    original = type(root)
    with StatusObserver(tree, clock=lambda: 0) as observer:
        observer.subscribe(lambda _t, uid, _prev, new: seen.append((uid, new)))
        observer.tick_finished(tick_exactly_once(root))
        assert type(root) is not original and type(root).__name__ == original.__name__
    assert type(root) is original  # closing gives every behaviour its class back
    assert seen[:3] == [(1, NodeStatus.RUNNING), (2, NodeStatus.SUCCESS), (3, NodeStatus.SUCCESS)]
    assert (2, NodeStatus.IDLE) in seen  # the Sequence reset its children when it finished
    assert seen[-1] == (1, NodeStatus.IDLE)  # Tree::tickRoot resets a finished root
    assert root.status == Status.SUCCESS  # ... without touching what bt-meta reads


def test_blackboard_entries_per_subtree_typed_like_btcpp() -> None:
    registry = registry_with_work([Status.FAILURE])
    root = load_tree_text(TREE, registry)
    tree = PublishedTree.build(root, registry=registry)
    main, first, second = tree.subtrees
    # Before any tick BT.CPP already has the entry {x} its Repeat ports created: shown as null.
    assert tree.blackboard(main) == {"x": None}
    assert tree.blackboard(first) == {} and tree.blackboard(second) == {}
    tick_exactly_once(root)
    # SetBlackboard wrote the text "3" into an entry an int port created: BT.CPP stores the number.
    assert tree.blackboard(main) == {"x": 3}


def test_a_monitored_action_shows_what_its_monitor_decided(tmp_path) -> None:
    """A compiled plan (a Monitor around every primitive): the failing primitive's uid carries the failure and the
    monitors themselves are no nodes of the published tree."""
    from pathlib import Path

    from bt_meta.bt.groot2.btlog import read_btlog
    from bt_meta.bt.groot2.session import Groot2Session
    from bt_meta.testing import TreeHarness
    from bt_meta.world.fake import Fault

    tasks = Path(__file__).resolve().parents[2] / "trees" / "letters.yaml"
    harness = TreeHarness.from_file(tasks, "A", world="fake", faults=[Fault.parse("place(b1, 0, 1)=fail")])
    session = Groot2Session.start(harness.root, registry=harness.compiled.registry, btlog=tmp_path / "a.btlog")
    try:
        wrapped = [node for node in session.tree.nodes if node.behaviour is not node.node]
        assert len(wrapped) == 6 and all(node.behaviour.is_monitor for node in wrapped)  # the six placements
        assert not any(getattr(node.node, "is_monitor", False) for node in session.tree.nodes)
        status = harness.tick()
        session.after_tick(status)
    finally:
        session.close()
        harness.close()
    assert status == Status.FAILURE
    log = read_btlog(tmp_path / "a.btlog")
    uids = {e.get("name"): int(e.get("_uid")) for e in ET.fromstring(log.tree_xml).iter() if e.get("_uid")}
    failing = uids["n3 place(b1, 0, 1)"]
    assert (failing, NodeStatus.FAILURE) in [(t.uid, t.status) for t in log.transitions]
    assert (uids["n5 place(b2, 3, 0)"], NodeStatus.RUNNING) not in [(t.uid, t.status) for t in log.transitions]
    assert not [e for e in ET.fromstring(log.tree_xml).iter() if e.tag.startswith("Monitor")]
