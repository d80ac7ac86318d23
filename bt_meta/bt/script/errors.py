"""Errors of the script language.

Offers:

* :class:`ScriptSyntaxError` -- a script that does not parse; ``offset`` is the 0-based character where it fails
* :class:`ScriptRuntimeError` -- a script that fails while it runs (BT.CPP throws the same at tick time)
"""

from __future__ import annotations

from bt_meta.errors import BtMetaError


class ScriptSyntaxError(BtMetaError):
    def __init__(self, message: str, offset: int) -> None:
        super().__init__(message)
        self.message = message
        self.offset = offset


class ScriptRuntimeError(BtMetaError):
    pass
