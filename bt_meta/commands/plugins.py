"""``bt-meta plugins``: which plugins are loaded, from where, and which hooks each implements.

Offers:

* :func:`register` -- adds ``plugins [--plugins DIR] [--project FILE] [--no-entry-points] [--json]``
"""

from __future__ import annotations

import argparse

from bt_meta.commands._common import print_json
from bt_meta.commands._plugin_args import add_plugin_arguments, plugin_host_from_args
from bt_meta.plugins import HOOK_NAMES, project_plugins_dir


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("plugins", help="list loaded plugins and the hooks each implements")
    add_plugin_arguments(parser)
    parser.add_argument("--project", metavar="FILE",
                        help="a task file or tree XML whose project plugins/ folder should be loaded too")
    parser.add_argument("--json", action="store_true", help="print the list as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    host = plugin_host_from_args(args, args.project)
    plugins = host.describe()
    project_dir = project_plugins_dir(args.project)
    if args.json:
        print_json({
            "plugins": plugins,
            "hooks": {hook: [impl.plugin_name for impl in host.implementations(hook)] for hook in HOOK_NAMES},
            "project_plugins_dir": None if project_dir is None else str(project_dir),
        })
        return 0
    print(f"{len(plugins)} plugins loaded" + (f" (project folder {project_dir})" if project_dir else ""))
    for plugin in plugins:
        print(f"  {plugin['name']}  [{plugin['source']}]")
        for hook in plugin["hooks"]:
            print(f"      {hook}")
    unimplemented = [hook for hook in HOOK_NAMES if not host.implements(hook)]
    if unimplemented:
        print("hooks nobody implements: " + ", ".join(unimplemented))
    return 0
