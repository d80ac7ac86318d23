"""The C library's standard streams, which Python's ``sys.stdout`` does not buffer or see.

pybullet prints with ``printf``: its text sits in the C library's buffer until flushed, so code that points file
descriptor 1 elsewhere and back flushes it first (:func:`flush_c_stdio`).
"""

from __future__ import annotations

__all__ = ["flush_c_stdio"]


def flush_c_stdio() -> None:
    """Flush the C library's output buffers (pybullet's ``printf`` text) to wherever their descriptors point now."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library to flush
        pass
