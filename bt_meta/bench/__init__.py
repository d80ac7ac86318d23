"""Benchmarks behind ``bt-meta bench NAME``, one module each.

Every benchmark measures its baseline in the same run and prints a ratio against it; a module defines
``register(subparsers)`` and is discovered by :mod:`bt_meta.commands.bench`.
"""
