"""The data model of the episodic memory: what one execution leaves behind.

Offers:

* :class:`ObjectState` -- pose (x, y, z, roll, pitch, yaw, robot base frame), attachment point AP and normal AN
* :class:`GridMap` -- a 6x6 occupancy grid-map (section 6.3) with its image crop (PNG), block colour, shape, centroid
* :class:`State` -- symbolic facts plus object states plus grid-maps: what held at one moment
* :class:`Step` -- one executed primitive: action, arguments, decomposition node, parent task, state after, outcome
* :class:`Expectation` -- one E_db row: causing action and argument pattern, parent task, facts, grid-map reference
* :class:`Episode` -- the header of a trace: task file, problem, variant, seed, times, outcome, configuration
* :class:`Trace` -- an episode with its initial state, steps and expectations; the unit written in one transaction
* :class:`TraceError` -- a trace that is malformed (raised on construction, before anything touches the store)
* :func:`trace_to_dict` / :func:`trace_from_dict` -- a trace as plain JSON types (the export format) and back

Values are validated when built, so a trace that reaches the store is always complete and self-consistent; the
store relies on that to write it in one transaction. Arguments, facts and configuration are JSON values: tuples
are normalised to lists below the top level, so a trace read back compares equal to the one written.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bt_meta.errors import BtMetaError
from bt_meta.world.simulation.objects import rpy_to_matrix

#: Outcomes an episode or a step may have.
OUTCOMES = ("success", "failure", "aborted")

#: Cells per side of the paper's grid-map: a 3 lb crop at 0.5 lb resolution.
GRID_CELLS = 6

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

JsonScalar = str | int | float | bool | None
Fact = tuple[Any, ...]


class TraceError(BtMetaError):
    """A trace, step or state that is malformed; raised before anything is written."""


def _json_value(value: Any, where: str) -> Any:
    """Normalise to plain JSON types (tuples become lists) and refuse what JSON cannot hold."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if not math.isfinite(number):
            raise TraceError(f"{where}: {number} is not a finite number")
        return number
    if isinstance(value, np.ndarray):
        return _json_value(value.tolist(), where)
    if isinstance(value, (list, tuple)):
        return [_json_value(item, where) for item in value]
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TraceError(f"{where}: mapping key {key!r} is not a string")
            out[key] = _json_value(item, where)
        return out
    raise TraceError(f"{where}: {type(value).__name__} {value!r} is not a JSON value")


def json_tuple(values: Iterable[Any], where: str) -> tuple[Any, ...]:
    """A top-level tuple of JSON values (arguments, argument patterns)."""
    if isinstance(values, (str, bytes)):
        raise TraceError(f"{where}: expected a sequence of values, got the string {values!r}")
    return tuple(_json_value(item, where) for item in values)


def _facts(values: Iterable[Any], where: str) -> tuple[Fact, ...]:
    """Ground atoms as tuples ``(predicate, arg, ...)`` whose first element is the predicate name."""
    if isinstance(values, (str, bytes)):
        raise TraceError(f"{where}: expected a sequence of facts, got the string {values!r}")
    facts = []
    for fact in values:
        if isinstance(fact, (str, bytes)) or not isinstance(fact, Sequence) or not fact:
            raise TraceError(f"{where}: fact {fact!r} is not a non-empty tuple (predicate, arg, ...)")
        if not isinstance(fact[0], str):
            raise TraceError(f"{where}: fact {fact!r} does not start with a predicate name")
        facts.append(json_tuple(fact, where))
    return tuple(facts)


def _floats(values: Iterable[Any], count: int, where: str) -> tuple[float, ...]:
    try:
        numbers = tuple(float(v) for v in values)
    except (TypeError, ValueError) as error:
        raise TraceError(f"{where}: expected {count} numbers ({error})") from None
    if len(numbers) != count:
        raise TraceError(f"{where}: expected {count} numbers, got {len(numbers)}")
    if not all(math.isfinite(n) for n in numbers):
        raise TraceError(f"{where}: {numbers} has a non-finite number")
    return numbers


def _outcome(value: str, where: str) -> str:
    if value not in OUTCOMES:
        raise TraceError(f"{where}: outcome {value!r} is not one of {', '.join(OUTCOMES)}")
    return value


