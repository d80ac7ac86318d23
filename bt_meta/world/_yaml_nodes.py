"""Reading a composed YAML node tree so that every error names its ``path:line:column``.

Offers:

* :class:`YamlNodeReader` -- the node helpers (mapping, required key, scalar, string, number, list) shared by the
  robot, catalogue and scene file readers; each subclass adds the numbers and checks of its own format
* :func:`shipped_yaml_path` -- a shipped name (``baxter``) or a ``.yaml``/``.yml`` path, as an existing file
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from bt_meta.errors import ConfigError
from bt_meta.safe_yaml import construct_yaml
from bt_meta.user_files import check_path_text

__all__ = ["YamlNodeReader", "shipped_yaml_path"]


def shipped_yaml_path(name: str | Path, folder: Path, unknown: Callable[[str], str], missing: str) -> Path:
    """``name`` without a YAML suffix is ``folder/NAME.yaml``; ``unknown(shipped names)`` words the error when
    that does not exist, ``missing`` when a given path does not."""
    path = Path(check_path_text(name, "YAML file", ConfigError))
    if path.suffix not in (".yaml", ".yml"):
        path = folder / f"{name}.yaml"
        if not path.is_file():
            raise ConfigError(unknown(", ".join(sorted(p.stem for p in folder.glob("*.yaml"))) or "none"))
    if not path.is_file():
        raise ConfigError(missing, path)
    return path


class YamlNodeReader:
    """Node helpers that raise :class:`~bt_meta.errors.ConfigError` located at the offending node."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, message: str, node: yaml.Node | None) -> ConfigError:
        if node is None:
            return ConfigError(message, self.path)
        return ConfigError(message, self.path, node.start_mark.line + 1, node.start_mark.column + 1)

    def mapping(
        self, node: yaml.Node, what: str, allowed: set[str] | None = None
    ) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        """Key name -> (key node, value node); duplicate keys, and keys outside ``allowed`` when given, are errors."""
        if not isinstance(node, yaml.MappingNode):
            raise self.error(f"{what} must be a mapping", node)
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key, value in node.value:
            if not isinstance(key, yaml.ScalarNode):
                raise self.error(f"{what}: keys must be plain names", key)
            if key.value in out:
                raise self.error(f"{what}: duplicate key {key.value!r}", key)
            if allowed is not None and key.value not in allowed:
                raise self.error(f"{what}: {_unknown_key(key.value, allowed)}", key)
            out[key.value] = (key, value)
        return out

    def check_keys(self, entries: dict[str, tuple[yaml.Node, yaml.Node]], allowed: set[str], what: str) -> None:
        for key, (key_node, _) in entries.items():
            if key not in allowed:
                raise self.error(f"{what}: {_unknown_key(key, allowed)}", key_node)

    def require(self, entries: dict[str, tuple[yaml.Node, yaml.Node]], key: str, parent: yaml.Node, what: str):
        if key not in entries:
            raise self.error(f"{what}: missing key {key!r}", parent)
        return entries[key][1]

    def scalar(self, node: yaml.Node, what: str) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            raise self.error(f"{what} must be a single value", node)
        return construct_yaml(node, str(self.path), ConfigError)

    def string(self, node: yaml.Node, what: str) -> str:
        value = self.scalar(node, what)
        if not isinstance(value, str) or not value:
            raise self.error(f"{what} must be a non-empty string", node)
        return value

    def number(self, node: yaml.Node, what: str, *, positive: bool = False) -> float:
        value = self.scalar(node, what)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(f"{what} must be a number", node)
        if positive and value <= 0:
            raise self.error(f"{what} must be positive", node)
        return float(value)

    def sequence(self, node: yaml.Node, what: str) -> list[yaml.Node]:
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(f"{what} must be a list", node)
        return list(node.value)


def _unknown_key(key: str, allowed: set[str]) -> str:
    return f"unknown key {key!r}; expected one of {', '.join(sorted(allowed))}"
