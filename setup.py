"""What pyproject.toml cannot say: ship the top-level data folders inside the wheel.

``models/``, ``scenarios/`` and ``benchmarks/`` stay at the top of the source tree (users and docs point at them).
A ``package_dir`` mapping puts them in the wheel as ``rover_sim/_data/<folder>/``, where ``rover_sim.resources``
finds them through ``importlib.resources``; a checkout or an editable install reads the source folders directly.
Everything else about the build is in pyproject.toml.
"""

from setuptools import find_namespace_packages, find_packages, setup

DATA_FOLDERS = {  # source folder -> files shipped from it and from every folder below it
    "models": ["*"],  # MJCF, README and any mesh or texture assets beside them
    "scenarios": ["*.toml", "*.md"],
    "benchmarks": ["*.json", "*.md", "*.toml"],
}

packages = find_packages(include=["rover_sim", "rover_sim.*", "nav", "nav.*", "terrains", "terrains.*"])
package_dir: dict[str, str] = {}
package_data = {"rover_sim": ["py.typed"], "nav": ["py.typed"]}
for folder, globs in DATA_FOLDERS.items():
    root = f"rover_sim._data.{folder}"
    below = [f"{root}.{sub}" for sub in find_namespace_packages(where=folder, exclude=["*__pycache__*"])]
    package_dir[root] = folder  # the folders below follow their parent
    for name in (root, *below):
        packages.append(name)
        package_data[name] = globs

setup(
    packages=packages,
    package_dir=package_dir,
    package_data=package_data,
    exclude_package_data={"": ["__pycache__/*", "*.py[co]", "*~", ".*"]},
)
