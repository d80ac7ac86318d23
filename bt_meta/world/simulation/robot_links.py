"""The robot's links as pybullet simulates them when fixed links are merged into the moving link they hang from.

pybullet's ``URDF_MERGE_FIXED_LINKS`` folds every link attached by a fixed joint (the Baxter's frames, cameras,
sensors, finger tips, the torso into the base: 56 links become 19) into its parent, so each physics step
integrates 19 bodies instead of 56; a rigid assembly moves the same whether or not it is split into links. The
merged links still have names the rest of bt-meta uses (an end effector frame, a hand camera): this module reads
the URDF's joint tree so that every name keeps resolving to a pybullet link and a fixed pose on it.

Offers:

* :class:`UrdfJoint` -- one URDF joint: name, parent and child link, type, origin (4x4)
* :func:`read_joints` -- the URDF's joints keyed by child link (parsed once per process per file version)
* :func:`merged_frames` -- for every link pybullet merged away: the link it lives on and its pose there
* :func:`subtree` -- a link and every link below it in the URDF tree
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bt_meta.errors import ConfigError
from bt_meta.model_cache import cached, file_signature

__all__ = ["UrdfJoint", "merged_frames", "read_joints", "subtree"]


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    parent: str
    child: str
    kind: str
    origin: np.ndarray  # pose of the child link's frame in the parent link's frame


def _origin(element: ElementTree.Element | None) -> np.ndarray:
    out = np.eye(4)
    if element is None:
        return out
    x, y, z = (float(v) for v in (element.get("xyz") or "0 0 0").split())
    roll, pitch, yaw = (float(v) for v in (element.get("rpy") or "0 0 0").split())
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    # URDF's rpy: fixed-axis roll about x, then pitch about y, then yaw about z (R = Rz Ry Rx).
    out[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                   [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                   [-sp, cp * sr, cp * cr]]
    out[:3, 3] = (x, y, z)
    return out


def read_joints(path: Path) -> Mapping[str, UrdfJoint]:
    """The URDF's joints, keyed by their child link (a link has at most one parent joint)."""

    def parse() -> dict[str, UrdfJoint]:
        root = ElementTree.parse(path).getroot()
        out: dict[str, UrdfJoint] = {}
        for el in root.findall("joint"):
            parent, child = el.find("parent"), el.find("child")
            if parent is None or child is None:
                raise ConfigError(f"joint {el.get('name')!r} has no parent or child link", path)
            joint = UrdfJoint(el.get("name", ""), parent.get("link", ""), child.get("link", ""),
                              el.get("type", ""), _origin(el.find("origin")))
            out[joint.child] = joint
        return out

    return cached(("urdf joints", file_signature(path)), parse)


def merged_frames(joints: Mapping[str, UrdfJoint], present: Iterable[str]) -> dict[str, tuple[str, np.ndarray]]:
    """Each URDF link not among ``present`` (pybullet's links after merging): the present link it was merged into,
    found by walking up its fixed joints, and its frame's pose in that link's URDF frame."""
    kept = set(present)
    out: dict[str, tuple[str, np.ndarray]] = {}
    for child in joints:
        if child in kept:
            continue
        link, offset = child, np.eye(4)
        while link not in kept:
            joint = joints.get(link)
            if joint is None or joint.kind != "fixed":
                raise ConfigError(f"link {child!r} was merged away but does not hang from a kept link by fixed "
                                  "joints", Path("<urdf>"))
            offset = joint.origin @ offset
            link = joint.parent
        out[child] = (link, offset)
    return out


def subtree(joints: Mapping[str, UrdfJoint], link: str) -> set[str]:
    """``link`` and every link below it."""
    out = {link}
    changed = True
    while changed:
        changed = False
        for joint in joints.values():
            if joint.parent in out and joint.child not in out:
                out.add(joint.child)
                changed = True
    return out
