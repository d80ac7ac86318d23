"""Joint-space paths around collisions: RRT-Connect, then shortcuts.

``MoveTo`` first tries the straight joint-space line to its IK solution, then the straight Cartesian line and a
lift before the line; when each of them collides (a held part that swings into the table as the wrist turns, a
finger that grazes it on the way down) it asks this module for a path to the same goal configuration that goes
around. The planner is the classic bidirectional rapidly-exploring random tree (Kuffner and LaValle, 2000):
a tree grows from each end toward random configurations, and each new node tries to join the other tree.

Deterministic on purpose: a seeded generator and a budget of iterations, never of seconds, so that a campaign
gives the same episodes on a slow machine as on a fast one. (OMPL is on PyPI, but its planners stop on a time
budget and its 2.0 Python bindings do not yet expose a state's values in a documented way.)

Offers:

* :func:`plan_path` -- a collision-free path between two configurations (a list of configurations), or ``None``
* :class:`PlanningStats` -- what the last call cost (iterations, collision checks), for the skill's info
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["PlanningStats", "plan_path"]

Free = Callable[[np.ndarray], bool]


@dataclass
class PlanningStats:
    """The cost of one :func:`plan_path` call."""

    iterations: int = 0
    checks: int = 0
    nodes: int = 0
    found: bool = False


class _Tree:
    """Nodes and their parents; nearest-neighbour by a linear scan (a few hundred nodes: faster than a k-d tree)."""

    def __init__(self, root: np.ndarray) -> None:
        self.nodes = [root]
        self.parents = [-1]
        self._array = root[None, :].copy()

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(np.sum((self._array - q) ** 2, axis=1)))

    def add(self, q: np.ndarray, parent: int) -> int:
        self.nodes.append(q)
        self.parents.append(parent)
        self._array = np.vstack([self._array, q])
        return len(self.nodes) - 1

    def branch(self, index: int) -> list[np.ndarray]:
        """The configurations from the root to node ``index``."""
        out = []
        while index >= 0:
            out.append(self.nodes[index])
            index = self.parents[index]
        return out[::-1]


class _Planner:
    def __init__(self, is_free: Free, lower: np.ndarray, upper: np.ndarray, resolution: float, extend: float,
                 rng: np.random.Generator, stats: PlanningStats) -> None:
        self.is_free = is_free
        self.lower, self.upper = lower, upper
        self.resolution = resolution
        self.extend_by = extend
        self.rng = rng
        self.stats = stats

    def free(self, q: np.ndarray) -> bool:
        self.stats.checks += 1
        return bool(self.is_free(q))

    def segment_free(self, a: np.ndarray, b: np.ndarray, include_end: bool = True) -> bool:
        """Every configuration on the line from ``a`` (excluded: it is a node already) to ``b``, ``resolution``
        apart in the joint that moves most."""
        count = max(1, math.ceil(float(np.max(np.abs(b - a))) / self.resolution))
        last = count if include_end else count - 1
        return all(self.free(a + (b - a) * (k / count)) for k in range(1, last + 1))

    def steer(self, tree: _Tree, target: np.ndarray) -> tuple[int, bool]:
        """Grow ``tree`` one step (at most ``extend``) toward ``target``: (the new node or -1, reached target)."""
        near = tree.nearest(target)
        start = tree.nodes[near]
        delta = target - start
        distance = float(np.linalg.norm(delta))
        reached = distance <= self.extend_by
        new = target.copy() if reached else start + delta * (self.extend_by / distance)
        if not self.segment_free(start, new):
            return -1, False
        return tree.add(new, near), reached

    def connect(self, tree: _Tree, target: np.ndarray) -> int:
        """Grow ``tree`` toward ``target`` until it gets there (the node that reached it) or is blocked (-1)."""
        while True:
            index, reached = self.steer(tree, target)
            if index < 0:
                return -1
            if reached:
                return index

    def sample(self) -> np.ndarray:
        return self.rng.uniform(self.lower, self.upper)


def plan_path(is_free: Free, start: Sequence[float], goal: Sequence[float], lower: Sequence[float],
              upper: Sequence[float], *, resolution: float = 0.03, extend: float = 0.3, iterations: int = 400,
              shortcuts: int = 80, seed: int = 0, stats: PlanningStats | None = None) -> list[np.ndarray] | None:
    """A path from ``start`` to ``goal`` (both included) whose every configuration, ``resolution`` apart, satisfies
    ``is_free``; ``None`` when ``iterations`` rounds of RRT-Connect found none. Neither end is checked (the arm is
    at ``start``; ``goal`` is an IK solution, checked when it was found). The path is then shortened by
    ``shortcuts`` random attempts to join two of its configurations directly. ``lower``/``upper`` bound the
    samples (joint limits)."""
    stats = stats if stats is not None else PlanningStats()
    q_start, q_goal = np.asarray(start, float), np.asarray(goal, float)
    low, high = np.asarray(lower, float), np.asarray(upper, float)
    rng = np.random.default_rng(seed)
    planner = _Planner(is_free, low, high, resolution, extend, rng, stats)
    if planner.segment_free(q_start, q_goal, include_end=False):
        stats.found = True
        return [q_start, q_goal]
    from_start, from_goal = _Tree(q_start), _Tree(q_goal)
    grow, other = from_start, from_goal
    path = None
    for iteration in range(1, iterations + 1):
        stats.iterations = iteration
        index, _ = planner.steer(grow, planner.sample())
        if index >= 0:
            joined = planner.connect(other, grow.nodes[index])
            if joined >= 0:
                first, second = grow.branch(index), other.branch(joined)
                path = first + second[::-1][1:] if grow is from_start else second + first[::-1][1:]
                break
        grow, other = other, grow
    stats.nodes = len(from_start.nodes) + len(from_goal.nodes)
    if path is None:
        return None
    stats.found = True
    return _shortcut(planner, path, shortcuts)


def _shortcut(planner: _Planner, path: list[np.ndarray], attempts: int) -> list[np.ndarray]:
    """Join two random configurations of ``path`` by a straight segment where it is free: the tree's zig-zags
    go (random nodes make a path several times longer than it needs to be)."""
    path = list(path)
    for _ in range(attempts):
        if len(path) <= 2:
            break
        i, j = sorted(planner.rng.choice(len(path), size=2, replace=False).tolist())
        if j - i < 2:
            continue
        if planner.segment_free(path[i], path[j]):
            path = path[:i + 1] + path[j:]
    return path
