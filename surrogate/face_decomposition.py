"""Parameter dependence of the face conductances of one RVE, for the reduced-basis model.

Every face of the discrete model (:mod:`itr_fv.discrete.model`) is a series of resistances: the two
half voxels ``h / (2 k)``, the interface ``s R`` where the face crosses one, the matrix film
``d / k_m`` of the gap contact model, the segment lengths of the contact zones or of the cut
cells (segment law). With the parameter vector ``rho`` made of ``1 / k`` for conductivities
and ``R`` for resistances, the face resistance (m^2 K/W) is therefore *affine*; the interface
law says so for each parameter kind (:attr:`itr_fv.discrete.interface_law.InterfaceLaw.affine_in`),
and a parameter it is not affine in is refused::

    r_f(rho) = c_f + sum_i a_fi rho_i,      g_f = 1 / r_f      (W/(m^2 K))

:class:`ResistanceDecomposition` finds ``c`` and ``a`` by evaluating the model itself
(:meth:`itr_fv.discrete.model.FaceGeometry.conductances`) at a few parameter sets and checks that
the decomposition reproduces the model to round-off at a further one: the model lives in
``itr_fv`` only. The resistance is affine, so the complementary (flux) energy of the RVE is
affine in ``rho`` exactly. The conductance ``g`` is not: faces whose resistance holds one
term only (inside a particle, ``g = k / h``) or no varying term (inside the matrix) are
affine in ``1 / rho_i`` or constant; every other face (interfaces, contact films) goes to
:class:`ConductanceInterpolation`, an empirical interpolation (EIM) of the vector of their
conductances with a measured maximum relative error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from itr_fv.discrete.model import FaceGeometry
from itr_fv.materials import Materials
from itr_fv.materials.parameters import is_log_scaled, parse_parameter

__all__ = ["ParameterBox", "ResistanceDecomposition", "ConductanceInterpolation",
           "interpolation_coefficients"]

#: A decomposition that does not reproduce the model to this relative error is refused.
AFFINE_CHECK_RTOL = 1e-9


class ParameterBox:
    """The varied parameters of a reduced basis, their bounds and the map to ``rho``.

    Parameters
    ----------
    bounds : mapping of str to (float, float)
        ``{flat parameter name: (lo, hi)}``; conductivities ``k_*`` (W/(m K)), filler-matrix
        resistances ``R_*`` and per-area contact resistances ``Rff_*`` (m^2 K/W).
    materials : Materials
        Values of every other parameter; each bounded name must be one of its parameters.
    """

    def __init__(self, bounds: Mapping[str, tuple[float, float]], materials: Materials) -> None:
        if not isinstance(bounds, Mapping) or not bounds:
            raise ValueError("bounds: expected a non-empty mapping {parameter name: (lo, hi)}")
        base = materials.to_parameters()
        self.names: list[str] = []
        lo, hi = [], []
        for name, pair in bounds.items():
            try:
                kind, _ = parse_parameter(name)
            except ValueError as exc:
                raise ValueError(f"bounds: {exc}") from None
            if kind == "Gc":
                raise ValueError(f"bounds: {name} is a contact-spot conductance; its faces are "
                                 "not series resistances, and the reduced basis does not vary it")
            if name not in base:
                raise ValueError(f"bounds: {name} is not a parameter of materials (they hold "
                                 f"{sorted(base)})")
            if isinstance(pair, (str, bytes)) or len(pair) != 2:
                raise ValueError(f"bounds: {name} needs (lo, hi), got {pair!r}")
            a, b = float(pair[0]), float(pair[1])
            if not (math.isfinite(a) and math.isfinite(b) and 0.0 < a < b):
                raise ValueError(f"bounds: {name} needs finite 0 < lo < hi, got ({a:g}, {b:g})")
            self.names.append(name)
            lo.append(a)
            hi.append(b)
        self.lo = np.array(lo)
        self.hi = np.array(hi)
        self.base = base
        self.is_conductivity = np.array([parse_parameter(n)[0] == "k" for n in self.names])

    @property
    def size(self) -> int:
        return len(self.names)

    def to_rho(self, values: np.ndarray) -> np.ndarray:
        """``rho`` (1/k or R) of parameter values, shape (n, P)."""
        return np.where(self.is_conductivity, 1.0 / values, values)

    def from_rho(self, rho: np.ndarray) -> np.ndarray:
        """Parameter values of ``rho`` (the inverse of :meth:`to_rho`)."""
        return np.where(self.is_conductivity, 1.0 / rho, rho)

    def sample(self, n: int, seed: int) -> np.ndarray:
        """``n`` parameter sets (n, P): a Latin hypercube, log-uniform for resistances,
        uniform for conductivities, with the 2^P corners of the box first."""
        from scipy.stats import qmc

        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * self.size, indexing="ij")
                           ).reshape(self.size, -1).T
        unit = qmc.LatinHypercube(d=self.size, seed=np.random.default_rng(seed)).random(n)
        return self.from_unit(np.vstack([corners, unit]))

    def from_unit(self, unit: np.ndarray) -> np.ndarray:
        log = np.array([is_log_scaled(n) for n in self.names])
        a = np.where(log, np.log10(self.lo), self.lo)
        b = np.where(log, np.log10(self.hi), self.hi)
        x = a + unit * (b - a)
        return np.where(log, 10.0 ** x, x)

    def materials(self, materials: Materials, values: np.ndarray) -> Materials:
        """``materials`` with the varied parameters set to ``values`` (shape (P,))."""
        return materials.with_parameters(dict(zip(self.names, map(float, values))))

    def to_dict(self) -> dict:
        return {n: [float(a), float(b)] for n, a, b in zip(self.names, self.lo, self.hi)}


class ResistanceDecomposition:
    """``r_f(rho) = c_f + a_f . rho`` over all faces (flattened ``(3, n1, n2, n3)``).

    Attributes
    ----------
    c : ndarray (F,)
        Fixed part of the face resistances, m^2 K/W.
    a : ndarray (F, P)
        Coefficients of ``rho``: m (for ``rho = 1/k``) or dimensionless (for ``rho = R``).
    constant : ndarray of int64
        Faces whose resistance does not vary (affine term ``g = 1/c``).
    pure : list of ndarray of int64
        Per parameter, faces whose resistance is ``a_fi rho_i`` alone (``g`` affine in 1/rho_i).
    nonaffine : ndarray of int64
        Every other face.
    check_error : float
        Largest relative difference between the decomposition and the model at a check point.
    """

    def __init__(self, geometry: FaceGeometry, materials: Materials, box: ParameterBox) -> None:
        self._check_law(geometry, box)
        P = box.size
        lo_set = box.materials(materials, box.lo)
        r_lo = self._resistance(geometry, lo_set)
        rho_lo = box.to_rho(box.lo)
        a = np.empty((r_lo.size, P))
        for i in range(P):
            values = box.lo.copy()
            values[i] = box.hi[i]
            r_i = self._resistance(geometry, box.materials(materials, values))
            a[:, i] = (r_i - r_lo) / (box.to_rho(values)[i] - rho_lo[i])
        c = r_lo - a @ rho_lo
        scale = np.maximum(r_lo, 1e-300)
        rho_max = np.maximum(np.abs(rho_lo), np.abs(box.to_rho(box.hi)))
        a[np.abs(a) * rho_max[None, :] <= 1e-14 * scale[:, None]] = 0.0
        pure_face = (np.abs(c) <= 1e-12 * scale) & ((a != 0).sum(axis=1) == 1)
        c[pure_face] = 0.0
        self.c, self.a = c, a
        varying = (a != 0).any(axis=1)
        self.constant = np.flatnonzero(~varying)
        self.pure = [np.flatnonzero(pure_face & (a[:, i] != 0)) for i in range(P)]
        self.nonaffine = np.flatnonzero(varying & ~pure_face)
        mid = box.from_unit(np.full(P, 0.37))
        r_mid = self._resistance(geometry, box.materials(materials, mid))
        self.check_error = float(np.max(np.abs(self.resistance(box.to_rho(mid)[None])[0] - r_mid)
                                        / r_mid))
        if self.check_error > AFFINE_CHECK_RTOL:
            raise RuntimeError(f"the face resistances are not affine in (1/k, R) for this model "
                               f"(relative deviation {self.check_error:.2g}); the reduced basis "
                               "cannot decompose it")

    @staticmethod
    def _check_law(geometry: FaceGeometry, box: ParameterBox) -> None:
        """Ask the interface law whether its face resistances are affine in ``rho`` (1/k for
        conductivities, the value for resistances) for every varied parameter."""
        law = geometry.law
        for name, is_k in zip(box.names, box.is_conductivity):
            kind = parse_parameter(name)[0]
            coordinate = law.affine_in.get(kind)
            if coordinate is None:
                raise ValueError(f"bounds: the {law.name} interface law's face resistances are "
                                 f"not affine in {name}; the reduced basis cannot vary it")
            if coordinate != ("inverse" if is_k else "linear"):
                raise ValueError(f"bounds: the {law.name} interface law is affine in "
                                 f"{name} through {coordinate!r}, not as the parameter box maps it")

    @staticmethod
    def _resistance(geometry: FaceGeometry, mat: Materials) -> np.ndarray:
        g = geometry.conductances(mat).ravel()
        if np.any(g <= 0):
            raise ValueError("materials: insulating interfaces (g = 0) are outside what the "
                             "reduced basis models; give finite resistances")
        return 1.0 / g

    def resistance(self, rho: np.ndarray) -> np.ndarray:
        """Face resistances for ``rho`` (n, P) -> (n, F), m^2 K/W."""
        return self.c[None, :] + rho @ self.a.T


class ConductanceInterpolation:
    """Empirical interpolation of the conductances of the non-affine faces.

    ``g_f(rho) ~ sum_q theta_q(rho) U_fq`` with ``theta = B^-1 g_magic(rho)``: the exact
    conductance at Q "magic" faces, chosen greedily where the relative error over a training
    set of parameter sets is largest, until it is below ``tol``.

    Parameters
    ----------
    c, a : ndarray
        The decomposition of the non-affine faces (``c[nonaffine]``, ``a[nonaffine]``).
    rho_train, rho_check : ndarray (n, P)
        Parameter sets (as rho) to build on and to measure the error on afterwards.
    tol : float
        Largest relative error to reach on the training set.
    max_terms : int
        Upper limit on Q.

    Attributes
    ----------
    magic : ndarray of int64 (Q,)
        Positions (into the non-affine faces) of the magic faces.
    basis : ndarray (F_na, Q)
        The interpolation basis U, W/(m^2 K) per unit theta.
    b_inv : ndarray (Q, Q)
        Inverse of ``U[magic]`` (lower triangular with unit diagonal).
    train_error, check_error : float
        Largest relative error of the interpolated conductances on the training and check sets.
    """

    def __init__(self, c: np.ndarray, a: np.ndarray, rho_train: np.ndarray,
                 rho_check: np.ndarray, *, tol: float, max_terms: int) -> None:
        exact = 1.0 / (c[:, None] + a @ rho_train.T)  # (F_na, n)
        res = exact.copy()
        rel = np.empty_like(res)
        magic, cols = [], []
        err = 0.0
        for _ in range(max_terms):
            np.abs(res, out=rel)
            rel /= exact
            f, m = np.unravel_index(int(np.argmax(rel)), rel.shape)
            err = float(rel[f, m])
            if err <= tol:
                break
            u = res[:, m] / res[f, m]
            res -= np.outer(u, res[f, :])
            magic.append(int(f))
            cols.append(u)
        else:
            np.abs(res, out=rel)
            rel /= exact
            err = float(rel.max())
        del exact, res, rel
        self.magic = np.array(magic, dtype=np.int64)
        self.basis = np.column_stack(cols) if cols else np.zeros((c.size, 0))
        self.b_inv = np.linalg.inv(self.basis[self.magic]) if cols else np.zeros((0, 0))
        self.c_magic = c[self.magic]
        self.a_magic = a[self.magic]
        self.train_error = err
        self.check_error = self._error(c, a, rho_check)

    @property
    def n_terms(self) -> int:
        return int(self.magic.size)

    def coefficients(self, rho: np.ndarray) -> np.ndarray:
        """theta (n, Q) for rho (n, P)."""
        return interpolation_coefficients(self.c_magic, self.a_magic, self.b_inv, rho)

    def _error(self, c: np.ndarray, a: np.ndarray, rho: np.ndarray, chunk: int = 32) -> float:
        worst = 0.0
        for s in range(0, rho.shape[0], chunk):
            part = rho[s:s + chunk]
            exact = 1.0 / (c[:, None] + a @ part.T)
            approx = self.basis @ self.coefficients(part).T
            worst = max(worst, float(np.max(np.abs(approx - exact) / exact)))
        return worst


def interpolation_coefficients(c_magic: np.ndarray, a_magic: np.ndarray, b_inv: np.ndarray,
                               rho: np.ndarray) -> np.ndarray:
    """theta (n, Q) of the conductance interpolation: the exact conductances at the magic
    faces (``c_magic``, ``a_magic``: their decomposition) times ``b_inv^T``."""
    g_magic = 1.0 / (c_magic[None, :] + rho @ a_magic.T)
    return g_magic @ b_inv.T
