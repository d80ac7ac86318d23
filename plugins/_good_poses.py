"""Known-good poses of the active object from successful traces, and the gripper poses that hold it there
(paper, section 7.4, step 4 of pose backtracking).

Offers:

* :class:`Candidate` -- one sampled pose of the active object: where it comes from (trace, turn) and the pose
* :func:`good_object_poses` -- seeded candidates relative to the reference, placed on the reference as it is now
* :func:`gripper_pose_for` -- the gripper pose that holds an object at a pose, through the grasp transform
* :func:`local_keypoints` -- an object state's AP and AN in its own frame
* :func:`matrix_of`, :func:`state_pose` -- 4x4 transforms of a 6-number pose and of an object state's pose
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bt_meta.perception.keypoints import KeypointError, keypoints_of
from bt_meta.world.poses import axis_angle_matrix
from bt_meta.world.simulation.objects import pose_to_matrix

__all__ = ["Candidate", "good_object_poses", "gripper_pose_for", "local_keypoints", "matrix_of", "state_pose"]


def _matrix(pose: Sequence[float]) -> np.ndarray:
    return pose_to_matrix([float(v) for v in pose])


def _state_pose(state: Any) -> np.ndarray:
    pose = state.get("pose") if isinstance(state, Mapping) else getattr(state, "pose", None)
    if pose is None or len(pose) != 6:
        raise KeypointError(f"object state {state!r} has no 6-number pose")
    return _matrix(pose)


def gripper_pose_for(object_pose: np.ndarray, grasp: np.ndarray) -> np.ndarray:
    """The gripper pose (4x4, base frame) that holds an object at ``object_pose`` when the object sits at ``grasp``
    in the gripper frame (the object-gripper relation): ``object = gripper @ grasp``."""
    return np.asarray(object_pose, dtype=float) @ np.linalg.inv(np.asarray(grasp, dtype=float))


def local_keypoints(state: Any) -> tuple[np.ndarray, np.ndarray]:
    """(AP, AN) of an object state in its own frame: intrinsic, the same in every trace of that object."""
    transform = _state_pose(state)
    ap, an = keypoints_of(state)
    rotation = transform[:3, :3]
    return rotation.T @ (ap - transform[:3, 3]), rotation.T @ an


@dataclass(frozen=True)
class Candidate:
    """A known-good pose of the active object for one step: from trace ``trace`` turned by ``turn`` about AN."""

    step: int
    trace: int
    turn: float
    object_pose: np.ndarray
    ap: np.ndarray
    an: np.ndarray


def good_object_poses(
    traces: Sequence[Any],
    step: int,
    active: str,
    reference: str,
    *,
    reference_now: Any,
    active_now: Any,
    turns: Sequence[float],
    order: Sequence[int],
) -> list[Candidate]:
    """Poses of the active object for ``step`` that succeeded before: for each trace in ``order`` (indices into
    ``traces``) and each ``turn`` (radians about the attachment normal; 0 keeps the trace's own orientation), the
    pose whose attachment point and normal relative to the reference are the trace's, placed on the reference as it
    is now (``reference_now``). ``active_now`` gives the active object's intrinsic AP/AN."""
    ap_local, an_local = local_keypoints(active_now)
    ref_now = _state_pose(reference_now)
    out = []
    for j in order:
        try:
            state = traces[j].steps[step].state
            ref_then, act_then = state.object(reference), state.object(active)
        except (IndexError, KeyError):
            continue
        relative = np.linalg.inv(_state_pose(ref_then)) @ _state_pose(act_then)
        ap_then, _ = keypoints_of(act_then)
        ap_rel = np.linalg.inv(_state_pose(ref_then)) @ np.append(ap_then, 1.0)
        target_ap = (ref_now @ ap_rel)[:3]
        base_rotation = ref_now[:3, :3] @ relative[:3, :3]
        target_an = base_rotation @ an_local
        for turn in turns:
            rotation = axis_angle_matrix(target_an, turn) @ base_rotation
            pose = np.eye(4)
            pose[:3, :3] = rotation
            pose[:3, 3] = target_ap - rotation @ ap_local
            out.append(Candidate(step, j, float(turn), pose, target_ap, target_an))
    return out


matrix_of = _matrix
state_pose = _state_pose
