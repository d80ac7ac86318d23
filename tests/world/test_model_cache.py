"""Process-lifetime model caches: loaded once, handed out as copies where a world mutates them, off on request."""

from __future__ import annotations

import numpy as np
import pytest

from bt_meta import model_cache
from bt_meta.safe_yaml import compose_yaml, load_yaml
from bt_meta.world.kinematics.collision import CollisionChecker
from bt_meta.world.kinematics.forward import Kinematics
from bt_meta.world.kinematics.mujoco_model import build_mujoco_model
from bt_meta.world.robot.description import load_robot


@pytest.fixture(autouse=True)
def _fresh_cache(monkeypatch):
    monkeypatch.delenv("BT_META_MODEL_CACHE", raising=False)
    model_cache.clear()
    yield
    model_cache.clear()


def test_cached_computes_once_and_not_at_all_when_switched_off(monkeypatch):
    calls = []
    assert model_cache.cached("k", lambda: calls.append(1) or len(calls)) == 1
    assert model_cache.cached("k", lambda: calls.append(1) or len(calls)) == 1
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    assert model_cache.cached("k", lambda: calls.append(1) or len(calls)) == 2
    assert len(calls) == 2


def test_a_failed_computation_is_not_remembered():
    def fail():
        raise ValueError("no")

    with pytest.raises(ValueError):
        model_cache.cached("bad", fail)
    assert model_cache.cached("bad", lambda: 3) == 3


def test_an_edited_file_gets_a_new_signature(tmp_path):
    path = tmp_path / "f.txt"
    path.write_text("a")
    before = model_cache.file_signature(path)
    path.write_text("ab")
    assert model_cache.file_signature(path) != before
    assert model_cache.file_signature(None) is None


def test_the_robot_description_is_parsed_once_per_process(monkeypatch):
    first = load_robot("baxter")
    assert load_robot("baxter") is first
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    again = load_robot("baxter")
    assert again is not first and again == first


def test_each_collision_checker_gets_its_own_geometry():
    kinematics = Kinematics(load_robot("baxter"))
    one, two = CollisionChecker(kinematics), CollisionChecker(kinematics)
    robot_geometries = one.geometry.ngeoms
    assert one.geometry is not two.geometry
    one.add_box("block", (0.05, 0.05, 0.05), (0.6, -0.2, -0.15))
    assert one.geometry.ngeoms == robot_geometries + 1
    assert two.geometry.ngeoms == robot_geometries
    assert CollisionChecker(kinematics).geometry.ngeoms == robot_geometries  # the cached model is untouched


def test_a_cached_checker_finds_what_an_uncached_one_finds(monkeypatch):
    kinematics = Kinematics(load_robot("baxter"))
    rng = np.random.default_rng(3)
    samples = [kinematics.random_q(rng) for _ in range(20)]
    CollisionChecker(kinematics)  # fills the cache
    cached = CollisionChecker(kinematics)
    monkeypatch.setenv("BT_META_MODEL_CACHE", "0")
    fresh = CollisionChecker(kinematics)
    for checker in (cached, fresh):
        checker.add_box("block", (0.3, 0.3, 0.3), (0.6, -0.2, 0.0))
    assert [str(cached.check(q)) for q in samples] == [str(fresh.check(q)) for q in samples]
    assert cached.n_self_pairs == fresh.n_self_pairs and cached.n_scene_pairs == fresh.n_scene_pairs


def test_each_ik_model_is_a_copy_of_the_compiled_one():
    kinematics = Kinematics(load_robot("baxter"))
    one, two = build_mujoco_model(kinematics, "right"), build_mujoco_model(kinematics, "right")
    assert one.model is not two.model and one.joint_names == two.joint_names
    one.model.jnt_range[0] = (0.0, 0.1)
    assert tuple(two.model.jnt_range[0]) != (0.0, 0.1)


def test_the_same_yaml_text_is_composed_once():
    text = "a: 1\nb: [1, 2]\n"
    assert compose_yaml(text, "x.yaml") is compose_yaml(text, "x.yaml")
    assert compose_yaml(text, "y.yaml") is not compose_yaml(text, "x.yaml")  # errors name the file they came from


def test_a_huge_yaml_text_is_not_kept():
    text = "a: [" + ", ".join(["1"] * 100_000) + "]\n"
    assert compose_yaml(text, "big.yaml") is not compose_yaml(text, "big.yaml")


def test_yaml_with_merge_keys_is_never_reused():
    text = "base: &b {x: 1}\nother:\n  <<: *b\n  y: 2\n"
    assert compose_yaml(text, "m.yaml") is not compose_yaml(text, "m.yaml")
    assert load_yaml(text, "m.yaml") == load_yaml(text, "m.yaml") == {"base": {"x": 1}, "other": {"x": 1, "y": 2}}


def test_bad_yaml_fails_every_time_with_its_position():
    from bt_meta.errors import UserInputError

    for _ in range(2):
        with pytest.raises(UserInputError, match=r"bad\.yaml:2:"):
            compose_yaml("a: 1\n b: [\n", "bad.yaml")
