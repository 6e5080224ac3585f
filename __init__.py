"""mechsim: intermittent-motion mechanisms (Geneva drive, roller-chain dwell, rolling-pair 4-bar) as hybrid
DAEs on SUNDIALS IDA and diffrax, with the temperature at their sliding contacts.

The repository root is this package: setuptools maps ``mechsim`` to it and its folders ``mechanisms/``,
``dynamics/``, ``thermal/``, ``scenarios/`` and ``benchmarks/`` to ``mechsim.mechanisms`` and so on
(``pyproject.toml``, ``[tool.setuptools.package-dir]``).
"""
from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("mechsim")
except _metadata.PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"
