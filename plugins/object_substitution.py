"""Object substitution (paper, section 6.4): when an entity the plan needs is missing and unknown ones are seen,
find in the episodic memory a decomposition that the unknown entities can carry out, and splice it into the plan.

The steps, as the paper gives them:

1. **mismatch vector** -- the failed step, the *missing* entities (objects of the problem whose shape or colour
   the world does not show: A's blue 1x2 bar) and the *unknown* ones seen (objects the problem does not know, or
   whose shape or colour differ: two red 1x1 blocks), from the monitor's grid-map mismatch and the world's
   object report (``world.observe()["objects"]`` with ``shape``/``colour``);
2. the **first action of the invoked task that uses the missing entity**: the first step of
   ``evidence["plan"]`` not done whose arguments name it;
3. **its expectation from P_a**: the stored execution of that same call in the run's root task
   (``EpisodicMemory.plan_executions``), its E_db grid-map (``expectations``) and its task occurrence (the
   decomposition it was part of, with the blocks' shape and colour from the episode's initial facts);
4. **ranked matches from E_db**: with the ``gridmap`` matcher, the nearest stored grid-maps
   (``EpisodicMemory.nearest_grid_maps``; by default task-level expectations only -- the last primitive of each
   task occurrence, bubbled up as section 6.2 says -- and without rotations: both letters are drawn in one
   table frame); with the ``symbolic`` matcher, the stored task occurrences nearest in their lifted facts (the
   multiset of ``shape``, ``colour`` and placement facts; the symbol-only baseline the paper compares with);
5. a match is **realisable** when the blocks of its decomposition can be bound one-to-one to the unknown
   entities: by shape for the grid-map matcher (its occupancy is colour presence: form, not colour), by shape
   and colour for the symbolic one (its expectations are exactly those facts). Each realisable match becomes a
   proposal: ``substitute {missing: unknown}`` when one block stands in for one (same call otherwise), else a
   ``splice`` replacing the invoked task's remaining steps with the matched decomposition's steps, rebound to the
   unknown entities (A's bar drawn with two 1x1 blocks at the cells of H's bar).

**Grounding spares** (:mod:`bt_meta_plugins._grounding_spares`) come first: a missing part that the plan names
only through a grounding symbol (the magnetic plan's poses are defined over ``active_part``) gets a ``rebind``
proposal binding the symbol to an unused object of the part's demonstrated type.

**Spares** (:mod:`bt_meta_plugins._spares`, no memory needed) come next: a missing entity that a step still to run
uses is replaced one for one (``substitute``) by an object seen on the table that the plan does not use, when the
precondition of every method that chose the missing entity holds with the spare in its place -- so colour counts
only where the task's symbols name one, and there as a preference (a spare of another colour is proposed, scored
lower, only when none has the colour; ``colours="require"`` makes it a condition). An entity a failure of the run
found out of reach where it lies (the skill's ``out_of_reach``) counts as missing and is never a spare. Besides
``unknown_entity`` and ``unexpected_configuration``, a ``collision``, ``physical``, ``precondition`` or
``reachability`` failure is answered when the failed step itself names a missing entity (a 1x2 block placed where a
1x1 was planned collides: A's bar then stands in for H's two 1x1 placements).

**Tilings** (:mod:`bt_meta_plugins._tilings`, no memory needed) come last: the cells the remaining placements
need, covered anew with the blocks on the table (many-for-one and one-for-many shape substitutions the
demonstrations never decomposed: one 1x2 where two 1x1 blocks that are not side by side were planned). When the
cells still to fill have no tiling, **re-tiling** (:mod:`bt_meta_plugins._retiling`) tiles the whole drawing again,
moving blocks already placed (the 1x1 on a leg's top goes to a foot so that two 1x2 can lie across the leg tops).

Before proposing, the unknown entities are **anchored** in the world's symbolic state (``world.apply_symbolic``):
their perceived ``block``/``shape``/``colour`` facts replace what the problem assumed, and an unknown entity the
failed step itself moved is made ``available`` again (its placement did not meet the expectation, and the repair
moves it; when the failure's context does not carry the step's effects, the primitive's effects under its
arguments are undone if the world shows them applied). The executor resets its belief to
``world.symbolic_state()`` before applying a proposal, so the spliced steps' preconditions are checked against
what was seen, and it keeps what was anchored with a learned refinement (``docs/meta-reasoning.md``).
``anchor=False`` turns this off.

Settings (:class:`ObjectSubstitution` arguments, :func:`configure` for the module-level plugin, or the
environment variable ``BT_META_SUBSTITUTION_MATCHER`` = ``gridmap`` | ``symbolic`` for the module's default):
``matcher``, ``k`` (matches kept), ``rotations``, ``level`` (``task`` | ``step``), ``max_proposals``, ``memory``,
``spares`` (spares and grounding spares), ``colours`` (``prefer`` | ``require``: whether a spare or a tiling may use
a block of another colour than the methods name when none of that colour can stand in; default: ``prefer`` with
the ``gridmap`` matcher, whose grid-maps compare form, ``require`` with the ``symbolic`` one), ``geometry`` (tilings;
default: with the ``gridmap`` matcher only -- the ``symbolic`` matcher is the symbol-only baseline).
Nothing here is random: ties are broken by rank, then by entity name.

Offers:

* :class:`ObjectSubstitution` -- the plugin as an object; :meth:`ObjectSubstitution.retrieve` gives the ranked
  matches without proposing (what ``bt-meta experiment substitution`` tabulates)
* :class:`Match`, :class:`Retrieval`; re-exported from its private modules: :class:`Entity`,
  :class:`MismatchVector` (``_mismatch``), :class:`Decomposition` (``_decompositions``)
* :func:`mismatch_vector` -- step 1 for a failure and its context
* :func:`bind` -- one-to-one binding of a decomposition's blocks to entities
* :func:`bt_meta_propose_repairs` -- the module-level plugin (see :func:`configure`)
* :data:`MATCHERS` -- ``("gridmap", "symbolic")``
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from bt_meta_plugins._decompositions import Decomposition, Library, bind, why_not
from bt_meta_plugins._grounding_spares import rebind_proposals
from bt_meta_plugins._mismatch import Entity, MismatchVector, mismatch_vector
from bt_meta_plugins._retiling import retiling_proposals
from bt_meta_plugins._spares import spare_proposals
from bt_meta_plugins._tilings import covers_the_same_cells, lands_on_a_block, planned_shapes, tiling_proposals

from bt_meta.bt.failures import FailureKind, RepairProposal
from bt_meta.errors import ConfigError
from bt_meta.meta.proposals import REBIND, SPLICE, SUBSTITUTE
from bt_meta.perception.recall import memory_for, root_task
from bt_meta.plugins import hookimpl

__all__ = [
    "MATCHERS",
    "Decomposition",
    "Entity",
    "Match",
    "MismatchVector",
    "ObjectSubstitution",
    "Retrieval",
    "bind",
    "bt_meta_propose_repairs",
    "configure",
    "mismatch_vector",
]

MATCHERS = ("gridmap", "symbolic")
LEVELS = ("task", "step")
COLOURS = ("prefer", "require")
"""How a colour the methods name binds a spare or a tiling's stand-in: first choice, or the only one."""
ENV_MATCHER = "BT_META_SUBSTITUTION_MATCHER"
_KINDS = (FailureKind.UNKNOWN_ENTITY, FailureKind.UNEXPECTED_CONFIGURATION)
DEMOTED = 0.9
"""A proposal that leaves the failed step's missing entity as it was is scored at most this fraction of the
lowest-scored one that changes it."""
_STEP_KINDS = (FailureKind.COLLISION, FailureKind.PHYSICAL, FailureKind.PRECONDITION, FailureKind.REACHABILITY)
"""Failures answered only when the failed step itself names a missing entity: a 1x2 block where a 1x1 was
planned collides at its placement; a block that is not there cannot be grasped."""


