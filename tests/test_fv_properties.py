"""Property-based checks of the discrete model: random periodic laminates against the
series / parallel rules (exact for the 7-point finite-volume scheme)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from itr_fv import Materials, Microstructure, homogenize

PHASES = ("matrix", "A", "B")
K = {"matrix": 0.18, "A": 30.0, "B": 200.0}

layer = st.tuples(st.sampled_from(PHASES), st.integers(min_value=1, max_value=4))
resistance = st.sampled_from([0.0, 1e-8, 2e-7, 5e-6])


@settings(max_examples=25, deadline=None)
@given(layers=st.lists(layer, min_size=2, max_size=7), axis=st.integers(0, 2),
       r_am=resistance, r_bm=resistance, r_ab=resistance, r_aa=resistance, r_bb=resistance)
def test_random_laminate_obeys_series_and_parallel_rules(layers, axis, r_am, r_bm, r_ab, r_aa,
                                                         r_bb):
    h = 0.2e-6
    R = {("A", "matrix"): r_am, ("B", "matrix"): r_bm, ("A", "B"): r_ab, ("A", "A"): r_aa,
         ("B", "B"): r_bb}
    # every filler layer is its own particle; consecutive matrix layers merge into matrix
    mids, pids, bounds = [], [], []
    for i, (phase, n) in enumerate(layers):
        mids += [PHASES.index(phase)] * n
        pids += [0 if phase == "matrix" else i + 1] * n
    mid = np.array(mids, dtype=np.int32)
    pid = np.array(pids, dtype=np.int32)
    shape = [2, 2, 2]
    shape[axis] = mid.size
    view = [1, 1, 1]
    view[axis] = mid.size
    ms = Microstructure.from_labels(np.broadcast_to(mid.reshape(view), shape).copy(),
                                    np.broadcast_to(pid.reshape(view), shape).copy(), h, PHASES)
    res = homogenize(ms, Materials(K, R, "matrix", contact="area"), solver="fv", tol=1e-12)
    # series rule: bulk resistance of every voxel plus R at every face between different ids
    series = sum(h / K[PHASES[m]] for m in mid)
    for j in range(mid.size):
        p, q = pid[j], pid[(j + 1) % mid.size]
        if p != q:
            a, b = sorted((PHASES[mid[j]], PHASES[mid[(j + 1) % mid.size]]))
            bounds.append(R[(a, b)])
    L = mid.size * h
    normal = L / (series + sum(bounds))
    parallel = float(np.mean([K[PHASES[m]] for m in mid]))
    assert abs(res.k_eff_energy[axis, axis] / normal - 1) < 1e-10
    assert abs(res.k_eff[axis, axis] / normal - 1) < 1e-8
    for d in {0, 1, 2} - {axis}:
        assert abs(res.k_eff[d, d] / parallel - 1) < 1e-10
