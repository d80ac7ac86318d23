"""HDDL in and out: importing HDDL domains and problems (the IPC HTN tracks' language) as task files.

Offers:

* :func:`load_hddl` -- an HDDL domain file and problem files to a loaded :class:`~bt_meta.htn.model.TaskFile`
* :func:`import_hddl` -- the same to a :class:`~.convert.Converted` (YAML text + map of renamed names)
* :func:`find_domain_file` -- the domain file of an IPC problem file (``domain.hddl`` or ``<name>-domain.hddl``)
* :class:`HddlError` -- a located error in HDDL input (a :class:`~bt_meta.errors.TaskFileError`)
"""

from __future__ import annotations

from bt_meta.htn.hddl.files import find_domain_file, import_hddl, load_hddl
from bt_meta.htn.hddl.sexpr import HddlError

__all__ = ["HddlError", "find_domain_file", "import_hddl", "load_hddl"]
