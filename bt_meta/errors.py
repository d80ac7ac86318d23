"""The exception hierarchy of bt-meta.

Everything bt-meta raises on purpose derives from :class:`BtMetaError`. Errors in what a user wrote (task files,
tree XML, robot descriptions, command-line arguments) derive from :class:`UserInputError`, carry the file and
position, and are printed by the CLI as one ``path:line:column: message`` line with exit status 2.

Offers:

* :class:`BtMetaError` -- root of the hierarchy
* :class:`UserInputError` -- a mistake in user input, located by path, line and column
* :class:`TaskFileError` -- a YAML task file that does not load or validate
* :class:`TreeXMLError` -- a BehaviorTree.CPP XML file that does not load
* :class:`ConfigError` -- a robot description or other configuration file that is wrong
* :class:`UnknownWorldError` -- no plugin makes a world of the name asked for (``--world moon``)
* :class:`PlanningError` -- the planner could not produce a plan (no plan, budget exhausted)
* :class:`PluginError` -- a plugin could not be loaded or misbehaved
* :class:`KinematicsError` -- kinematics used wrongly (a frame, arm or joint the robot does not have)
"""

from __future__ import annotations

from pathlib import Path


class BtMetaError(Exception):
    """Root of every error bt-meta raises on purpose."""


class UserInputError(BtMetaError):
    """A mistake in something a user wrote, located as precisely as we can.

    ``line`` and ``column`` are 1-based; either may be ``None`` when the position is unknown.
    """

    def __init__(
        self,
        message: str,
        path: str | Path | None = None,
        line: int | None = None,
        column: int | None = None,
    ) -> None:
        self.message = message
        self.path = str(path) if path is not None else None
        self.line = line
        self.column = column
        super().__init__(self.location_message())

    @property
    def location(self) -> str:
        """``path:line:column`` with the parts that are known."""
        parts = [self.path or "<input>"]
        if self.line is not None:
            parts.append(str(self.line))
            if self.column is not None:
                parts.append(str(self.column))
        return ":".join(parts)

    def location_message(self) -> str:
        return f"{self.location}: {self.message}"


class TaskFileError(UserInputError):
    """A YAML task file that does not load or validate."""


class TreeXMLError(UserInputError):
    """A BehaviorTree.CPP v4 XML document that does not load."""


class ConfigError(UserInputError):
    """A robot description, scene or other configuration file that is wrong."""


class UnknownWorldError(UserInputError):
    """No plugin makes a world of the name asked for: a bad argument, so exit status 2."""


class PlanningError(BtMetaError):
    """The planner could not produce a plan."""


class PluginError(BtMetaError):
    """A plugin could not be loaded, or broke the contract of a hook."""


class KinematicsError(BtMetaError):
    """Kinematics used wrongly: a frame, arm or joint the robot does not have, a malformed configuration."""
