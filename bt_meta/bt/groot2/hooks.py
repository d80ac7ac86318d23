"""Groot2 breakpoints and node replacement: BehaviorTree.CPP's ``Monitor::Hook`` and what the publisher does with it.

Groot2 inserts a hook on a node (HOOK_INSERT, JSON ``{uid, position, mode, enabled, once, desired_status}``):

* ``mode`` 0, **breakpoint**: when the node is about to tick (``position`` 0, pre) the tick stops there, Groot2 is
  told (a BREAKPOINT_REACHED message with the uid on the PUB socket), and the tree waits until Groot2 unlocks it
  (BREAKPOINT_UNLOCK with the status to return: SUCCESS or FAILURE replace the node's own tick, anything else lets
  it tick) or the hook is disabled or removed;
* ``mode`` 1, **replace**: the node returns ``desired_status`` without ticking, every time;
* ``once``: the hook removes itself after it fired; ``position`` 1 (post) runs after the node ticked and replaces
  its result.

A hook only replaces a tick with SUCCESS or FAILURE, and only when the node is IDLE or RUNNING, as in
``TreeNode::executeTick``. When no request arrived for 5 s (Groot2 went away) every hook is disabled, and enabled
again on the next request, so an abandoned breakpoint never blocks a run forever.

Offers:

* :class:`Hook` -- one hook; :func:`hook_from_json`, :meth:`Hook.to_json`
* :class:`HookTable` -- the hooks of one published tree and the tick-time check (:meth:`~HookTable.run`)
* :class:`HookError` -- a request naming no hook or carrying bad JSON (answered with an error reply)
"""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from bt_meta.bt.groot2.protocol import NodeStatus
from bt_meta.errors import BtMetaError

PRE, POST = 0, 1
BREAKPOINT, REPLACE = 0, 1
_WAIT_SLICE_S = 0.05


class HookError(BtMetaError):
    """A hook request that cannot be applied (the server replies with the message)."""


@dataclass
class Hook:
    """``BT::Monitor::Hook``."""

    uid: int
    position: int = PRE
    mode: int = BREAKPOINT
    enabled: bool = True
    once: bool = False
    desired_status: NodeStatus = NodeStatus.SKIPPED
    ready: bool = False
    wakeup: threading.Condition = field(default_factory=threading.Condition, repr=False, compare=False)

    def to_json(self) -> dict[str, Any]:
        return {"desired_status": self.desired_status.name, "enabled": self.enabled, "mode": self.mode,
                "once": self.once, "position": self.position, "uid": self.uid}

    def update(self, data: dict[str, Any]) -> None:
        """Take every field of ``data`` (BT.CPP's ``from_json``: all of them are required)."""
        try:
            enabled, uid, once = data["enabled"], data["uid"], data["once"]
            mode, position, desired = data["mode"], data["position"], data["desired_status"]
        except (KeyError, TypeError) as missing:
            raise HookError(f"hook JSON lacks field {missing}") from None
        if not isinstance(uid, int) or not 0 <= uid <= 0xFFFF or mode not in (0, 1) or position not in (0, 1):
            raise HookError(f"bad hook JSON: {json.dumps(data)}")
        if desired not in NodeStatus.__members__:
            raise HookError(f"bad desired_status {desired!r}")
        self.enabled, self.uid, self.once = bool(enabled), uid, bool(once)
        self.mode, self.position, self.desired_status = mode, position, NodeStatus[desired]


def hook_from_json(data: dict[str, Any]) -> Hook:
    hook = Hook(0)
    hook.update(data)
    return hook


def _parse(text: bytes) -> Any:
    try:
        return json.loads(text)
    except ValueError as error:
        raise HookError(f"bad JSON: {error}") from None


