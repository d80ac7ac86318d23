"""The shipped taxonomy rules, one kind at a time, and their place in the firstresult hook."""

from __future__ import annotations

from typing import Any

import pytest
from bt_meta_plugins.classification_rules import classify

from bt_meta.bt.context import RunContext
from bt_meta.bt.expectations import Comparison, Expectation, StepContext
from bt_meta.bt.failures import Failure, FailureKind
from bt_meta.htn import plan
from bt_meta.meta import MetaReasoner, PlanState, ReasonerPlugin
from bt_meta.plugins import hookimpl
from bt_meta.world.fake import FakeWorld

from .conftest import make_host

K = FailureKind


def _mismatch(*missing: str) -> Comparison:
    return Comparison(False, "effects not observed", {"missing": list(missing), "not_deleted": []},
                      Expectation("symbolic", "effects"))


def _failure(kind: FailureKind = K.UNEXPECTED_CONFIGURATION, message: str = "mismatch", **evidence: Any) -> Failure:
    return Failure(kind=kind, message=message, step=1, node_id="n2", action="put", args=("b0", "0", "0"),
                   evidence=evidence)


class ObjectsWorld(FakeWorld):
    def __init__(self, *args: Any, objects: dict[str, Any], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.objects = objects

    def observe(self) -> dict[str, Any]:
        return {"symbolic_state": self.symbolic_state(), "objects": self.objects}


def _context(blocks, objects=None) -> StepContext:
    problem = blocks.problem("two")
    world = ObjectsWorld(blocks.domain, problem, objects=objects or {})
    run = RunContext(world, None, domain=blocks.domain, problem=problem)
    return StepContext(action="put", args=("b0", "0", "0"), run=run)


@pytest.mark.parametrize(("failure", "mismatches", "expected"), [
    (_failure(K.INTERNAL, "plugin raised"), [], None),
    (_failure(K.PRECONDITION, "precondition held(b0) does not hold", condition="held(?b)"), [], None),
    (_failure(K.PHYSICAL, "arm stopped", colliding_pair=["right_gripper", "b1"]), [], K.COLLISION),
    (_failure(K.PHYSICAL, "blocked", contacts=[{"a": "hand", "b": "table"}]), [], K.COLLISION),
    (_failure(K.PHYSICAL, "no motion", unreachable_target=[1.5, 0, 0, 0, 0, 0]), [], K.REACHABILITY),
    (_failure(K.PHYSICAL, "no IK solution for the grasp pose"), [], K.REACHABILITY),
    (_failure(K.PHYSICAL, "target out of workspace"), [], K.REACHABILITY),
    (_failure(K.UNEXPECTED_CONFIGURATION, "goal missing", verifier="goal"), [], K.VERIFICATION),
    (_failure(K.UNEXPECTED_CONFIGURATION, "part still on the table",
              localisation={"ancestors": [{"task": ["VerifyAttachment", "a", "r"]}]}), [_mismatch("lifted(a)")],
     K.VERIFICATION),
    (_failure(), [Comparison(False, "", {"unknown_entities": ["blob3"]}, Expectation("gridmap", "crop"))],
     K.UNKNOWN_ENTITY),
    (_failure(), [Comparison(False, "b5: 4 cells differ", {"suggested_kind": "unknown_entity"},
                             Expectation("gridmap", "crop"))], K.UNKNOWN_ENTITY),
    (_failure(), [Comparison(False, "R_n off", {"suggested_kind": "no_such_kind"}, Expectation("keypoint", "R_n"))],
     K.UNEXPECTED_CONFIGURATION),
    (_failure(), [_mismatch("held(b0)")], K.PHYSICAL),
    (_failure(K.UNEXPECTED_CONFIGURATION, "the block slipped"), [], K.PHYSICAL),
    (_failure(), [_mismatch("at(b0, 0, 0)")], K.UNEXPECTED_CONFIGURATION),
    (_failure(K.PHYSICAL, "scripted fault"), [], None),
])
def test_rules(failure, mismatches, expected):
    assert classify(failure, mismatches, None) == expected


def test_unknown_entities_are_found_by_comparing_the_world_with_the_problem(blocks):
    # b1 is gone and two blocks the problem does not know are on the table (section 6.4's variants)
    context = _context(blocks, {"b0": {}, "b2": {}, "x1": {}, "x2": {}})
    failure = _failure()
    assert classify(failure, [_mismatch("at(b1, 1, 0)")], context) is K.UNKNOWN_ENTITY
    assert failure.evidence["missing_entities"] == ["b1"]
    assert failure.evidence["unknown_entities"] == ["x1", "x2"]
    # every object accounted for: a known entity in an unseen configuration
    context = _context(blocks, {"b0": {}, "b1": {}, "b2": {}})
    assert classify(_failure(), [_mismatch("at(b1, 1, 0)")], context) is K.UNEXPECTED_CONFIGURATION


class SaysCollision:
    @hookimpl(tryfirst=True)
    def bt_meta_classify_failure(self, failure: Any, mismatches: Any, context: Any) -> str:
        return "collision"


class SaysNonsense:
    @hookimpl(tryfirst=True)
    def bt_meta_classify_failure(self, failure: Any, mismatches: Any, context: Any) -> str:
        return "gremlins"


def _diagnose(blocks, host, failure):
    problem = blocks.problem("two")
    state = PlanState(plan(blocks.domain, problem).tree, 1)
    run = RunContext(FakeWorld(blocks.domain, problem), host, domain=blocks.domain, problem=problem)
    return MetaReasoner(host).diagnose([failure], state, run), run


def test_the_reasoner_localises_and_classifies_through_the_hook(blocks):
    failure = _failure(mismatches=[{"expectation": "effects", "kind": "symbolic", "plugin": "symbolic_expectations",
                                    "message": "", "evidence": {"missing": ["held(b0)"]}}])
    diagnosis, _ = _diagnose(blocks, make_host(), failure)
    assert diagnosis.kind is K.PHYSICAL and diagnosis.classified_by == "classification_rules"
    assert failure.evidence["suggested_kind"] == "unexpected_configuration"
    assert diagnosis.step == 1 and diagnosis.node_id == "n2"
    assert [a["task"] for a in diagnosis.ancestors] == [["put_at", "0", "0"], ["draw"]]
    assert [s["done"] for s in failure.evidence["plan"]] == [True, False, False, False]


def test_a_tryfirst_plugin_overrides_the_shipped_rules(blocks):
    diagnosis, _ = _diagnose(blocks, make_host(("mine", SaysCollision())), _failure())
    assert diagnosis.kind is K.COLLISION and diagnosis.classified_by == "mine"


def test_a_classifier_answering_an_unknown_kind_is_noted_not_obeyed(blocks):
    failure = _failure()
    diagnosis, _ = _diagnose(blocks, make_host(("nonsense", SaysNonsense())), failure)
    assert diagnosis.kind is K.UNEXPECTED_CONFIGURATION
    assert "unknown failure kind 'gremlins'" in failure.evidence["classification_error"]


def test_the_advice_plugin_ranks_proposals_on_failure(bt_harness):
    from .conftest import BLOCKS

    host = make_host()
    host.register(ReasonerPlugin(host), "meta_advice")
    harness = bt_harness(BLOCKS, "two", plugins=host, faults=["pick#1=fail:physical"])
    harness.tick_until("done")
    notes = harness.failures[0].evidence["meta"]["meta_advice"]
    assert notes["kind"] == "physical"
    assert [p["action"] for p in notes["proposals"]] == ["retry", "replan", "replan_scratch"]
