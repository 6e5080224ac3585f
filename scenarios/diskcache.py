"""A small on-disk cache of pure results (JSON), in the user's cache folder, so that a fresh process need not
recompute them: `mechsim run` converts the same quantity strings ("75 mm", "7 N*m") on every start, and pint
itself (with what it imports) costs more than a closed-form run (docs/benchmarks.md, "Cold start").

Folder: $MECHSIM_CACHE_DIR, else platformdirs' user cache folder for "mechsim" (~/.cache/mechsim on Linux).
Each cache is one JSON file named by what it holds and the versions its values depend on; it is read once per
process and written atomically (a temporary file renamed over it), merged with what another process wrote
meanwhile. A cache that cannot be read or written is simply not used: correctness never depends on it.
"""
from __future__ import annotations

import atexit
import json
from pathlib import Path

from mechsim.dynamics.user_cache import cache_dir, write_atomically

#: entries kept per cache file (the oldest are dropped beyond this)
MAX_ENTRIES = 20000




class JsonCache:
    """A str -> JSON value map persisted in `<cache_dir>/<name>.json`; `get` / `put`, flushed at exit."""

    def __init__(self, name: str):
        self.name = name
        self._data: dict | None = None
        self._new: dict = {}

    @property
    def path(self) -> Path:
        return cache_dir() / f"{self.name}.json"

    def _read(self) -> dict:
        try:
            data = json.loads(self.path.read_text())
            return data if isinstance(data, dict) else {}
        except (OSError, ValueError):
            return {}

    def get(self, key: str):
        if self._data is None:
            self._data = self._read()
        return self._data.get(key)

    def put(self, key: str, value) -> None:
        if self._data is None:
            self._data = self._read()
        if not self._new:
            atexit.register(self.flush)
        self._data[key] = value
        self._new[key] = value

    def discard_unsaved(self) -> None:
        """Forget the entries not yet written (a refused command writes nothing, its cache entries included)."""
        for key in self._new:
            self._data.pop(key, None)
        self._new = {}

    def flush(self) -> None:
        """Merge the new entries into the file (atomically); any OS error leaves the cache as it was."""
        if not self._new:
            return
        try:
            merged = {**self._read(), **self._new}
            if len(merged) > MAX_ENTRIES:
                merged = dict(list(merged.items())[-MAX_ENTRIES:])
            if write_atomically(self.path, json.dumps(merged).encode(), prefix=f".{self.name}."):
                self._new = {}
        except OSError:
            pass
