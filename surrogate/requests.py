"""What travels between the client and a solve: requests, results and their plain-data forms.

A full solve is a :class:`SolveRequest`: an RVE (its particle table and grid,
:class:`RVEData`), its :class:`~itr_fv.materials.Materials` (conductivities, resistances, the
contact model), the :class:`~itr_fv.solvers.choice.Solver` and the tolerance, plus labels
written with its row. A worker gets a request as plain data (:func:`request_payload`: lists
and numbers, no path, no object of this package) and returns plain data
(:func:`result_payload`); :func:`solve_row` is the one record format of a finished solve,
which the solve store writes and a run's ``full_solves.parquet`` lists.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from itr_fv.materials import Materials
from itr_fv.rve.contact_film import ContactFilm
from itr_fv.rve.microstructure import Microstructure
from itr_fv.solvers.choice import Solver, as_solver, default_solver

from .rows import rve_id, tensor_columns

__all__ = ["RVEData", "SolveRequest", "SolveResult", "solve_row", "request_payload",
           "request_of_payload", "result_payload", "result_of_payload"]


@dataclass(frozen=True, eq=False)
class RVEData:
    """What a worker needs to rebuild an RVE's voxels: spheres and grid.

    Attributes
    ----------
    centers_m : ndarray, shape (P, 3)
        Sphere centres, m.
    radii_m : ndarray, shape (P,)
        Radii, m.
    materials : tuple of str
        Phase of every sphere.
    box_m : float
        Box edge, m.
    shape : (int, int, int)
        Voxels per axis.
    matrix : str
        Matrix phase.
    contact : ContactFilm
        Which pairs touch and the film they meet at.
    """

    centers_m: np.ndarray
    radii_m: np.ndarray
    materials: tuple[str, ...]
    box_m: float
    shape: tuple[int, int, int]
    matrix: str
    contact: ContactFilm = ContactFilm()

    @classmethod
    def of(cls, ms: Microstructure) -> RVEData:
        """The sphere data of a packed microstructure (needs its particle table)."""
        table = ms.particles
        if table is None:
            raise ValueError("ms: the engine needs the particle table of the microstructure "
                             "(a packed RVE, e.g. from itr_fv.rve.generate_rve)")
        box = float(np.asarray(ms.box_m, dtype=np.float64).ravel()[0])
        return cls(np.asarray(table.centers_m, dtype=np.float64),
                   np.asarray(table.radii_m, dtype=np.float64),
                   tuple(str(m) for m in table.material), box, tuple(ms.shape), ms.names[0],
                   table.contact)

    @property
    def rve_id(self) -> str:
        """Hash of the particle table and the grid (the campaign store's RVE identity)."""
        cached = self.__dict__.get("_id")
        if cached is None:
            cached = rve_id(self.centers_m, self.radii_m, list(self.materials), self.shape,
                            self.box_m / self.shape[0], self.contact)
            object.__setattr__(self, "_id", cached)
        return cached

    def microstructure(self) -> Microstructure:
        """The voxel image (the same voxels as the packing that produced the data)."""
        return Microstructure.from_spheres(self.centers_m, self.radii_m, list(self.materials),
                                           box_m=self.box_m, shape=self.shape,
                                           matrix=self.matrix, contact=self.contact)

    def to_payload(self) -> dict:
        return {"centers_m": self.centers_m.tolist(), "radii_m": self.radii_m.tolist(),
                "materials": list(self.materials), "box_m": self.box_m,
                "shape": list(self.shape), "matrix": self.matrix,
                "contact": self.contact.to_dict()}

    @classmethod
    def from_payload(cls, d: Mapping[str, Any]) -> RVEData:
        return cls(np.asarray(d["centers_m"], dtype=np.float64).reshape(-1, 3),
                   np.asarray(d["radii_m"], dtype=np.float64), tuple(d["materials"]),
                   float(d["box_m"]), tuple(int(n) for n in d["shape"]), str(d["matrix"]),
                   ContactFilm.from_dict(d.get("contact")))


@dataclass(frozen=True)
class SolveRequest:
    """One full solve: an RVE, its materials, a solver and a tolerance.

    Attributes
    ----------
    rve : RVEData
    materials : Materials
        Conductivities (W/(m K)), resistances (m^2 K/W) and the contact model; the
        RVE's matrix.
    tol : float
        Relative residual of the solve.
    solver : Solver
        The resolved solver (:func:`~itr_fv.solvers.choice.resolve_solver`; its default
        by default).
    fields : bool
        Keep theta (the reduced basis's snapshots need it).
    labels : mapping
        Purpose, formulation, replica...: written with the row, not part of the key.
    """

    rve: RVEData
    materials: Materials
    tol: float
    solver: Solver = field(default_factory=default_solver)
    fields: bool = False
    labels: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def for_materials(cls, rve: RVEData, mat: Materials, tol: float, *,
                      solver: Solver | str | None = None, fields: bool = False,
                      **labels: Any) -> SolveRequest:
        """A request checked before any work: ``mat``'s matrix is the RVE's; ``solver``
        a Solver or a name (:func:`~itr_fv.solvers.choice.as_solver`)."""
        if not isinstance(mat, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(mat).__name__}")
        if mat.matrix != rve.matrix:
            raise ValueError(f"mat: matrix {mat.matrix!r} differs from the RVE's {rve.matrix!r}")
        return cls(rve, mat, float(tol), as_solver(solver), bool(fields), dict(labels))

    @property
    def contact(self) -> str:
        """The contact model of the materials (``"gap"`` or ``"area"``)."""
        return self.materials.contact

    @property
    def parameters(self) -> dict[str, float]:
        """Every conductivity and resistance under the flat names (``Materials.to_parameters``)."""
        return dict(self.materials.to_parameters())

    @property
    def key(self) -> str:
        """The store key: RVE, parameters (to 12 significant digits), contact, solver, tol."""
        params = {k: float(f"{float(v):.12g}") for k, v in sorted(self.parameters.items())}
        text = json.dumps({"rve": self.rve.rve_id, "parameters": params,
                           "contact": self.contact, "solver": self.solver.key,
                           "tol": float(f"{self.tol:.6g}")}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:20]


@dataclass
class SolveResult:
    """A finished solve: the tensor (W/(m K)), its energy estimate, iterations, residual,
    seconds, theta (when asked for), whether it came from the store, and whether the worker
    built the RVE's geometry for it."""

    k_eff: np.ndarray
    k_eff_energy: np.ndarray
    iterations: list[int]
    residual: float
    wall_s: float
    theta: np.ndarray | None = None
    cached: bool = False
    geometry_built: bool = False

    @property
    def k_diagonal(self) -> np.ndarray:
        return np.diag(self.k_eff).copy()


def request_payload(req: SolveRequest) -> dict:
    """A request as plain data for a Dask worker."""
    return {"rve": req.rve.to_payload(), "parameters": req.parameters,
            "matrix": req.materials.matrix, "contact": req.contact, "tol": req.tol,
            "solver": req.solver.key, "fields": req.fields, "labels": dict(req.labels)}


def request_of_payload(payload: Mapping[str, Any]) -> SolveRequest:
    """The request of :func:`request_payload`'s plain data (on the worker)."""
    mat = Materials.from_parameters(payload["parameters"], payload["matrix"],
                                    contact=payload["contact"])
    return SolveRequest(RVEData.from_payload(payload["rve"]), mat, payload["tol"],
                        as_solver(payload["solver"]), payload["fields"], payload["labels"])


def result_payload(res: SolveResult) -> dict:
    """A finished solve as plain data (from the worker)."""
    return {"k_eff": res.k_eff.tolist(), "k_eff_energy": res.k_eff_energy.tolist(),
            "iterations": res.iterations, "residual": res.residual, "wall_s": res.wall_s,
            "theta": res.theta, "geometry_built": res.geometry_built,
            "worker_pid": os.getpid()}


def result_of_payload(d: Mapping[str, Any]) -> SolveResult:
    """The result of :func:`result_payload`'s plain data (on the client)."""
    return SolveResult(np.asarray(d["k_eff"]), np.asarray(d["k_eff_energy"]), d["iterations"],
                       d["residual"], d["wall_s"],
                       None if d["theta"] is None else np.asarray(d["theta"]), False,
                       d["geometry_built"])


def solve_row(request: SolveRequest, result: SolveResult) -> dict[str, Any]:
    """One finished solve as the store's row: the request's key, RVE, contact, solver and
    tolerance, its labels, the flat parameters, the tensor (:func:`tensor_columns`),
    iterations, residual and wall time (the campaign row's columns where they are shared).
    The one record format of a full solve: the store writes it and a run's
    ``full_solves.parquet`` lists it."""
    from itr_fv import __version__

    row: dict[str, Any] = {"key": request.key, "rve_id": request.rve.rve_id,
                           "n": request.rve.shape[0],
                           "voxel_um": request.rve.box_m / request.rve.shape[0] * 1e6,
                           "box_um": request.rve.box_m * 1e6, "contact": request.contact,
                           "solver": request.solver.key, "tol": request.tol,
                           "package_version": __version__}
    row.update({str(k): (json.dumps(v) if isinstance(v, (list, dict)) else v)
                for k, v in request.labels.items()})
    row.update({k: float(v) for k, v in sorted(request.parameters.items())})
    row.update(tensor_columns(result.k_eff))
    row.update({"k_energy_json": json.dumps(np.asarray(result.k_eff_energy).tolist()),
                "iterations": int(max(result.iterations, default=0)),
                "iterations_json": json.dumps([int(i) for i in result.iterations]),
                "residual": float(result.residual), "wall_s": float(result.wall_s)})
    return row
