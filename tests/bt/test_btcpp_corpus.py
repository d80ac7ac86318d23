"""A corpus of realistic v4 trees of our own writing (navigation with recoveries, table clearing, BT.CPP's crossdoor
tutorial, a patrol, a Groot2-saved file with editor metadata and a bare ``&&``, a delivery split over three files,
BT.CPP's plugin example with a C++ comment line before ``<root>``), each loaded by BehaviorTree.CPP (behaviortreepy)
and by bt-meta and ticked identically.

The custom nodes are scripted leaves (seeded statuses per ID, RUNNING included); behaviortreepy cannot declare
ports, so its copy of each file has the custom nodes' port attributes removed, while bt-meta loads the files as
written, with the custom nodes registered with those ports.
"""

from __future__ import annotations

import random
import re
from pathlib import Path

import behaviortreepy as btpy
import py_trees
import pytest
from py_trees.common import Status

from bt_meta.bt.nodes.status import returned
from bt_meta.bt.nodes.ticking import tick_exactly_once, tick_once
from bt_meta.bt.registry import NodeType, PortSpec, default_registry
from bt_meta.bt.script.values import to_string
from bt_meta.bt.xml.document import parse_file
from bt_meta.bt.xml.reader import load_tree_file

pytestmark = pytest.mark.usefixtures("clean_blackboard")

CORPUS = Path(__file__).parent / "corpus"
FILES = sorted(p.name for p in CORPUS.glob("*.xml"))
STRUCTURE = {"root", "BehaviorTree", "TreeNodesModel", "include", "SubTree", "input_port", "output_port",
             "inout_port", "Action", "Condition", "Control", "Decorator", "MetadataFields"}  # fmt: skip
_TAG = re.compile(r"<([A-Za-z_][\w]*)(\s[^<>]*?)?(/?)>")
_ATTR = re.compile(r'([\w:.-]+)="([^"]*)"')


def custom_ids(document_files: list[str]) -> dict[str, set[str]]:
    """Custom node IDs used by the files, with the port attributes each is written with."""
    builtins = set(default_registry().ids())
    found: dict[str, set[str]] = {}
    for name in document_files:
        text = Path(name).read_text()
        text = re.sub(r"<TreeNodesModel>.*?</TreeNodesModel>", "", text, flags=re.S)
        for tag, attrs, _ in _TAG.findall(text):
            if tag in STRUCTURE or tag in builtins:
                continue
            ports = {a for a, _ in _ATTR.findall(attrs or "") if a[:1].isalpha() and a != "name"}
            found.setdefault(tag, set()).update(ports)
    return found


def strip_custom_ports(text: str, custom: set[str]) -> str:
    def fix(match: re.Match[str]) -> str:
        tag, attrs, close = match.group(1), match.group(2) or "", match.group(3)
        if tag not in custom:
            return match.group(0)
        kept = " ".join(f'{a}="{v}"' for a, v in _ATTR.findall(attrs) if a == "name" or a.startswith("_"))
        return f"<{tag}{' ' + kept if kept else ''}{close}>"

    model = re.compile(r"<TreeNodesModel>.*?</TreeNodesModel>", re.S)
    return model.sub("", _TAG.sub(fix, text))


def scripts_for(ids: list[str], seed: int) -> dict[str, list[str]]:
    rng = random.Random(seed)
    return {node_id: [rng.choice(["SUCCESS", "SUCCESS", "FAILURE", "RUNNING"]) for _ in range(rng.randint(1, 4))]
            for node_id in ids}  # fmt: skip


class _Leaf(py_trees.behaviour.Behaviour):
    """behaviortreepy's stateful action: a finished leaf ticked again before a reset keeps its status."""

    def __init__(
        self, name: str, node_id: str, script: list[str], calls: list[int], log: list[tuple[str, str]]
    ) -> None:
        super().__init__(name)
        # ``calls`` is shared by every node of one ID, as the callbacks registered with behaviortreepy are.
        self.node_id, self.script, self.calls, self.log = node_id, script, calls, log

    def update(self) -> Status:
        if self.status in (Status.SUCCESS, Status.FAILURE):
            return self.status
        status = self.script[self.calls[0] % len(self.script)]
        self.calls[0] += 1
        self.log.append((self.node_id, status))
        return Status[status]

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            self.log.append((self.node_id, "HALT"))


