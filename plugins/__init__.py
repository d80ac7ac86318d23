"""The strategies bt-meta ships, each a plain pluggy plugin module (installed as ``bt_meta_plugins``).

They register exactly like a user's plugin would: through the ``bt_meta`` entry-point group. A user's own plugin
file dropped into a project's ``plugins/`` folder, or a folder passed with ``--plugins DIR``, loads the same way.
"""
