"""Exact discrete solutions: laminates with interfaces and space-filling cubes with contacts."""

import math

import numpy as np
import pytest

from itr_fv import Materials, Microstructure, homogenize

# layer sequence along the stacking axis: (phase, particle id, voxels)
LAYERS = [("matrix", 0, 3), ("A", 1, 2), ("A", 2, 4), ("B", 3, 3), ("matrix", 0, 2), ("B", 4, 5)]
K = {"matrix": 0.18, "A": 30.0, "B": 200.0}
H = 0.1e-6


def laminate(axis: int, transverse: int = 3) -> Microstructure:
    names = ("matrix", "A", "B")
    mid_1d = np.concatenate([[names.index(p)] * n for p, _, n in LAYERS]).astype(np.int32)
    pid_1d = np.concatenate([[q] * n for _, q, n in LAYERS]).astype(np.int32)
    shape = [transverse] * 3
    shape[axis] = mid_1d.size
    view = [1, 1, 1]
    view[axis] = mid_1d.size
    mid = np.broadcast_to(mid_1d.reshape(view), shape).copy()
    pid = np.broadcast_to(pid_1d.reshape(view), shape).copy()
    return Microstructure.from_labels(mid, pid, H, names)


def exact_normal(scale: float) -> tuple[float, float]:
    """Series formula L / (sum l_i / k_i + sum of interface resistances)."""
    R = resistances(scale)
    seq = LAYERS + [LAYERS[0]]
    series = sum(n * H / K[p] for p, _, n in LAYERS)
    for (p1, q1, _), (p2, q2, _) in zip(seq[:-1], seq[1:]):
        if q1 != q2:
            series += R[tuple(sorted((p1, p2)))]
    L = sum(n for *_, n in LAYERS) * H
    return L / series, sum(n * K[p] for p, _, n in LAYERS) / sum(n for *_, n in LAYERS)


def resistances(scale: float) -> dict:
    return {("A", "matrix"): 1.0 * scale, ("A", "A"): 3.0 * scale,
            ("A", "B"): 2.0 * scale, ("B", "matrix"): 0.5 * scale}


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("scale", [0.0, 1e-8, 1e-6, 1e-4])
def test_laminate_with_interfaces(axis, scale):
    """Series and parallel rules to 1e-10, up to R 200x the whole stack's bulk resistance."""
    mat = Materials(K, resistances(scale), matrix="matrix", contact="area")
    res = homogenize(laminate(axis), mat, solver="fv", tol=1e-12)
    normal, parallel = exact_normal(scale)
    assert res.k_eff[axis, axis] == pytest.approx(normal, rel=1e-10)
    assert res.k_eff_energy[axis, axis] == pytest.approx(normal, rel=1e-10)
    for d in {0, 1, 2} - {axis}:
        assert res.k_eff[d, d] == pytest.approx(parallel, rel=1e-10)
        assert abs(res.k_eff[d, axis]) <= 1e-10 * parallel
    assert res.converged and res.floating.count == 0


@pytest.mark.parametrize("scale", [1e-3, 1e-1])
def test_laminate_with_very_large_interface_resistance(scale):
    """k_normal / k_parallel down to 1e-8: the energy estimate keeps 1e-10, the flux average
    loses the digits that round-off takes from the residual (about tol ||b|| / k_normal)."""
    mat = Materials(K, resistances(scale), matrix="matrix", contact="area")
    res = homogenize(laminate(2), mat, solver="fv", tol=1e-12)
    normal, parallel = exact_normal(scale)
    assert normal / parallel < 1e-5
    assert res.k_eff_energy[2, 2] == pytest.approx(normal, rel=1e-10)
    assert res.k_eff[2, 2] == pytest.approx(normal, rel=1e-6)
    assert res.k_eff[0, 0] == pytest.approx(parallel, rel=1e-10)


def test_laminate_insulating_interface_cuts_layers_off():
    R = {("A", "matrix"): math.inf, ("A", "A"): 1e-7, ("A", "B"): math.inf, ("B", "matrix"): 1e-7}
    res = homogenize(laminate(2), Materials(K, R, matrix="matrix", contact="area"), solver="fv",
                     tol=1e-12)
    _, parallel = exact_normal(0.0)
    assert abs(res.k_eff[2, 2]) <= 1e-10 * parallel
    assert res.k_eff[0, 0] == pytest.approx(parallel, rel=1e-10)
    # the A layers (particles 1, 2) and B + matrix + B (wrapping) are separated by two R = inf faces
    assert res.floating.count == 1
    assert res.floating.volume_fraction == pytest.approx(6 / 19)


@pytest.mark.parametrize("cube", [2, 3, 5])
@pytest.mark.parametrize("R", [0.0, 1e-8, 2e-7, 5e-5])
def test_space_filling_cubes_with_contact_resistance(cube, R):
    n = 4 * cube
    h = 0.25e-6
    idx = np.arange(n) // cube
    pid = idx[:, None, None] * 16 + idx[None, :, None] * 4 + idx[None, None, :] + 1
    pid = pid.astype(np.int32)
    ms = Microstructure.from_labels(np.ones_like(pid), pid, h, ("silicone", "Al2O3"))
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "Al2O3"): R}, matrix="silicone",
                    contact="area")
    res = homogenize(ms, mat, solver="fv", tol=1e-12)
    expected = 1.0 / (1.0 / 30.0 + R / (cube * h))
    np.testing.assert_allclose(np.diag(res.k_eff), expected, rtol=1e-10)
    off = res.k_eff - np.diag(np.diag(res.k_eff))
    assert np.abs(off).max() <= 1e-10 * expected
