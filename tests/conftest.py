"""Suite-wide policy: the long campaigns run only when asked for.

Tests marked ``fuzz`` (10,000-input loader and XML campaigns, the full BehaviorTree.CPP differential sweeps) or
``guard`` (the outcome guard's whole population) are skipped unless ``-m`` names their marker, so the default run
(CI's and the README's) stays within its time budget. docs/benchmarks.md gives their counts and commands.
"""

from __future__ import annotations

import pytest

ON_REQUEST = ("fuzz", "guard")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    asked = config.option.markexpr or ""
    for item in items:
        for marker in ON_REQUEST:
            if item.get_closest_marker(marker) is not None and marker not in asked:
                item.add_marker(pytest.mark.skip(reason=f"a long campaign: run it with -m {marker}"))
