"""The layering: what decides a run's outcome and a variant's label shares no code with what is judged, and the
campaigns build on the shared run layer (bt_meta/runs/), never on the demo.

Every module's imports (top level and inside functions) are read from its source with :mod:`ast`, so a lazy import
counts as much as a top-level one.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import bt_meta

ROOT = Path(bt_meta.__file__).parent

#: package (folder under bt_meta/, or a module) -> imports it must not make
RULES = {
    "judge": ("bt_meta.demo", "bt_meta.campaign", "bt_meta.meta", "bt_meta_plugins", "bt_meta.configurations"),
    "campaign": ("bt_meta.demo",),
    "campaign/labeller.py": ("bt_meta.meta", "bt_meta_plugins", "bt_meta.configurations", "bt_meta.demo"),
    "campaign/families.py": ("bt_meta.meta", "bt_meta_plugins", "bt_meta.demo"),
    "campaign/generator.py": ("bt_meta.meta", "bt_meta_plugins", "bt_meta.demo"),
    "campaign/spec.py": ("bt_meta.meta", "bt_meta_plugins", "bt_meta.demo"),
    "demo": ("bt_meta.campaign",),
    "runs": ("bt_meta.demo", "bt_meta.campaign", "bt_meta.commands", "bt_meta.experiments"),
}


def imported(path: Path) -> set[str]:
    """Every module name ``path`` imports (absolute; relative imports resolved against its package)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = ".".join(("bt_meta", *path.relative_to(ROOT).parent.parts))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            names.add(base)
            names |= {f"{base}.{alias.name}" for alias in node.names}
    return names


def _files(target: str) -> list[Path]:
    path = ROOT / target
    return sorted(path.rglob("*.py")) if path.is_dir() else [path]


def _forbidden(names: set[str], prefixes: tuple[str, ...]) -> list[str]:
    return sorted(n for n in names if any(n == p or n.startswith(p + ".") for p in prefixes))


@pytest.mark.parametrize("target", sorted(RULES))
def test_layering(target):
    files = _files(target)
    assert files, f"{target} has no module"
    bad = {str(f.relative_to(ROOT)): _forbidden(imported(f), RULES[target]) for f in files}
    assert not {k: v for k, v in bad.items() if v}


def test_the_walk_sees_lazy_and_relative_imports(tmp_path):
    """The rule test can fail: an import inside a function is found."""
    module = ROOT / "judge" / "checks.py"
    assert "bt_meta.world.simulation.objects" in imported(module)  # imported inside a function there
    assert _forbidden({"bt_meta.demo.runner", "bt_meta.world"}, RULES["judge"]) == ["bt_meta.demo.runner"]
