"""What watching, recording and reporting one run needs, below the demo, the campaigns and ``bt-meta run``.

Modules: :mod:`~bt_meta.runs.capture` (progress lines, the trace-event capture, the tree-snapshotting executor, top
views), :mod:`~bt_meta.runs.demonstrations` (recording a task's nominal runs into the episodic memory),
:mod:`~bt_meta.runs.report` (a run's HTML page and the markup the demo's report shares), :mod:`~bt_meta.runs.svg`
(behaviour trees as inline SVG). It imports neither :mod:`bt_meta.demo` nor :mod:`bt_meta.campaign`.
"""
