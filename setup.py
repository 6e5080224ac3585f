"""Package discovery for setuptools (the rest of the configuration is in pyproject.toml).

The repository root is the package `mechsim` (`package-dir = {mechsim = "."}`), so setuptools' own discovery,
which names packages relative to the folder it searches, would install `mechanisms`, `dynamics`, ... at the top
level. Here every folder below the root with an `__init__.py` is found and named `mechsim.<folder>`: a new
`mechanisms/<name>/` ships without an edit here. The documentation folders (data only, no `__init__.py`) ship
as `mechsim.docs...` with the package data pyproject.toml lists.
"""
from setuptools import find_namespace_packages, find_packages, setup

#: folders that are never part of the package
EXCLUDE = ("tests", "tests.*", "build", "build.*", "dist", "dist.*", "docs", "docs.*")

PACKAGES = (["mechsim"] + [f"mechsim.{name}" for name in find_packages(where=".", exclude=EXCLUDE)]
            + [f"mechsim.{name}" for name in find_namespace_packages(where=".", include=("docs", "docs.*"),
                                                                       exclude=("*__pycache__",))])

if __name__ == "__main__":
    setup(packages=PACKAGES)
