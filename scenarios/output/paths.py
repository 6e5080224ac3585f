"""Where outputs go: only `--out` chooses a folder; a scenario's `name` is a label, never a path.

Without --out a command writes to results/<slug>, the slug made from the name with only letters, digits, '.',
'_' and '-' (no separators, no leading dot), so a scenario file cannot point a write anywhere else.
"""
from __future__ import annotations

import re
from pathlib import Path

RESULTS = Path("results")
SLUG_MAX = 64


def slug(label: str) -> str:
    """A safe one-component folder name for `label`: 'geneva-lc1' stays, '../../x' -> 'x', '/tmp/a b' -> 'tmp-a-b'."""
    text = re.sub(r"[^A-Za-z0-9._-]+", "-", str(label))
    text = re.sub(r"\.{2,}", ".", text).strip(".-_")[:SLUG_MAX].strip(".-_")
    return text or "scenario"


def default_folder(label: str, prefix: str = "") -> Path:
    """results/<prefix><slug(label)>: the folder a command writes to when --out is not given."""
    return RESULTS / f"{prefix}{slug(label)}"
