"""The time budget of one hook call: a plugin that sleeps or loops cannot stall a run.

:class:`bt_meta.plugins.PluginHost` runs every hook implementation between :func:`enter` and :func:`leave`, which
only note the call's deadline (a list append; no system call, so a hook call costs well under a microsecond more).
A watchdog thread, started at the first budgeted call, looks at the deadlines every :data:`POLL_SECONDS`; when the
call running in the main thread is past its deadline it sends the main thread ``SIGUSR2``, whose handler raises
:class:`HookTimeout` inside the late call at the point it has reached (a ``sleep``, a Python loop), so its
``finally`` blocks run and it ends at once. A call in another thread, or blocked in C code that does not return to
Python until it is done, runs to its end. Either way the host discards the late call's result and records the call
as an ``internal`` failure naming the plugin, the hook and the budget; the run goes on.

No interval timer is touched (pytest-timeout's and a program's own ``SIGALRM`` keep working); a ``SIGUSR2`` that
is not the watchdog's goes to the handler that was installed before.

Offers:

* :data:`BUDGET_ENV` -- ``BT_META_HOOK_BUDGET``, seconds per hook call (``0`` or ``off`` for none)
* :data:`DEFAULT_HOOK_BUDGET` -- 60 seconds, well above any shipped plugin's slowest call (loading the simulator)
* :func:`budget_from_environment`, :func:`parse_budget` -- the budget asked for by the environment or a flag
* :class:`HookTimeout` -- raised inside a call past its budget (a ``BaseException``: ``except Exception`` in a
  plugin does not swallow it)
* :func:`enter`, :func:`leave` -- bracket one call under a budget
* :class:`HookBudgetExceeded` -- the error a late call is recorded with
"""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

from bt_meta.errors import PluginError, UserInputError

BUDGET_ENV = "BT_META_HOOK_BUDGET"
DEFAULT_HOOK_BUDGET = 60.0
POLL_SECONDS = 0.05
INTERRUPT_SIGNAL = getattr(signal, "SIGUSR2", None)

_deadlines: list[float] = []  # monotonic deadlines of the main thread's budgeted calls in progress, outermost first
_pending: list[float] = []  # the deadline the watchdog interrupted for, until the handler has seen it
_previous_handler: Any = None
_watchdog: threading.Thread | None = None


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


def _on_interrupt(signum: int, frame: Any) -> None:
    if _pending:
        due = _pending.pop()
        if due in _deadlines:
            raise HookTimeout(due)
        return  # the late call ended while the signal was on its way
    previous = _previous_handler
    if callable(previous):
        previous(signum, frame)


def _watch(main_ident: int) -> None:
    while True:
        time.sleep(POLL_SECONDS)
        deadlines = list(_deadlines)
        if not deadlines or _pending or time.monotonic() < min(deadlines):
            continue
        if signal.getsignal(INTERRUPT_SIGNAL) is not _on_interrupt:  # type: ignore[arg-type]
            continue  # someone replaced the handler: the late call runs to its end and loses its result
        _pending.append(min(deadlines))
        try:
            signal.pthread_kill(main_ident, INTERRUPT_SIGNAL)  # type: ignore[arg-type]
        except (OSError, ValueError):  # pragma: no cover - the main thread is gone
            return


_armed = False
_main_ident = threading.main_thread().ident


def _arm() -> bool:
    """Install the handler and start the watchdog, once per process (main thread only)."""
    global _previous_handler, _watchdog, _armed
    if INTERRUPT_SIGNAL is None:
        return False
    try:
        if signal.getsignal(INTERRUPT_SIGNAL) is not _on_interrupt:
            _previous_handler = signal.signal(INTERRUPT_SIGNAL, _on_interrupt)
    except (ValueError, OSError):  # pragma: no cover - an embedding that forbids handlers
        return False
    _watchdog = threading.Thread(target=_watch, args=(threading.get_ident(),), name="bt-meta hook budget",
                                 daemon=True)
    _watchdog.start()
    _armed = True
    return True


def _after_fork() -> None:
    global _watchdog, _armed, _main_ident
    _watchdog, _armed, _main_ident = None, False, threading.main_thread().ident
    _deadlines.clear()
    _pending.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork)


def enter(budget: float) -> float | None:
    """Note the start of a call with ``budget`` seconds; returns its deadline when it can be interrupted (the main
    thread), else ``None`` (the caller still compares the elapsed time with the budget afterwards)."""
    if threading.get_ident() != _main_ident or not (_armed or _arm()):
        return None
    deadline = time.monotonic() + budget
    _deadlines.append(deadline)
    return deadline


def leave(deadline: float | None) -> None:
    """Note the end of the call :func:`enter` returned ``deadline`` for."""
    if deadline is not None and deadline in _deadlines:
        _deadlines.remove(deadline)


class HookBudgetExceeded(PluginError):
    """A hook call ran past its budget; ``interrupted`` says whether it was stopped or ran to its end."""

    def __init__(self, hook: str, budget: float, elapsed: float, interrupted: bool) -> None:
        ending = "interrupted" if interrupted else f"it could not be interrupted and ran {elapsed:.3g} s"
        super().__init__(f"{hook} ran past its budget of {budget:g} s ({ending}); its result is discarded")
        self.hook = hook
        self.budget = budget
        self.elapsed = elapsed
        self.interrupted = interrupted