@dataclass
class Match:
    """A ranked hit of one matcher, with what reusing it would take."""

    rank: int
    matcher: str
    decomposition: Decomposition
    distance: int
    step_index: int
    call: str
    binding: dict[str, str] | None = None
    reason: str = ""
    rotation: int = 0

    @property
    def realisable(self) -> bool:
        return self.binding is not None

    def to_dict(self) -> dict[str, Any]:
        d = self.decomposition
        return {"rank": self.rank, "matcher": self.matcher, "episode": d.episode_id, "task": d.task,
                "parent_task": d.parent_task, "step": self.step_index, "call": self.call,
                "distance": self.distance, "rotation": self.rotation, "decomposition": d.describe(),
                "blocks": {b: f"{d.blocks[b][1]} {d.blocks[b][0]}" for b in d.block_args()},
                "realisable": self.realisable, "binding": self.binding, "reason": self.reason}


@dataclass
class Retrieval:
    """Steps 2-4 for one failure: the query (the first step using the missing entity and its stored
    execution) and the ranked matches."""

    vector: MismatchVector
    matcher: str
    query_step: int | None = None
    query_call: str | None = None
    query: Decomposition | None = None
    query_episode: int | None = None
    matches: list[Match] = field(default_factory=list)
    note: str = ""

    @property
    def found(self) -> Match | None:
        return next((m for m in self.matches if m.realisable), None)

    def to_dict(self) -> dict[str, Any]:
        return {"matcher": self.matcher, "vector": self.vector.to_dict(), "query_step": self.query_step,
                "query_call": self.query_call, "query_episode": self.query_episode,
                "query": None if self.query is None else self.query.describe(),
                "matches": [m.to_dict() for m in self.matches], "found": None if self.found is None
                else self.found.to_dict(), "note": self.note}


