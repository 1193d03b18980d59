"""Build glue that pyproject.toml cannot express: ``configs/`` (kept at the top of the
repository) is shipped inside the package as ``vhgen.configs``."""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["vhgen*"]), "vhgen.configs"],
    package_dir={"vhgen.configs": "configs"},
)
