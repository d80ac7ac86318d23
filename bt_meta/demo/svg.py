"""The tree pictures now live in :mod:`bt_meta.runs.svg` (shared with the campaigns and ``bt-meta run``); these
names stay importable from here."""

from __future__ import annotations

from bt_meta.runs.svg import STATUS_COLOURS, TreeNode, tree_from_behaviour, tree_svg

__all__ = ["STATUS_COLOURS", "TreeNode", "tree_from_behaviour", "tree_svg"]
