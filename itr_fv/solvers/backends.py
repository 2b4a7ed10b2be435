"""The backend protocol and the registry of solver backends.

A backend solves the linear systems of one discrete problem (:mod:`itr_fv.discrete.problem`) for
the solve driver (:func:`itr_fv.solvers.driver.homogenize`), which does everything else (argument
checks, the system's face conductances, load vectors, the gauge, the result). A backend

- has a ``name`` (the ``solver`` of a result, the ``backend=`` argument of the driver),
- states its peak memory per voxel (:meth:`Backend.bytes_per_voxel`, used by the memory
  guard before any work),
- prepares one system (:meth:`Backend.prepare`: the AMG hierarchy, the FFT symbols and
  ``g_ref``), and the prepared system solves the load cases with
  ``solve_block(loads, starts, tol, maxiter, callback)`` (by default one at a time with
  ``solve(b, x0, tol, maxiter, callback)``; a backend that reads its conductances once for
  all of them overrides it), written over :mod:`itr_fv.solvers.krylov`.

A prepared system may keep its arrays on its own device (a GPU): it states where they live
with the namespace ``xp``, the face conductances ``g`` and the cluster projection
``clusters`` as it holds them, and ``to_host(array)``. The driver then builds the load
vectors there (:func:`itr_fv.discrete.operator.load_vector` on ``g``), gets the solution
there, removes the cluster means and computes the mean flux and the energy tensor there,
and brings back only the 3x3 tensors (and the fields when asked for). A host backend sets
none of these: ``g`` None means the system's own host conductances, and ``to_host`` is the
identity, so every backend runs the same driver lines.

Backends register themselves (:func:`register_backend`) when their module is imported;
installed packages also announce them under the entry-point group ``itr.backends``
(``name = "module:Class"``), so the driver finds a backend by name without importing
any of them itself. Adding a backend is one module and one registration.
"""

from __future__ import annotations

import importlib.metadata
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..discrete.connectivity import ClusterProjection
from ..discrete.problem import DiscreteSystem

__all__ = ["Backend", "PreparedSystem", "LoadCaseSolution", "register_backend",
           "backend_for", "available_backends", "ENTRY_POINT_GROUP"]

#: Entry-point group under which installed packages announce their backends.
ENTRY_POINT_GROUP = "itr.backends"

#: ``callback(iteration, relative_residual)`` of a backend's solve.
IterationCallback = Callable[[int, float], None]
#: ``callback(case, iteration, relative_residual)`` of a backend's block solve.
BlockCallback = Callable[[int, int, float], None]


@dataclass
class LoadCaseSolution:
    """What a prepared system returns for one load case.

    Attributes
    ----------
    x : array, shape (n1, n2, n3), float64
        theta, K (gauge not yet fixed: the driver removes cluster means), in the prepared
        system's namespace and on its device (a host NumPy array for host backends).
    iterations : int
        CG iterations.
    history : list of float
        Relative residual ||b - A x|| / ||b|| at the start and after every iteration
        (the last entry is the true residual).
    residual : float
        Final true relative residual.
    restarts : int
        CG restarts (recursive residual below ``tol`` while the true one was not, or a
        breakdown).
    replacements : int
        Reliable updates of mixed precision (the true residual replaced the recursive one).
    seconds : float or None
        Wall time of this load case's solve, s, where it was solved on its own; None for
        load cases solved together (the driver shares their time by iterations).
    """

    x: np.ndarray
    iterations: int
    history: list[float]
    residual: float
    restarts: int = 0
    replacements: int = 0
    seconds: float | None = None


class PreparedSystem(ABC):
    """One system prepared by a backend; solves its load cases one at a time.

    A backend whose arrays live on a device sets ``xp``, ``g`` and ``clusters`` and
    overrides :meth:`to_host`; a host (NumPy) backend needs none of them.
    """

    #: Facts about the preparation for the result's ``info`` (levels, g_ref, ...).
    info: dict[str, Any]

    #: Array namespace of the prepared system's arrays (NumPy for host backends).
    xp: Any = np

    #: Face conductances (3, n1, n2, n3), W/(m^2 K), as the prepared system holds them (on
    #: its device, in its precision); None: the system's host ``g`` (float64).
    g: Any = None

    #: Projection removing the cluster means, built next to ``g``
    #: (:class:`~itr_fv.discrete.connectivity.ClusterProjection`); None: the driver builds
    #: one from the system's labels.
    clusters: ClusterProjection | None = None

    def to_host(self, x: Any) -> np.ndarray:
        """A host NumPy array of ``x``, one of the prepared system's arrays (the only way
        the driver brings a field back; identity for host backends)."""
        return np.asarray(x)

    @abstractmethod
    def solve(self, b: Any, x0: np.ndarray | None, tol: float, maxiter: int,
              callback: IterationCallback | None = None) -> LoadCaseSolution:
        """Solve A x = b to ``||b - A x|| <= tol ||b||``.

        Parameters
        ----------
        b : array, shape (n1, n2, n3), float64
            Load vector, W/m^2 x m (sums to zero on every connected cluster), built by the
            driver on ``g`` and so in the prepared system's namespace and on its device.
        x0 : ndarray or None
            Start (theta of a neighbouring solve), K, host NumPy.
        tol : float
            Relative residual to reach.
        maxiter : int
            CG iterations at most.
        callback : callable, optional
            ``callback(iteration, relative_residual)`` after every iteration.
        """

    def solve_block(self, loads: Sequence[Any], starts: Sequence[np.ndarray | None],
                    tol: float, maxiter: int,
                    callback: BlockCallback | None = None) -> list[LoadCaseSolution]:
        """Solve several load cases of this system (the driver's one call).

        A backend that can solve them together (one pass over the conductances for all)
        overrides this; the default solves them one after the other with :meth:`solve`.

        Parameters
        ----------
        loads : sequence of arrays
            Load vectors, as ``b`` of :meth:`solve`.
        starts : sequence of ndarray or None
            One start per load (None: zero).
        tol, maxiter
            As :meth:`solve` (``maxiter`` per load case).
        callback : callable, optional
            ``callback(case, iteration, relative_residual)``, ``case`` the position in
            ``loads``.
        """
        out = []
        for c, (b, x0) in enumerate(zip(loads, starts)):
            step = None if callback is None else (lambda it, res, _c=c: callback(_c, it, res))
            t = time.perf_counter()
            sol = self.solve(b, x0, tol, maxiter, step)
            sol.seconds = time.perf_counter() - t
            out.append(sol)
        return out

    def close(self) -> None:
        """Give back what the preparation holds (threads, device memory); called by the
        driver after the post-processing, so ``g`` and the solutions stay usable until
        then."""


