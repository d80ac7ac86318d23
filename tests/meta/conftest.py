"""Shared task files, worlds and plugin hosts for the meta-reasoner tests (fake world only, no simulator)."""

from __future__ import annotations

from typing import Any

import pytest
from bt_meta_plugins import (
    classification_rules,
    ground_truth_perception,
    refinement_predicates,
    retry_repair,
    symbolic_expectations,
)

from bt_meta.htn import load_task_text
from bt_meta.plugins import create_plugin_host
from bt_meta.world.base import FAILURE, SkillFailure
from bt_meta.world.fake import FakeWorld

BLOCKS = """
domain:
  name: blocks
  types: [block, cell]
  predicates:
    on_table: [block]
    at: [block, cell, cell]
    hand_empty: []
    held: [block]
  primitives:
    pick:
      parameters: [?b - block]
      precondition: on_table(?b) and hand_empty()
      add: [held(?b)]
      delete: [on_table(?b), hand_empty()]
    put:
      parameters: [?b - block, ?x - cell, ?y - cell]
      precondition: held(?b)
      add: [at(?b, ?x, ?y), hand_empty()]
      delete: [held(?b)]
  tasks:
    put_at: [?x - cell, ?y - cell]
    draw: []
  methods:
    - name: draw_two
      task: draw()
      subtasks: [put_at(0, 0), put_at(1, 0)]
    - name: put_any
      task: put_at(?x, ?y)
      precondition: on_table(?b)
      subtasks: [pick(?b), put(?b, ?x, ?y)]
    - name: put_held
      task: put_at(?x, ?y)
      precondition: held(?b)
      subtasks: [put(?b, ?x, ?y)]
problems:
  two:
    objects: {block: [b0, b1, b2], cell: [0, 1]}
    init: [on_table(b0), on_table(b1), on_table(b2), hand_empty()]
    tasks: [draw()]
    goal: [at(b0, 0, 0)]
  one:
    objects: {block: [b0, b1, b2], cell: [0, 1]}
    init: [on_table(b0), on_table(b1), on_table(b2), hand_empty()]
    tasks: [put_at(0, 0)]
    goal: [at(b0, 0, 0)]
"""

ATTACH = """
domain:
  name: attach
  types: [part, pose]
  predicates:
    at: [pose]
    grasp_pose: [part, pose]
    holding: [part]
    attached: [part, part]
  primitives:
    MoveTo:
      parameters: [?p - pose]
      precondition: at(?from)
      add: [at(?p)]
      delete: [at(?from)]
    Grasp:
      parameters: [?x - part]
      add: [holding(?x)]
      delete: []
    Attach:
      parameters: [?a - part, ?r - part]
      precondition: holding(?a)
      add: [attached(?a, ?r)]
      delete: [holding(?a)]
  tasks:
    MagneticAttach: [?a - part, ?r - part]
  methods:
    - name: nominal
      task: MagneticAttach(?a, ?r)
      precondition: grasp_pose(?a, ?g)
      subtasks: [MoveTo(?g), Grasp(?a), Attach(?a, ?r)]
problems:
  attach:
    objects: {part: [active, reference], pose: [home, g_nominal, g_alt]}
    init: [at(home), grasp_pose(active, g_nominal)]
    tasks: [MagneticAttach(active, reference)]
    goal: [attached(active, reference)]
"""

NOMINAL_POSE = [0.60, -0.20, 0.80, 0.0, 0.0, 0.0]
VARIANT_POSE = [0.60, -0.20, 0.80, 3.14159, 0.0, 0.0]  # upside down
REFERENCE_POSE = [0.70, 0.10, 0.80, 0.0, 0.0, 0.0]


class ScriptedFailure:
    """A skill that fails at once with a given kind and evidence (a collision, an unreachable target, ...)."""

    def __init__(self, world: Any, kind: str, message: str, evidence: dict[str, Any]) -> None:
        self.world = world
        self.failure: SkillFailure | None = None
        self._failure = SkillFailure(kind, message, evidence)

    def start(self, args: Any, ctx: Any = None) -> None:
        self.world.scripted_starts += 1

    def tick(self) -> str:
        self.failure = self._failure
        return FAILURE

    def record(self) -> dict[str, Any]:
        return {"scripted": self._failure.kind}


class ScriptedWorld(FakeWorld):
    """A fake world where ``scripted[action] = (kind, message, evidence)`` makes every ``action`` fail that way."""

    def __init__(self, *args: Any, scripted: dict[str, tuple[str, str, dict[str, Any]]] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.scripted = dict(scripted or {})
        self.scripted_starts = 0

    def skill(self, action: str) -> Any:
        if action in self.scripted:
            kind, message, evidence = self.scripted[action]
            return ScriptedFailure(self, kind, message, evidence)
        return super().skill(action)


class PosedWorld(FakeWorld):
    """The magnetic-attach stand-in: objects have poses; ``Attach`` fails unless the gripper went to the grasp pose
    that fits the active part's pose (``g_alt`` when it is upside down), as a misaligned attachment would."""

    def __init__(self, domain: Any, problem: Any, active_pose: list[float], **kwargs: Any) -> None:
        super().__init__(domain, problem, **kwargs)
        self.poses = {"active": list(active_pose), "reference": list(REFERENCE_POSE)}
        self.fitting = "g_alt" if abs(active_pose[3]) > 1.0 else "g_nominal"
        self.gripper_target: str | None = None
        self.scripted_starts = 0

    def observe(self) -> dict[str, Any]:
        return {"symbolic_state": self.symbolic_state(),
                "objects": {name: {"name": name, "pose": list(pose)} for name, pose in self.poses.items()}}

    def skill(self, action: str) -> Any:
        world = self
        if action == "Attach" and self.gripper_target != self.fitting:
            return ScriptedFailure(self, "unexpected_configuration", "attachment points misaligned",
                                   {"R_p": 0.05, "R_n": 3.1, "gripper_target": self.gripper_target})
        skill = super().skill(action)
        if action == "MoveTo":
            start = skill.start

            def remember(args: Any, ctx: Any = None) -> None:
                world.gripper_target = args[0]
                start(args, ctx)

            skill.start = remember  # type: ignore[method-assign]
        return skill


SHIPPED = (
    ("ground_truth_perception", ground_truth_perception),
    ("symbolic_expectations", symbolic_expectations),
    ("classification_rules", classification_rules),
    ("retry_repair", retry_repair),
    ("refinement_predicates", refinement_predicates),
)


def make_host(*extra: tuple[str, Any], perception: bool = True, retry: bool = True) -> Any:
    plugins = [(name, module) for name, module in SHIPPED
               if (perception or name not in ("ground_truth_perception", "symbolic_expectations"))
               and (retry or name != "retry_repair")]
    return create_plugin_host(entry_points=False, plugins=[*plugins, *extra])


@pytest.fixture
def blocks():
    return load_task_text(BLOCKS, "<blocks>")


@pytest.fixture
def attach():
    return load_task_text(ATTACH, "<attach>")


@pytest.fixture(autouse=True)
def _clean_blackboard(bt_blackboard):
    yield
