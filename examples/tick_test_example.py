"""Testing a behaviour tree tick by tick with bt-meta's pytest plugin (no simulator needed).

The ``bt_harness`` fixture (from ``bt_meta.testing``, installed as a pytest plugin) plans a task file, compiles the
plan into a py_trees tree with a Monitor around every primitive, and ticks it in the fake world. Run it with
``pytest examples/tick_test_example.py``.
"""

from __future__ import annotations

from py_trees.common import Status

from bt_meta.resources import shipped_tree

LETTERS = shipped_tree("letters.yaml")


def test_letter_A_is_drawn_block_by_block(bt_harness):
    harness = bt_harness(LETTERS, "A", ticks_per_skill=2)  # every place() takes two ticks
    assert harness.tick() is Status.RUNNING
    first = harness.node(next(name for name in harness.statuses() if " place(" in name), raw=True)
    assert harness.status(first.name) is Status.RUNNING
    assert harness.tick_until(Status.SUCCESS) is Status.SUCCESS
    assert harness.failures == []
    placed = [atom for atom in harness.state if atom[0] == "at"]
    assert len(placed) == len(harness.world.executed)  # one block placed per primitive


def test_a_block_that_silently_stays_put_is_caught_at_its_step(bt_harness):
    # The third place() reports SUCCESS but its effect does not happen; the symbolic expectation plugin notices.
    harness = bt_harness(LETTERS, "A", faults=["place#3=silent"])
    assert harness.tick_until() is Status.FAILURE
    [failure] = harness.failures
    assert failure.kind.value == "unexpected_configuration"
    assert failure.step == 2 and failure.action == "place"
    assert harness.status(failure.node_id) is Status.FAILURE
    print(failure.summary())
