"""``bt-meta demo``: the paper's scenario end to end on the simulator, with an HTML report.

Offers (each in its own module):

* :func:`run_demo`, :func:`run_variant`, :func:`record_demonstration`, :class:`DemoResult` -- record the
  demonstrations, run the variants with monitors and repairs, run them again with the learned refinements
  (``runner``)
* :func:`write_report` -- ``report.html``: trees, camera images, grid-maps, R_p / R_n plots, repair log,
  refinements (``report``)
* :class:`Demonstration`, :class:`VariantRun`, :func:`demonstrations`, :func:`variants` -- the scenario as data
  (``scenario``)
* :data:`CONFIGURATIONS`, :func:`plugin_host` -- which plugins a run has: dual, symbolic, low-level, retry
  (:mod:`bt_meta.configurations`)
* :class:`Progress`, :class:`RunCapture`, :class:`CapturingExecutor` -- what the demo watches, and
  :func:`tree_svg` -- the behaviour tree as an inline SVG picture: from :mod:`bt_meta.runs` (shared with the
  campaigns and ``bt-meta run --report``; ``bt_meta.demo.capture`` and ``bt_meta.demo.svg`` still name them)
"""

from __future__ import annotations

from bt_meta.configurations import CONFIGURATIONS, plugin_host
from bt_meta.demo.report import write_report
from bt_meta.demo.runner import DemoResult, record_demonstration, run_demo, run_variant
from bt_meta.demo.scenario import Demonstration, VariantRun, demonstrations, variants
from bt_meta.runs.capture import CapturingExecutor, Progress, RunCapture
from bt_meta.runs.svg import tree_svg

__all__ = [
    "CONFIGURATIONS",
    "CapturingExecutor",
    "DemoResult",
    "Demonstration",
    "Progress",
    "RunCapture",
    "VariantRun",
    "demonstrations",
    "plugin_host",
    "record_demonstration",
    "run_demo",
    "run_variant",
    "tree_svg",
    "variants",
    "write_report",
]
