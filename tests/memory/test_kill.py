"""THE KILL TEST: a writer process killed with SIGKILL at random moments never leaves half a trace behind.

The test spawns this file as a writer (``python test_kill.py DB RUN``) that writes large traces in a loop and
announces ``begin N`` / ``commit N`` around every write. It is killed at a seeded random moment after it is
ready, many times over the same file; after every kill the file must pass ``PRAGMA integrity_check``, every
stored episode must be complete (declared step, object-state, grid-map and expectation counts all present), and
the last stored trace must equal, field for field, the trace the writer built.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time

import numpy as np

KILLS = 30
STEPS = 150
OBJECTS = 3


def writer_trace():
    """The large, fully deterministic trace every writer stores over and over under new headers."""
    from bt_meta.memory import Episode, Expectation, GridMap, ObjectState, State, Step, Trace

    rng = np.random.default_rng(20240607)
    poses = rng.uniform(-1, 1, (STEPS, OBJECTS, 12))
    grids = (rng.random((STEPS, 6, 6)) < 0.4).astype(np.uint8)
    crop = np.repeat(np.repeat(grids[0][..., None] * 200, 8, axis=0), 8, axis=1).repeat(3, axis=2)
    steps = tuple(
        Step(
            index=i,
            action="MoveTo" if i % 2 == 0 else "Grasp",
            args=(f"obj{i % OBJECTS}", [float(v) for v in poses[i, 0, :6]]),
            node_id=f"n{i}",
            parent_task=f"task{i // 50}",
            state=State(
                facts=(("at", f"obj{i % OBJECTS}", i), ("gripper", "closed" if i % 2 else "open")),
                objects=tuple(
                    ObjectState(f"obj{k}", poses[i, k, :6], poses[i, k, 6:9], poses[i, k, 9:12]) for k in range(OBJECTS)
                ),
                grid_maps=(GridMap(grids[i], image=crop if i % 10 == 0 else None, colour="red", shape="1x1"),),
            ),
        )
        for i in range(STEPS)
    )
    expectations = tuple(
        Expectation(i, steps[i].action, (None, "?pose"), steps[i].parent_task, steps[i].state.facts, 0)
        for i in range(0, STEPS, 3)
    )
    episode = Episode(
        task="MagneticAttach",
        task_file="attach.yaml",
        problem="nominal",
        started=0.0,
        outcome="success",
    )
    return Trace(episode=episode, steps=steps, expectations=expectations)


def _writer(path: str, run: int) -> None:
    from bt_meta.memory import EpisodicMemory

    base = writer_trace()
    with EpisodicMemory.open(path) as memory:
        print("ready", flush=True)
        number = 0
        while True:
            trace = numbered(base, run, number)
            print(f"begin {number}", flush=True)
            memory.write(trace)
            print(f"commit {number}", flush=True)
            number += 1


def numbered(trace, run: int, number: int):
    """The run's trace with the header of its ``number``-th write (built once: writes are not slowed down)."""
    from dataclasses import replace

    episode = replace(
        trace.episode,
        started=float(run * 1000 + number),
        seed=run * 1000 + number,
        config={"run": run, "number": number},
    )
    return replace(trace, episode=episode)


if __name__ == "__main__":  # the writer: runs until it is killed, without importing pytest (faster start)
    _writer(sys.argv[1], int(sys.argv[2]))

import pytest  # noqa: E402


@pytest.mark.slow
def test_sigkill_never_leaves_half_a_trace(tmp_path):
    from bt_meta.memory import EpisodicMemory

    path = tmp_path / "memory.sqlite"
    rng = random.Random(20240607)
    committed_total = 0
    base = writer_trace()
    killed_mid_write = 0
    started = time.monotonic()
    for run in range(KILLS):
        process = subprocess.Popen(
            [sys.executable, __file__, str(path), str(run)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert process.stdout is not None
        ready = process.stdout.readline().strip()
        assert ready == "ready", process.stderr.read() if process.stderr else ""
        time.sleep(rng.uniform(0.0, 0.1))
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        assert process.returncode == -signal.SIGKILL
        lines = process.stdout.read().split()
        process.stdout.close()
        if process.stderr:
            process.stderr.close()
        announced = [(lines[i], int(lines[i + 1])) for i in range(0, len(lines), 2)]
        commits = sum(1 for word, _ in announced if word == "commit")
        if announced and announced[-1][0] == "begin":
            killed_mid_write += 1
        with EpisodicMemory.open(path) as memory:
            assert memory.integrity_check() == "ok"
            assert memory.check() == []
            summaries = memory.episodes(task="MagneticAttach")
            in_run = sorted(s.episode.config["number"] for s in summaries if s.episode.config["run"] == run)
            # Everything acknowledged is stored; at most the one write in flight may also have committed.
            assert in_run == list(range(len(in_run)))
            assert commits <= len(in_run) <= commits + 1
            assert all(s.step_count == STEPS and s.object_count == STEPS * OBJECTS for s in summaries)
            if in_run:
                last_id = next(
                    s.episode.id for s in summaries if s.episode.config == {"run": run, "number": in_run[-1]}
                )
                assert memory.trace(last_id) == numbered(base, run, in_run[-1])
            committed_total += len(in_run)
    elapsed = time.monotonic() - started
    assert committed_total > KILLS  # the writers really wrote, across the runs
    assert killed_mid_write >= KILLS // 3, f"only {killed_mid_write} kills landed inside a write"
    print(f"{KILLS} kills in {elapsed:.1f} s, {killed_mid_write} inside a write, {committed_total} traces stored")
