"""Map the top-level data and plugin folders into the wheel.

The project keeps ``plugins/``, ``robots/`` and ``trees/`` at the top of the repository where integrators look
for them; a wheel needs them under import names of our own so that a non-editable install works from any
directory: ``plugins/`` becomes ``bt_meta_plugins`` and the data folders become ``bt_meta.data.robots`` and
``bt_meta.data.trees``.
"""

from setuptools import find_packages, setup

packages = find_packages(include=["bt_meta", "bt_meta.*"])
package_dir = {"bt_meta": "bt_meta"}
for folder, name in (("plugins", "bt_meta_plugins"),):
    package_dir[name] = folder
    packages.append(name)
    packages.extend(f"{name}.{sub}" for sub in find_packages(where=folder))
for folder in ("robots", "trees"):
    name = f"bt_meta.data.{folder}"
    package_dir[name] = folder
    packages.append(name)

setup(
    packages=packages,
    package_dir=package_dir,
    package_data={
        "bt_meta.data.robots": ["*.yaml"],
        "bt_meta.data.trees": ["*.yaml", "*.xml", "*.md", "scenes/*.yaml", "poses/*.yaml", "poses/*.md",
                             "families/*.yaml", "objects/*.yaml", "objects/meshes/*.obj"],
        "bt_meta_plugins": ["*.yaml"],
        "bt_meta.bench": ["problems/*.yaml"],
        "bt_meta.campaign": ["specs/*.yaml"],
        "bt_meta.ros2": ["interfaces/*/CMakeLists.txt", "interfaces/*/package.xml", "interfaces/*/LICENSE",
                         "interfaces/*/msg/*.msg", "interfaces/*/action/*.action"],
    },
    include_package_data=False,
)
