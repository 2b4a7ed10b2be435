"""The FFT pair of the FFT preconditioner: SciPy's (the default) or FFTW's (an optional extra).

One application of the preconditioner is a real forward FFT of the residual, a division by
the Laplacian's symbol on the half spectrum, and the inverse FFT; at 128^3 on 2 cores the
pair is about 11 ms of a 21 ms CG iteration in float32 (``validation/results/
bench_default_solve.md``). SciPy's pocketfft is always there; FFTW, through pyFFTW
(``pip install 'itr-composites[fft]'``; pyFFTW is BSD-licensed, the FFTW library its wheel
bundles is GPL-2.0-or-later), plans each grid once per process (``FFTW_MEASURE``) and
reuses aligned buffers.

Both pairs keep SciPy's conventions: ``forward`` is ``rfftn`` (unnormalised), ``inverse``
is ``irfftn`` (divided by the number of voxels); the inverse returns an array the caller
owns. The forward's half spectrum may be a buffer the pair reuses: it is valid until the
next ``forward`` and is meant to be divided in place, then handed to ``inverse``.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np
import scipy.fft

__all__ = ["FFTS", "FFTWPair", "ScipyPair", "fft_pair", "fftw_available"]

#: The FFT pairs by name.
FFTS = ("scipy", "fftw")
#: FFTW plans (with their buffers) kept per process, least recently used dropped first.
PLANS_KEPT = 2
_PLANS: OrderedDict[tuple, FFTWPair] = OrderedDict()


def fftw_available() -> bool:
    """Whether pyFFTW imports here (the extra ``itr-composites[fft]``)."""
    try:
        import pyfftw  # noqa: F401
    except Exception:  # noqa: BLE001 - not installed or a broken build: both mean "no"
        return False
    return True


class ScipyPair:
    """SciPy's real FFTs on ``workers`` threads."""

    name = "scipy"

    def __init__(self, shape: tuple[int, int, int], workers: int) -> None:
        self.shape = tuple(shape)
        self.workers = workers

    def forward(self, r: np.ndarray) -> np.ndarray:
        return scipy.fft.rfftn(r, workers=self.workers)

    def inverse(self, rhat: np.ndarray) -> np.ndarray:
        return scipy.fft.irfftn(rhat, s=self.shape, workers=self.workers, overwrite_x=True)


class FFTWPair:
    """FFTW's real FFTs on ``workers`` threads, planned once (``FFTW_MEASURE``) for one
    grid and precision, with aligned buffers reused by every application."""

    name = "fftw"

    def __init__(self, shape: tuple[int, int, int], dtype: Any, workers: int) -> None:
        import pyfftw

        self.shape = tuple(shape)
        self._in = pyfftw.empty_aligned(self.shape, dtype=np.dtype(dtype))
        self._fwd = pyfftw.builders.rfftn(self._in, threads=workers,
                                          planner_effort="FFTW_MEASURE", avoid_copy=True)
        self._inv = pyfftw.builders.irfftn(self._fwd.output_array, s=self.shape,
                                           threads=workers, planner_effort="FFTW_MEASURE",
                                           avoid_copy=True)

    def forward(self, r: np.ndarray) -> np.ndarray:
        self._in[...] = r
        return self._fwd()

    def inverse(self, rhat: np.ndarray) -> np.ndarray:
        target = self._inv.input_array       # the forward's output where FFTW allowed it
        if rhat is not target:
            target[...] = rhat
        return self._inv().copy()


def fft_pair(fft: str, shape: tuple[int, int, int], dtype: Any,
             workers: int) -> ScipyPair | FFTWPair:
    """The FFT pair ``fft`` (:data:`FFTS`) for real arrays of ``shape`` in ``dtype``
    (float32 or float64) on ``workers`` threads; FFTW's planned once per process and
    grid (at most :data:`PLANS_KEPT` kept)."""
    if fft == "scipy":
        return ScipyPair(shape, workers)
    if fft != "fftw":
        raise ValueError(f"fft: expected one of {FFTS}, got {fft!r}")
    key = (tuple(shape), np.dtype(dtype).str, int(workers))
    pair = _PLANS.get(key)
    if pair is None:
        pair = FFTWPair(shape, dtype, workers)
        _PLANS[key] = pair
        while len(_PLANS) > PLANS_KEPT:
            _PLANS.popitem(last=False)
    _PLANS.move_to_end(key)
    return pair
