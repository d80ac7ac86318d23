"""bt-meta: behaviour trees with meta-reasoning for incremental repairs in robot manipulation tasks.

Task files (YAML HTN domains) are planned, compiled into py_trees behaviour trees with a Monitor around every
primitive, and ticked on a simulated Baxter; failures are classified and repaired from an episodic memory.
"""

from bt_meta.errors import BtMetaError, UserInputError

__version__ = "0.1.0"

__all__ = ["BtMetaError", "UserInputError", "__version__"]
