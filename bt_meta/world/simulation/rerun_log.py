"""An episode in the simulator as a Rerun recording (``.rrd``), tick by tick, for the Rerun viewer.

Needs the optional extra ``rerun`` (``pip install 'bt-meta[rerun]'``, rerun-sdk); without it
:class:`RerunRecorder` raises :class:`RerunMissing`, a user-input error the CLI reports with exit status 2.

What is logged, on the timeline ``tick``:

* ``robot/joints/<joint>`` -- every movable joint's position (scalars)
* ``robot/gripper/<arm>`` -- each end effector's pose (transform)
* ``objects/<name>`` -- each object's pose (transform) and its bounding box (logged once, static)
* ``obstacles/<name>`` -- static obstacles (transform and box, once)
* ``tree/status`` -- the root's status and the status of every shown node (text log), ``tree/failures`` each
  failure as it happens
* ``camera/top`` -- the top-view camera image every ``camera_every`` ticks (and at the first and last)

Offers:

* :class:`RerunRecorder` -- ``log_tick(tick, status, nodes, failures)``, ``log_event(event)``, ``close()``
* :class:`RerunMissing` -- the optional extra is not installed
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bt_meta.errors import UserInputError
from bt_meta.hookspecs import hookimpl

__all__ = ["RerunMissing", "RerunRecorder"]


class RerunMissing(UserInputError):
    """rerun-sdk is not installed."""


class RerunRecorder:
    """Writes one episode of a :class:`~bt_meta.world.simulation.sim_world.SimWorld` to ``path``."""

    def __init__(self, path: str | Path, world: Any, *, camera_every: int = 10, application: str = "bt-meta") -> None:
        try:
            import rerun
        except ImportError:
            raise RerunMissing("--record-rrd needs rerun-sdk: pip install 'bt-meta[rerun]'") from None
        if camera_every < 1:
            raise UserInputError("the camera interval must be at least 1 tick")
        self.rr = rerun
        self.path = Path(path)
        self.world = world
        self.camera_every = camera_every
        self.stream = rerun.RecordingStream(application)
        self.stream.save(str(self.path))
        self._camera: Any = None
        self._last_tick = -1
        self._log_static()

    # -- what is logged ---------------------------------------------------------------------------------------

    def _log_static(self) -> None:
        rr, sim = self.rr, self.world.sim
        for name in sim.object_names():
            low, high = sim.object_model(name).extent()
            box = rr.Boxes3D(centers=[(low + high) / 2.0], half_sizes=[(high - low) / 2.0], labels=[name])
            self.stream.log(f"objects/{name}/box", box, static=True)
        for name, (model, transform) in sim.obstacles().items():
            low, high = model.extent()
            self.stream.log(f"obstacles/{name}", self._transform(transform), static=True)
            self.stream.log(f"obstacles/{name}/box", rr.Boxes3D(centers=[(low + high) / 2.0],
                                                              half_sizes=[(high - low) / 2.0], labels=[name]),
                            static=True)

    def log_tick(self, tick: int, status: str, nodes: Mapping[str, str] | None = None,
                 failures: Iterable[str] = ()) -> None:
        """The world's state after tick ``tick`` and what the tree reported."""
        rr, sim, stream = self.rr, self.world.sim, self.stream
        stream.set_time("tick", sequence=tick)
        for joint, value in sim.joint_positions().items():
            stream.log(f"robot/joints/{joint}", rr.Scalars(value))
        for arm in sim.robot.arms:
            stream.log(f"robot/gripper/{arm}", self._transform(sim.link_transform(sim.robot.arm(arm).end_effector)))
        for name in sim.object_names():
            stream.log(f"objects/{name}", self._transform(sim.object_transform(name)))
        listed = "  ".join(f"{name}={value}" for name, value in (nodes or {}).items())
        stream.log("tree/status", rr.TextLog(f"{status} {listed}".strip()))
        for failure in failures:
            stream.log("tree/failures", rr.TextLog(failure, level="ERROR"))
        if self._last_tick < 0 or tick - self._last_tick >= self.camera_every or status not in ("RUNNING",):
            self._log_camera()
            self._last_tick = tick

    def log_event(self, event: Mapping[str, Any]) -> None:
        """A trace event of a repaired run (steps, failures, repairs): the state at that moment."""
        kind = event.get("type")
        if kind not in ("step_end", "failure", "repair"):
            return
        tick = int(event.get("tick", 0) or 0)
        if kind == "step_end":
            call = f"{event.get('action')}({', '.join(str(a) for a in event.get('args') or ())})"
            self.log_tick(tick, str(event.get("status")), {f"step {event.get('step')}": call})
        elif kind == "failure":
            failure = event.get("failure") or {}
            self.log_tick(tick, "FAILURE", failures=[f"[{failure.get('kind')}] {failure.get('message')}"])
        else:
            self.log_tick(tick, "REPAIR", {"outcome": str(event.get("outcome"))})

    @hookimpl
    def bt_meta_trace_event(self, event: dict[str, Any]) -> None:
        self.log_event(event)

    def _log_camera(self) -> None:
        from bt_meta.world.simulation.camera import TopViewCamera

        if self._camera is None:
            self._camera = TopViewCamera(self.world.sim)
        image = self._camera.capture(depth=False, segmentation=False)
        self.stream.log("camera/top", self.rr.Image(np.ascontiguousarray(image.rgb[..., :3])))

    def _transform(self, transform: np.ndarray) -> Any:
        return self.rr.Transform3D(translation=transform[:3, 3], mat3x3=transform[:3, :3])

    def close(self) -> None:
        self.stream.flush()
        self.stream.disconnect()
