"""Ground-truth perception: the world's own symbolic state and object states, as observations.

For the fake world and the simulator, perception can read the truth; camera perception (HSV blobs, grid-maps)
replaces or complements it in other plugins.

Offers:

* :func:`bt_meta_observe` -- ``{"symbolic_state": world.symbolic_state(), "objects": ...}``
"""

from __future__ import annotations

from typing import Any

from bt_meta.plugins import hookimpl


@hookimpl
def bt_meta_observe(world: Any, context: Any) -> dict[str, Any] | None:
    if world is None:
        return None
    observations: dict[str, Any] = {}
    symbolic = getattr(world, "symbolic_state", None)
    if symbolic is not None:
        observations["symbolic_state"] = symbolic()
    observe = getattr(world, "observe", None)
    if observe is not None:
        objects = observe().get("objects")
        if objects is not None:
            observations["objects"] = objects
    return observations or None
