"""Tick-by-tick test harness and pytest fixtures for bt-meta trees (registered as the ``pytest11`` plugin)."""
