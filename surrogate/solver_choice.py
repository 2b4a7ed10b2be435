"""The one place where a solver is chosen: campaign files, the reduced basis, identification
and the command line name a solver here, and get a backend of :mod:`itr_fv.solvers.backends`.

A choice is ``"fft"`` (the numba FFT-PCG backend ``itr_fft``), ``"mg"`` (the same backend
with the particle-deflated multigrid preconditioner, for high contrast and resistive
interfaces), ``"gpu"`` (the array-API backend on a CUDA device), ``"fv"`` (the pyamg
reference ``itr_fv``), ``"auto"`` (the cheaper one for the grid), or the name of any
registered backend (``itr_fv.solvers.backends.available_backends()``, e.g. ``"scipy_fft"``).
A choice that runs on a GPU asks the campaign engine's Dask workers for the resource
``GPU`` (:func:`worker_resources`; start such workers with ``--resources GPU=1``).

Measured (validation/results/crossval.md, bench_solvers.md; shared 2-core machine):
itr_fft was faster than itr_fv at every size tried -- 24^3 (0.1-0.3 s vs 0.6-20 s),
64^3 (1-7 s vs 21-32 s for the sphere arrays, 3 s vs FV for the dense 60 % RVE) and
128^3 -- because pyamg's set-up alone costs more than the whole FFT solve. There is no
crossover in the measured range, so ``CROSSOVER_VOXELS = 0``: ``"auto"`` is always
itr_fft. itr_fv stays the reference (and the fallback a caller can force).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import itr_fft  # noqa: F401 - registers the FFT backends
from itr_fv.solvers.backends import Backend, available_backends, backend_for
from itr_fv.solvers.driver import homogenize

__all__ = ["choose_solver", "check_solver", "solver_backend", "homogenize_auto",
           "worker_resources", "CROSSOVER_VOXELS", "SOLVER_CHOICES"]

#: Grids with fewer voxels than this are solved by itr_fv (measured: none, see above).
CROSSOVER_VOXELS = 0
#: Short names accepted besides the registered backend names: (backend, its options).
SOLVER_CHOICES = {"fft": ("itr_fft", {}), "fv": ("itr_fv", {}),
                  "mg": ("itr_fft", {"preconditioner": "multigrid"}),
                  "gpu": ("array_api", {"device": "cuda"})}


def choose_solver(shape: int | Sequence[int]) -> str:
    """``"itr_fv"`` or ``"itr_fft"``, whichever the benchmark found cheaper for this grid."""
    n = int(np.prod(shape)) if not isinstance(shape, (int, np.integer)) else int(shape) ** 3
    return "itr_fv" if n < CROSSOVER_VOXELS else "itr_fft"


def check_solver(choice: str, name: str = "solver") -> str:
    """``choice`` if it names a solver (``fft``, ``fv``, ``auto`` or a backend), else a
    ValueError naming the argument ``name`` and the choices."""
    if isinstance(choice, str) and (choice in SOLVER_CHOICES or choice == "auto"
                                    or choice in available_backends()):
        return choice  # (the short names first: no scan of the installed backends)
    names = ", ".join(repr(c) for c in (*SOLVER_CHOICES, "auto", *available_backends()))
    raise ValueError(f"{name}: expected one of {names}, got {choice!r}")


def solver_backend(choice: str, shape: int | Sequence[int], *,
                   threads: int | None = None) -> Backend:
    """The backend object for a solver choice on a grid.

    Parameters
    ----------
    choice : str
        ``"fft"``, ``"fv"``, ``"auto"`` or a registered backend name.
    shape : int or (n1, n2, n3)
        The grid (``"auto"`` picks by its size).
    threads : int, optional
        Threads of the numba FFT backend (None: its default for the grid).
    """
    choice = check_solver(choice)
    if choice == "auto":
        name, options = choose_solver(shape), {}
    else:
        name, options = SOLVER_CHOICES.get(choice, (choice, {}))
    if name == "itr_fft" and threads is not None:
        options = {**options, "workers": threads}
    return backend_for(name, **options)


def worker_resources(choice: str) -> dict[str, int] | None:
    """Dask worker resources a solve of this choice needs: ``{"GPU": 1}`` for a choice that
    runs on a GPU (``"gpu"``), else None (any worker)."""
    choice = check_solver(choice)
    name, options = SOLVER_CHOICES.get(choice, (choice, {}))
    return {"GPU": 1} if options.get("device") == "cuda" else None


def homogenize_auto(ms, mat, **kwargs):
    """:func:`itr_fv.solvers.driver.homogenize` on the backend :func:`choose_solver` picks for the
    grid of ``ms`` (a Microstructure or a DiscreteProblem)."""
    return homogenize(ms, mat, backend=solver_backend("auto", ms.shape), **kwargs)
