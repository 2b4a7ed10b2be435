"""Shared builders for the test suite (small microstructures with known answers)."""

import numpy as np
import pytest

from itr_fv import Microstructure


def sc_sphere(n: int, f: float, box_m: float = 1.0) -> Microstructure:
    """One sphere of volume fraction f centred in a periodic cube: a simple-cubic array."""
    a = (3.0 * f / (4.0 * np.pi)) ** (1.0 / 3.0) * box_m
    return Microstructure.from_spheres(np.full((1, 3), 0.5 * box_m), np.array([a]), "filler",
                                       box_m=box_m, shape=n, matrix="matrix")


def random_spheres(n: int, fraction: float, seed: int, box_m: float = 1.0,
                   r_range: tuple[float, float] = (0.06, 0.14)) -> Microstructure:
    """Non-overlapping polydisperse spheres by random sequential addition (low fractions)."""
    rng = np.random.default_rng(seed)
    centres, radii = [], []
    volume = 0.0
    while volume < fraction * box_m**3:
        r = rng.uniform(*r_range) * box_m
        for _ in range(2000):
            c = rng.uniform(0, box_m, 3)
            if centres:
                dx = c - np.array(centres)
                dx -= box_m * np.round(dx / box_m)
                clear = np.all(np.sqrt((dx * dx).sum(axis=1)) > r + np.array(radii) + 0.01 * box_m)
            else:
                clear = True
            if clear:
                centres.append(c)
                radii.append(r)
                volume += 4.0 / 3.0 * np.pi * r**3
                break
        else:
            raise RuntimeError("random_spheres: could not place a sphere")
    mats = ["A" if i % 2 else "B" for i in range(len(radii))]
    return Microstructure.from_spheres(np.array(centres), np.array(radii), mats, box_m=box_m,
                                       shape=n, matrix="matrix")


@pytest.fixture
def tmp_out(tmp_path):
    return tmp_path


def fast_few(values, *fast):
    """Parameter values of a sweep in two tiers: those named in `fast` run in the default
    (fast) tier, every other one is marked `slow` (run by .ci/run after the fast tier). A
    value may be a tuple of several arguments; it is named by its first."""
    def tier(v):
        key = v[0] if isinstance(v, tuple) else v
        if key in fast:
            return v
        return pytest.param(*(v if isinstance(v, tuple) else (v,)), marks=pytest.mark.slow)
    unknown = set(fast) - {v[0] if isinstance(v, tuple) else v for v in values}
    if unknown:
        raise ValueError(f"fast: {sorted(unknown)} not among the values")
    return [tier(v) for v in values]
