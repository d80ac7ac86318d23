"""Campaign families as data: a YAML file naming the task, problem, scene, demonstrations, perturbations and checks.

A family file (docs/campaigns.md has the format and a full example) says which task file and problem a campaign
runs, the scene its variants perturb, which problems are recorded as demonstrations, the perturbations (inline or
a ``spec:`` file) and the ``success:`` mapping of :mod:`bt_meta.judge.success`; ``grasped`` and
``absolute_fixtures`` may be given, else they are derived from the nominal plan and the grounding. The four
shipped families are such files (``trees/families/*.yaml``); ``bt-meta campaign generate letters_A`` is a shortcut
for the shipped file. A user's task needs no family file at all (:func:`task_family`).

Offers:

* :class:`CampaignFamily` -- a loaded family; :meth:`CampaignFamily.success_check`, :meth:`CampaignFamily.spec`
* :func:`family` -- a shipped family by name; :func:`shipped_families` -- their names
* :func:`load_family` -- a family file (every mistake a :class:`FamilyError` at ``path:line:column``)
* :func:`task_family` -- the family of a task file and problem as it stands (an optional family file adds to it)
* :func:`family_of_manifest` -- the family a campaign directory was generated from
* :func:`family_spec` -- a family's perturbation spec read against a scene
* :func:`needed_objects` / :func:`derived_grasped` / :func:`derived_fixtures` -- what the plan uses
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError, UserInputError

__all__ = ["CampaignFamily", "FamilyError", "derived_fixtures", "derived_grasped", "family", "family_of_manifest",
           "family_spec", "load_family", "needed_objects", "shipped_families", "task_family"]

_KEYS = {"family", "description", "task", "problem", "scene", "demonstrations", "grasped", "absolute_fixtures",
         "success", "perturbations", "spec"}
GRASP_HEIGHT = 0.02
"""A pose ``above: OBJECT`` at most this high over it is where the gripper takes the object."""
FIXTURE_RADIUS = 0.03
"""An object within this distance (x, y) of an absolute pose the plan moves to is where that pose was taught."""


class FamilyError(ConfigError):
    """A family file that is wrong, located at ``path:line:column``."""


@dataclass(frozen=True)
class CampaignFamily:
    name: str
    task: Path
    """The task file (absolute)."""
    problem: str
    scene: str | None = None
    """A scene name or file the variants perturb; ``None``: the problem's scene in its grounding."""
    demonstrations: tuple[tuple[str, int], ...] = ()
    """(problem, repeats) recorded before the episodes, from seeds ``seed .. seed + repeats - 1``."""
    grasped: tuple[str, ...] | None = None
    """Objects the robot picks up; ``None``: derived (:func:`derived_grasped`)."""
    absolute_fixtures: tuple[str, ...] | None = None
    """Objects the nominal plan's absolute poses were taught over; ``None``: derived (:func:`derived_fixtures`)."""
    file: Path | None = None
    """The family file (its ``success:``, ``perturbations:`` / ``spec:``); ``None``: the task as it stands."""
    shipped: bool = False

    @property
    def task_file(self) -> str:
        return str(self.task)

    def task_path(self) -> Path:
        return self.task

    def demonstration_list(self) -> tuple[tuple[str, int], ...]:
        return self.demonstrations or ((self.problem, 1),)

    def _node(self, key: str) -> yaml.Node | None:
        if self.file is None:
            return None
        root = _compose(self.file)
        return next((value for k, value in root.value if str(k.value) == key), None)

    def success_check(self, task_file: Any, problem: Any, grounding: Any, scene_objects: Sequence[str] = ()) -> Any:
        """The :class:`~bt_meta.judge.success.SuccessCheck` of this family's problem."""
        from bt_meta.judge.success import success_check, success_check_file

        if self.file is None:
            return success_check(task_file, problem, grounding, scene_objects=scene_objects)
        return success_check_file(self.file, task_file, problem, grounding, scene_objects=scene_objects)

    def spec(self, objects: Mapping[str, tuple[str, str | None]], roles: Mapping[str, Sequence[str]]) -> Any:
        """The family's perturbations (inline, or its ``spec:`` file), or the shipped default spec."""
        from bt_meta.campaign.spec import load_spec, read_perturbations

        inline = self._node("perturbations")
        if inline is not None and self.file is not None:
            return read_perturbations(self.file, inline, objects, family=self.name, roles=roles)
        named = self._node("spec")
        if named is not None and self.file is not None:
            return load_spec((self.file.parent / str(named.value)), objects, roles=roles)
        return load_spec(Path(__file__).parent / "specs" / "default.yaml", objects, roles=roles)


