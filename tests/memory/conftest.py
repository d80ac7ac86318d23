"""Fixtures for the memory tests: seeded traces shaped like the paper's letter and magnetic-attach executions."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from bt_meta.memory import Episode, Expectation, GridMap, ObjectState, State, Step, Trace

TraceFactory = Callable[..., Trace]


def build_trace(
    seed: int,
    *,
    task: str = "draw_A",
    steps: int = 4,
    objects: int = 2,
    outcome: str = "success",
    started: float | None = None,
    image: bool = True,
    parent_tasks: tuple[str, ...] = ("place_block",),
) -> Trace:
    """A random but complete trace: every step places a block, observes every object and one grid-map."""
    rng = np.random.default_rng(seed)
    names = [f"b{i}" for i in range(objects)]

    def objects_state() -> tuple[ObjectState, ...]:
        return tuple(
            ObjectState(
                name,
                rng.uniform(-1, 1, 6),
                rng.uniform(-0.05, 0.05, 3),
                rng.normal(size=3) / 2,
            )
            for name in names
        )

    def grid_map(name: str) -> GridMap:
        occupancy = (rng.random((6, 6)) < 0.4).astype(np.uint8)
        crop = rng.integers(0, 256, (18, 18, 3), dtype=np.uint8) if image else None
        return GridMap(
            occupancy,
            image=crop,
            object_name=name,
            colour=str(rng.choice(["red", "blue"])),
            shape=str(rng.choice(["1x1", "1x2"])),
            centroid=rng.uniform(0.3, 0.9, 2),
        )

    step_list = []
    expectations = []
    for index in range(steps):
        block = names[index % objects]
        x, y = (float(v) for v in rng.uniform(0.4, 0.8, 2))
        occurrence = (index * len(parent_tasks)) // steps
        parent = parent_tasks[occurrence]
        facts = (("placed", block, index), ("holding", None), ("gripper", "open"))
        failed = outcome == "failure" and index == steps - 1
        step_list.append(
            Step(
                index=index,
                action="place",
                args=(block, x, y),
                node_id=f"n{index + 3}",
                parent_task=parent,
                parent_node=f"t{occurrence}",
                state=State(facts, objects_state(), (grid_map(block),)),
                outcome="failure" if failed else "success",
                failure_kind="unknown_entity" if failed else None,
                duration=float(rng.uniform(0.1, 2.0)),
            )
        )
        expectations.append(
            Expectation(
                step_index=index,
                action="place",
                args_pattern=(block, "?x", "?y"),
                parent_task=parent,
                facts=facts[:1],
                grid_map_index=0,
            )
        )
    start = float(rng.uniform(1.7e9, 1.8e9)) if started is None else started
    episode = Episode(
        task=task,
        task_file="trees/letters.yaml",
        problem=f"{task}_problem",
        started=start,
        finished=start + 12.5,
        outcome=outcome,
        variant="nominal" if seed % 2 == 0 else None,
        seed=seed,
        config={"camera": "hand", "thresholds": [0.1, 0.2], "seed": seed},
    )
    return Trace(
        episode=episode,
        steps=tuple(step_list),
        initial=State((("gripper", "open"),), objects_state(), ()),
        expectations=tuple(expectations),
    )


@pytest.fixture
def make_trace() -> TraceFactory:
    return build_trace
