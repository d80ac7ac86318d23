"""The one rclpy node every ROS leaf of a process shares, with an executor spinning on a background thread.

BehaviorTree.ROS2 hands every leaf the integrator's ``rclcpp::Node``; here the first ROS leaf that ticks opens
a node of its own (``bt_meta_leaves``, its own context, localhost-only discovery unless the environment says
otherwise: :mod:`bt_meta.ros2.environment`). Requests are made on the executor's thread (rclpy drops a response
taken between sending a request and registering it, see :class:`bt_meta.ros2.action_clients.ActionClient`), and
callbacks hand their results over to the tick through :class:`Pending`, so a tick never blocks on the network but
for the bounded waits BehaviorTree.ROS2 has too (``wait_for_server_timeout``, a cancel on halt).

At exit (or :func:`close_runtime`) every leaf still waiting on a goal cancels it, then the context shuts down.

Offers:

* :class:`Pending` -- a value a callback will set; ``done``, ``value``, ``wait(timeout)``
* :class:`LeafRuntime` -- ``node``, ``call(make)`` (``make()`` on the executor thread, its future as a Pending),
  ``entity(key, make)`` (a client, publisher or subscription made once per process), ``on_close(callback)``,
  ``close()``
* :func:`runtime` -- the process's runtime, opened at first use; :func:`close_runtime`
"""

from __future__ import annotations

import atexit
import contextlib
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["LeafRuntime", "Pending", "close_runtime", "runtime"]

_RUNTIME: LeafRuntime | None = None
_LOCK = threading.Lock()


class Pending:
    """A result that arrives on the executor thread; the tick reads it without waiting."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.value: Any = None
        self.error: BaseException | None = None

    def set(self, value: Any = None, error: BaseException | None = None) -> None:
        self.value, self.error = value, error
        self._event.set()

    @property
    def done(self) -> bool:
        return self._event.is_set()

    def wait(self, timeout: float) -> bool:
        return self._event.wait(timeout)


class LeafRuntime:
    def __init__(self, node_name: str = "bt_meta_leaves") -> None:
        from bt_meta.ros2.environment import import_rclpy

        rclpy = import_rclpy()
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(node_name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._closers: list[Callable[[], None]] = []
        self.finished = False
        """Closed: the closers ran and the context is shut down (a leaf asking now gets a new runtime)."""
        self._entities: dict[Any, Any] = {}
        self._entity_lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._spin, name="bt-meta-ros2-leaves", daemon=True)
        self._thread.start()
        atexit.register(self.close)  # rclpy's threads must not be left to the interpreter's exit

    def _spin(self) -> None:
        from bt_meta.ros2.connection import spin_until_shutdown

        spin_until_shutdown(self.executor, self.context)

    def call(self, make: Callable[[], Any]) -> Pending:
        """Run ``make()`` on the executor thread; the Pending gets the result of the future it returns (or of
        ``make()`` itself when that is no future)."""
        pending = Pending()

        def request() -> None:
            try:
                made = make()
            except Exception as error:  # handed to the tick, which reports it
                pending.set(error=error)
                return
            if hasattr(made, "add_done_callback"):
                made.add_done_callback(lambda future: pending.set(*_outcome(future)))
            else:
                pending.set(made)

        self.executor.create_task(request)
        return pending

    def entity(self, key: Any, make: Callable[[], Any], timeout: float = 5.0) -> Any:
        """The client, publisher or subscription ``key`` names, made by ``make()`` on the executor thread once."""
        with self._entity_lock:
            if key in self._entities:
                return self._entities[key]
            pending = self.call(make)
            if not pending.wait(timeout):
                raise RuntimeError(f"the ROS 2 executor did not make {key!r} within {timeout:g} s")
            if pending.error is not None:
                raise pending.error
            self._entities[key] = pending.value
            return pending.value

    def on_close(self, callback: Callable[[], None]) -> None:
        self._closers.append(callback)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        try:
            for callback in self._closers:
                with contextlib.suppress(Exception):
                    callback()
        finally:
            self.finished = True
            self.context.try_shutdown()
            self._thread.join(timeout=2.0)
            with contextlib.suppress(Exception):  # handles already gone with the context
                self.executor.shutdown(timeout_sec=1.0)
                self.node.destroy_node()


def _outcome(future: Any) -> tuple[Any, BaseException | None]:
    error = future.exception()
    return (None, error) if error is not None else (future.result(), None)


def runtime() -> LeafRuntime:
    global _RUNTIME
    with _LOCK:
        if _RUNTIME is None or _RUNTIME.finished:
            _RUNTIME = LeafRuntime()
        return _RUNTIME


def close_runtime() -> None:
    """Cancel what the leaves still wait on and close the node (the process's next ROS leaf opens a new one)."""
    global _RUNTIME
    with _LOCK:
        opened, _RUNTIME = _RUNTIME, None
    if opened is not None:
        opened.close()
