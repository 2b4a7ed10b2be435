"""A certified reduced-basis surrogate of one RVE: k_eff for any parameter set in microseconds.

For one RVE the discrete operator is ``A(mu) = D^T G(mu) D`` with ``G`` the diagonal of face
conductances (:mod:`itr_fv.discrete.model`), and the effective tensor follows from two extremum
principles of the same discrete model (``N`` voxels of edge ``h``, faces ``f``):

- primal (temperature): ``K_ii = 1/(N h) min_theta sum_f g_f (D theta + l_i)_f^2`` with
  ``l_i = h`` on the faces normal to ``e_i``. Galerkin in the span of full solutions at a
  few parameter sets gives ``K_N >= K`` (an upper bound, the reported value);
- dual (flux): ``K_ii >= 1/(N h) max_beta [2 m_i . beta - beta^T H beta]`` over
  divergence-free periodic face fluxes ``q = Phi beta`` with ``H = Phi^T diag(r) Phi`` and
  ``r = 1/g``; ``m_i`` are the mean fluxes. Taking ``Phi`` from the full solutions' fluxes
  gives a lower bound ``K_low``.

The face resistances are affine in ``rho = (1/k, R)`` (:mod:`itr_surrogate.face_decomposition`),
so ``H`` is affine exactly; the conductances of interface and contact faces are not, and are
replaced by an empirical interpolation with a measured relative error ``eps`` (then
``(1 + eps) K_N`` is still an upper bound, since K is monotone in every g). The gap
``(1 + eps) K_N - K_low`` bounds the error of ``K_N``: it is the constitutive-relation
residual of the pair (Prager-Synge), ``sum_f r_f (q_f - g_f dT_f)^2 / (N h)`` at the
optimal pair. The greedy basis adds the full solve where the relative gap over a training
set of parameter sets is largest, until it is below ``tol`` everywhere.

Example
-------
>>> rb = ReducedBasis(ms, mat, bounds={"k_Al2O3": (20, 40),
...                                    "R_Al2O3_silicone": (1e-8, 5e-5)}).fit()
>>> rb.predict({"k_Al2O3": [25.0, 30.0], "R_Al2O3_silicone": [1e-7, 2e-6]}).shape
(2, 3, 3)
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse

from itr_fv.discrete.model import apply_operator
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.io import atomic_path
from itr_fv.materials import Materials
from itr_fv.rve.microstructure import Microstructure
from itr_fv.solvers.choice import Solver, as_solver

from .face_decomposition import (
    ConductanceInterpolation,
    ParameterBox,
    ResistanceDecomposition,
    interpolation_coefficients,
)
from .reduced_kernels import galerkin_tensors

__all__ = ["ReducedBasis", "ReducedBasisWarning"]

FORMAT = "itr-reduced-basis"
VERSION = 1
_CHUNK = 2048


class ReducedBasisWarning(UserWarning):
    """The greedy stopped at ``max_solves`` before the training gap met ``tol``."""


def _face_difference(theta: np.ndarray) -> np.ndarray:
    """``(D theta)_f = theta_p - theta_{p + e_d}`` for every face, shape (3, n1, n2, n3)."""
    return np.stack([theta - np.roll(theta, -1, axis=d) for d in range(3)])


def _divergence(q: np.ndarray) -> np.ndarray:
    """``(D^T q)_p``: net outflow of the face field q from every voxel."""
    return sum(q[d] - np.roll(q[d], 1, axis=d) for d in range(3))


def _project_divergence_free(q: np.ndarray) -> np.ndarray:
    """``q - D psi`` with ``D^T D psi = D^T q`` (periodic, by FFT): the nearest divergence-free
    face field; the mean flux does not change. Removes the solver's residual from a flux."""
    shape = q.shape[1:]
    div = _divergence(q)
    lap = np.zeros(tuple(shape[:2]) + (shape[2] // 2 + 1,))
    for d, n in enumerate(shape):
        freq = np.fft.rfftfreq(n) if d == 2 else np.fft.fftfreq(n)
        view = [1, 1, 1]
        view[d] = freq.size
        lap = lap + (2.0 - 2.0 * np.cos(2.0 * np.pi * freq)).reshape(view)
    lap.flat[0] = 1.0
    psi_hat = np.fft.rfftn(div) / lap
    psi_hat.flat[0] = 0.0
    psi = np.fft.irfftn(psi_hat, s=shape, axes=(0, 1, 2))
    return q - _face_difference(psi)


def _incidence(shape: tuple[int, int, int], faces: np.ndarray) -> scipy.sparse.csr_array:
    """``D[faces]`` as a sparse (len(faces), N) matrix: +1 at p, -1 at p + e_d."""
    N = int(np.prod(shape))
    d, p = np.divmod(faces, N)
    ijk = np.unravel_index(p, shape)
    q = np.array(ijk)
    q[d, np.arange(faces.size)] += 1
    for ax in range(3):
        q[ax] %= shape[ax]
    qn = np.ravel_multi_index(tuple(q), shape)
    rows = np.repeat(np.arange(faces.size), 2)
    cols = np.column_stack([p, qn]).ravel()
    vals = np.tile([1.0, -1.0], faces.size)
    return scipy.sparse.csr_array((vals, (rows, cols)), shape=(faces.size, N))


class ReducedBasis:
    """Certified reduced-basis model of the effective conductivity of one RVE.

    Parameters
    ----------
    ms : Microstructure or DiscreteProblem
        The RVE (its contact model must be that of ``materials``).
    materials : Materials
        Values of every parameter; those in ``bounds`` vary, the others stay fixed.
        Contact spots (``Gc_*`` > 0) and insulating interfaces are not supported.
    bounds : mapping of str to (float, float)
        Varied parameters by flat name (:mod:`itr_fv.materials.parameters`): conductivities
        ``k_<phase>`` in W/(m K) (sampled uniformly), resistances ``R_<A>_<B>`` and
        ``Rff_<A>_<B>`` in m^2 K/W (sampled log-uniformly).
    tol : float
        Largest relative gap between upper and lower bound, over the training set, at
        which the greedy stops.
    max_solves : int
        Full solves at most.
    n_train : int
        Parameter sets of the greedy's training set (plus the 2^P corners of the box).
    seed : int
        Seed of the training and check sets.
    solver : Solver or str, optional
        Full solver of the snapshots: a :class:`~itr_fv.solvers.choice.Solver`, or a name
        (``"fft"``, ``"fv"``, ``"auto"``, a backend name) resolved once here (None: the
        default).
    solver_tol : float
        Relative residual of the full solves.
    interpolation_tol : float, optional
        Relative error target of the conductance interpolation (default ``tol / 1000``: its
        error then weighs nothing against ``tol``).
    max_interpolation_terms : int
        Upper limit on its terms.
    progress : bool
        A progress bar over the full solves.

    Attributes
    ----------
    n_solves_ : int
        Full solves used.
    converged_ : bool
        The training gap met ``tol``.
    training_gap_ : float
        Largest relative gap ``(upper - lower) / lower`` over training set and directions.
    interpolation_error_ : float
        ``eps``: twice the largest relative error of the interpolated conductances measured
        on the training and a separate check set.
    n_interpolation_terms_ : int
        Terms of the conductance interpolation.
    history_ : list of dict
        Per full solve: the parameter set, its k_eff diagonal (W/(m K)), the training gap
        after adding it, the seconds it took.
    fit_time_ : float
        Seconds of :meth:`fit`.

    Notes
    -----
    Memory during :meth:`fit`: the interpolation's training matrix, three arrays of
    ``F_na x (n_train + 2^P)`` doubles (F_na: interface and contact faces, about 0.15 M on
    an 80^3 Al2O3-60 RVE: 0.9 GB), the basis fields and fluxes (``3 x 4 N`` doubles per full
    solve, N voxels) and one full solve. The fitted model holds only reduced matrices
    (0.2 MB for that RVE).
    """

    def __init__(self, ms: Microstructure | DiscreteProblem, materials: Materials,
                 bounds: Mapping[str, tuple[float, float]], *, tol: float = 1e-3,
                 max_solves: int = 40, n_train: int = 256, seed: int = 0,
                 solver: Solver | str | None = None,
                 solver_tol: float = 1e-9, interpolation_tol: float | None = None,
                 max_interpolation_terms: int = 120, progress: bool = False) -> None:
        self.ms = ms
        self.materials = materials
        self.bounds = bounds
        self.tol = tol
        self.max_solves = max_solves
        self.n_train = n_train
        self.seed = seed
        self.solver = as_solver(solver)
        self.solver_tol = solver_tol
        self.interpolation_tol = interpolation_tol
        self.max_interpolation_terms = max_interpolation_terms
        self.progress = progress

    # ------------------------------------------------------------------ checks
    def _check_params(self) -> DiscreteProblem:
        if not isinstance(self.materials, Materials):
            raise ValueError(f"materials: expected a Materials object, got "
                             f"{type(self.materials).__name__}")
        if any(v > 0 for v in self.materials.contact_conductance.values()):
            raise ValueError("materials: contact spots (Gc_* > 0) make the face resistance "
                             "non-affine; the reduced basis does not support them")
        if any(math.isinf(v) for v in self.materials.resistance.values()):
            raise ValueError("materials: insulating interfaces (R = inf) are not supported")
        for name, value, low, high in (("tol", self.tol, 1e-12, 0.5),
                                       ("solver_tol", self.solver_tol, 1e-14, 1e-4),
                                       ("interpolation_tol", self._interpolation_tol(), 1e-14,
                                        1e-2)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not low <= value <= high:
                raise ValueError(f"{name}: expected a number in [{low:g}, {high:g}], "
                                 f"got {value!r}")
        for name, value, low in (("max_solves", self.max_solves, 1), ("n_train", self.n_train, 1),
                                 ("max_interpolation_terms", self.max_interpolation_terms, 1),
                                 ("seed", self.seed, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{name}: expected a whole number >= {low}, got {value!r}")
        if isinstance(self.ms, DiscreteProblem):
            problem = self.ms
        elif isinstance(self.ms, Microstructure):
            problem = DiscreteProblem.for_materials(self.ms, self.materials)
        else:
            raise ValueError(f"ms: expected a Microstructure or DiscreteProblem, got "
                             f"{type(self.ms).__name__}")
        if problem.contact != self.materials.contact:
            raise ValueError(f"ms: the problem uses contact={problem.contact!r}, the materials "
                             f"contact={self.materials.contact!r}")
        return problem

    # --------------------------------------------------------------------- fit
    def fit(self, *, full_solve: Callable | None = None) -> "ReducedBasis":
        """Greedy construction from full solves; returns self.

        Parameters
        ----------
        full_solve : callable, optional
            ``full_solve(problem, materials)`` returning an object with ``theta`` (one field
            per load case) and ``k_eff_energy`` (W/(m K)): how each snapshot is solved, e.g.
            through the solve engine (:mod:`surrogate.engine`) so that its snapshots are
            kept and reused. Default: :func:`itr_fv.solvers.driver.homogenize` on the backend of
            ``solver``. The greedy's choice depends only on the snapshots, so the same
            snapshots give the same model.
        """
        t0 = time.perf_counter()
        problem = self._check_params()
        box = ParameterBox(self.bounds, self.materials)
        geometry = problem.geometry
        shape = problem.shape
        N = int(np.prod(shape))
        h = problem.voxel_m
        dec = ResistanceDecomposition(geometry, self.materials, box)
        rho_train = box.to_rho(box.sample(self.n_train, self.seed))
        rho_check = box.to_rho(box.sample(max(64, self.n_train // 2), self.seed + 1))
        eim = ConductanceInterpolation(dec.c[dec.nonaffine], dec.a[dec.nonaffine], rho_train,
                                       rho_check, tol=self._interpolation_tol(),
                                       max_terms=self.max_interpolation_terms)
        self._setup(box, dec, eim, h, N)
        builder = _Builder(self, dec, eim, shape, h, problem)
        solve = self._full_solver() if full_solve is None else full_solve
        mu_values = box.from_unit(np.full(box.size, 0.5))
        history = []
        bar = None
        if self.progress:
            from tqdm.auto import tqdm
            bar = tqdm(total=self.max_solves, desc="reduced basis", unit="solve")
        converged, gap = False, math.inf
        for _ in range(self.max_solves):
            t1 = time.perf_counter()
            mat = box.materials(self.materials, mu_values)
            res = solve(problem, mat)
            builder.add_snapshot(res.theta, geometry.conductances(mat))
            self._set_reduced(builder.reduced())
            gaps = self._relative_gap(rho_train)
            worst = gaps.max(axis=1)
            gap = float(worst.max())
            history.append({"parameters": dict(zip(box.names, map(float, mu_values))),
                            "k_diagonal": [float(v) for v in np.diag(res.k_eff_energy)],
                            "training_gap": gap, "seconds": time.perf_counter() - t1})
            if bar is not None:
                bar.update(1)
                bar.set_postfix(gap=f"{gap:.2e}")
            if gap <= self.tol:
                converged = True
                break
            mu_values = box.from_rho(rho_train[int(np.argmax(worst))])
        if bar is not None:
            bar.close()
        if not converged:
            warnings.warn(f"reduced basis: {self.max_solves} full solves leave a relative gap "
                          f"of {gap:.3g} on the training set, above tol={self.tol:g}; "
                          "error_estimate() tells where", ReducedBasisWarning, stacklevel=2)
        self.n_solves_ = len(history)
        self.converged_ = converged
        self.training_gap_ = gap
        self.history_ = history
        self.fit_time_ = time.perf_counter() - t0
        self.microstructure_info_ = {"shape": list(shape), "voxel_m": h,
                                     "contact": problem.contact,
                                     "interface_faces": geometry.n_interface_faces,
                                     "nonaffine_faces": int(dec.nonaffine.size)}
        return self

    def _interpolation_tol(self) -> float:
        if self.interpolation_tol is None and isinstance(self.tol, (int, float)):
            return 1e-3 * self.tol
        return self.interpolation_tol

    def _full_solver(self):
        from itr_fv import homogenize

        def solve(problem, mat):
            backend = self.solver.backend(voxels=math.prod(problem.shape))
            return homogenize(problem, mat, solver=backend, tol=self.solver_tol)
        return solve

    def _setup(self, box: ParameterBox, dec: ResistanceDecomposition,
               eim: ConductanceInterpolation, h: float, N: int) -> None:
        self.box_ = box
        self.scale_ = 1.0 / (N * h)
        self.pure_params_ = np.array([i for i, f in enumerate(dec.pure) if f.size], dtype=np.int64)
        self.eim_c_ = eim.c_magic
        self.eim_a_ = eim.a_magic
        self.eim_b_inv_ = eim.b_inv
        self.n_interpolation_terms_ = eim.n_terms
        self.interpolation_error_ = 2.0 * max(eim.train_error, eim.check_error)

    def _set_reduced(self, reduced: dict[str, Any]) -> None:
        self.gram_ = reduced["gram"]
        self.column_direction_ = reduced["column_direction"]
        self.dual_gram_ = reduced["dual_gram"]
        self.dual_mean_ = reduced["dual_mean"]
        # columns reordered as [l_0, basis of x, l_1, basis of y, l_2, basis of z]: every
        # load case's Galerkin block is a contiguous slice
        order, self._blocks = [], []
        for i in range(3):
            own = np.flatnonzero(self.column_direction_ == i)
            self._blocks.append((len(order), int(own.size)))
            order += [i, *own]
        order = np.array(order)
        self._gram_blocked = np.ascontiguousarray(self.gram_[:, order][:, :, order])

    # ----------------------------------------------------------- evaluation
    def _check_fitted(self) -> None:
        if not hasattr(self, "gram_"):
            raise ValueError("ReducedBasis: not fitted; call fit() first (or load())")

    def _rho(self, parameter_sets: Any) -> np.ndarray:
        """rho (n, P) of parameter sets given as one mapping, a mapping of arrays, or a
        sequence of mappings; names not varied must keep the value of ``materials``."""
        box = self.box_
        if isinstance(parameter_sets, Mapping):
            columns = {k: np.atleast_1d(np.asarray(v, dtype=np.float64))
                       for k, v in parameter_sets.items()}
            sizes = {c.size for c in columns.values()}
            if len(sizes) > 1:
                raise ValueError(f"parameter_sets: columns of different lengths {sorted(sizes)}")
            n = sizes.pop() if sizes else 1
        elif isinstance(parameter_sets, Sequence) and not isinstance(parameter_sets, (str, bytes)):
            if not all(isinstance(p, Mapping) for p in parameter_sets):
                raise ValueError("parameter_sets: expected a mapping {name: value(s)} or a "
                                 "sequence of such mappings")
            names = {k for p in parameter_sets for k in p}
            n = len(parameter_sets)
            columns = {k: np.array([float(p.get(k, self._base_value(k))) for p in parameter_sets])
                       for k in names}
        else:
            raise ValueError(f"parameter_sets: expected a mapping or a sequence of mappings, got "
                             f"{type(parameter_sets).__name__}")
        values = np.empty((n, box.size))
        for name, col in columns.items():
            if name in box.names:
                continue
            base = self._base_value(name)
            if not np.allclose(col, base, rtol=1e-12, atol=0.0):
                raise ValueError(f"parameter_sets: {name} is fixed at {base:g} in this reduced "
                                 f"basis (it varies {box.names})")
        for i, name in enumerate(box.names):
            col = columns.get(name)
            col = np.full(n, box.base[name]) if col is None else col
            if not np.all(np.isfinite(col)):
                raise ValueError(f"parameter_sets: {name} holds NaN or inf")
            bad = (col < box.lo[i] * (1 - 1e-9)) | (col > box.hi[i] * (1 + 1e-9))
            if bad.any():
                raise ValueError(f"parameter_sets: {name} = {col[bad][0]:g} is outside the "
                                 f"reduced basis bounds [{box.lo[i]:g}, {box.hi[i]:g}]")
            values[:, i] = col
        return box.to_rho(values)

    def _base_value(self, name: str) -> float:
        if name not in self.box_.base:
            raise ValueError(f"parameter_sets: unknown parameter {name!r} (this reduced basis "
                             f"knows {sorted(self.box_.base)})")
        return self.box_.base[name]

    def _primal_terms(self, rho: np.ndarray) -> np.ndarray:
        n = rho.shape[0]
        parts = [np.ones((n, 1)), 1.0 / rho[:, self.pure_params_]]
        if self.eim_b_inv_.size:
            parts.append(interpolation_coefficients(self.eim_c_, self.eim_a_, self.eim_b_inv_,
                                                    rho))
        return np.hstack(parts)

    def _galerkin(self, rho: np.ndarray) -> np.ndarray:
        """K_N (n, 3, 3), W/(m K)."""
        return galerkin_tensors(self._primal_terms(rho), self._gram_blocked,
                                np.array(self._blocks), self.scale_)

    def _dual_lower(self, rho: np.ndarray) -> np.ndarray:
        """Lower bound of every diagonal entry (n, 3), W/(m K)."""
        terms = np.hstack([np.ones((rho.shape[0], 1)), rho])
        out = np.empty((rho.shape[0], 3))
        for i in range(3):
            G = self.dual_gram_[i]
            m = G.shape[1]
            H = (terms @ G.reshape(G.shape[0], m * m)).reshape(-1, m, m)
            v = np.broadcast_to(self.dual_mean_[i], (rho.shape[0], m))
            x = np.linalg.solve(H, v[:, :, None])[:, :, 0]
            out[:, i] = np.einsum("na,na->n", v, x)
        return out

    def _relative_gap(self, rho: np.ndarray) -> np.ndarray:
        upper, lower = self._bounds_of_rho(rho)
        return (upper - lower) / lower

    def _bounds_of_rho(self, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uppers, lowers = [], []
        for s in range(0, rho.shape[0], _CHUNK):
            part = rho[s:s + _CHUNK]
            K = self._galerkin(part)
            uppers.append((1.0 + self.interpolation_error_) * np.diagonal(K, axis1=1, axis2=2))
            lowers.append(self._dual_lower(part))
        return np.concatenate(uppers), np.concatenate(lowers)

    def predict(self, parameter_sets: Any) -> np.ndarray:
        """Galerkin effective tensor, shape (n, 3, 3), W/(m K).

        Its diagonal is an upper bound of the full solver's (up to the interpolation error
        ``interpolation_error_``, relative); :meth:`error_estimate` bounds its error.

        Parameters
        ----------
        parameter_sets : mapping or sequence of mappings
            ``{name: value}`` (one set), ``{name: array}`` (n sets, fastest) or a list of
            ``{name: value}``; names use the package's flat naming, names left out keep the
            values of ``materials``.
        """
        self._check_fitted()
        rho = self._rho(parameter_sets)
        return np.concatenate([self._galerkin(rho[s:s + _CHUNK])
                               for s in range(0, rho.shape[0], _CHUNK)])

    def bounds_of(self, parameter_sets: Any) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds of the diagonal of k_eff, each shape (n, 3), W/(m K)."""
        self._check_fitted()
        upper, lower = self._bounds_of_rho(self._rho(parameter_sets))
        return lower, upper

    def error_estimate(self, parameter_sets: Any) -> np.ndarray:
        """Bound of ``|predict - k_eff|`` on the diagonal, shape (n, 3), W/(m K):
        ``(1 + eps) K_N - K_low``, the complementary-energy (constitutive-relation)
        residual of the reduced pair."""
        self._check_fitted()
        lower, upper = self.bounds_of(parameter_sets)
        return upper - lower

    # ----------------------------------------------------------------- storage
    def _meta(self) -> dict:
        mat = self.materials
        return {"format": FORMAT, "version": VERSION, "bounds": self.box_.to_dict(),
                "materials": {"parameters": self.box_.base, "matrix": mat.matrix,
                              "contact": mat.contact},
                "tol": self.tol, "max_solves": self.max_solves, "n_train": self.n_train,
                "seed": self.seed, "solver": self.solver.key, "solver_tol": self.solver_tol,
                "interpolation_tol": self.interpolation_tol,
                "max_interpolation_terms": self.max_interpolation_terms,
                "scale": self.scale_, "interpolation_error": self.interpolation_error_,
                "n_interpolation_terms": self.n_interpolation_terms_,
                "n_solves": self.n_solves_, "converged": self.converged_,
                "training_gap": self.training_gap_, "history": self.history_,
                "fit_time": self.fit_time_, "microstructure": self.microstructure_info_}

    def save(self, path: str | Path) -> Path:
        """Write the fitted model as ``.npz`` (plain arrays + a JSON header; no pickle)."""
        self._check_fitted()
        path = Path(path)
        arrays = {"meta": np.array(json.dumps(self._meta())), "gram": self.gram_,
                  "column_direction": self.column_direction_,
                  "pure_params": self.pure_params_, "eim_c": self.eim_c_,
                  "eim_a": self.eim_a_, "eim_b_inv": self.eim_b_inv_}
        for i in range(3):
            arrays[f"dual_gram_{i}"] = self.dual_gram_[i]
            arrays[f"dual_mean_{i}"] = self.dual_mean_[i]
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ReducedBasis":
        """Read a model written by :meth:`save` (never unpickles)."""
        try:
            with np.load(Path(path), allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError) as exc:
            raise ValueError(f"path: {path} is not a reduced-basis file ({exc})") from None
        try:
            meta = json.loads(str(arrays["meta"]))
        except (KeyError, json.JSONDecodeError):
            meta = {}
        if meta.get("format") != FORMAT:
            raise ValueError(f"path: {path} is not a reduced-basis file")
        m = meta["materials"]
        mat = Materials.from_parameters(m["parameters"], m["matrix"], contact=m["contact"])
        rb = cls(None, mat, {k: tuple(v) for k, v in meta["bounds"].items()}, tol=meta["tol"],
                 max_solves=meta["max_solves"], n_train=meta["n_train"], seed=meta["seed"],
                 solver=meta["solver"], solver_tol=meta["solver_tol"],
                 interpolation_tol=meta["interpolation_tol"],
                 max_interpolation_terms=meta["max_interpolation_terms"])
        rb.box_ = ParameterBox(rb.bounds, mat)
        rb.scale_ = meta["scale"]
        rb.interpolation_error_ = meta["interpolation_error"]
        rb.n_interpolation_terms_ = meta["n_interpolation_terms"]
        rb.pure_params_ = arrays["pure_params"]
        rb.eim_c_, rb.eim_a_, rb.eim_b_inv_ = arrays["eim_c"], arrays["eim_a"], arrays["eim_b_inv"]
        rb._set_reduced({"gram": arrays["gram"], "column_direction": arrays["column_direction"],
                         "dual_gram": [arrays[f"dual_gram_{i}"] for i in range(3)],
                         "dual_mean": [arrays[f"dual_mean_{i}"] for i in range(3)]})
        rb.n_solves_ = meta["n_solves"]
        rb.converged_ = meta["converged"]
        rb.training_gap_ = meta["training_gap"]
        rb.history_ = meta["history"]
        rb.fit_time_ = meta["fit_time"]
        rb.microstructure_info_ = meta["microstructure"]
        return rb

    def __repr__(self) -> str:
        if not hasattr(self, "gram_"):
            return f"ReducedBasis(bounds={dict(self.bounds)!r}, tol={self.tol:g}, not fitted)"
        return (f"ReducedBasis({self.box_.names}, {self.n_solves_} full solves, "
                f"{self.n_interpolation_terms_} interpolation terms, training gap "
                f"{self.training_gap_:.2e})")


class _Builder:
    """The full-size parts of the greedy: basis fields, fluxes and the reduced matrices."""

    def __init__(self, rb: ReducedBasis, dec: ResistanceDecomposition,
                 eim: ConductanceInterpolation, shape: tuple[int, int, int], h: float,
                 problem: DiscreteProblem) -> None:
        self.shape, self.h = shape, h
        self.N = int(np.prod(shape))
        F = 3 * self.N
        # primal term families: (faces, weights (len(faces), T_family))
        fams = [(dec.constant, (1.0 / dec.c[dec.constant])[:, None])]
        for i in rb.pure_params_:
            faces = dec.pure[i]
            fams.append((faces, (1.0 / dec.a[faces, i])[:, None]))
        fams.append((dec.nonaffine, eim.basis))
        self.families = [(faces, w, _incidence(shape, faces)) for faces, w in fams]
        self.n_terms = sum(w.shape[1] for _, w, _ in self.families)
        self.axis_of_face = np.repeat(np.arange(3), self.N)
        self.dual_weights = np.column_stack([dec.c, dec.a])  # (F, 1 + P)
        assert self.dual_weights.shape[0] == F
        self.fields: list[np.ndarray] = []  # orthonormal basis fields (voxel arrays)
        self.direction: list[int] = []
        self.gram = np.zeros((self.n_terms, 0, 0))
        for i in range(3):  # the load columns l_0, l_1, l_2
            self._add_column(None, i)
        self.fluxes: list[list[np.ndarray]] = [[], [], []]
        self.dual_gram = [np.zeros((1 + dec.a.shape[1], 0, 0)) for _ in range(3)]
        self.dual_mean = [np.zeros(0) for _ in range(3)]
        self.g_ref: np.ndarray | None = None  # conductances of the first snapshot
        self.r_ref: np.ndarray | None = None  # their inverse, flattened

    def _load(self, i: int) -> np.ndarray:
        z = np.zeros(3 * self.N)
        z[i * self.N:(i + 1) * self.N] = self.h
        return z

    def _add_column(self, field: np.ndarray | None, direction: int) -> None:
        """Append a column (a basis field, or the load l_direction when field is None) to
        the primal Gram matrices of every term."""
        z = self._load(direction) if field is None else _face_difference(field).ravel()
        S = self.gram.shape[1]
        new = np.zeros((self.n_terms, S + 1))
        t = 0
        V = np.array(self.fields).reshape(len(self.fields), -1) if self.fields else None
        for faces, w, Dsub in self.families:
            Y = w * z[faces][:, None]  # (len(faces), T_f)
            nt = w.shape[1]
            for i in range(min(S, 3)):  # against the load columns l_0 .. l_2
                on_axis = self.axis_of_face[faces] == i
                new[t:t + nt, i] = self.h * Y[on_axis].sum(axis=0)
            if V is not None:  # against the basis fields (columns 3 .. S-1)
                new[t:t + nt, 3:S] = (V @ (Dsub.T @ Y)).T
            new[t:t + nt, S] = z[faces] @ Y
            t += nt
        gram = np.zeros((self.n_terms, S + 1, S + 1))
        gram[:, :S, :S] = self.gram
        gram[:, :, S] = new
        gram[:, S, :] = new
        self.gram = gram

    def add_snapshot(self, thetas: np.ndarray, g: np.ndarray) -> None:
        """Add the three load cases of one full solve (theta (3, n1, n2, n3), its exact face
        conductances g (3, n1, n2, n3))."""
        if self.g_ref is None:
            self.g_ref = g
            self.r_ref = 1.0 / g.ravel()
        for i in range(3):
            v = self._orthonormal(thetas[i], i)
            if v is not None:
                self._add_column(v, i)
                self.fields.append(v)
                self.direction.append(i)
            q = g * (_face_difference(thetas[i]) + self._load(i).reshape(g.shape))
            self._add_flux(_project_divergence_free(q), i)

    def _orthonormal(self, theta: np.ndarray, direction: int) -> np.ndarray | None:
        """theta orthonormalised against the basis fields of its direction in the energy
        inner product of the first snapshot (two Gram-Schmidt passes); None if dependent."""
        own = [f for f, d in zip(self.fields, self.direction) if d == direction]
        v = theta - theta.mean()
        norm0 = math.sqrt(max(float(np.sum(v * apply_operator(self.g_ref, v))), 0.0))
        if norm0 == 0.0:
            return None
        for _ in range(2):
            Av = apply_operator(self.g_ref, v)
            for f in own:
                v = v - float(np.sum(f * Av)) * f
        norm = math.sqrt(max(float(np.sum(v * apply_operator(self.g_ref, v))), 0.0))
        if norm <= 1e-10 * norm0:
            return None
        return v / norm

    def _add_flux(self, q: np.ndarray, direction: int) -> None:
        """Append a divergence-free flux of load case ``direction`` to its dual basis
        (orthonormalised in the resistance-weighted inner product of the first snapshot)."""
        r_ref = self.r_ref
        q = q.ravel()
        own = self.fluxes[direction]
        norm0 = math.sqrt(float(np.sum(r_ref * q * q)))
        for _ in range(2):
            for f in own:
                q = q - float(np.sum(r_ref * f * q)) * f
        norm = math.sqrt(float(np.sum(r_ref * q * q)))
        if norm <= 1e-10 * norm0:
            return
        q = q / norm
        own.append(q)
        Phi = np.array(own)  # (m, F)
        weighted = self.dual_weights * q[:, None]  # (F, 1 + P)
        col = np.einsum("mf,ft->tm", Phi, weighted)  # (1 + P, m)
        m = Phi.shape[0]
        G = np.zeros((self.dual_weights.shape[1], m, m))
        G[:, :m - 1, :m - 1] = self.dual_gram[direction]
        G[:, :, m - 1] = col
        G[:, m - 1, :] = col
        self.dual_gram[direction] = G
        mean = q.reshape(3, self.N)[direction].mean()
        self.dual_mean[direction] = np.append(self.dual_mean[direction], mean)

    def reduced(self) -> dict[str, Any]:
        s = 1.0 / (self.N * self.h)
        return {"gram": self.gram, "column_direction": np.array([-1, -1, -1] + self.direction),
                "dual_gram": [G * s for G in self.dual_gram],
                "dual_mean": list(self.dual_mean)}
