"""Subcommands of the ``bt-meta`` CLI, one module each, discovered by :mod:`bt_meta.cli`.

A module here defines ``register(subparsers)``; it adds its parser with ``subparsers.add_parser`` and sets
``func``. Modules whose name starts with an underscore are helpers, not commands.
"""
