"""Shared fixtures for the world tests: the Baxter kinematic model and its collision checker, one per test module;
``place``, a place skill ticked to its end."""

from __future__ import annotations

import pytest

from bt_meta.world.base import RUNNING
from bt_meta.world.kinematics.collision import CollisionChecker
from bt_meta.world.kinematics.forward import Kinematics
from bt_meta.world.robot.description import load_robot


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics(load_robot("baxter"))


@pytest.fixture(scope="module")
def checker(kin) -> CollisionChecker:
    return CollisionChecker(kin)


@pytest.fixture
def place():
    """``place(world, block, x, y)``: the world's place skill started and ticked until it ends (600 ticks at most);
    the skill it ran, to read its outcome from."""
    def run(world, block: str, x: str, y: str):
        skill = world.skill("place")
        skill.start([block, x, y])
        for _ in range(600):
            if skill.tick() != RUNNING:
                return skill.inner
        raise AssertionError("place did not finish")

    return run
