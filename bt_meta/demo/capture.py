"""The demo's run watching now lives in :mod:`bt_meta.runs.capture` (shared with the campaigns and ``bt-meta run``);
these names stay importable from here."""

from __future__ import annotations

from bt_meta.runs.capture import CapturingExecutor, Progress, RunCapture, Segment, top_view_png

__all__ = ["CapturingExecutor", "Progress", "RunCapture", "Segment", "top_view_png"]
