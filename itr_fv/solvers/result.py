"""Result object shared by both homogenization solvers."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..rve.microstructure import Microstructure

from ..discrete.connectivity import FloatingClusters

__all__ = ["HomogenizationResult", "ConvergenceError", "FloatingClusters"]


class ConvergenceError(RuntimeError):
    """The iterative solve stopped at ``maxiter`` above the tolerance.

    The partial result is attached as ``.result``.
    """

    def __init__(self, message: str, result: "HomogenizationResult") -> None:
        super().__init__(message)
        self.result = result


@dataclass
class HomogenizationResult:
    """Effective conductivity and fields from one homogenization.

    Attributes
    ----------
    k_eff : ndarray, shape (3, 3)
        Effective conductivity tensor, W/(m K); ``k_eff[i, j] = <q_i>`` for the load
        E = e_j (1 K/m). Columns of directions not solved are NaN.
    k_eff_energy : ndarray, shape (3, 3)
        Variational estimate ``<dT_i g dT_j>`` of the same tensor, W/(m K): symmetric by
        construction, error quadratic in the solver error (see
        :func:`itr_fv.discrete.model.energy_tensor`). Agrees with ``k_eff`` to about the solver
        tolerance.
    directions : tuple of int
        The load cases solved, in order.
    iterations : list of int
        CG iterations per load case.
    residuals : list of float
        Final relative residual ||b - A theta|| / ||b|| per load case.
    residual_history : list of ndarray
        Relative residual after every iteration, per load case.
    converged : bool
        All load cases reached ``tol``.
    temperature : ndarray or None, shape (ndir, n1, n2, n3)
        Total temperature T = -E.x + theta per load case, K (E = 1 K/m).
    theta : ndarray or None, shape (ndir, n1, n2, n3)
        Periodic fluctuation per load case, K (zero mean on every connected cluster); pass
        as ``x0`` to warm-start a neighbouring solve.
    fluxes : ndarray or None, shape (ndir, 3, n1, n2, n3)
        Face flux densities, W/m^2: ``fluxes[c, d][p]`` crosses the face between p and p + e_d.
    setup_time, solve_times, wall_time : float, list of float, float
        Seconds: geometry + assembly + preconditioner set-up, each load case, everything.
    floating : FloatingClusters
        Clusters cut off by insulating interfaces.
    solver : str
        ``"itr_fv"`` or ``"itr_fft"``.
    tol : float
        Requested relative residual tolerance.
    """

    k_eff: np.ndarray
    k_eff_energy: np.ndarray
    directions: tuple[int, ...]
    iterations: list[int]
    residuals: list[float]
    residual_history: list[np.ndarray]
    converged: bool
    temperature: np.ndarray | None
    theta: np.ndarray | None
    fluxes: np.ndarray | None
    setup_time: float
    solve_times: list[float]
    wall_time: float
    floating: FloatingClusters
    solver: str
    tol: float
    microstructure: "Microstructure | None" = field(default=None, repr=False)
    info: dict = field(default_factory=dict)

    @property
    def symmetry_error(self) -> float:
        """max |K - K^T| / max |K| over the solved block (0 when fewer than 2 directions)."""
        d = list(self.directions)
        block = self.k_eff[np.ix_(d, d)]
        scale = np.abs(block).max()
        if len(d) < 2 or scale == 0:
            return 0.0
        return float(np.abs(block - block.T).max() / scale)

    @property
    def k_mean(self) -> float:
        """Mean of the solved diagonal entries, W/(m K)."""
        return float(np.mean([self.k_eff[d, d] for d in self.directions]))

    def to_vtk(self, path: str | Path, *, load_cases: Sequence[int] | None = None,
               vectors: bool = True, precision: str = "float32") -> Path:
        """Write a compressed ``.vti`` image: material, particle id, temperature, its
        fluctuation, flux magnitude (and vectors) per load case; written atomically.

        See :func:`itr_fv.output.vtk.write_vti`.
        """
        from ..output.vtk import write_vti
        return write_vti(self, path, load_cases=load_cases, vectors=vectors,
                         precision=precision)

    def render_png(self, path: str | Path, load_case: int = 0, *,
                   k_text: str | None = None) -> Path:
        """Off-screen PNG: heat-flux magnitude and interfaces on mid-planes, phases, k_eff
        (or ``k_text`` in its place).

        See :func:`itr_fv.output.vtk.render_png`.
        """
        from ..output.vtk import render_png
        return render_png(self, path, load_case=load_case, k_text=k_text)

    def summary(self) -> str:
        """Human-readable summary of tensor, iterations and residuals."""
        lines = [f"{self.solver}: k_eff (W/(m K)) =",
                 np.array2string(self.k_eff, precision=6, suppress_small=True)]
        for d, it, r, t in zip(self.directions, self.iterations, self.residuals,
                               self.solve_times):
            lines.append(f"  load e{d + 1}: {it} iterations, relative residual {r:.2e}, {t:.2f} s")
        lines.append(f"  set-up {self.setup_time:.2f} s, total {self.wall_time:.2f} s, "
                     f"symmetry error {self.symmetry_error:.2e}")
        if self.floating.count:
            lines.append(f"  {self.floating.count} floating clusters "
                         f"({100 * self.floating.volume_fraction:.2f} vol%) cut off by R = inf")
        return "\n".join(lines)