def _done_targets(plan: Sequence[Mapping[str, Any]]) -> set[tuple[str, ...]]:
    """Each executed step as its action and its arguments after the first (the entity it moved, as in
    ``place(block, x, y)``): for ``place``, the cells an executed step already filled."""
    targets = set()
    for step in plan:
        if step.get("done"):
            args = [str(a) for a in step["args"]]
            targets.add((str(step["action"]), *args[1:]))
    return targets


def _without_placed(vector: MismatchVector, plan: Sequence[Mapping[str, Any]]) -> MismatchVector:
    """``vector`` without the unknown entities an executed step already moved (a stand-in placed earlier): taking
    one again would undo that step's work, and a letter drawn so has a hole where it was."""
    placed = {str(a) for step in plan if step.get("done") for a in step.get("args") or []}
    unknown = tuple(e for e in vector.unknown if e.name not in placed)
    return vector if len(unknown) == len(vector.unknown) else replace(vector, unknown=unknown)


def _names_missing(failure: Any, vector: MismatchVector) -> bool:
    """Whether the failed step's arguments -- or, for a method's guard that no longer holds, the entities the
    method bound -- name an entity the world does not show as the plan assumes it (a leg method's 1x1 seen as a
    1x2 after the step that put it down)."""
    bindings = (getattr(failure, "evidence", None) or {}).get("bindings")
    bound = {str(v) for v in bindings.values()} if isinstance(bindings, Mapping) else set()
    return bool(_failed_missing(failure, vector) or {e.name for e in vector.missing} & bound)


def _mends_the_failed_step(proposal: RepairProposal, failure: Any, vector: MismatchVector, context: Any) -> bool:
    """Whether ``proposal`` changes what the failed step does with a missing entity it names: a substitution or a
    rebinding of another missing block (b5 -> a spare) leaves a 1x2 placed where a 1x1 was planned failing as
    before, and a stand-in put down on the cell the 1x2 still lies on collides with it, so these are tried after
    the proposals that do, whatever their score. True when the failed step names no missing entity."""
    named = _failed_missing(failure, vector)
    step = getattr(failure, "step", None)
    if not named or step is None:
        return True
    if proposal.action == SUBSTITUTE:
        mapping = proposal.changes.get("mapping") or {}
        return bool(named & set(mapping)) and not lands_on_a_block(failure, mapping, context)
    if proposal.action == REBIND:
        return bool(named & set(proposal.changes.get("symbols") or {}))
    if proposal.action == SPLICE:
        start, end = proposal.changes.get("start"), proposal.changes.get("end")
        return isinstance(start, int) and isinstance(end, int) and start <= step < end
    return True


def _mending_first(proposals: list[RepairProposal], failure: Any, vector: MismatchVector, context: Any
                   ) -> list[RepairProposal]:
    """``proposals`` by score, those that do not mend the failed step scored below every one that does (the
    reasoner ranks all plugins' proposals by score): each keeps a note of why in its evidence."""
    mends = {id(p): _mends_the_failed_step(p, failure, vector, context) for p in proposals}
    mending = [p.score for p in proposals if mends[id(p)]]
    if mending and len(mending) < len(proposals):
        below = min(mending) * DEMOTED
        proposals = [p if mends[id(p)] else replace(
            p, score=round(min(p.score, below), 4),
            evidence={**p.evidence, "demoted": f"does not change what failed step {failure.step} does with "
                                              f"{', '.join(sorted(_failed_missing(failure, vector)))}"})
            for p in proposals]
    return sorted(proposals, key=lambda p: -p.score)


