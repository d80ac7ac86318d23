"""One entry point for "give me a runnable tree" from a YAML task file or a BehaviorTree.CPP XML file.

Offers:

* :func:`load_runnable` -- a task file is planned and compiled (or compiled as a policy); a tree XML is loaded with
  the domain's node types and a Monitor around every primitive. Returns a
  :class:`~bt_meta.bt.compiler.CompiledTree`
* :func:`is_xml` -- whether a path names tree XML (by suffix, else by its first non-blank character)
* :func:`companion_task_file` -- the task file a tree XML uses when none is given: ``X.yaml`` (or ``X.yml``) next to
  ``X.xml``
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bt_meta.bt.compiler import DEFAULT_POLICY_DEPTH, CompiledTree, assign_steps, compile_task_file
from bt_meta.bt.domain_nodes import domain_registry
from bt_meta.bt.monitor import monitor_action
from bt_meta.errors import UserInputError
from bt_meta.user_files import MAX_USER_FILE_BYTES, check_path_text, read_user_bytes


def is_xml(path: str | Path) -> bool:
    path = Path(path)
    if path.suffix.lower() == ".xml":
        return True
    if path.suffix.lower() in (".yaml", ".yml"):
        return False
    try:
        head = read_user_bytes(path, max_bytes=MAX_USER_FILE_BYTES)[:200].decode("utf-8", errors="replace").lstrip()
    except UserInputError:
        return False  # the loader that runs next reports why the file cannot be read
    return head.startswith("<")


def companion_task_file(xml_path: str | Path) -> Path | None:
    xml_path = Path(xml_path)
    for suffix in (".yaml", ".yml"):
        candidate = xml_path.with_suffix(suffix)
        if candidate.is_file():
            return candidate
    return None


def load_runnable(
    file: str | Path,
    *,
    problem: str | None = None,
    task_file: str | Path | None = None,
    policy: bool = False,
    plugins: Any = None,
    tree_id: str | None = None,
    max_depth: int = DEFAULT_POLICY_DEPTH,
    xml_sources: Any = None,
    stubs: Any = None,
) -> CompiledTree:
    """A runnable tree from ``file`` (task file or tree XML), its domain and problem when known.

    For tree XML: ``tree_id`` picks the tree, ``xml_sources`` (a :class:`~bt_meta.bt.xml.document.TreeSources`)
    adds other files' trees, ``stubs`` (a :class:`~bt_meta.bt.nodes.stubs.StubPolicy`) stubs unimplemented nodes."""
    from bt_meta.htn import load_task_file

    path = Path(check_path_text(file, "file", UserInputError))
    if not path.is_file():
        raise UserInputError("no such file", path)
    if not is_xml(path):
        return compile_task_file(path, problem, policy=policy, plugins=plugins, max_depth=max_depth)
    from bt_meta.bt.xml import load_tree_file

    source = Path(task_file) if task_file is not None else companion_task_file(path)
    loaded = load_task_file(source) if source is not None else None
    domain = loaded.domain if loaded is not None else None
    chosen = loaded.problem(problem) if loaded is not None and loaded.problems else None
    registry = domain_registry(domain, plugins)
    root = load_tree_file(path, registry, tree_id=tree_id, wrap_action=monitor_action, sources=xml_sources,
                          stubs=stubs)
    steps = assign_steps(root)
    return CompiledTree(root, domain, chosen, loaded, None, registry, "xml", {"primitives": steps})