def run_both(name: str, tmp_path: Path, seed: int, mode: str, ticks: int = 15) -> tuple[list, list]:
    main = CORPUS / name
    document = parse_file(main)
    custom = custom_ids(document.files)
    scripts = scripts_for(sorted(custom), seed)
    # BT.CPP's copy: same layout, custom ports removed.
    for file_name in document.files:
        source = Path(file_name).resolve()
        target = tmp_path / source.relative_to(CORPUS.resolve())
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(strip_custom_ports(source.read_text(), set(custom)))
    factory = btpy.BehaviorTreeFactory()
    log: list[tuple[str, str]] = []
    for node_id, script in scripts.items():
        calls = [0]

        def step(_node: object, node_id: str = node_id, script: list[str] = script, calls: list[int] = calls) -> object:
            status = script[calls[0] % len(script)]
            calls[0] += 1
            log.append((node_id, status))
            return getattr(btpy.NodeStatus, status)

        def halted(_node: object, node_id: str = node_id) -> None:
            log.append((node_id, "HALT"))

        factory.register_simple_stateful_action(node_id, step, step, halted)
    theirs = factory.create_tree_from_file(str(tmp_path / name))
    expected = []
    for _ in range(ticks):
        status = (theirs.tick_exactly_once() if mode == "exactly_once" else theirs.tick_once()).name
        board = theirs.root_blackboard()
        keys = sorted(k for k in board.get_keys() if not k.startswith("_"))
        values = {}
        for key in keys:
            try:
                values[key] = board.get_string(key)
            except RuntimeError:
                values[key] = "?"
        expected.append((status, list(log), values))
        log.clear()

    ours_log: list[tuple[str, str]] = []
    registry = default_registry()
    for node_id, script in scripts.items():
        ports = [PortSpec(port, "inout") for port in sorted(custom[node_id])]

        shared = [0]

        def make(
            *, name: str, ports: dict, children: list, node_id: str = node_id, script: list[str] = script,
            shared: list[int] = shared,
        ) -> _Leaf:
            return _Leaf(name, node_id, script, shared, ours_log)

        registry.register(NodeType(node_id, "Action", ports, make))
    ours = load_tree_file(main, registry)
    actual = []
    storage = py_trees.blackboard.Blackboard.storage
    for _ in range(ticks):
        result = tick_exactly_once(ours) if mode == "exactly_once" else tick_once(ours)
        values = {k.lstrip("/"): to_string(v) if isinstance(v, (int, float, str)) else "?" for k, v in storage.items()
                  if k.count("/") == 1 and k.lstrip("/") in expected[len(actual)][2]}  # fmt: skip
        actual.append((result.name, list(ours_log), values))
        ours_log.clear()
    assert returned(ours) is not None
    return expected, actual


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("mode", ["exactly_once", "once"])
def test_corpus_trees_tick_like_behaviortree_cpp(name: str, mode: str, tmp_path: Path) -> None:
    for seed in range(12):
        expected, actual = run_both(name, tmp_path / f"{seed}", seed, mode)
        for tick, (want, got) in enumerate(zip(expected, actual, strict=True)):
            assert got == want, f"{name} seed {seed} mode {mode} tick {tick}\nBT.CPP: {want}\nours:   {got}"


def test_the_corpus_covers_what_integrators_write() -> None:
    text = "".join((CORPUS / name).read_text() for name in FILES) + "".join(
        p.read_text() for p in (CORPUS / "lib").glob("*.xml")
    )
    for feature in ("<include", "_skipIf", "_while", "_onSuccess", "_onFailure", "_post", "_autoremap", "_collapsed",
                    "<Script ", "<ScriptCondition", "<Precondition", "<IfThenElse", "<WhileDoElse", "<Switch3",
                    "<LoopString", "<LoopInt", "<ParallelAll", "<RunOnce", "<SkipUnlessUpdated", "<WasEntryUpdated",
                    "<UnsetBlackboard", "<AsyncSequence", "<TreeNodesModel", " && ",
                    "// clang-format off"):  # fmt: skip
        assert feature in text, feature