def shipped_dir() -> Path:
    from bt_meta.resources import trees_dir

    return trees_dir() / "families"


def shipped_families() -> list[str]:
    return sorted(p.stem for p in shipped_dir().glob("*.yaml"))


def family(name: str) -> CampaignFamily:
    """A shipped family by name (``trees/families/<name>.yaml``)."""
    path = shipped_dir() / f"{name}.yaml"
    if not path.is_file():
        raise UserInputError(f"unknown family {name!r}; shipped: {', '.join(shipped_families())} (or give a family "
                             "file, or --task FILE --problem P)", "<command line>")
    return dataclasses.replace(load_family(path), shipped=True)


def _compose(path: Path) -> yaml.MappingNode:
    try:
        root = yaml.compose(path.read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
    except OSError as error:
        raise FamilyError(f"cannot read the family file: {error.strerror or error}", path) from None
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        raise FamilyError(f"not valid YAML: {error.problem or error}", path, mark.line + 1 if mark else None,
                          mark.column + 1 if mark else None) from None
    if not isinstance(root, yaml.MappingNode):
        raise FamilyError("a family file is a mapping (task:, problem:, ...)", path, 1, 1)
    return root


def _error(path: Path, message: str, node: yaml.Node) -> FamilyError:
    return FamilyError(message, path, node.start_mark.line + 1, node.start_mark.column + 1)


def load_family(path: str | Path, *, task: str | Path | None = None, problem: str | None = None,
                scene: str | None = None) -> CampaignFamily:
    """Read a family file; ``task`` / ``problem`` / ``scene`` (the command line's) override the file's. The task
    file is loaded and the problem, the demonstrations' problems, ``grasped``, ``absolute_fixtures`` and the
    ``success:`` mapping are checked against it (and the perturbations against the scene when generating)."""
    path = Path(path)
    if not path.is_file():
        raise FamilyError("family file not found", path)
    root = _compose(path)
    entries: dict[str, tuple[yaml.Node, yaml.Node]] = {}
    for key, value in root.value:
        name = str(key.value)
        if name in entries:
            raise _error(path, f"duplicate key {name!r}", key)
        if name not in _KEYS:
            raise _error(path, f"unknown key {name!r}; expected one of {', '.join(sorted(_KEYS))}", key)
        entries[name] = (key, value)

    def scalar(key: str) -> str | None:
        if key not in entries:
            return None
        node = entries[key][1]
        if not isinstance(node, yaml.ScalarNode) or not node.value:
            raise _error(path, f"{key}: a name or a file", node)
        return str(node.value)

    def names(key: str) -> tuple[str, ...] | None:
        if key not in entries:
            return None
        node = entries[key][1]
        if not isinstance(node, yaml.SequenceNode) or not all(isinstance(i, yaml.ScalarNode) for i in node.value):
            raise _error(path, f"{key}: a list of object names", node)
        return tuple(str(i.value) for i in node.value)

    task_path = Path(task).resolve() if task is not None else None
    if task_path is None:
        text = scalar("task")
        if text is None:
            raise FamilyError("a family file needs `task:` (the task file, relative to this file)", path, 1, 1)
        task_path = (path.parent / text).resolve()
        if not task_path.is_file():
            raise _error(path, f"task file {text!r} not found (read beside this file: {task_path})",
                         entries["task"][1])
    problem = problem or scalar("problem")
    if problem is None:
        raise FamilyError("a family file needs `problem:`", path, 1, 1)
    scene_text = scene if scene is not None else scalar("scene")
    if scene is None and scene_text is not None and scene_text.endswith((".yaml", ".yml")):
        scene_text = str((path.parent / scene_text).resolve())
    demonstrations: list[tuple[str, int]] = []
    if "demonstrations" in entries:
        node = entries["demonstrations"][1]
        if not isinstance(node, yaml.SequenceNode) or not node.value:
            raise _error(path, "demonstrations: a non-empty list of {problem: P, repeats: N}", node)
        for item in node.value:
            if not isinstance(item, yaml.MappingNode):
                raise _error(path, "a demonstration is {problem: P, repeats: N}", item)
            fields = {str(k.value): v for k, v in item.value}
            for key, _ in item.value:
                if str(key.value) not in ("problem", "repeats"):
                    raise _error(path, f"a demonstration: unknown key {key.value!r}; expected problem, repeats", key)
            if "problem" not in fields:
                raise _error(path, "a demonstration needs `problem:`", item)
            repeats = yaml.safe_load(fields["repeats"].value) if "repeats" in fields else 1
            if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= 100:
                raise _error(path, "repeats: a whole number from 1 to 100", fields.get("repeats", item))
            demonstrations.append((str(fields["problem"].value), repeats))
    chosen = CampaignFamily(name=scalar("family") or path.stem, task=task_path, problem=problem,
                            scene=scene_text, demonstrations=tuple(demonstrations), grasped=names("grasped"),
                            absolute_fixtures=names("absolute_fixtures"), file=path.resolve())
    _check_against_task(chosen, path, entries)
    return chosen


def _check_against_task(chosen: CampaignFamily, path: Path, entries: dict[str, tuple[yaml.Node, yaml.Node]]) -> None:
    """The problem and the demonstrations' problems exist; ``success:`` names known predicates and objects."""
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import load_grounding

    task_file = load_task_file(chosen.task)
    if chosen.problem not in task_file.problems:
        node = entries["problem"][1] if "problem" in entries else None
        message = f"no problem {chosen.problem!r} in {chosen.task}; problems: {', '.join(task_file.problems)}"
        raise (_error(path, message, node) if node is not None else UserInputError(message, "<command line>"))
    if "demonstrations" in entries:
        for item in entries["demonstrations"][1].value:
            fields = {str(k.value): v for k, v in item.value}
            if str(fields["problem"].value) not in task_file.problems:
                raise _error(path, f"no problem {fields['problem'].value!r} in {chosen.task}; problems: "
                             f"{', '.join(task_file.problems)}", fields["problem"])
    grounding = load_grounding(task_file.domain.name, chosen.task)
    scene_names = _scene_object_names(chosen, grounding)
    for key in ("grasped", "absolute_fixtures"):
        if key in entries:
            for item in entries[key][1].value:
                if str(item.value) not in scene_names:
                    raise _error(path, f"{key}: unknown object {item.value!r}; the scene's: "
                                 f"{', '.join(scene_names)}", item)
    chosen.success_check(task_file, task_file.problem(chosen.problem), grounding, scene_names)


def _scene_object_names(chosen: CampaignFamily, grounding: Any) -> list[str]:
    try:
        return [o.name for o in scene_of(chosen, grounding).objects]
    except Exception:  # the scene is checked where it is built; here it only widens the names checks accept
        return []


def scene_of(chosen: CampaignFamily, grounding: Any) -> Any:
    """The family's scene: its own, else the problem's scene in the grounding."""
    from bt_meta.world.simulation.scenes import load_scene

    if chosen.scene is not None:
        return load_scene(chosen.scene)
    setup = grounding.problem(chosen.problem) if hasattr(grounding, "problem") else {}
    scene = setup.get("scene")
    if scene is None:
        raise UserInputError(f"the grounding names no scene for problem {chosen.problem!r}: give --scene",
                             getattr(grounding, "path", None))
    candidate = Path(str(scene))
    if candidate.suffix and not candidate.is_absolute() and getattr(grounding, "path", None):
        candidate = Path(grounding.path).parent / candidate
        return load_scene(str(candidate))
    return load_scene(str(scene))


def task_family(task: str | Path, problem: str, *, scene: str | None = None,
                family_file: str | Path | None = None) -> CampaignFamily:
    """The family of a user's task as it stands: its problem recorded once as the demonstration, its goal as the
    success check, the default perturbations; a ``family_file`` adds demonstrations, perturbations and checks."""
    task_path = Path(task)
    if not task_path.is_file():
        raise UserInputError("task file not found", task_path)
    if family_file is not None:
        return load_family(family_file, task=task_path, problem=problem, scene=scene)
    from bt_meta.htn import load_task_file
    from bt_meta.world.simulation.sim_world import load_grounding

    task_file = load_task_file(task_path)
    if problem not in task_file.problems:
        raise UserInputError(f"--problem {problem!r}: no such problem in {task_path}; problems: "
                             f"{', '.join(task_file.problems)}", "<command line>")
    chosen = CampaignFamily(name=task_path.stem, task=task_path.resolve(), problem=problem,
                            scene=str(Path(scene).resolve()) if scene and Path(scene).suffix else scene)
    grounding = load_grounding(task_file.domain.name, task_path)
    chosen.success_check(task_file, task_file.problem(problem), grounding, _scene_object_names(chosen, grounding))
    return chosen


def family_spec(chosen: CampaignFamily, scene: Any = None, roles: Mapping[str, Sequence[str]] | None = None) -> Any:
    """A family's perturbation spec read against ``scene`` (default its own): objects by name, type or role."""
    from bt_meta.world.simulation.scenes import load_scene

    if scene is None:
        scene = load_scene(chosen.scene) if chosen.scene is not None else None
    objects = {o.name: (o.type, o.model().role) for o in scene.objects}
    return chosen.spec(objects, roles or {})


def family_of_manifest(manifest: Mapping[str, Any]) -> CampaignFamily:
    """The family a campaign was generated from: a shipped one by name (this install's file), else its family file
    or task file as the manifest records them. Read once per process for the same files (an episode asks for it
    to label its seed and for each of its runs: ~50 ms a time; an edited file is read again)."""
    from bt_meta.model_cache import cached, signature_or_none

    key = ("family_of_manifest", *(str(manifest.get(k)) for k in ("shipped", "family", "family_file", "task_file",
                                                                      "problem", "family_scene")),
           *(signature_or_none(p) for p in (manifest.get("family_file"), manifest.get("task_file"),
                                            manifest.get("family_scene"),
                                            shipped_dir() / f"{manifest.get('family')}.yaml")))
    return cached(key, lambda: _family_of_manifest(manifest))


def _family_of_manifest(manifest: Mapping[str, Any]) -> CampaignFamily:
    shipped = manifest.get("shipped")
    if shipped is None:  # a bare {family: NAME} (bt-meta bench episode): the shipped family of that name
        shipped = not manifest.get("family_file") and str(manifest.get("family")) in shipped_families()
    if shipped:
        return family(str(manifest["family"]))
    scene = manifest.get("family_scene")
    if manifest.get("family_file"):
        return load_family(manifest["family_file"], task=manifest["task_file"], problem=manifest["problem"],
                           scene=scene)
    return task_family(manifest["task_file"], manifest["problem"], scene=scene)


def needed_objects(problem: Any, grounding: Any) -> list[str]:
    """The simulator objects a problem names: its non-pose objects through the grounding's ``objects:`` map, and
    the objects its features belong to."""
    objects = getattr(problem, "objects", None) or {}
    groups = objects.items() if isinstance(objects, Mapping) else [("object", objects)]
    out: list[str] = []
    for kind, group in groups:
        if kind == "pose":
            continue
        for symbol in group:
            if symbol in grounding.features:
                name = str(grounding.features[symbol]["object"])
            else:
                name = grounding.objects.get(symbol, symbol)
            if name not in out:
                out.append(name)
    return out


def _world_name(grounding: Any, symbol: str) -> str:
    return str(grounding.objects.get(symbol, symbol))


def derived_grasped(plan: Sequence[Any], grounding: Any, present: Sequence[str]) -> tuple[str, ...]:
    """The objects the nominal plan picks up: those a pose it moves to takes from above (``above: OBJECT`` at most
    :data:`GRASP_HEIGHT` over it), and the first argument of a primitive whose skill moves a part (place, insert,
    a closing grasp)."""
    out: list[str] = []
    for action in plan:
        skill = grounding.skills.get(action.name, {}) if hasattr(grounding, "skills") else {}
        kind, mode = skill.get("skill"), skill.get("mode")
        candidates = []
        if kind in ("place", "insert") or (kind == "grasp" and mode == "close"):
            candidates.append(str(action.args[0]) if action.args else "")
        for arg in action.args:
            spec = grounding.poses.get(str(arg)) or {}
            if "above" in spec and float(spec.get("height", 0.0)) <= GRASP_HEIGHT:
                candidates.append(str(spec["above"]))
        for symbol in candidates:
            name = _world_name(grounding, symbol)
            if name in present and name not in out:
                out.append(name)
    return tuple(out)


def derived_fixtures(plan: Sequence[Any], grounding: Any, positions: Mapping[str, Sequence[float]],
                     offset: Sequence[float] = (0.0, 0.0, 0.0)) -> tuple[str, ...]:
    """The objects within :data:`FIXTURE_RADIUS` (x, y) of an absolute pose (``pose:``) the nominal plan moves to:
    the poses were taught over them, so one that moved needs a repair. ``positions``: object -> (x, y) in the
    robot base frame; ``offset``: the robot's scene offset (absolute poses are in the scene frame)."""
    out: list[str] = []
    for action in plan:
        for arg in action.args:
            spec = grounding.poses.get(str(arg)) or {}
            if "pose" not in spec:
                continue
            x, y = float(spec["pose"][0]) + float(offset[0]), float(spec["pose"][1]) + float(offset[1])
            for name, (px, py, *_) in positions.items():
                if math.hypot(px - x, py - y) <= FIXTURE_RADIUS and name not in out:
                    out.append(name)
    return tuple(out)
