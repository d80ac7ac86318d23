"""A campaign directory's manifest, ``campaign.json``: what was generated, by which version, with which spec.

The generator writes the variant scene files first and the manifest last, atomically (a temporary file renamed),
so a directory with a manifest is complete; one without it is half-written and refused. A manifest of another
:data:`~bt_meta.campaign.CAMPAIGN_VERSION` is refused too: its rows would mean something else.

Offers:

* :func:`new_manifest` / :func:`write_manifest` / :func:`read_manifest`
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

__all__ = ["MANIFEST", "CampaignDirError", "manifest_digest", "new_manifest", "read_manifest", "write_manifest"]

MANIFEST = "campaign.json"


class CampaignDirError(UserInputError):
    """A campaign directory that is missing, half-written or of another version."""


def new_manifest(family: Any, seed: int, spec: Any, scene: Any, variants: list[dict[str, Any]]) -> dict[str, Any]:
    from bt_meta import __version__

    return {"campaign_version": CAMPAIGN_VERSION, "bt_meta_version": __version__, "family": family.name,
            "task_file": family.task_file, "problem": family.problem, "scene": str(scene.path), "seed": seed,
            "spec_file": spec.path, "spec": spec.to_dict(), "variants": variants}


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
