"""Shipped data: robot descriptions (``robots``) and the paper's task files and trees (``trees``).

In the repository these live in the top-level ``robots/`` and ``trees/`` folders; ``setup.py`` maps them here.
"""