@dataclass(frozen=True)
class ObjectState:
    """The sub-symbolic state of one object (section 7.2.1), everything in the robot base frame except AN.

    ``pose`` is (x, y, z, roll, pitch, yaw) in metres and radians; ``ap`` the attachment point (3, base frame);
    ``an`` the attachment normal (3), expressed in the object frame as the paper's AA(obj) relative to P(obj) --
    an intrinsic affordance of the object. :attr:`an_base` turns it into the base frame (for R_n);
    :meth:`from_base_normal` builds a state from a base-frame normal (e.g. ``SimObjectState.an``; or pass
    ``SimObjectState.an_object`` straight as ``an``).
    """

    name: str
    pose: tuple[float, float, float, float, float, float]
    ap: tuple[float, float, float] = (0.0, 0.0, 0.0)
    an: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise TraceError(f"object state: name {self.name!r} is not a non-empty string")
        object.__setattr__(self, "pose", _floats(self.pose, 6, f"object {self.name}: pose"))
        object.__setattr__(self, "ap", _floats(self.ap, 3, f"object {self.name}: AP"))
        object.__setattr__(self, "an", _floats(self.an, 3, f"object {self.name}: AN"))

    @classmethod
    def from_base_normal(
        cls, name: str, pose: Sequence[float], ap: Sequence[float], an_base: Sequence[float]
    ) -> ObjectState:
        """Build from a normal expressed in the robot base frame (what a simulator or detector usually gives)."""
        state = cls(name, tuple(pose), tuple(ap), (0.0, 0.0, 1.0))  # type: ignore[arg-type]
        normal = state.rotation().T @ np.asarray(_floats(an_base, 3, f"object {name}: AN (base)"))
        return cls(name, state.pose, state.ap, tuple(float(v) for v in normal))  # type: ignore[arg-type]

    def rotation(self) -> np.ndarray:
        """The object's orientation as a 3x3 matrix, R = Rz(yaw) Ry(pitch) Rx(roll) (pybullet's and ROS's RPY)."""
        roll, pitch, yaw = self.pose[3:]
        return rpy_to_matrix(roll, pitch, yaw)

    @property
    def an_base(self) -> tuple[float, float, float]:
        """The attachment normal in the robot base frame, where R_n = arccos(AN_a . AN_r) compares two objects."""
        normal = self.rotation() @ np.asarray(self.an)
        return (float(normal[0]), float(normal[1]), float(normal[2]))


