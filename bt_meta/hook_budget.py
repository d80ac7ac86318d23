"""The time budget of one hook call: a plugin that sleeps or loops cannot stall a run.

:class:`bt_meta.plugins.PluginHost` runs every hook implementation inside :func:`budgeted`. Where the call runs in
the main thread of a POSIX process, a real-time interval timer (``SIGALRM``) raises :class:`HookTimeout` inside the
late call at the point it has reached (a ``sleep``, a Python loop), so its ``finally`` blocks run and it ends at
once; where it cannot be interrupted (another thread, or a C function that does not return to Python until it is
done) it runs to its end. Either way the host discards the late call's result and records the call as an
``internal`` failure naming the plugin, the hook and the budget; the run goes on.

An interval timer that was already set (pytest-timeout's, an outer hook call's) is kept: when it is due sooner it
stays as it was, and after the call it is set again to what remains of it, with its previous signal handler
called when it fires.

Offers:

* :data:`BUDGET_ENV` -- ``BT_META_HOOK_BUDGET``, seconds per hook call (``0`` or ``off`` for none)
* :data:`DEFAULT_HOOK_BUDGET` -- 60 seconds, well above any shipped plugin's slowest call (loading the simulator)
* :func:`budget_from_environment` -- the budget ``$BT_META_HOOK_BUDGET`` asks for, else the default
* :class:`HookTimeout` -- raised inside a call past its budget (a ``BaseException``: ``except Exception`` in a
  plugin does not swallow it)
* :func:`budgeted` -- a context manager running one call under a budget
* :class:`HookBudgetExceeded` -- the error a late call is recorded with
* :func:`parse_budget` -- seconds from a command-line or environment value
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from bt_meta.errors import PluginError, UserInputError

BUDGET_ENV = "BT_META_HOOK_BUDGET"
DEFAULT_HOOK_BUDGET = 60.0

_CAN_INTERRUPT = hasattr(signal, "setitimer") and hasattr(signal, "SIGALRM")
_deadlines: list[float] = []  # monotonic deadlines of the budgeted calls in progress, outermost first
_previous_handler: Any = None


class HookTimeout(BaseException):
    """Raised inside a hook call that ran past its budget; ``deadline`` says which call it belongs to."""

    def __init__(self, deadline: float) -> None:
        super().__init__(deadline)
        self.deadline = deadline


def parse_budget(text: str, where: str = BUDGET_ENV) -> float | None:
    """Seconds from ``text``; ``0``, ``off`` or ``none`` mean no budget. A bad value is a :class:`UserInputError`."""
    if text.strip().lower() in ("0", "off", "none", ""):
        return None
    try:
        value = float(text)
    except ValueError:
        raise UserInputError(f"{where} must be a number of seconds (0 or off for no budget), found {text!r}") from None
    if not value > 0 or value == float("inf"):
        if value == 0:
            return None
        raise UserInputError(f"{where} must be a positive number of seconds, found {text!r}")
    return value


def budget_from_environment() -> float | None:
    """``$BT_META_HOOK_BUDGET`` when set, else :data:`DEFAULT_HOOK_BUDGET`."""
    text = os.environ.get(BUDGET_ENV)
    return DEFAULT_HOOK_BUDGET if text is None else parse_budget(text)


def _on_alarm(signum: int, frame: Any) -> None:
    if _deadlines:
        due = min(_deadlines)
        if time.monotonic() >= due - 1e-3:
            raise HookTimeout(due)
    previous = _previous_handler
    if callable(previous):
        previous(signum, frame)


def _install_handler() -> bool:
    global _previous_handler
    current = signal.getsignal(signal.SIGALRM)
    if current is _on_alarm:
        return True
    try:
        signal.signal(signal.SIGALRM, _on_alarm)
    except (ValueError, OSError):  # pragma: no cover - not the main thread after all
        return False
    _previous_handler = current
    return True


@contextmanager
def budgeted(budget: float | None) -> Iterator[float | None]:
    """Run the body under ``budget`` seconds; yields the call's deadline (``None`` without a budget).

    The caller catches :class:`HookTimeout` whose ``deadline`` is the one yielded (another deadline belongs to an
    outer call and must be re-raised) and also compares the elapsed time with the budget, for calls that could
    not be interrupted.
    """
    if budget is None:
        yield None
        return
    deadline = time.monotonic() + budget
    interrupt = _CAN_INTERRUPT and threading.current_thread() is threading.main_thread() and _install_handler()
    if not interrupt:
        yield deadline
        return
    started = time.monotonic()
    _deadlines.append(deadline)
    old_delay, old_interval = signal.setitimer(signal.ITIMER_REAL, budget)
    if 0 < old_delay < budget:
        signal.setitimer(signal.ITIMER_REAL, old_delay, old_interval)  # the sooner timer stays

    def restore() -> None:
        if deadline in _deadlines:
            _deadlines.remove(deadline)
        if old_delay > 0:
            remaining = old_delay - (time.monotonic() - started)
            signal.setitimer(signal.ITIMER_REAL, max(remaining, 1e-6), old_interval)
        else:
            signal.setitimer(signal.ITIMER_REAL, 0)

    try:
        yield deadline
    finally:
        try:
            restore()
        except HookTimeout:
            restore()  # the alarm landed while restoring: the deadline is gone now, so this cannot be interrupted
            raise


class HookBudgetExceeded(PluginError):
    """A hook call ran past its budget; ``interrupted`` says whether it was stopped or ran to its end."""

    def __init__(self, hook: str, budget: float, elapsed: float, interrupted: bool) -> None:
        ending = "interrupted" if interrupted else f"it could not be interrupted and ran {elapsed:.3g} s"
        super().__init__(f"{hook} ran past its budget of {budget:g} s ({ending}); its result is discarded")
        self.hook = hook
        self.budget = budget
        self.elapsed = elapsed
        self.interrupted = interrupted
