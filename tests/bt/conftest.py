"""Shared fixtures for the behaviour-tree tests."""

from __future__ import annotations

import py_trees
import pytest


@pytest.fixture
def clean_blackboard():
    """Empty py_trees' whole process-wide blackboard before and after the test (test files opt in with
    ``pytestmark = pytest.mark.usefixtures("clean_blackboard")``)."""
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()
