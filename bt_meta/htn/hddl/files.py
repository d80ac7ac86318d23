"""HDDL files to task files: reading, converting and loading, and finding an IPC problem's domain file.

Offers:

* :func:`import_hddl` -- domain path + problem paths -> :class:`~.convert.Converted` (YAML text, names map)
* :func:`load_hddl` -- the same, loaded as a :class:`~bt_meta.htn.model.TaskFile`
* :func:`find_domain_file` -- ``<problem>-domain.hddl`` or ``domain.hddl`` beside a problem file
* :func:`load_task_input` -- what ``plan``/``validate``/``compile``/``verify`` accept: a YAML task file, an HDDL
  domain (with ``--problem`` naming an HDDL problem file) or an HDDL problem file (its domain found beside it)
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from bt_meta.htn.hddl.convert import Converted, convert
from bt_meta.htn.hddl.parser import file_kind, parse_domain, parse_problem, read_text
from bt_meta.htn.hddl.sexpr import HddlError
from bt_meta.htn.model import TaskFile


def import_hddl(domain_path: str | Path, problem_paths: Sequence[str | Path] = ()) -> Converted:
    """Parse and convert an HDDL domain and problems; every mistake is a located :class:`HddlError`."""
    domain_text = read_text(domain_path)
    if file_kind(domain_text, str(domain_path)) != "domain":
        raise HddlError("expected an HDDL domain (define (domain NAME) ...), found a problem", str(domain_path), 1, 1)
    domain = parse_domain(domain_text, str(domain_path))
    problems = []
    for problem_path in problem_paths:
        text = read_text(problem_path)
        if file_kind(text, str(problem_path)) != "problem":
            raise HddlError("expected an HDDL problem (define (problem NAME) ...), found a domain",
                            str(problem_path), 1, 1)
        problems.append(parse_problem(text, str(problem_path)))
    return convert(domain, problems)


def load_hddl(domain_path: str | Path, problem_paths: Sequence[str | Path] = ()) -> TaskFile:
    """An HDDL domain and problems as a loaded task file (problems keyed by their HDDL names)."""
    from bt_meta.htn.loader import load_task_text

    converted = import_hddl(domain_path, problem_paths)
    taskfile = load_task_text(converted.text, f"{domain_path} (imported)", base_dir=Path(domain_path).parent)
    taskfile.path = str(domain_path)
    return taskfile


def find_domain_file(problem_path: str | Path) -> Path:
    """The domain of an IPC problem file: ``<stem>-domain.hddl``, ``domain-<stem>.hddl`` or ``domain.hddl``."""
    path = Path(problem_path)
    for candidate in (path.with_name(f"{path.stem}-domain.hddl"), path.with_name(f"domain-{path.stem}.hddl"),
                      path.with_name("domain.hddl")):
        if candidate.is_file():
            return candidate
    raise HddlError(f"no domain file found for this problem (looked for {path.stem}-domain.hddl and domain.hddl "
                    "beside it); give the domain file first", str(problem_path))


def is_hddl(path: str | Path) -> bool:
    return str(path).lower().endswith((".hddl", ".pddl"))  # IPC 2023 names some HDDL problems .pddl


def load_task_input(file: str | Path, problem: str | None) -> tuple[TaskFile, str | None]:
    """A YAML task file, or HDDL: ``domain.hddl --problem p.hddl`` or just ``p.hddl`` (domain found beside it).

    Returns the task file and the problem name to plan (``None``: the caller picks the only one or complains).
    """
    from bt_meta.htn.loader import load_task_file

    if not is_hddl(file):
        if problem is not None and is_hddl(problem):
            raise HddlError("an HDDL problem needs an HDDL domain: give the domain's .hddl file first", str(file))
        return load_task_file(file), problem
    text = read_text(file)
    if file_kind(text, str(file)) == "problem":
        if problem is not None and not is_hddl(problem):
            loaded = load_hddl(find_domain_file(file), [file])
            return loaded, problem
        domain_path = find_domain_file(file)
        loaded = load_hddl(domain_path, [file])
        return loaded, next(iter(loaded.problems), None)
    if problem is None:
        return load_hddl(file), None
    if not is_hddl(problem):
        raise HddlError(f"--problem {problem!r}: with an HDDL domain, --problem names an HDDL problem file",
                        str(file))
    loaded = load_hddl(file, [problem])
    return loaded, next(iter(loaded.problems), None)