class HookTable:
    """The hooks of one tree, shared by the server thread (requests) and the ticking thread (:meth:`run`)."""

    def __init__(self, uids: set[int], notify: Callable[[int], None],
                 on_insert: Callable[[int], None] = lambda _uid: None) -> None:
        self.uids = uids
        self.notify = notify
        self.on_insert = on_insert
        self._hooks: dict[tuple[int, int], Hook] = {}
        self._lock = threading.Lock()
        self.closed = False

    def __bool__(self) -> bool:
        return bool(self._hooks)

    # -- requests (server thread) -------------------------------------------------------------------------------

    def insert(self, payload: bytes) -> None:
        """HOOK_INSERT: one hook or a list; an existing hook is updated (a breakpoint turned replace is released)."""
        received = _parse(payload)
        for data in received if isinstance(received, list) else [received]:
            if not isinstance(data, dict):
                raise HookError("a hook is a JSON object")
            fresh = hook_from_json(data)
            if fresh.uid not in self.uids:
                continue  # BehaviorTree.CPP ignores hooks on unknown nodes
            with self._lock:
                hook = self._hooks.get((fresh.position, fresh.uid))
                if hook is None:
                    self.on_insert(fresh.uid)
                    self._hooks[(fresh.position, fresh.uid)] = fresh
                    continue
            with hook.wakeup:
                was_breakpoint = hook.mode == BREAKPOINT
                hook.update(data)
                if was_breakpoint and hook.mode == REPLACE:
                    hook.ready = True
                    hook.wakeup.notify_all()

    def unlock(self, payload: bytes) -> None:
        """BREAKPOINT_UNLOCK: ``{uid, position, desired_status, remove_when_done}``."""
        data = _parse(payload)
        try:
            uid, position = int(data["uid"]), int(data["position"])
            status, remove = str(data["desired_status"]), bool(data["remove_when_done"])
        except (KeyError, TypeError, ValueError) as missing:
            raise HookError(f"unlock JSON lacks or mistypes field {missing}") from None
        hook = self._hooks.get((position, uid))
        if hook is None:
            raise HookError("Node ID not found")
        with hook.wakeup:
            hook.desired_status = NodeStatus[status] if status in ("SUCCESS", "FAILURE") else NodeStatus.SKIPPED
            hook.once |= remove
            if hook.mode == BREAKPOINT:
                hook.ready = True
                hook.wakeup.notify_all()

    def remove(self, payload: bytes) -> None:
        """HOOK_REMOVE: ``{uid, position}``; a breakpoint waiting there is released."""
        data = _parse(payload)
        try:
            key = (int(data["position"]), int(data["uid"]))
        except (KeyError, TypeError, ValueError) as missing:
            raise HookError(f"remove JSON lacks or mistypes field {missing}") from None
        self._drop(key)

    def _drop(self, key: tuple[int, int]) -> None:
        with self._lock:
            hook = self._hooks.pop(key, None)
        if hook is None:
            raise HookError("Node ID not found")
        with hook.wakeup:
            hook.enabled = False
            hook.wakeup.notify_all()

    def remove_all(self) -> None:
        for key in list(self._hooks):
            with contextlib.suppress(HookError):  # removed meanwhile
                self._drop(key)

    def enable_all(self, enabled: bool) -> None:
        for hook in list(self._hooks.values()):
            with hook.wakeup:
                hook.enabled = enabled
                hook.wakeup.notify_all()

    def dump(self) -> bytes:
        """HOOKS_DUMP: the hooks as a JSON array (nlohmann's compact dump, keys sorted)."""
        hooks = sorted(self._hooks.values(), key=lambda h: (h.position, h.uid))
        return json.dumps([h.to_json() for h in hooks], separators=(",", ":"), sort_keys=True).encode()

    def close(self) -> None:
        """Release every waiting breakpoint for good (the server is going away)."""
        self.closed = True
        self.enable_all(False)

    # -- tick time (ticking thread) -----------------------------------------------------------------------------

    def run(self, position: int, uid: int) -> NodeStatus | None:
        """The status that replaces this node's tick (pre) or result (post), or ``None`` to leave it alone."""
        hook = self._hooks.get((position, uid))
        if hook is None or not hook.enabled or self.closed:
            return None
        self.notify(uid)
        with hook.wakeup:
            if hook.mode == BREAKPOINT:
                while not (hook.ready or not hook.enabled or self.closed):
                    hook.wakeup.wait(_WAIT_SLICE_S)
                hook.ready = False
                if not hook.enabled or self.closed:
                    return None
            desired = hook.desired_status
            once = hook.once
            if once:
                hook.enabled = False
        if once:
            with self._lock:
                if self._hooks.get((position, uid)) is hook:
                    del self._hooks[(position, uid)]
        return desired if desired in (NodeStatus.SUCCESS, NodeStatus.FAILURE) else None
