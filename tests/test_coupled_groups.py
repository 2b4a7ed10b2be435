"""The groups the multigrid and the particle deflation follow (itr_fft.multigrid.
coupled_groups): matrix cells that conduct like a particle's bulk join that particle, the
rest stay with the matrix; only the preconditioner changes, so the tensor does not, and
touching particles at the stated 0 nm film converge in about half the iterations."""

from __future__ import annotations

import numpy as np
import pytest
from refusals import refuses

import itr_fft.numba_backend as nb
from itr_fft.multigrid import JOIN_PASSES, coupled_groups
from itr_fv import homogenize, resolve_solver
from validation.bench_gpu import aln_problem

FILLER, MATRIX, RESISTIVE = 100.0, 1.0, 0.5


def two_particles_and_a_bridge(bridge: int):
    """Particles 1 (x = 1..3) and 2 (x = 4 + bridge .. 6 + bridge) in a matrix of g = 1,
    ``bridge`` matrix cells between them on the line y = z = 4 with filler-grade faces;
    every other particle-matrix face resistive (0.5)."""
    n = 12
    ids = np.zeros((n, n, n), dtype=np.int32)
    ids[1:4, 2:7, 2:7] = 1
    ids[4 + bridge:7 + bridge, 2:7, 2:7] = 2
    g = np.full((3, n, n, n), MATRIX)
    for d in range(3):
        nbr = np.roll(ids, -1, axis=d)
        g[d][(ids > 0) & (nbr == ids)] = FILLER
        g[d][(ids > 0) != (nbr > 0)] = RESISTIVE
        g[d][(ids > 0) & (nbr > 0) & (nbr != ids)] = RESISTIVE
    for c in range(bridge + 1):  # faces x = 3 + c -> 4 + c on the line
        g[0, 3 + c, 4, 4] = FILLER
    return g, ids


@pytest.mark.parametrize("bridge", [1, 2, 3])
def test_a_bridge_of_filler_grade_matrix_cells_joins_a_particle_and_nothing_else_moves(bridge):
    g, ids = two_particles_and_a_bridge(bridge)
    before = ids.copy()
    out = coupled_groups(g, ids)
    np.testing.assert_array_equal(ids, before)  # the caller's ids untouched
    changed = np.argwhere(out != ids)
    assert sorted(map(tuple, changed)) == [(4 + c, 4, 4) for c in range(bridge)]
    assert set(out[4:4 + bridge, 4, 4]) <= {1, 2}
    if bridge > 1:  # the cell next to particle 1 takes particle 1 (its only strong face)
        assert out[4, 4, 4] == 1 and out[3 + bridge, 4, 4] == 2


def test_resistive_faces_and_a_plain_matrix_join_nothing():
    g, ids = two_particles_and_a_bridge(1)
    g[0, 3, 4, 4] = g[0, 4, 4, 4] = 0.4 * FILLER  # below theta = 0.5 of the filler's bulk
    np.testing.assert_array_equal(coupled_groups(g, ids), ids)
    assert coupled_groups(g, None) is None
    assert JOIN_PASSES >= 3


def test_theta_is_checked():
    g, ids = two_particles_and_a_bridge(1)
    with refuses(ValueError, "theta"):
        coupled_groups(g, ids, theta=0.0)


def test_touching_alN_at_zero_film_converges_in_about_half_the_iterations_with_the_same_k(
        monkeypatch):
    """AlN-60 (Table 1, R = 3e-8 m^2 K/W, gap model, 6 um at 0.125 um): 56-57 iterations
    per load case with the particle ids as groups, 28-29 with the coupled groups (measured
    2026-11-29); the tensor the same to round-off."""
    problem, mat, _ = aln_problem(48)
    res = {}
    multigrid = resolve_solver("fft", preconditioner="multigrid")
    for name, groups in (("ids", lambda g, ids: ids), ("coupled", coupled_groups)):
        monkeypatch.setattr(nb, "coupled_groups", groups)
        res[name] = homogenize(problem, mat, solver=multigrid, tol=1e-8, store_fields=False)
    assert max(res["coupled"].iterations) <= 0.6 * min(res["ids"].iterations)
    k = res["ids"].k_eff
    scale = np.trace(k) / 3
    assert np.max(np.abs(res["coupled"].k_eff - k)) <= 1e-7 * scale  # both to tol 1e-8
