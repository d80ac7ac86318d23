"""The observe request: a camera frame is rendered only when a reader of observations will read it, and observe
plugins written before the request existed still work."""

from __future__ import annotations

from typing import Any

import bt_meta_plugins.camera_perception as camera_plugin
import bt_meta_plugins.gridmap_expectations as gridmap_plugin
import bt_meta_plugins.ground_truth_perception as truth_plugin
import bt_meta_plugins.symbolic_expectations as symbolic_plugin
import pytest
from py_trees.common import Status

from bt_meta.bt.expectations import Comparison
from bt_meta.memory import EpisodicMemory
from bt_meta.perception.synthetic import blank, top_view_projection
from bt_meta.perception.topview import analyse
from bt_meta.plugins import create_plugin_host, hookimpl
from bt_meta.resources import trees_dir
from bt_meta.testing import TreeHarness

PLACES = 6  # letter A on the fake world: six place steps


class CountingCamera(camera_plugin.CameraPerception):
    """The shipped camera perception with the render replaced by a counted synthetic frame."""

    def __init__(self) -> None:
        super().__init__()
        self.renders = 0

    def look(self, world: Any) -> Any:
        self.renders += 1
        projection = top_view_projection()
        return analyse(blank(projection), projection)


class ImageReader:
    """A comparison plugin written before ``bt_meta_observation_needs``: it reads the image without saying so."""

    def __init__(self) -> None:
        self.images: list[Any] = []

    @hookimpl
    def bt_meta_compare(self, expectation: Any, observations: dict[str, Any], context: Any) -> Comparison | None:
        self.images.append(observations.get("image"))
        return None


def _run(camera: CountingCamera, *extra: tuple[str, Any], faults: tuple[str, ...] = (),
         symbolic: bool = True) -> tuple[Status, Any]:
    monitors = [("symbolic_expectations", symbolic_plugin)] if symbolic else []
    plugins = create_plugin_host(entry_points=False, plugins=[
        ("ground_truth_perception", truth_plugin), *monitors, ("camera_perception", camera), *extra])
    harness = TreeHarness.from_file(trees_dir() / "letters.yaml", "A", plugins=plugins, faults=faults)
    return harness.tick_until(), harness


def test_no_frame_is_rendered_when_no_reader_reads_one():
    camera = CountingCamera()
    status, harness = _run(camera)
    assert status is Status.SUCCESS and harness.failures == []
    assert camera.renders == 0  # the symbolic monitor reads the symbolic state only


def test_no_frame_is_rendered_when_nothing_compares():
    """A demonstration being recorded: perception observes for the belief, the recorder takes its own frame."""
    camera = CountingCamera()
    status, _ = _run(camera, symbolic=False)
    assert status is Status.SUCCESS and camera.renders == 0


def test_a_grid_map_reader_gets_the_start_view_and_every_steps_view_but_none_after_a_failure(tmp_path):
    with EpisodicMemory.open(tmp_path / "memory.sqlite") as memory:
        camera = CountingCamera()
        status, _ = _run(camera, ("gridmap_expectations", gridmap_plugin.GridMapExpectations(memory)))
        assert status is Status.SUCCESS
        assert camera.renders == 1 + PLACES  # the run's start, then after each step (the next step's "before")
        camera = CountingCamera()
        status, harness = _run(camera, ("gridmap_expectations", gridmap_plugin.GridMapExpectations(memory)),
                               faults=("place=fail:physical",))
        assert status is Status.FAILURE
        assert [f.kind.value for f in harness.failures] == ["physical"]
        assert camera.renders == 1  # the start only: after the failed step only the belief is read


def test_a_comparison_plugin_that_does_not_declare_its_needs_gets_every_view():
    camera, reader = CountingCamera(), ImageReader()
    status, _ = _run(camera, ("image_reader", reader))
    assert status is Status.SUCCESS
    assert camera.renders == 1 + PLACES
    assert reader.images and all(image is not None and hasattr(image, "grid_map_at") for image in reader.images)


class OldStyleObserver:
    """An observe plugin written to the hookspec before the request: ``(world, context)``."""

    def __init__(self) -> None:
        self.calls = 0

    @hookimpl
    def bt_meta_observe(self, world: Any, context: Any) -> dict[str, Any] | None:
        self.calls += 1
        return {"counted": self.calls}


class CountedReader:
    @hookimpl
    def bt_meta_observation_needs(self, context: Any) -> list[str] | None:
        return ["counted"]

    @hookimpl
    def bt_meta_compare(self, expectation: Any, observations: dict[str, Any], context: Any) -> Comparison | None:
        if expectation.kind != "symbolic":
            return None
        seen = observations.get("counted")
        return Comparison(matched=seen is not None, message=f"counted {seen}")


@pytest.mark.parametrize("reader", [False, True])
def test_an_observe_plugin_written_to_the_old_hookspec_still_observes(reader):
    observer = OldStyleObserver()
    extra = [("old_observer", observer)] + ([("counted_reader", CountedReader())] if reader else [])
    status, harness = _run(CountingCamera(), *extra)
    assert status is Status.SUCCESS and harness.failures == []
    assert observer.calls == 1 + PLACES  # called at the start and after every step, with or without a request


def test_a_needs_hook_that_returns_a_wrong_type_is_contained_and_everything_is_requested():
    class Broken:
        @hookimpl
        def bt_meta_observation_needs(self, context: Any) -> Any:
            return "image"  # a string, not a list of keys

        @hookimpl
        def bt_meta_compare(self, expectation: Any, observations: dict[str, Any], context: Any) -> None:
            return None

    camera = CountingCamera()
    status, _ = _run(camera, ("broken", Broken()))
    assert status is Status.SUCCESS
    assert camera.renders == 1 + PLACES
