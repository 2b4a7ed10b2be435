"""Argument checks shared across the package: bad input raises a ValueError naming it."""

from __future__ import annotations

import math

__all__ = ["finite_number"]


def finite_number(value: object, argument: str) -> float:
    """``float(value)``, or a ValueError naming ``argument`` if it is no finite number."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{argument}: not a number: {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{argument} must be finite, got {v!r}")
    return v