def _failed_missing(failure: Any, vector: MismatchVector) -> set[str]:
    return ({e.name for e in vector.missing} | set(vector.unusable)) & {str(a) for a in getattr(failure, "args", ())
                                                                        or ()}


def _call(action: str, args: Sequence[Any]) -> str:
    return f"{action}({', '.join(str(a) for a in args)})"


def _applied_effects(context: Any, current: set[Any]) -> tuple[list[Any], list[Any]]:
    """The failed step's (add, delete) when the context does not carry them (the meta-reasoner's context of a
    monitor failure): its primitive's effects under its arguments, if every added fact is in the world's state --
    the skill ran and the world applied them before the monitor objected. Else nothing to undo."""
    primitive = getattr(context, "primitive", None)
    bindings = getattr(context, "bindings", None)
    if primitive is None or not bindings:
        return [], []
    try:
        add, delete = primitive.effects(dict(bindings))
    except (KeyError, TypeError, ValueError):  # effects that need the precondition's bindings: not undone
        return [], []
    if not add or any(tuple(f) not in current for f in add):
        return [], []
    return list(add), list(delete)


# -- the plugin -----------------------------------------------------------------------------------------------------


class ObjectSubstitution:
    """Section 6.4's repair with one matcher (``gridmap`` or ``symbolic``); see the module docstring."""

    def __init__(self, memory: Any = None, *, matcher: str | None = None, k: int = 5, rotations: bool = False,
                 level: str = "task", max_proposals: int = 3, anchor: bool = True, candidates: int = 200,
                 spares: bool = True, geometry: bool | None = None, colours: str | None = None) -> None:
        where = "<plugin settings>"
        if matcher is None:
            matcher = os.environ.get(ENV_MATCHER) or "gridmap"
            where = f"${ENV_MATCHER}" if os.environ.get(ENV_MATCHER) else where
        if matcher not in MATCHERS:
            raise ConfigError(f"object substitution: matcher must be one of {', '.join(MATCHERS)}, got {matcher!r}",
                              where)
        if level not in LEVELS:
            raise ConfigError(f"object substitution: level must be one of {', '.join(LEVELS)}, got {level!r}",
                              "<plugin settings>")
        # a colour the methods name binds as the matcher compares: grid-maps see form (occupancy is colour
        # presence), the symbol-only baseline compares exactly the facts
        colours = colours or ("prefer" if matcher == "gridmap" else "require")
        if colours not in COLOURS:
            raise ConfigError(f"object substitution: colours must be one of {', '.join(COLOURS)}, got {colours!r}",
                              "<plugin settings>")
        if k < 1 or max_proposals < 1 or candidates < 1:
            raise ConfigError("object substitution: k, max_proposals and candidates must be >= 1", "<plugin settings>")
        self.memory = memory
        self.matcher = matcher
        self.k = k
        self.rotations = rotations
        self.level = level
        self.max_proposals = max_proposals
        self.anchor = anchor
        self.candidates = candidates
        self.spares = spares
        self.colours = colours
        # the tilings read the placements' cells -- sub-symbolic, as the grid-maps are: the symbol-only baseline
        # (the symbolic matcher, the paper's comparison) goes without them unless asked
        self.geometry = (matcher == "gridmap") if geometry is None else geometry

    # -- steps 2 to 4 -----------------------------------------------------------------------------------------------

    def retrieve(self, vector: MismatchVector, plan: Sequence[Mapping[str, Any]], memory: Any,
                 task: str | None) -> Retrieval:
        """The query for ``vector`` in ``plan`` (``evidence["plan"]`` records) and this matcher's ranked matches."""
        retrieval = Retrieval(vector, self.matcher)
        names = {e.name for e in vector.missing}
        first = next((p for p in plan if not p.get("done") and names.intersection(str(a) for a in p["args"])), None)
        if first is None:
            retrieval.note = "no step still to run uses the missing entities"
            return retrieval
        retrieval.query_step = int(first["step"])
        retrieval.query_call = _call(first["action"], first["args"])
        library = Library(memory)
        args = [str(a) for a in first["args"]]
        stored = [r for r in library.rows if (task is None or r.task == task) and r.action == first["action"]
                  and [str(a) for a in r.args] == args]
        if not stored:
            retrieval.note = f"P_a has no execution of {retrieval.query_call}" + (f" in {task}" if task else "")
            return retrieval
        row = max(stored, key=lambda r: r.episode_id)  # the newest demonstration
        retrieval.query_episode = row.episode_id
        retrieval.query = library.occurrence(row.episode_id, row.step_index)
        if self.matcher == "gridmap":
            retrieval.matches = self._gridmap_matches(library, row, vector, retrieval)
        else:
            retrieval.matches = self._symbolic_matches(library, vector, retrieval)
        return retrieval

    def _gridmap_matches(self, library: Library, row: Any, vector: MismatchVector, retrieval: Retrieval
                         ) -> list[Match]:
        memory = library.memory
        maps = [x for x in memory.expectations(action=row.action, task=row.task)
                if x.episode_id == row.episode_id and x.step_index == row.step_index and x.grid_map_id is not None]
        if not maps:
            retrieval.note = f"E_db has no grid-map for {retrieval.query_call} (episode {row.episode_id})"
            return []
        missing = {e.name for e in vector.missing}
        chosen = next((x for x in maps if set(str(a) for a in x.args_pattern) & missing), maps[0])
        query = memory.grid_map(chosen.grid_map_id)
        hits = memory.nearest_grid_maps(query, k=self.candidates, rotations=self.rotations)
        matches: list[Match] = []
        seen: set[tuple[Any, ...]] = set()
        for hit in hits:
            if self.level == "task" and not library.ends_task(hit.episode_id, hit.step_index):
                continue
            decomposition = library.occurrence(hit.episode_id, hit.step_index)
            if decomposition is None or decomposition.signature() in seen:
                continue
            seen.add(decomposition.signature())
            binding = bind(decomposition, vector.unknown, colour=False)
            matches.append(Match(len(matches) + 1, "gridmap", decomposition, hit.distance, hit.step_index,
                                 _call(hit.action, hit.args_pattern), binding,
                                 "" if binding else why_not(decomposition, vector.unknown, colour=False),
                                 hit.rotation))
            if len(matches) >= self.k:
                break
        return matches

    def _symbolic_matches(self, library: Library, vector: MismatchVector, retrieval: Retrieval) -> list[Match]:
        query = retrieval.query
        assert query is not None
        wanted = query.lifted_facts()
        scored = []
        seen: set[tuple[Any, ...]] = set()
        for decomposition in library.occurrences():
            if decomposition.signature() in seen:
                continue
            seen.add(decomposition.signature())
            facts = decomposition.lifted_facts()
            distance = sum(((wanted - facts) + (facts - wanted)).values())
            scored.append((distance, decomposition.episode_id, decomposition.first_step, decomposition))
        scored.sort(key=lambda s: (s[0], s[1], s[2]))
        matches = []
        for distance, _, _, decomposition in scored[: self.k]:
            last = decomposition.first_step + len(decomposition.calls) - 1
            action, args = decomposition.calls[-1]
            binding = bind(decomposition, vector.unknown, colour=True)
            matches.append(Match(len(matches) + 1, "symbolic", decomposition, distance, last, _call(action, args),
                                 binding, "" if binding else why_not(decomposition, vector.unknown, colour=True)))
        return matches

    # -- step 5: proposals ------------------------------------------------------------------------------------------

    def proposals(self, retrieval: Retrieval, plan: Sequence[Mapping[str, Any]]) -> list[RepairProposal]:
        """One proposal per realisable match (best first), at most ``max_proposals``."""
        if retrieval.query_step is None or retrieval.query is None:
            return []
        start = retrieval.query_step
        query = retrieval.query
        offset = next((i for i, (a, args) in enumerate(query.calls)
                       if a == plan[start]["action"] and [*args] == [str(x) for x in plan[start]["args"]]), 0)
        tail = query.calls[offset:]
        current = [(p["action"], [str(a) for a in p["args"]]) for p in plan[start:start + len(tail)]]
        end = start + len(tail) if [a for a, _ in current] == [a for a, _ in tail] else start + 1
        missing = {e.name for e in retrieval.vector.missing}
        done_targets = _done_targets(plan)
        out: list[RepairProposal] = []
        for match in retrieval.matches:
            if not match.realisable or len(out) >= self.max_proposals:
                continue
            assert match.binding is not None
            score = self._score(match)
            evidence = {"matcher": self.matcher, "match": match.to_dict(), "vector": retrieval.vector.to_dict(),
                        "query": {"step": start, "call": retrieval.query_call, "episode": retrieval.query_episode,
                                  "decomposition": query.describe()}}
            calls = [[action, *(match.binding.get(a, a) for a in args)] for action, args in match.decomposition.calls]
            entities = set(match.binding.values())
            if any((c[0], *(a for a in c[1:] if a not in entities)) in done_targets for c in calls):
                # The matched decomposition would put a block where an executed step already put one (e.g. A's
                # own legs matched when H was never recorded): it cannot be the form the missing entity drew.
                continue
            one_for_one = (len(calls) == end - start == 1 and calls[0][0] == plan[start]["action"]
                           and len(match.binding) == 1)
            if one_for_one:
                old = [str(a) for a in plan[start]["args"]]
                mapping = {a: b for a, b in zip(old, calls[0][1:], strict=False) if a != b and a in missing}
                if mapping and [mapping.get(a, a) for a in old] == [str(c) for c in calls[0][1:]]:
                    pairs = ", ".join(f"{a} -> {b}" for a, b in mapping.items())
                    out.append(RepairProposal(
                        SUBSTITUTE, score, f"substitute {pairs} ({self.matcher} match: {match.call} of "
                        f"{match.decomposition.task}, distance {match.distance})",
                        changes={"mapping": mapping, "from_step": start}, evidence=evidence))
                    continue
                if not mapping and [str(c) for c in calls[0][1:]] == old:
                    continue  # the same call again: nothing to substitute (the entity keeps its name)
            shown = "; ".join(_call(c[0], c[1:]) for c in calls)
            out.append(RepairProposal(
                SPLICE, score, f"steps {start}..{end - 1} as {match.decomposition.parent_task} of "
                f"{match.decomposition.task} does it: {shown} ({self.matcher} match, distance {match.distance})",
                changes={"start": start, "end": end, "actions": calls}, evidence=evidence))
        return out

    def _same_cells(self, proposals: list[RepairProposal], plan: Sequence[Mapping[str, Any]], context: Any
                    ) -> list[RepairProposal]:
        """``proposals`` without the splices whose placements would cover other cells than the steps they replace
        (a remembered decomposition of another part of the letter: the letter would have a hole and a block too
        many elsewhere)."""
        problem = getattr(getattr(context, "run", None), "problem", None)
        assumed = planned_shapes(problem, getattr(context, "world", None))
        observe = getattr(getattr(context, "world", None), "observe", None)
        seen = ((observe() or {}).get("objects") or {}) if observe is not None else {}
        perceived = {str(k): str(v["shape"]) for k, v in seen.items() if isinstance(v, Mapping) and v.get("shape")}
        return [p for p in proposals if p.action != SPLICE
                or covers_the_same_cells(p, plan, assumed, perceived) is not False]

    def _score(self, match: Match) -> float:
        """Experience-based: above the retry baseline (0.3), higher for nearer matches."""
        scale = 36.0 if self.matcher == "gridmap" else 12.0
        return round(max(0.35, 0.9 - 0.5 * min(match.distance / scale, 1.0) - 0.01 * (match.rank - 1)), 4)

    # -- anchoring ------------------------------------------------------------------------------------------------

    def anchor_entities(self, vector: MismatchVector, failure: Any, context: Any,
                        proposals: Sequence[RepairProposal]) -> None:
        """Give the unknown entities the proposals use their perceived facts in the world's symbolic state: the
        missing entity's initial unary facts (type, availability), their own shape and colour; the failed step's
        effects on an entity it moved are undone (the repair moves it again). A block seen only in another colour
        than the problem says keeps its facts: it still fills its own role."""
        world = getattr(context, "world", None)
        apply = getattr(world, "apply_symbolic", None)
        state = getattr(world, "symbolic_state", None)
        if apply is None or state is None:
            return
        used = {str(a) for p in proposals for call in p.changes.get("actions", []) for a in call[1:]}
        used |= {str(v) for p in proposals for v in (p.changes.get("mapping") or {}).values()}
        problem = getattr(getattr(context, "run", None), "problem", None)
        initial = list(getattr(problem, "state", None) or getattr(problem, "init", None) or ())  # with type facts
        missing = {e.name for e in vector.missing}
        template = sorted({f[0] for f in initial if len(f) == 2 and str(f[1]) in missing})
        current = set(state())
        effects = getattr(context, "effects", None) or _applied_effects(context, current)
        add: list[tuple[str, ...]] = []
        delete: list[tuple[str, ...]] = []
        planned = {e.name: e for e in vector.missing}
        for entity in vector.unknown:
            if entity.name not in used:
                continue
            if entity.name in planned and planned[entity.name].shape == entity.shape:
                continue  # only its colour differs: it keeps its role and the facts its methods chose (grid-maps
                # compare form; anchoring the colour would fail the guards of the steps still to run)
            delete += [f for f in current if len(f) == 3 and f[0] in ("shape", "colour") and f[1] == entity.name]
            add += [(name, entity.name) for name in template]
            add += [("shape", entity.name, str(entity.shape)), ("colour", entity.name, str(entity.colour))]
            added, deleted = effects
            delete += [tuple(f) for f in added if entity.name in f[1:] and tuple(f) in current]
            add += [tuple(f) for f in deleted if entity.name in f[1:]]
        delete = [f for f in delete if f not in add]
        if add or delete:
            apply(add=add, delete=delete)

    # -- the hook -------------------------------------------------------------------------------------------------

    @hookimpl
    def bt_meta_propose_repairs(self, failure: Any, context: Any) -> list[RepairProposal] | None:
        if failure.kind not in _KINDS and failure.kind not in _STEP_KINDS:
            return None
        rebinds = rebind_proposals(failure, context, failed_step_only=failure.kind in _STEP_KINDS) \
            if self.spares else []
        vector = mismatch_vector(failure, context)
        if vector is None:
            return rebinds or None
        if failure.kind in _STEP_KINDS and not _names_missing(failure, vector):
            # a motion or grasp failure of a step whose entities are as the plan assumes -- but for a part the
            # plan names through the grounding, which the step's arguments do not show (rebinds)
            return rebinds or None
        plan = failure.evidence.get("plan") or []
        vector = _without_placed(vector, plan)
        spares = spare_proposals(vector, failure, context, colours=self.colours) if self.spares else []
        renamed = {k for p in spares for k in (p.changes.get("mapping") or {})}
        # a symbol the plan's arguments name and a renaming spare covers is renamed (its methods' conditions are
        # checked); rebinding is for the parts the plan names only through the grounding
        proposals = [p for p in rebinds if not set(p.changes["symbols"]) & renamed] + spares
        memory = memory_for(context, self.memory) if vector.unknown else None
        if memory is not None:
            retrieval = self.retrieve(vector, plan, memory, root_task(context))
            proposals += self.proposals(retrieval, plan)
        if self.geometry:
            proposals = self._same_cells(proposals, plan, context)
            known = [p.changes.get("actions") for p in proposals if p.action == SPLICE]
            tiled = (tiling_proposals(vector, failure, context, self.colours)
                     or retiling_proposals(vector, failure, context, self.colours))
            proposals += [p for p in tiled if p.changes["actions"] not in known]
        proposals = _mending_first(proposals, failure, vector, context)
        if proposals and self.anchor:
            self.anchor_entities(vector, failure, context, proposals)
        return proposals or None


_plugin: ObjectSubstitution | None = None


def configure(**settings: Any) -> ObjectSubstitution | None:
    """Replace the module-level plugin's settings (keyword arguments of :class:`ObjectSubstitution`); with no
    settings, back to the defaults (the matcher from ``BT_META_SUBSTITUTION_MATCHER``, read on first use)."""
    global _plugin
    _plugin = ObjectSubstitution(**settings) if settings else None
    return _plugin


@hookimpl
def bt_meta_propose_repairs(failure: Any, context: Any) -> list[RepairProposal] | None:
    global _plugin
    if _plugin is None:
        _plugin = ObjectSubstitution()
    return _plugin.bt_meta_propose_repairs(failure, context)
