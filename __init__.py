"""mechsim: intermittent-motion mechanisms (Geneva drive, roller-chain dwell, rolling-pair 4-bar) as hybrid
DAEs on SUNDIALS IDA and diffrax, with the temperature at their sliding contacts.

The Python API (docs/api.md), loaded on first use so that `import mechsim` stays cheap:

    import mechsim
    r = mechsim.run(mechsim.load("geneva-motor", set=["duration=2 s"]))
    r.timeseries, r.events, r.summary, r.plot(), r.save("results/motor")

`load`, `open`, `run`, `sweep`, `compare`, `compare_backends`, `sensitivity`, `size`, `output_size`, `builtins`,
`Result`, `Scenario` and `ScenarioError` come from `mechsim.scenarios.api`. The repository root is this package:
setuptools maps ``mechsim`` to it and its folders ``mechanisms/``, ``dynamics/``, ``thermal/``, ``scenarios/`` and
``benchmarks/`` to ``mechsim.mechanisms`` and so on (``pyproject.toml``, ``[tool.setuptools.package-dir]``).
"""
#: the API's names, imported from mechsim.scenarios.api on first access (PEP 562)
_API = ("load", "open", "run", "sweep", "compare", "compare_backends", "sensitivity", "size", "output_size",
        "builtins", "Result", "Scenario", "ScenarioError")
__all__ = [*_API, "__version__"]


def __getattr__(name: str):
    if name == "__version__":            # from the package metadata, read on first use (~20-50 ms)
        from importlib import metadata
        try:
            value = metadata.version("mechsim")
        except metadata.PackageNotFoundError:  # a source tree that was never installed
            value = "0+unknown"
        globals()[name] = value
        return value
    if name in _API:
        from mechsim.scenarios import api
        value = getattr(api, name)
        globals()[name] = value          # later look-ups skip this function
        return value
    raise AttributeError(f"module 'mechsim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