@dataclass(frozen=True, eq=False)
class GridMap:
    """A block's grid-map (section 6.3): occupancy of a 3 lb x 3 lb crop at 0.5 lb resolution and the crop image.

    ``occupancy`` is a 2-D uint8 array (nonzero = the block's colour is present; 6x6 for the paper's grid);
    ``image`` is the crop as PNG bytes -- a uint8 image array is encoded to PNG losslessly on construction, and
    :meth:`image_array` decodes it. ``centroid`` is the block centroid (x, y) in the robot base frame. ``id`` is
    set when the map was read from a store and takes no part in equality.
    """

    occupancy: np.ndarray
    image: bytes | None = None
    object_name: str | None = None
    colour: str | None = None
    shape: str | None = None
    centroid: tuple[float, float] = (0.0, 0.0)
    id: int | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        grid = np.asarray(self.occupancy)
        if grid.ndim != 2 or grid.size == 0:
            raise TraceError(f"grid-map: occupancy must be a non-empty 2-D array, got shape {grid.shape}")
        if grid.dtype == bool:
            grid = grid.astype(np.uint8)
        if not np.issubdtype(grid.dtype, np.integer) or grid.min() < 0 or grid.max() > 255:
            raise TraceError("grid-map: occupancy must hold integers 0..255 (nonzero = occupied)")
        grid = np.ascontiguousarray(grid, dtype=np.uint8)
        grid.setflags(write=False)
        object.__setattr__(self, "occupancy", grid)
        image = self.image
        if isinstance(image, np.ndarray):
            image = encode_png(image)
        elif image is not None:
            image = bytes(image)
            if not image.startswith(PNG_SIGNATURE):
                raise TraceError("grid-map: image bytes are not a PNG (give PNG bytes or a uint8 array)")
        object.__setattr__(self, "image", image)
        object.__setattr__(self, "centroid", _floats(self.centroid, 2, "grid-map: centroid"))

    def image_array(self) -> np.ndarray | None:
        """The crop image decoded from its PNG bytes, exactly as it was given."""
        if self.image is None:
            return None
        import cv2

        decoded = cv2.imdecode(np.frombuffer(self.image, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if decoded is None:
            raise TraceError("grid-map: image PNG does not decode")
        return decoded

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, GridMap):
            return NotImplemented
        return (
            np.array_equal(self.occupancy, other.occupancy)
            and self.image == other.image
            and self.object_name == other.object_name
            and self.colour == other.colour
            and self.shape == other.shape
            and self.centroid == other.centroid
        )

    __hash__ = None  # type: ignore[assignment]


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG of a uint8 image (H x W, H x W x 3 or H x W x 4)."""
    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 3, 4)):
        raise TraceError(f"grid-map: image must be a uint8 H x W (x 1, 3 or 4) array, got {array.dtype} {array.shape}")
    import cv2

    ok, buffer = cv2.imencode(".png", array)
    if not ok:
        raise TraceError("grid-map: image could not be encoded as PNG")
    return buffer.tobytes()


@dataclass(frozen=True)
class State:
    """What held at one moment: symbolic facts, object states and grid-maps (the paper's dual encoding)."""

    facts: tuple[Fact, ...] = ()
    objects: tuple[ObjectState, ...] = ()
    grid_maps: tuple[GridMap, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "facts", _facts(self.facts, "state facts"))
        objects = tuple(self.objects)
        for item in objects:
            if not isinstance(item, ObjectState):
                raise TraceError(f"state: {item!r} is not an ObjectState")
        names = [item.name for item in objects]
        if len(set(names)) != len(names):
            raise TraceError(f"state: object names repeat: {names}")
        object.__setattr__(self, "objects", objects)
        grid_maps = tuple(self.grid_maps)
        for item in grid_maps:
            if not isinstance(item, GridMap):
                raise TraceError(f"state: {item!r} is not a GridMap")
        object.__setattr__(self, "grid_maps", grid_maps)

    def object(self, name: str) -> ObjectState:
        for item in self.objects:
            if item.name == name:
                return item
        raise KeyError(name)


@dataclass(frozen=True)
class Step:
    """One executed primitive and the state it left behind.

    ``node_id`` is the decomposition-tree node of the primitive (so execution can backtrack to it);
    ``parent_task`` the name of the task that decomposed into it and ``parent_node`` that task's node id (which
    tells two consecutive occurrences of the same task apart); ``failure_kind`` a taxonomy kind when ``outcome``
    is not success. ``task_index`` is filled by the store: the position of the step among the consecutive steps
    of the same parent task occurrence (0-based), the paper's "task-step i" of section 7.4.
    """

    index: int
    action: str
    args: tuple[Any, ...] = ()
    node_id: str | None = None
    parent_task: str | None = None
    parent_node: str | None = None
    state: State = field(default_factory=State)
    outcome: str = "success"
    failure_kind: str | None = None
    duration: float | None = None
    task_index: int | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.index, int) or self.index < 0:
            raise TraceError(f"step: index {self.index!r} is not a non-negative integer")
        if not isinstance(self.action, str) or not self.action:
            raise TraceError(f"step {self.index}: action {self.action!r} is not a non-empty string")
        object.__setattr__(self, "args", json_tuple(self.args, f"step {self.index} args"))
        if not isinstance(self.state, State):
            raise TraceError(f"step {self.index}: state is not a State")
        _outcome(self.outcome, f"step {self.index}")
        if self.outcome == "success" and self.failure_kind is not None:
            raise TraceError(f"step {self.index}: a successful step has no failure kind ({self.failure_kind!r})")
        if self.duration is not None:
            object.__setattr__(self, "duration", _floats([self.duration], 1, f"step {self.index} duration")[0])


@dataclass(frozen=True)
class Expectation:
    """One E_db row (section 6.3): what should hold after ``action`` applied to arguments matching ``args_pattern``.

    It points back to the ``parent_task`` (many actions may map to one task's expectation), carries the
    symbolic ``facts`` and, optionally, a reference to a grid-map of the causing step's state:
    ``grid_map_index`` indexes ``trace.steps[step_index].state.grid_maps``. In a pattern, ``None`` or a string
    starting with ``?`` matches any argument. ``id``, ``grid_map_id`` and ``episode_id`` are set when read from a
    store.
    """

    step_index: int
    action: str
    args_pattern: tuple[Any, ...] = ()
    parent_task: str | None = None
    facts: tuple[Fact, ...] = ()
    grid_map_index: int | None = None
    id: int | None = field(default=None, compare=False)
    grid_map_id: int | None = field(default=None, compare=False)
    episode_id: int | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.action, str) or not self.action:
            raise TraceError(f"expectation: action {self.action!r} is not a non-empty string")
        object.__setattr__(self, "args_pattern", json_tuple(self.args_pattern, "expectation args pattern"))
        object.__setattr__(self, "facts", _facts(self.facts, "expectation facts"))

    def matches(self, action: str, args: Sequence[Any]) -> bool:
        """Whether an executed ``action(args)`` is covered by this expectation's action and pattern."""
        if action != self.action or len(args) != len(self.args_pattern):
            return False
        return all(
            pattern is None or (isinstance(pattern, str) and pattern.startswith("?")) or pattern == value
            for pattern, value in zip(self.args_pattern, json_tuple(args, "args"), strict=True)
        )


