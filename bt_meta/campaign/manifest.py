"""A campaign directory's manifest, ``campaign.json``: what was generated, by which version, with which spec.

The generator writes the variant scene files first and the manifest last, atomically (a temporary file renamed),
so a directory with a manifest is complete; one without it is half-written and refused. A manifest of another
:data:`~bt_meta.campaign.CAMPAIGN_VERSION` is refused too: its rows would mean something else.

Offers:

* :func:`new_manifest` / :func:`write_manifest` / :func:`read_manifest`
* :func:`manifest_robot` / :func:`check_robot` -- the robot a campaign is for; another one is refused
* :func:`manifest_digest` -- the SHA-256 of the manifest file (the database remembers which manifest it ran)
* :class:`CampaignDirError` -- a campaign directory that cannot be used, and why
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from bt_meta.campaign import CAMPAIGN_VERSION
from bt_meta.errors import UserInputError

__all__ = ["MANIFEST", "CampaignDirError", "check_robot", "manifest_digest", "manifest_robot", "new_manifest",
           "read_manifest", "write_manifest"]

MANIFEST = "campaign.json"


class CampaignDirError(UserInputError):
    """A campaign directory that is missing, half-written or of another version."""


def new_manifest(family: Any, seed: int, spec: Any, scene: Any, variants: list[dict[str, Any]], *,
                 robot: str = "baxter", robot_file: str | None = None) -> dict[str, Any]:
    """The manifest of a generated campaign. ``robot``: the robot's name its labels are for (``robot_file``: the
    robot YAML as given, when not a shipped name); ``shipped``: a shipped family, found by name again."""
    from bt_meta import __version__

    given = robot_file if robot_file is not None and Path(robot_file).suffix else None
    return {"campaign_version": CAMPAIGN_VERSION, "bt_meta_version": __version__, "family": family.name,
            "shipped": bool(getattr(family, "shipped", False)),
            "family_file": None if family.file is None else str(family.file), "family_scene": family.scene,
            "task_file": family.task_file, "problem": family.problem, "scene": str(scene.path), "seed": seed,
            "robot": robot, "robot_file": None if given is None else str(Path(given).resolve()),
            "spec_file": spec.path, "spec": spec.to_dict(), "variants": variants}


def manifest_robot(manifest: dict[str, Any]) -> str:
    """The robot a campaign's labels are for: its YAML file when one was given, else its shipped name."""
    return str(manifest.get("robot_file") or manifest.get("robot") or "baxter")


def check_robot(manifest: dict[str, Any], robot: str | None, folder: str | Path) -> str:
    """The campaign's robot; ``robot`` (a name or YAML path asked for on the command line) must be it: a campaign
    is labelled for one robot, and its episodes on another would be judged against the wrong labels."""
    recorded = manifest_robot(manifest)
    if robot is None:
        return recorded
    from bt_meta.world.robot.description import load_robot

    if load_robot(robot).name != str(manifest.get("robot") or "baxter"):
        raise CampaignDirError(f"was generated for the robot {manifest.get('robot')!r}, not {robot!r}: its labels "
                               "are for that robot; generate a campaign for this one with `campaign generate ... "
                               f"--robot {robot}`", Path(folder) / MANIFEST)
    return recorded


def write_manifest(folder: Path, manifest: dict[str, Any]) -> None:
    path = folder / MANIFEST
    temporary = folder / f".{MANIFEST}.tmp"
    temporary.write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    os.replace(temporary, path)


def read_manifest(folder: str | Path) -> dict[str, Any]:
    folder = Path(folder)
    if not folder.is_dir():
        raise CampaignDirError("not a campaign directory (it does not exist); make one with `bt-meta campaign "
                               "generate`", folder)
    path = folder / MANIFEST
    if not path.is_file():
        what = "half-written (variants/ but no campaign.json: generation was stopped)" if (
            folder / "variants").is_dir() else f"not a campaign directory (no {MANIFEST})"
        raise CampaignDirError(f"{what}; generate it again with `bt-meta campaign generate ... -o {folder}`", folder)
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise CampaignDirError(f"not valid JSON: {error.msg}", path, error.lineno, error.colno) from None
    version = manifest.get("campaign_version") if isinstance(manifest, dict) else None
    if version != CAMPAIGN_VERSION:
        raise CampaignDirError(f"made by another version of bt-meta (campaign version {version!r}, this one reads "
                               f"{CAMPAIGN_VERSION}); generate it again", path)
    missing = [v["file"] for v in manifest.get("variants", []) if not (folder / v["file"]).is_file()]
    if missing:
        raise CampaignDirError(f"{len(missing)} variant file(s) listed in {MANIFEST} are missing, first "
                               f"{missing[0]}", path)
    return manifest


def manifest_digest(folder: str | Path) -> str:
    return hashlib.sha256((Path(folder) / MANIFEST).read_bytes()).hexdigest()
