"""Shared fixtures for the world tests: the Baxter kinematic model and its collision checker, one per test module."""

from __future__ import annotations

import pytest

from bt_meta.world.kinematics.collision import CollisionChecker
from bt_meta.world.kinematics.forward import Kinematics
from bt_meta.world.robot.description import load_robot


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics(load_robot("baxter"))


@pytest.fixture(scope="module")
def checker(kin) -> CollisionChecker:
    return CollisionChecker(kin)
