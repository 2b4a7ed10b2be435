"""The FFT preconditioner's FFT pair (itr_fft.fft_pair): FFTW's (the extra
itr-composites[fft]) gives SciPy's transforms to round-off, hence the same iterations and
tensor; asking for it without pyFFTW is a ValueError naming the argument."""

from __future__ import annotations

import numpy as np
import pytest
from refusals import refuses

import itr_fft.numba_backend as nb
from itr_fft.fft_pair import _PLANS, PLANS_KEPT, fft_pair
from itr_fv import homogenize, resolve_solver
from validation.gallery import build

pytest.importorskip("pyfftw")


@pytest.mark.parametrize("dtype, tol", [(np.float32, 1e-6), (np.float64, 1e-14)])
def test_fftw_pair_is_scipys_transform_pair_on_odd_and_even_grids(dtype, tol):
    for shape in ((24, 20, 18), (15, 16, 17)):
        r = np.random.default_rng(1).standard_normal(shape).astype(dtype)
        a, b = fft_pair("scipy", shape, dtype, 1), fft_pair("fftw", shape, dtype, 2)
        ha, hb = a.forward(r), b.forward(r)
        assert np.max(np.abs(ha - hb)) <= tol * np.max(np.abs(ha))
        ha *= 0.5
        hb *= 0.5
        za, zb = a.inverse(ha), b.inverse(hb)
        assert np.max(np.abs(zb - 0.5 * r)) <= 10 * tol * np.max(np.abs(r))
        assert np.max(np.abs(za - zb)) <= 10 * tol * np.max(np.abs(za))
        b.inverse(b.forward(3 * r))       # the next application leaves zb as it was
        assert np.max(np.abs(zb - 0.5 * r)) <= 10 * tol * np.max(np.abs(r))
    assert len(_PLANS) <= PLANS_KEPT


def test_a_solve_with_fftw_takes_scipys_iterations_and_tensor():
    ms, mat = build("al2o3_60", 24, contact="gap")
    res = {fft: homogenize(ms, mat, solver=resolve_solver("fft", preconditioner="fft", fft=fft),
                           tol=1e-10, store_fields=False) for fft in ("scipy", "fftw")}
    assert res["fftw"].iterations == res["scipy"].iterations
    assert res["fftw"].info["fft"] == "fftw"
    k = res["scipy"].k_eff
    assert np.max(np.abs(res["fftw"].k_eff - k)) <= 1e-9 * np.max(np.abs(k))


def test_fftw_without_pyfftw_is_refused_in_one_line(monkeypatch):
    monkeypatch.setattr(nb, "fftw_available", lambda: False)
    with pytest.raises(ValueError, match=r"fft: 'fftw' needs pyFFTW \(pip install"):
        nb.NumbaFFTBackend(fft="fftw")
    with refuses(ValueError, "fft"):
        nb.NumbaFFTBackend(fft="mkl")
