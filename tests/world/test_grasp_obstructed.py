"""An empty grasp does not pass: a block resting on the part to grasp makes the grasp a ``collision`` with the
pair, at the grasp, instead of closing on the block and failing two steps later as ``physical`` (simulator, slow).
"""

from __future__ import annotations

import pytest

from bt_meta.htn import load_task_file
from bt_meta.meta import Limits, MetaExecutor
from bt_meta.plugins import create_plugin_host
from bt_meta.resources import trees_dir

MAGNETIC = trees_dir() / "magnetic_attach.yaml"


def run_attach(lid: bool):
    from bt_meta_plugins import classification_rules

    from bt_meta.world.simulation.objects import megablok
    from bt_meta.world.simulation.sim_world import SimWorld, quiet_stdout

    task_file = load_task_file(MAGNETIC)
    with quiet_stdout():
        world = SimWorld.from_task_file(MAGNETIC, "attach_only", seed=0)
    try:
        if lid:
            x, y = world.sim.object_transform("active")[:2, 3]
            top = world.object_top("active")
            world.sim.spawn("lid", megablok("1x1", "green"), (x, y, top + 0.02, 0.0, 0.0, 0.0))
            world.sim.settle(60)
            world.sync_collision()
        host = create_plugin_host(entry_points=False, plugins=[("classification_rules", classification_rules)])
        report = MetaExecutor(task_file.domain, task_file.problem("attach_only"), world, host,
                              limits=Limits(max_attempts=0)).run()
        return report, world.sim.held("right")
    finally:
        world.close()


@pytest.mark.slow
def test_a_block_lying_on_the_part_makes_the_grasp_a_collision_with_the_pair():
    report, held = run_attach(lid=True)
    assert not report.ok
    first = report.failures[0]
    assert (first["kind"], first["step"], first["action"]) == ("collision", 2, "Grasp")
    assert first["evidence"]["colliding_pair"] == ["right_gripper", "lid"]
    assert "'lid' lies on 'active'" in first["message"] and held is None
    assert report.reported[0]["evidence"]["colliding_pair"] == ["right_gripper", "lid"]


@pytest.mark.slow
def test_the_nominal_grasp_still_holds_the_part():
    report, _ = run_attach(lid=False)
    assert report.ok, report.stop_reason
