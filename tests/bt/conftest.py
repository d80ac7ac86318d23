"""Shared fixtures for the behaviour-tree tests."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable

import py_trees
import pytest


@pytest.fixture
def clean_blackboard():
    """Empty py_trees' whole process-wide blackboard before and after the test (test files opt in with
    ``pytestmark = pytest.mark.usefixtures("clean_blackboard")``)."""
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


@pytest.fixture
def btcpp_tick_order() -> Callable[[ET.Element, dict[str, str]], list[str]]:
    """``run(document, custom)``: tick a tree document once in the real BehaviorTree.CPP (behaviortreepy), every
    custom node (ID -> category) a SUCCESS-returning simple node registered without ports (behaviortreepy cannot
    declare ports, so their port attributes are dropped from ``document``); asserts the tree succeeds and returns
    the custom nodes' names in the order BT.CPP ticked them."""
    import behaviortreepy as btpy

    def run(document: ET.Element, custom: dict[str, str]) -> list[str]:
        for element in document.iter():
            if element.tag in custom:
                for attribute in [a for a in element.attrib if a != "name"]:
                    del element.attrib[attribute]
        factory = btpy.BehaviorTreeFactory()
        order: list[str] = []

        def tick(node):
            order.append(node.name())
            return btpy.NodeStatus.SUCCESS

        for node_id, category in custom.items():
            if category == "Condition":
                factory.register_simple_condition(node_id, tick)
            else:
                factory.register_simple_action(node_id, tick)
        tree = factory.create_tree_from_text(ET.tostring(document, encoding="unicode"))
        assert tree.tick_once() == btpy.NodeStatus.SUCCESS
        return order

    return run
