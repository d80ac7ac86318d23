"""The paper's experiments, reproduced in simulation, one module each (``bt-meta experiment NAME``).

A module defines ``register(subparsers)``; :mod:`bt_meta.commands.experiment` discovers it, like benchmarks.
"""
