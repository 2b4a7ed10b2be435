"""Append-only CSV row stores of the validation studies: a killed run loses nothing, and a
re-run skips the rows already there."""

from __future__ import annotations

import csv
from pathlib import Path


def load_rows(path: Path) -> list[dict]:
    """All rows of the store (empty if it does not exist yet)."""
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def append_row(path: Path, fields: list[str], row: dict) -> None:
    """Append one row (writing the header first if the file is new), flushed at once."""
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        if new:
            w.writeheader()
        w.writerow(row)
        fh.flush()