class Backend(ABC):
    """A way to solve the discrete system; options are fixed at construction."""

    #: Name under which the backend registers (the result's ``solver``).
    name: str = ""
    #: CG iterations per load case when the caller gives none.
    default_maxiter: int = 1000

    @abstractmethod
    def bytes_per_voxel(self) -> int:
        """Measured peak host memory of a solve per voxel, bytes (fields not kept)."""

    def array_namespace(self) -> tuple[Any, Any] | None:
        """``(xp, device)`` where the backend's arrays live, so the driver builds the face
        conductances there (:meth:`itr_fv.discrete.problem.DiscreteProblem.system`); None
        (the default): NumPy on the host."""
        return None

    def device_bytes_per_voxel(self) -> int:
        """Peak memory per voxel a solve holds on an accelerator, bytes (0: its arrays live
        on the host, all counted by :meth:`bytes_per_voxel`). The memory guard compares it
        with the device's free memory (:func:`itr_fv.solvers.resources.check_memory`)."""
        return 0

    def check(self, shape: tuple[int, int, int], tol: float) -> None:
        """Refuse options that cannot work on this grid at this tolerance (ValueError)."""

    @abstractmethod
    def prepare(self, system: DiscreteSystem, voxel_m: float) -> PreparedSystem:
        """Prepare ``system`` (face conductances, clusters) on a grid of voxel edge
        ``voxel_m`` (m) for any number of load cases."""

    def options(self) -> dict[str, Any]:
        """The backend's options, for reports and the campaign store's keys."""
        return {}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"


_REGISTRY: dict[str, type[Backend]] = {}


def register_backend(cls: type[Backend]) -> type[Backend]:
    """Register a backend class under its ``name`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, Backend)) or not cls.name:
        raise ValueError(f"backend: expected a Backend subclass with a name, got {cls!r}")
    known = _REGISTRY.get(cls.name)
    if known is not None and known is not cls and \
            (known.__module__, known.__qualname__) != (cls.__module__, cls.__qualname__):
        raise ValueError(f"backend: the name {cls.name!r} is taken by {known.__module__}."
                         f"{known.__qualname__}")
    _REGISTRY[cls.name] = cls
    return cls


_ENTRY_POINTS_LOADED = {"done": False}


def _load_entry_points() -> None:
    """Register the installed backends (once per process: the scan costs milliseconds)."""
    if _ENTRY_POINTS_LOADED["done"]:
        return
    _ENTRY_POINTS_LOADED["done"] = True
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in _REGISTRY:
            try:
                register_backend(ep.load())
            except ImportError:  # an optional backend whose library is missing
                continue


def available_backends() -> tuple[str, ...]:
    """Names of the backends that can be used here (registered or installed)."""
    _load_entry_points()
    return tuple(sorted(_REGISTRY))


def backend_for(backend: str | Backend, **options: Any) -> Backend:
    """The backend object for a name (with options) or a backend object itself.

    Parameters
    ----------
    backend : str or Backend
        A registered name (``available_backends()``) or a configured backend.
    **options
        Options of the named backend's constructor (none with an object).

    Raises
    ------
    ValueError
        Unknown name, options given with an object, or bad options.
    """
    if isinstance(backend, Backend):
        if options:
            raise ValueError(f"backend: options {sorted(options)} given with a configured "
                             f"backend object {backend!r}; configure it when creating it")
        return backend
    if not isinstance(backend, str):
        raise ValueError(f"backend: expected a name or a Backend, got {type(backend).__name__}")
    if backend not in _REGISTRY:
        _load_entry_points()
    if backend not in _REGISTRY:
        raise ValueError(f"backend: unknown {backend!r}; available: "
                         f"{', '.join(available_backends()) or 'none'}")
    try:
        return _REGISTRY[backend](**options)
    except TypeError as err:  # an option the backend does not take
        raise ValueError(f"backend: {backend!r} does not take these options: {err}") from None