@dataclass(frozen=True)
class Episode:
    """The header of one execution: what was run, with which seed and configuration, and how it ended.

    ``task`` is the root task of the plan (e.g. ``draw_A``, ``MagneticAttach``), the key of "the last N traces of
    a task"; ``started``/``finished`` are UNIX times in seconds. ``id`` is set by the store.
    """

    task: str
    task_file: str
    problem: str
    started: float
    outcome: str
    finished: float | None = None
    variant: str | None = None
    seed: int | None = None
    config: Mapping[str, Any] = field(default_factory=dict)
    id: int | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        for name in ("task", "task_file", "problem"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value:
                raise TraceError(f"episode: {name} {value!r} is not a non-empty string")
        _outcome(self.outcome, "episode")
        object.__setattr__(self, "started", _floats([self.started], 1, "episode started")[0])
        if self.finished is not None:
            object.__setattr__(self, "finished", _floats([self.finished], 1, "episode finished")[0])
        if self.seed is not None and not isinstance(self.seed, int):
            raise TraceError(f"episode: seed {self.seed!r} is not an integer")
        if not isinstance(self.config, Mapping):
            raise TraceError("episode: config is not a mapping")
        object.__setattr__(self, "config", _json_value(self.config, "episode config"))


@dataclass(frozen=True)
class Trace:
    """One execution step by step: the unit the store writes in a single transaction.

    Steps are numbered 0..n-1 in order; every expectation refers to an existing step and, if it has one, to an
    existing grid-map of that step.
    """

    episode: Episode
    steps: tuple[Step, ...] = ()
    initial: State = field(default_factory=State)
    expectations: tuple[Expectation, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.episode, Episode):
            raise TraceError("trace: episode is not an Episode")
        steps = tuple(self.steps)
        for position, step in enumerate(steps):
            if not isinstance(step, Step):
                raise TraceError(f"trace: {step!r} is not a Step")
            if step.index != position:
                raise TraceError(f"trace: step at position {position} has index {step.index}; steps are 0..n-1")
        object.__setattr__(self, "steps", steps)
        if not isinstance(self.initial, State):
            raise TraceError("trace: initial is not a State")
        expectations = tuple(self.expectations)
        for expectation in expectations:
            if not isinstance(expectation, Expectation):
                raise TraceError(f"trace: {expectation!r} is not an Expectation")
            if not 0 <= expectation.step_index < len(steps):
                raise TraceError(
                    f"trace: expectation for {expectation.action} refers to step {expectation.step_index}, "
                    f"the trace has {len(steps)} steps"
                )
            if expectation.grid_map_index is not None:
                maps = steps[expectation.step_index].state.grid_maps
                if not 0 <= expectation.grid_map_index < len(maps):
                    raise TraceError(
                        f"trace: expectation for {expectation.action} refers to grid-map "
                        f"{expectation.grid_map_index} of step {expectation.step_index}, which has {len(maps)}"
                    )
        object.__setattr__(self, "expectations", expectations)

    def state_before(self, index: int) -> State:
        """The state a step started from: the previous step's state, or the initial state for step 0."""
        return self.initial if index == 0 else self.steps[index - 1].state


def state_to_dict(state: State) -> dict[str, Any]:
    return {
        "facts": [list(fact) for fact in state.facts],
        "objects": [{"name": o.name, "pose": list(o.pose), "ap": list(o.ap), "an": list(o.an)} for o in state.objects],
        "grid_maps": [
            {
                "id": g.id,
                "object_name": g.object_name,
                "colour": g.colour,
                "shape": g.shape,
                "centroid": list(g.centroid),
                "occupancy": g.occupancy.tolist(),
                "image_png_base64": None if g.image is None else base64.b64encode(g.image).decode("ascii"),
            }
            for g in state.grid_maps
        ],
    }


def trace_to_dict(trace: Trace) -> dict[str, Any]:
    """A trace as plain JSON types (grid-maps as nested lists, PNG crops as base64): the export format."""
    episode = trace.episode
    return {
        "episode": {
            "id": episode.id,
            "task": episode.task,
            "task_file": episode.task_file,
            "problem": episode.problem,
            "variant": episode.variant,
            "seed": episode.seed,
            "started": episode.started,
            "finished": episode.finished,
            "outcome": episode.outcome,
            "config": episode.config,
        },
        "initial": state_to_dict(trace.initial),
        "steps": [
            {
                "index": s.index,
                "action": s.action,
                "args": list(s.args),
                "node_id": s.node_id,
                "parent_task": s.parent_task,
                "parent_node": s.parent_node,
                "task_index": s.task_index,
                "outcome": s.outcome,
                "failure_kind": s.failure_kind,
                "duration": s.duration,
                "state": state_to_dict(s.state),
            }
            for s in trace.steps
        ],
        "expectations": [
            {
                "id": x.id,
                "step_index": x.step_index,
                "action": x.action,
                "args_pattern": list(x.args_pattern),
                "parent_task": x.parent_task,
                "facts": [list(fact) for fact in x.facts],
                "grid_map_index": x.grid_map_index,
                "grid_map_id": x.grid_map_id,
            }
            for x in trace.expectations
        ],
    }


def _state_from_dict(data: Mapping[str, Any]) -> State:
    return State(
        facts=tuple(tuple(f) for f in data.get("facts", ())),
        objects=tuple(ObjectState(o["name"], o["pose"], o["ap"], o["an"]) for o in data.get("objects", ())),
        grid_maps=tuple(
            GridMap(
                np.array(g["occupancy"], dtype=np.uint8),
                image=None if g.get("image_png_base64") is None else base64.b64decode(g["image_png_base64"]),
                object_name=g.get("object_name"),
                colour=g.get("colour"),
                shape=g.get("shape"),
                centroid=g.get("centroid", (0.0, 0.0)),
            )
            for g in data.get("grid_maps", ())
        ),
    )


def trace_from_dict(data: Mapping[str, Any]) -> Trace:
    """The inverse of :func:`trace_to_dict` (store ids are dropped: a re-imported trace gets new ones)."""
    try:
        episode = data["episode"]
        return Trace(
            episode=Episode(
                task=episode["task"],
                task_file=episode["task_file"],
                problem=episode["problem"],
                started=episode["started"],
                outcome=episode["outcome"],
                finished=episode.get("finished"),
                variant=episode.get("variant"),
                seed=episode.get("seed"),
                config=episode.get("config", {}),
            ),
            initial=_state_from_dict(data.get("initial", {})),
            steps=tuple(
                Step(
                    index=s["index"],
                    action=s["action"],
                    args=tuple(s.get("args", ())),
                    node_id=s.get("node_id"),
                    parent_task=s.get("parent_task"),
                    parent_node=s.get("parent_node"),
                    state=_state_from_dict(s.get("state", {})),
                    outcome=s.get("outcome", "success"),
                    failure_kind=s.get("failure_kind"),
                    duration=s.get("duration"),
                )
                for s in data.get("steps", ())
            ),
            expectations=tuple(
                Expectation(
                    step_index=x["step_index"],
                    action=x["action"],
                    args_pattern=tuple(x.get("args_pattern", ())),
                    parent_task=x.get("parent_task"),
                    facts=tuple(tuple(f) for f in x.get("facts", ())),
                    grid_map_index=x.get("grid_map_index"),
                )
                for x in data.get("expectations", ())
            ),
        )
    except (KeyError, TypeError, AttributeError) as error:
        raise TraceError(f"trace document is malformed: {type(error).__name__} {error}") from None
