"""From HTN decompositions to py_trees behaviour trees with a Monitor around every primitive.

Two modes:

* **plan** -- the planner's decomposition tree, node for node: a compound task becomes a ``Sequence`` (BT.CPP
  semantics: resumes at the RUNNING child, restarts after a failure) whose first child is a ``CheckCondition``
  guard for the method's precondition under the node's bindings, followed by its subtasks; a primitive becomes
  its action in a :class:`~bt_meta.bt.monitor.Monitor`. Names keep the decomposition-node ids
  (``"n3 place(b0, 2, 1)"``), so a failure maps back to the HTN node.
* **policy** -- the whole method library, without a plan: a compound task becomes a ``Fallback`` over its
  methods, each a ``Sequence`` behind a guard that binds the method's variables at run time and writes them to the
  blackboard (``{p<k>_<var>}``) for the subtasks' ports; the method's nodes are named ``p<k> ...``.
  Recursive methods are expanded to ``max_depth`` levels;
  deeper branches are ``AlwaysFailure`` nodes named ``... depth limit``. Unordered methods run in written order.

Every behaviour is built through the node registry (:func:`~bt_meta.bt.domain_nodes.domain_registry`), so it
carries ``bt_node`` and compiles to the same behaviours the XML loader builds from the written XML.

Offers:

* :func:`compile_plan` -- decomposition tree -> behaviour tree
* :func:`compile_policy` -- method library + task network -> behaviour tree
* :func:`compile_task_file` -- load, plan (unless policy) and compile; returns a :class:`CompiledTree`
* :class:`CompiledTree` -- root, task file, domain, problem, plan result and registry of one compilation
* :func:`assign_steps` -- number the primitive actions of a tree in tick order (for trees loaded from XML)
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import py_trees

from bt_meta.bt.actions import PrimitiveAction
from bt_meta.bt.domain_nodes import CHECK_CONDITION, domain_registry, node_id_of
from bt_meta.bt.guards import format_bindings
from bt_meta.bt.monitor import Monitor
from bt_meta.bt.nodes.ticking import install_wake_up
from bt_meta.bt.registry import NodeRegistry
from bt_meta.errors import BtMetaError, PlanningError
from bt_meta.htn.state import atom_text

DEFAULT_POLICY_DEPTH = 6
DEFAULT_POLICY_NODES = 20_000


class CompileError(BtMetaError):
    """A decomposition or method library that cannot become a behaviour tree."""


@dataclass
class CompiledTree:
    """One compilation: the root behaviour and where it came from."""

    root: py_trees.behaviour.Behaviour
    domain: Any
    problem: Any = None
    task_file: Any = None
    plan_result: Any = None
    registry: NodeRegistry | None = None
    mode: str = "plan"
    stats: dict[str, Any] = field(default_factory=dict)


def compile_plan(
    tree: Any,
    domain: Any,
    *,
    registry: NodeRegistry | None = None,
    name: str = "plan",
    monitor: bool = True,
) -> py_trees.behaviour.Behaviour:
    """The behaviour tree of a decomposition tree (see the module docstring)."""
    registry = registry or domain_registry(domain)
    methods = {method.name: method for method in domain.methods}

    def build(node_id: str) -> py_trees.behaviour.Behaviour:
        node = tree.nodes[node_id]
        label = f"{node.id} {atom_text(node.task)}"
        if node.kind == "primitive":
            primitive = domain.primitives.get(node.task[0])
            if primitive is None:
                raise CompileError(f"decomposition node {node.id}: unknown primitive {node.task[0]!r}")
            ports = dict(zip(primitive.parameters, node.task[1:], strict=True))
            action = registry.create(primitive.name, name=label, ports=ports)
            if isinstance(action, PrimitiveAction):
                action.node_id, action.step = node.id, node.step
            return Monitor(action) if monitor else action
        children: list[py_trees.behaviour.Behaviour] = []
        method = methods.get(node.method) if node.method else None
        if method is not None and not method.precondition.trivial:
            children.append(registry.create(CHECK_CONDITION, name=f"{node.id} guard {method.name}", ports={
                "condition": method.precondition.source,
                "bindings": format_bindings(node.bindings),
                "method": method.name,
            }))
        children.extend(build(child) for child in node.children)
        if not children:
            children.append(registry.create("AlwaysSuccess", name=f"{node.id} empty method {node.method}"))
        return registry.create("Sequence", name=label, children=children)

    roots = [build(root) for root in tree.roots]
    if not roots:
        roots = [registry.create("AlwaysSuccess", name="empty plan")]
    root = registry.create("Sequence", name=name, children=roots)
    install_wake_up(root)
    return root


def compile_policy(
    domain: Any,
    tasks: Sequence[tuple[str, ...]],
    *,
    registry: NodeRegistry | None = None,
    name: str = "policy",
    max_depth: int = DEFAULT_POLICY_DEPTH,
    max_nodes: int = DEFAULT_POLICY_NODES,
    monitor: bool = True,
) -> py_trees.behaviour.Behaviour:
    """A reactive tree over the whole method library for the task network ``tasks`` (ground atoms)."""
    from bt_meta.htn.conditions import Var, term_text

    registry = registry or domain_registry(domain)
    scopes = itertools.count(1)
    count = [0]

    def create(node_id: str, **kwargs: Any) -> py_trees.behaviour.Behaviour:
        count[0] += 1
        if count[0] > max_nodes:
            raise CompileError(f"the policy tree exceeds {max_nodes} nodes; lower the depth (now {max_depth})")
        return registry.create(node_id, **kwargs)

    def expand(pred: str, args: list[str], depth: int) -> py_trees.behaviour.Behaviour:
        label = f"{pred}({', '.join(args)})"
        if pred in domain.primitives:
            primitive = domain.primitives[pred]
            action = create(pred, name=label, ports=dict(zip(primitive.parameters, args, strict=True)))
            return Monitor(action) if monitor else action
        if pred not in domain.tasks:
            raise CompileError(f"unknown task {pred!r}")
        if depth >= max_depth:
            return create("AlwaysFailure", name=f"{label} depth limit {max_depth}")
        options = []
        for method in domain.methods_by_task.get(pred, []):
            scope = f"p{next(scopes)}_"
            bindings: dict[str, str] = {}
            checks: list[str] = []
            fits = True
            for index, (term, arg) in enumerate(zip(method.task_args, args, strict=True)):
                literal = not arg.startswith("{")
                if isinstance(term, Var):
                    if term.name in bindings and bindings[term.name] != arg:
                        if literal and not bindings[term.name].startswith("{"):
                            fits = False
                            break
                        bindings[f"_h{index}"] = arg
                        checks.append(f"?_h{index} == ?{term.name}")
                    else:
                        bindings.setdefault(term.name, arg)
                elif literal:
                    if arg != term:
                        fits = False
                        break
                else:
                    bindings[f"_h{index}"] = arg
                    checks.append(f"?_h{index} == {term_text(term)}")
            if not fits:
                continue
            condition = method.precondition.source
            if checks:
                condition = " and ".join([*checks, f"({condition})"])
            children = [create(CHECK_CONDITION, name=f"{scope[:-1]} guard {method.name}", ports={
                "condition": condition, "bindings": format_bindings(bindings), "method": method.name,
                "output_prefix": scope, "record": "false",
            })]
            for subtask in method.subtasks:
                sub_args = []
                for term in subtask[1:]:
                    if isinstance(term, Var):
                        bound = bindings.get(term.name)
                        sub_args.append(bound if bound is not None and not bound.startswith("{")
                                        else "{" + scope + term.name + "}")
                    else:
                        sub_args.append(str(term))
                children.append(expand(subtask[0], sub_args, depth + 1))
            options.append(create("Sequence", name=f"{scope[:-1]} {method.name} for {label}", children=children))
        if not options:
            return create("AlwaysFailure", name=f"{label} no method fits")
        return create("Fallback", name=label, children=options)

    roots = [expand(task[0], [str(a) for a in task[1:]], 0) for task in tasks]
    if not roots:
        roots = [create("AlwaysSuccess", name="empty task network")]
    root = create("Sequence", name=name, children=roots)
    install_wake_up(root)
    return root


def compile_task_file(
    source: str | Path | Any,
    problem: str | None = None,
    *,
    policy: bool = False,
    plugins: Any = None,
    registry: NodeRegistry | None = None,
    monitor: bool = True,
    max_depth: int = DEFAULT_POLICY_DEPTH,
    plan_options: dict[str, Any] | None = None,
) -> CompiledTree:
    """Load a task file (a path or a loaded ``TaskFile``), plan its problem unless ``policy``, and compile.

    Raises :class:`~bt_meta.errors.PlanningError` when the planner finds no plan; the plan gets the default
    budget of :mod:`bt_meta.htn.budgets` unless ``plan_options`` give one.
    """
    from bt_meta.htn import load_task_file, plan
    from bt_meta.htn.budgets import with_default_budget

    task_file = load_task_file(source) if isinstance(source, (str, Path)) else source
    domain = task_file.domain
    chosen = task_file.problem(problem)
    registry = registry or domain_registry(domain, plugins)
    if policy:
        root = compile_policy(domain, chosen.tasks, registry=registry, name=f"policy {chosen.name}",
                              max_depth=max_depth, monitor=monitor)
        return CompiledTree(root, domain, chosen, task_file, None, registry, "policy")
    external = None if plugins is None else plugins.external_predicate
    result = plan(domain, chosen, external=external, **with_default_budget(plan_options))
    if result.status != "success" or result.tree is None:
        raise PlanningError(f"no plan for problem {chosen.name!r}: {result.status}"
                            + (f" ({result.message})" if result.message else ""))
    root = compile_plan(result.tree, domain, registry=registry, name=f"plan {chosen.name}", monitor=monitor)
    return CompiledTree(root, domain, chosen, task_file, result, registry, "plan",
                        {"primitives": len(result.plan), **dict(result.stats or {})})


def assign_steps(root: py_trees.behaviour.Behaviour) -> int:
    """Number the primitive actions under ``root`` in pre-order (tick order of a plan) and fill missing node ids.

    Trees loaded from XML know their node ids from the names but not their plan steps. Returns the count.
    """
    step = 0
    for behaviour in _preorder(root):
        if isinstance(behaviour, PrimitiveAction):
            if behaviour.node_id is None:
                behaviour.node_id = node_id_of(behaviour.name)
            if behaviour.step is None:
                behaviour.step = step
            step += 1
    return step


def _preorder(root: py_trees.behaviour.Behaviour):
    stack = [root]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(node.children))
