"""What each hook must return, checked on every result so a plugin returning garbage is an ``internal`` failure.

A hook returning ``42`` from ``bt_meta_expectations`` would otherwise surface far away as a ``TypeError`` traceback
in the monitor; :class:`bt_meta.plugins.PluginHost` checks each non-``None`` result against the contract here at the
call and turns a breach into a contained error naming the plugin and the hook, exactly like an exception.

Offers:

* :class:`HookContractError` -- a result of the wrong type (a :class:`~bt_meta.errors.PluginError`)
* :func:`check_result` -- raise :class:`HookContractError` when ``value`` breaks ``hook``'s contract
* :data:`RESULT_CONTRACTS` -- hook name -> the words for what it must return
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bt_meta.errors import PluginError


class HookContractError(PluginError):
    """A hook implementation returned a value its hookspec does not allow."""


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool) or type(value).__name__ == "bool_"  # numpy's bool from a comparison


def _is_world(value: Any) -> bool:
    return all(callable(getattr(value, name, None)) for name in ("symbolic_state", "skill", "observe"))


def _list_of(kind: Callable[[], type]) -> Callable[[Any], bool]:
    def check(value: Any) -> bool:
        cls = kind()
        return isinstance(value, (list, tuple)) and all(isinstance(item, cls) for item in value)

    return check


def _instance_of(kind: Callable[[], type]) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, kind())


def _expectation() -> type:
    from bt_meta.bt.expectations import Expectation

    return Expectation


def _comparison() -> type:
    from bt_meta.bt.expectations import Comparison

    return Comparison


def _proposal() -> type:
    from bt_meta.bt.failures import RepairProposal

    return RepairProposal


def _is_proposals(value: Any) -> bool:
    from bt_meta.bt.failures import Failure

    return isinstance(value, (list, tuple, _proposal(), Failure))


def _is_keys(value: Any) -> bool:
    return isinstance(value, (list, tuple, set, frozenset)) and all(isinstance(key, str) for key in value)


def _is_kind(value: Any) -> bool:
    from bt_meta.bt.failures import FailureKind

    return isinstance(value, (str, FailureKind))


RESULT_CONTRACTS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "bt_meta_make_world": (_is_world, "a World (with symbolic_state, skill and observe) or None"),
    "bt_meta_external_predicate": (_is_bool, "True, False or None"),
    "bt_meta_observation_needs": (_is_keys, "a list of observation keys (str) or None"),
    "bt_meta_observe": (lambda value: isinstance(value, dict), "a dict of observations or None"),
    "bt_meta_expectations": (_list_of(_expectation), "a list of Expectation or None"),
    "bt_meta_compare": (_instance_of(_comparison), "a Comparison or None"),
    "bt_meta_classify_failure": (_is_kind, "a FailureKind, a kind's string or None"),
    "bt_meta_on_failure": (lambda value: isinstance(value, dict), "a dict of notes or None"),
    # The meta-reasoner checks each item itself and reports the ones it drops, so only the container is checked.
    "bt_meta_propose_repairs": (_is_proposals, "a list of RepairProposal (or of motion-limit Failure) or None"),
}


def check_result(hook: str, value: Any) -> None:
    """Raise :class:`HookContractError` when the non-``None`` ``value`` is not what ``hook`` must return.

    Hooks that return nothing by contract (``bt_meta_register_nodes``, ``bt_meta_trace_event``) accept anything:
    their results are not used.
    """
    contract = RESULT_CONTRACTS.get(hook)
    if contract is None:
        return
    valid, expected = contract
    if not valid(value):
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        raise HookContractError(f"returned {type(value).__name__} {shown}; {hook} must return {expected}")
