"""Exact and reference formulas for the effective conductivity of simple composites.

These are the benchmarks against which the voxel solvers (:mod:`itr_fv`, :mod:`itr_fft`) are
verified:

* :func:`sphere_array` -- periodic simple-cubic (``"sc"``), body-centred (``"bcc"``) and
  face-centred (``"fcc"``) cubic arrays of identical spheres with an interface (Kapitza)
  resistance, solved with Rayleigh's multipole method and Ewald lattice sums (converged to
  better than 1e-5 relative); :func:`sphere_array_details` also returns the multipole order used.
* :func:`hasselman_johnson` -- the Hasselman-Johnson (1987) dilute (Maxwell-Garnett type) formula
  for spheres with an interface resistance.
* :func:`maxwell_garnett` -- the Maxwell-Garnett (= Hashin-Shtrikman lower) formula.
* :func:`hashin_shtrikman` -- the Hashin-Shtrikman bounds of an isotropic two-phase composite.
* :func:`hashin_shtrikman_multiphase` -- the same bounds for any number of phases (in W/(m K)).
* :func:`laminate` -- exact conductivity of a periodic layered medium, normal and parallel to the
  layers, with interface resistances.

Conventions: ``k_ratio = k_p / k_m`` (particle over matrix conductivity, dimensionless, may be
``math.inf``), ``alpha = R k_m / a`` (R: interface resistance in m^2 K/W, k_m: matrix
conductivity in W/(m K), a: sphere radius in m; dimensionless). All composite results are
returned as the ratio ``k_eff / k_m`` except :func:`laminate`, which works in SI units.

The multipole method
--------------------
Around the sphere at the origin the temperature is expanded as
``T = sum_{l,m} (A_lm r^l + B_lm r^(-l-1)) Y_lm`` (Schmidt-normalised complex harmonics with
the Condon-Shortley phase; by symmetry the coefficients here are real and B_{l,-m} = B_{l,m}). The
regular part ``A`` is the applied field plus the singular parts of all other spheres re-expanded
about the origin (Rayleigh's identity); the re-expansion coefficients are lattice sums
``S_n^k = sum_{R != 0} Y_n^k(R/|R|) / |R|^(n+1)`` (n >= 4, absolutely convergent), evaluated by
Ewald summation; the conditionally convergent dipole sum (n = 2) is replaced by the Lorentz
cavity term ``4 pi / (3 V)``, its cubic-lattice value. Each sphere answers the l-th regular field
with ``B_lm = -gamma_l a^(2l+1) A_lm``, ``gamma_l = l (kappa_l - 1) / (l kappa_l + l + 1)``, where
``kappa_l = k_ratio / (1 + l alpha k_ratio)`` is the conductivity (over k_m) of the homogeneous
sphere equivalent to the coated one for the l-th multipole. The effective conductivity follows from
the dipole coefficient: ``k_eff/k_m = 1 + 4 pi B_10 / (V E_0)``. For a field along a cube axis
only odd l and m = 0 (mod 4) occur. The series is truncated at ``l <= order``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np
from scipy.special import gammaincc, gammaln

__all__ = [
    "LATTICES",
    "SphereArrayDetails",
    "f_max",
    "sphere_array",
    "sphere_array_details",
    "rayleigh_sc_coefficient",
    "lattice_sum_s4",
    "maxwell_garnett",
    "hasselman_johnson",
    "hashin_shtrikman",
    "hashin_shtrikman_multiphase",
    "laminate",
]

#: Names of the cubic sphere lattices understood by :func:`sphere_array`.
LATTICES = ("sc", "bcc", "fcc")

# Primitive vectors (rows) in units of the conventional cubic cell edge, nearest-neighbour
# distance and primitive-cell volume (same units).
_PRIMITIVE = {
    "sc": np.eye(3),
    "bcc": 0.5 * np.array([[-1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, -1.0]]),
    "fcc": 0.5 * np.array([[0.0, 1.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 0.0]]),
}
_NEAREST = {"sc": 1.0, "bcc": math.sqrt(3.0) / 2.0, "fcc": 1.0 / math.sqrt(2.0)}

# Ewald cut-offs: exp(-_EWALD_X) ~ 2e-22 is the size of the neglected terms.
_EWALD_X = 50.0
_DEFAULT_TOL = 1e-6
_DEFAULT_MAX_ORDER = 255
_START_ORDER = 5


# ----------------------------------------------------------------------------- input checks
def _check_lattice(lattice: str) -> str:
    if not isinstance(lattice, str) or lattice.lower() not in LATTICES:
        raise ValueError(f"lattice must be one of {LATTICES}, got {lattice!r}")
    return lattice.lower()


def _check_real(name: str, value, *, allow_inf: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if math.isnan(x):
        raise ValueError(f"{name} must not be NaN")
    if math.isinf(x) and not (allow_inf and x > 0):
        raise ValueError(f"{name} must be finite, got {x}")
    return x


def _check_k_ratio(k_ratio) -> float:
    k = _check_real("k_ratio", k_ratio, allow_inf=True)
    if k <= 0.0:
        raise ValueError(f"k_ratio must be > 0 (k_p / k_m), got {k}")
    return k


def _check_alpha(alpha) -> float:
    x = _check_real("alpha", alpha, allow_inf=True)
    if x < 0.0:
        raise ValueError(f"alpha must be >= 0 (alpha = R k_m / a), got {x}")
    return x


def _check_fraction(f, upper: float, what: str) -> float:
    x = _check_real("f", f)
    if not 0.0 < x < upper:
        raise ValueError(f"f must lie in (0, {upper:.6g}) ({what}), got {x}")
    return x


def f_max(lattice: str) -> float:
    """Volume fraction at which the spheres of a cubic lattice touch.

    Parameters
    ----------
    lattice : {"sc", "bcc", "fcc"}

    Returns
    -------
    float
        ``pi/6`` (sc), ``sqrt(3) pi/8`` (bcc), ``sqrt(2) pi/6`` (fcc); dimensionless.
    """
    lat = _check_lattice(lattice)
    d = _NEAREST[lat]
    vol = abs(np.linalg.det(_PRIMITIVE[lat]))
    return 4.0 * math.pi * (d / 2.0) ** 3 / (3.0 * vol)


# ----------------------------------------------------------------------- harmonics and sums
def _schmidt_harmonics(cos_t: np.ndarray, sin_t: np.ndarray, n_max: int, ms: Sequence[int]
                       ) -> dict[int, np.ndarray]:
    """Schmidt semi-normalised associated Legendre functions (Condon-Shortley phase).

    ``P[m][n - m, :] = sqrt((n-m)!/(n+m)!) P_n^m(cos t)`` for ``m <= n <= n_max``, for each
    requested ``m >= 0``. Stable three-term recurrence in n; |values| <= 1.
    """
    out: dict[int, np.ndarray] = {}
    ms = sorted(set(int(m) for m in ms))
    pmm = np.ones_like(cos_t)
    m_done = 0
    for m in ms:
        for mm in range(m_done + 1, m + 1):  # P_mm = -sqrt((2m-1)/(2m)) sin P_{m-1,m-1}
            pmm = -math.sqrt((2.0 * mm - 1.0) / (2.0 * mm)) * sin_t * pmm
        m_done = max(m_done, m)
        rows = np.empty((n_max - m + 1, cos_t.size))
        rows[0] = pmm
        if n_max > m:
            rows[1] = math.sqrt(2.0 * m + 1.0) * cos_t * pmm
        for n in range(m + 2, n_max + 1):
            rows[n - m] = ((2.0 * n - 1.0) * cos_t * rows[n - m - 1]
                           - math.sqrt((n + m - 1.0) * (n - m - 1.0)) * rows[n - m - 2]
                           ) / math.sqrt((n - m) * (n + m))
        out[m] = rows
    return out


def _lattice_points(basis: np.ndarray, cutoff: float) -> np.ndarray:
    """All non-zero points ``c @ basis`` (c integer) with norm <= cutoff."""
    inv = np.linalg.inv(basis)
    n = int(math.ceil(cutoff * np.max(np.linalg.norm(inv, axis=0)))) + 1
    r = np.arange(-n, n + 1)
    c = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = c @ basis
    norm = np.linalg.norm(pts, axis=1)
    keep = (norm > 0) & (norm <= cutoff)
    return pts[keep]


@lru_cache(maxsize=None)
def _lattice_sums(lattice: str, n_max: int, eta_scale: float = 1.0) -> np.ndarray:
    """Scaled lattice sums ``d^(n+1) S_n^k`` for even n <= n_max and k = 0, 4, 8, ... <= n.

    ``S_n^k = sum_{R != 0} Yhat_n^k(R) / |R|^(n+1)`` over the Bravais lattice (Schmidt-normalised
    harmonics with Condon-Shortley phase), d = nearest-neighbour distance. Evaluated by Ewald
    summation (real-space incomplete-gamma part + reciprocal Gaussian part; the G = 0 term vanishes
    because the solid harmonic vanishes at the origin). Returned as a real array
    ``out[n, k]`` (entries with odd n, k not a multiple of 4, or k > n are zero). ``S_2`` is not
    computed (set to 0): it vanishes on a cubic lattice and the dipole sum is handled by the
    Lorentz term. ``eta_scale`` changes the Ewald splitting parameter (for self-checks only).
    """
    basis = _PRIMITIVE[lattice] / _NEAREST[lattice]  # nearest-neighbour distance = 1
    vol = abs(np.linalg.det(basis))
    recip = 2.0 * math.pi * np.linalg.inv(basis).T
    eta = eta_scale * math.sqrt(math.pi) / vol ** (1.0 / 3.0)
    r_cut = math.sqrt(_EWALD_X) / eta
    g_cut = 2.0 * eta * math.sqrt(_EWALD_X)
    real_pts = _lattice_points(basis, r_cut)
    rec_pts = _lattice_points(recip, g_cut)
    ks = list(range(0, n_max + 1, 4))
    out = np.zeros((n_max + 1, n_max + 1))
    parts = []
    for pts in (real_pts, rec_pts):
        rho = np.linalg.norm(pts, axis=1)
        cos_t = pts[:, 2] / rho
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t ** 2))
        phi = np.arctan2(pts[:, 1], pts[:, 0])
        leg = _schmidt_harmonics(cos_t, sin_t, n_max, ks)
        # real parts of exp(i k phi); the sums of the imaginary parts vanish by the mirror symmetry
        # y -> -y of all three lattices (and the result is real by construction below).
        cosk = {k: np.cos(k * phi) for k in ks}
        parts.append((rho, leg, cosk))
    (r_rho, r_leg, r_cos), (g_rho, g_leg, g_cos) = parts
    log_pref = math.log(4.0 * math.pi ** 1.5 / vol)
    for n in range(4, n_max + 1, 2):
        w_real = gammaincc(n + 0.5, (eta * r_rho) ** 2) * r_rho ** (-(n + 1.0))
        # (-i/2)^n with n even = (-1)^(n/2) 2^-n; log-domain to avoid overflow of G^(n-2)
        log_w = (log_pref - gammaln(n + 0.5) - n * math.log(2.0) + (n - 2.0) * np.log(g_rho)
                 - g_rho ** 2 / (4.0 * eta ** 2))
        w_rec = (-1.0) ** (n // 2) * np.exp(log_w)
        for k in ks:
            if k > n:
                break
            out[n, k] = (np.dot(w_real, r_leg[k][n - k] * r_cos[k])
                         + np.dot(w_rec, g_leg[k][n - k] * g_cos[k]))
    return out


def _lattice_sums_upto(lattice: str, n_max: int) -> np.ndarray:
    """Cached lattice sums, computed in blocks (n_max rounded up to a multiple of 64)."""
    return _lattice_sums(lattice, 64 * max(1, math.ceil(n_max / 64)))


@lru_cache(maxsize=None)
def _interaction_block(lattice: str, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         np.ndarray]:
    """Geometry part of the multipole system for multipoles l <= order (odd l, m = 0 mod 4).

    Unknowns are ordered by l, then m (m >= 0; the +-m pair is folded since B_{l,-m} = B_{l,m}
    by the mirror symmetry y -> -y), so the system of a lower order is a leading block.
    Returns ``(ls, ms, sign, logabs)``: in nearest-neighbour units and for sphere radius rho
    (also in those units) the coefficient of the regular harmonic (l_i, m_i) at the origin
    produced by unit singular harmonics (l_j, +-m_j) on all the other spheres is
    ``sign[i, j] * exp(logabs[i, j] + (l_i + l_j + 1) log rho)`` (Schmidt-normalised
    harmonics). The log form keeps the binomial factors (up to 2^(l_i + l_j)) finite.
    """
    idx = [(l, m) for l in range(1, order + 1, 2) for m in range(0, l + 1, 4)]
    ls = np.array([p[0] for p in idx])
    ms = np.array([p[1] for p in idx])
    sums = _lattice_sums_upto(lattice, 2 * order)
    j = ls[:, None]
    q = ms[:, None]
    lcol = ls[None, :]
    terms = []
    for msign in (1, -1):
        mcol = msign * ms[None, :]
        n = j + lcol
        k = mcol - q
        # translation N_l^m(r - R) = sum_{j,q} (-1)^(q+l) M_j^q(r) N_{j+l}^{m-q}(R), summed over
        # R != 0; S_n^{-k} = (-1)^k conj(S_n^k) = S_n^k (k even, real sums)
        s = sums[n, np.abs(k)] * (-1.0) ** ((q + lcol) % 2)
        # sqrt((n+k)! (n-k)! / ((j+q)! (j-q)! (l+m)! (l-m)!)) = sqrt(C(n+k, j-q) C(n-k, j+q))
        logc = 0.5 * (gammaln(n + k + 1.0) - gammaln(j - q + 1.0) - gammaln(lcol + mcol + 1.0)
                      + gammaln(n - k + 1.0) - gammaln(j + q + 1.0) - gammaln(lcol - mcol + 1.0))
        if msign == -1:
            s = np.where(ms[None, :] > 0, s, 0.0)
        terms.append((s, logc))
    # combine the two folded terms in log form: both share the row/column scaling
    (s1, c1), (s2, c2) = terms
    cmax = np.maximum(c1, c2)
    val = s1 * np.exp(c1 - cmax) + s2 * np.exp(c2 - cmax)
    total_sign = np.sign(val)
    with np.errstate(divide="ignore"):
        logabs = np.log(np.abs(val)) + cmax
    return ls, ms, total_sign, logabs


def _order_bucket(order: int) -> int:
    """Orders are computed in blocks 31, 63, 95, ... (the block is cached per lattice)."""
    return 32 * math.ceil((order + 1) / 32) - 1


def _interaction_matrix(lattice: str, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                          np.ndarray]:
    """Leading block of :func:`_interaction_block` for multipoles l <= order (cached blocks)."""
    ls, ms, sign, logabs = _interaction_block(lattice, _order_bucket(order))
    size = int(np.searchsorted(ls, order, side="right"))
    return ls[:size], ms[:size], sign[:size, :size], logabs[:size, :size]


def _gamma_l(l: int | np.ndarray, k_ratio: float, alpha: float) -> np.ndarray:
    """Multipole response gamma_l = l (kappa_l - 1) / (l kappa_l + l + 1) of a coated sphere."""
    l = np.asarray(l, dtype=float)
    if alpha == 0.0:
        kappa = np.full_like(l, k_ratio)
    elif math.isinf(k_ratio):
        kappa = 1.0 / (l * alpha)
    else:
        kappa = k_ratio / (1.0 + l * alpha * k_ratio)
    with np.errstate(invalid="ignore"):
        g = np.where(np.isinf(kappa), 1.0, l * (kappa - 1.0) / (l * kappa + l + 1.0))
    return g


def _solve(lattice: str, f: float, k_ratio: float, alpha: float, order: int) -> float:
    ls, ms, sign, wlog = _interaction_matrix(lattice, order)
    vol = abs(np.linalg.det(_PRIMITIVE[lattice])) / _NEAREST[lattice] ** 3
    rho = (3.0 * f * vol / (4.0 * math.pi)) ** (1.0 / 3.0)  # sphere radius / nearest distance
    gam = _gamma_l(ls, k_ratio, alpha)
    expo = (ls[:, None] + ls[None, :] + 1.0) * math.log(rho)
    w = sign * np.exp(wlog + expo)
    w[0, 0] += -4.0 * math.pi / (3.0 * vol) * rho ** 3  # Lorentz cavity term (dipole-dipole)
    # unknowns u_i = B_i / rho^(l_i + 1/2):  (I + diag(gamma) W) u = gamma_1 rho^(3/2) e_0
    a = np.eye(len(ls)) + gam[:, None] * w
    rhs = np.zeros(len(ls))
    rhs[0] = gam[0] * rho ** 1.5  # zero for a neutral inclusion: then u = 0 and k_eff = k_m
    u = np.linalg.solve(a, rhs)
    b10 = u[0] * rho ** 1.5
    return float(1.0 + 4.0 * math.pi * b10 / vol)


@dataclass(frozen=True)
class SphereArrayDetails:
    """Result of :func:`sphere_array_details`.

    Attributes
    ----------
    value : float
        ``k_eff / k_m`` (dimensionless).
    order : int
        Highest multipole degree l used (odd; l = 1 is the dipole).
    previous_order : int
        The order before the last increase (``last_change`` compares the two).
    last_change : float
        Relative change ``|value(order) - value(previous_order)| / value(order)``.
    converged : bool
        Whether the requested tolerance was met (True when ``order`` was given explicitly).
    n_unknowns : int
        Size of the multipole linear system (multipoles with odd l <= order, m = 0 mod 4, m >= 0).
    """

    value: float
    order: int
    previous_order: int
    last_change: float
    converged: bool
    n_unknowns: int


def _next_order(order: int) -> int:
    """Order schedule of the automatic search: +2 up to 21, then about +12 %."""
    return order + (2 if order < 21 else 2 * math.ceil(order / 16))


def sphere_array_details(lattice: str, f: float, k_ratio: float, alpha: float,
                         order: int | None = None, *, tol: float = _DEFAULT_TOL,
                         max_order: int = _DEFAULT_MAX_ORDER) -> SphereArrayDetails:
    """Effective conductivity of a cubic array of coated spheres, with convergence information.

    Same arguments as :func:`sphere_array`. When ``order`` is None the multipole order is raised
    from 5 (in steps of 2 up to 21, then in steps of about 12 %) until the relative changes at
    two successive increases are both below ``tol``; a :class:`RuntimeWarning` is issued (and
    ``converged`` is False) if ``max_order`` is reached first. When ``order`` is given (odd; an
    even value is rounded up), ``last_change`` compares with ``order - 2``.

    Returns
    -------
    SphereArrayDetails
    """
    lat = _check_lattice(lattice)
    f = _check_fraction(f, f_max(lat), f"the spheres of the {lat} lattice touch at f_max")
    k_ratio = _check_k_ratio(k_ratio)
    alpha = _check_alpha(alpha)
    if order is not None:
        if isinstance(order, bool) or int(order) != order or order < 1:
            raise ValueError(f"order must be a positive integer, got {order!r}")
        order = int(order) | 1  # odd
        value = _solve(lat, f, k_ratio, alpha, order)
        prev_order = max(order - 2, 1)
        prev = _solve(lat, f, k_ratio, alpha, prev_order) if order > 1 else 1.0
        n = len(_interaction_matrix(lat, order)[0])
        return SphereArrayDetails(value, order, prev_order, abs(value - prev) / abs(value),
                                  True, n)
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol!r}")
    if int(max_order) != max_order or max_order < _START_ORDER:
        raise ValueError(f"max_order must be an integer >= {_START_ORDER}, got {max_order!r}")
    prev_order = _START_ORDER - 2
    prev = _solve(lat, f, k_ratio, alpha, prev_order)
    order = _START_ORDER
    small = 0
    while True:
        value = _solve(lat, f, k_ratio, alpha, order)
        change = abs(value - prev) / abs(value)
        small = small + 1 if change < tol else 0
        nxt = min(_next_order(order), int(max_order) | 1)
        if small >= 2 or nxt <= order:
            break
        prev, prev_order, order = value, order, nxt
    converged = small >= 2
    if not converged:
        import warnings
        warnings.warn(f"sphere_array({lat!r}, f={f}, k_ratio={k_ratio}, alpha={alpha}) did not "
                      f"converge to {tol} by order {order} (last change {change:.2e})",
                      RuntimeWarning, stacklevel=2)
    n = len(_interaction_matrix(lat, order)[0])
    return SphereArrayDetails(value, order, prev_order, change, converged, n)


def sphere_array(lattice: str, f: float, k_ratio: float, alpha: float,
                 order: int | None = None, *, tol: float = _DEFAULT_TOL,
                 max_order: int = _DEFAULT_MAX_ORDER) -> float:
    """Effective conductivity ratio ``k_eff / k_m`` of a cubic array of spheres with an ITR.

    Rayleigh's multipole method with Ewald lattice sums (see the module docstring); the
    effective tensor of a cubic array is isotropic.

    Parameters
    ----------
    lattice : {"sc", "bcc", "fcc"}
        Simple, body-centred or face-centred cubic arrangement of the sphere centres.
    f : float
        Sphere volume fraction, ``0 < f < f_max(lattice)`` (dimensionless).
    k_ratio : float
        ``k_p / k_m``, particle over matrix conductivity (dimensionless, > 0, may be ``math.inf``).
    alpha : float
        ``R k_m / a`` >= 0 with R the interface resistance (m^2 K/W), k_m the matrix conductivity
        (W/(m K)) and a the sphere radius (m); may be ``math.inf`` (insulating interface).
    order : int, optional
        Highest multipole degree (odd; 1 = dipoles only, the Maxwell-Garnett-like truncation).
        Default: chosen automatically, see ``tol``.
    tol : float, keyword-only
        Relative change below which (twice in a row) the automatic order stops increasing.
        The default 1e-6 gives results converged to better than 1e-5 relative.
    max_order : int, keyword-only
        Upper limit of the automatic order.

    Returns
    -------
    float
        ``k_eff / k_m`` (dimensionless).

    Raises
    ------
    ValueError
        For an unknown ``lattice``, ``f`` outside (0, f_max), ``k_ratio`` <= 0 or NaN,
        ``alpha`` < 0 or NaN.

    Notes
    -----
    A sphere with interface resistance R answers the l-th multipole like a homogeneous sphere of
    conductivity ``k_p / (1 + l R k_p / a)``. With ``alpha = 1 - 1/k_ratio`` the dipole response
    vanishes (neutral inclusion) and the result is exactly 1. References: Lord Rayleigh, Phil. Mag.
    34 (1892) 481; McKenzie, McPhedran & Derrick, Proc. R. Soc. A 362 (1978) 211; Cheng &
    Torquato, Proc. R. Soc. A 453 (1997) 145 (interface resistance).
    """
    if order is not None:  # fixed order: one solve (the details also solve order - 2)
        lat = _check_lattice(lattice)
        f = _check_fraction(f, f_max(lat), f"the spheres of the {lat} lattice touch at f_max")
        k_ratio = _check_k_ratio(k_ratio)
        alpha = _check_alpha(alpha)
        if isinstance(order, bool) or int(order) != order or order < 1:
            raise ValueError(f"order must be a positive integer, got {order!r}")
        return _solve(lat, f, k_ratio, alpha, int(order) | 1)
    return sphere_array_details(lattice, f, k_ratio, alpha, None, tol=tol,
                                max_order=max_order).value


def rayleigh_sc_coefficient(lattice: str = "sc") -> float:
    """Coefficient C of the leading multipole correction to Maxwell-Garnett (Rayleigh's formula).

    Keeping the dipoles and the octupoles they excite, the multipole system gives
    ``k_eff/k_m = 1 + 3 f / (1/beta_1 - f - C beta_3 f^(10/3) + O(f^(14/3)))`` with
    ``beta_1 = (k_r - 1)/(k_r + 2)`` and ``beta_3 = (k_r - 1)/(k_r + 4/3)``. Only the m = 0
    octupole couples to the dipole (the m = +-4 couplings carry a zero binomial factor), so
    ``C = 16 S_4^2 (3 V / (4 pi))^(10/3)`` with ``S_4 = sum_{R != 0} P_4(cos theta_R) / R^5`` the
    lattice sum and V the primitive-cell volume (any length unit). For the simple-cubic lattice
    this is Rayleigh's coefficient (1.65 in Rayleigh 1892, corrected to 1.305 by McKenzie,
    McPhedran & Derrick 1978).

    Parameters
    ----------
    lattice : {"sc", "bcc", "fcc"}

    Returns
    -------
    float
        C (dimensionless).
    """
    lat = _check_lattice(lattice)
    s4 = _lattice_sums_upto(lat, 4)[4, 0]  # nearest-neighbour distance = 1
    vol = abs(np.linalg.det(_PRIMITIVE[lat])) / _NEAREST[lat] ** 3
    return 16.0 * s4 ** 2 * (3.0 * vol / (4.0 * math.pi)) ** (10.0 / 3.0)


def lattice_sum_s4(lattice: str) -> float:
    """Lattice sum ``S_4 = sum_{R != 0} P_4(cos theta_R) / |R|^5`` (Ewald), cube edge = 1.

    ``theta_R`` is the angle between R and a cube axis; R runs over the Bravais lattice with unit
    conventional cube edge (sc: 3.10823, Rayleigh's constant).
    """
    lat = _check_lattice(lattice)
    return float(_lattice_sums_upto(lat, 4)[4, 0] / _NEAREST[lat] ** 5)


# -------------------------------------------------------------------------- closed forms
def maxwell_garnett(f: float, k_ratio: float) -> float:
    """Maxwell-Garnett (Maxwell 1873) conductivity ratio of dilute spheres, ``k_eff / k_m``.

    ``(k_r (1 + 2f) + 2 (1 - f)) / (k_r (1 - f) + 2 + f)``; for ``k_ratio = inf`` the limit
    ``(1 + 2f)/(1 - f)``. Equal to the Hashin-Shtrikman lower bound for ``k_ratio >= 1``.

    Parameters
    ----------
    f : float
        Sphere volume fraction in [0, 1).
    k_ratio : float
        ``k_p / k_m`` > 0, may be ``math.inf``.
    """
    f = _check_real("f", f)
    if not 0.0 <= f < 1.0:
        raise ValueError(f"f must lie in [0, 1), got {f}")
    k = _check_k_ratio(k_ratio)
    if math.isinf(k):
        return (1.0 + 2.0 * f) / (1.0 - f)
    return (k * (1.0 + 2.0 * f) + 2.0 * (1.0 - f)) / (k * (1.0 - f) + 2.0 + f)


def hasselman_johnson(f: float, k_ratio: float, alpha: float) -> float:
    """Hasselman-Johnson (1987) conductivity ratio ``k_eff / k_m`` for spheres with an ITR.

    Maxwell-Garnett with the sphere conductivity replaced by the dipole-equivalent value
    ``kappa = k_r / (1 + alpha k_r)`` (``alpha = R k_m / a``)::

        k_eff/k_m = (kappa (1 + 2 f) + 2 (1 - f)) / (kappa (1 - f) + 2 + f)
                  = (k_r (1 + 2f + 2 alpha (1 - f)) + 2 (1 - f))
                    / (k_r (1 - f + alpha (2 + f)) + 2 + f)

    which is Hasselman & Johnson's eq. with their ``a_K / a = alpha``.

    Parameters
    ----------
    f : float
        Sphere volume fraction in [0, 1) (dimensionless).
    k_ratio : float
        ``k_p / k_m`` > 0, may be ``math.inf`` (then ``kappa = 1/alpha``).
    alpha : float
        ``R k_m / a`` >= 0 (dimensionless), may be ``math.inf``.

    Returns
    -------
    float
        ``k_eff / k_m``.

    References
    ----------
    D. P. H. Hasselman and L. F. Johnson, J. Compos. Mater. 21 (1987) 508-515.
    """
    k = _check_k_ratio(k_ratio)
    a = _check_alpha(alpha)
    if a == 0.0:
        kappa = k
    elif math.isinf(k):
        kappa = 1.0 / a
    else:
        kappa = k / (1.0 + a * k)
    if kappa == 0.0:  # insulating interface
        f = _check_real("f", f)
        if not 0.0 <= f < 1.0:
            raise ValueError(f"f must lie in [0, 1), got {f}")
        return 2.0 * (1.0 - f) / (2.0 + f)
    return maxwell_garnett(f, kappa)


def hashin_shtrikman(f: float, k_ratio: float) -> tuple[float, float]:
    """Hashin-Shtrikman bounds on ``k_eff / k_m`` of an isotropic two-phase composite.

    Phase 1 (matrix, conductivity 1 after scaling) at fraction ``1 - f``, phase 2 (``k_ratio``)
    at fraction ``f``, perfect interfaces::

        HS(k1 <- k2) = k1 + f2 / (1/(k2 - k1) + f1/(3 k1))

    evaluated with the less conducting phase as reference gives the lower bound, with the more
    conducting one the upper bound.

    Parameters
    ----------
    f : float
        Volume fraction of the inclusion phase in [0, 1].
    k_ratio : float
        ``k_p / k_m`` > 0; ``math.inf`` gives an infinite upper bound.

    Returns
    -------
    (lower, upper) : tuple of float
        Bounds on ``k_eff / k_m`` (dimensionless).

    References
    ----------
    Z. Hashin and S. Shtrikman, J. Appl. Phys. 33 (1962) 3125-3131.
    """
    f = _check_real("f", f)
    if not 0.0 <= f <= 1.0:
        raise ValueError(f"f must lie in [0, 1], got {f}")
    k = _check_k_ratio(k_ratio)

    def hs(k1: float, f1: float, k2: float, f2: float) -> float:
        # HS estimate with phase 1 (k1, fraction f1) as the reference medium
        if k2 == k1 or f2 == 0.0:
            return k1
        if math.isinf(k1):
            return math.inf
        if math.isinf(k2):
            return k1 + 3.0 * k1 * f2 / f1 if f1 > 0 else math.inf
        return k1 + f2 / (1.0 / (k2 - k1) + f1 / (3.0 * k1))

    a = hs(1.0, 1.0 - f, k, f)   # matrix as reference
    b = hs(k, f, 1.0, 1.0 - f)   # inclusion as reference
    return (min(a, b), max(a, b))


def hashin_shtrikman_multiphase(fractions: Sequence[float], conductivities: Sequence[float]
                                ) -> tuple[float, float]:
    """Hashin-Shtrikman bounds of an isotropic composite of any number of phases, W/(m K).

    With perfect interfaces, volume fractions ``f_i`` (summing to 1) and conductivities
    ``k_i``::

        k_HS(k_ref) = [ sum_i f_i / (k_i + 2 k_ref) ]^-1 - 2 k_ref

    is the lower bound for ``k_ref = min k_i`` and the upper bound for ``k_ref = max k_i``.
    An interface resistance only lowers the effective conductivity, so the upper bound
    holds for any resistance >= 0; for two phases both equal :func:`hashin_shtrikman`.

    Parameters
    ----------
    fractions : sequence of float
        Volume fractions in [0, 1], summing to 1 (to 1e-9).
    conductivities : sequence of float
        Phase conductivities, W/(m K), finite and > 0, one per fraction.

    Returns
    -------
    (lower, upper) : tuple of float
        Bounds on the effective conductivity, W/(m K).

    References
    ----------
    Z. Hashin and S. Shtrikman, J. Appl. Phys. 33 (1962) 3125-3131.
    """
    f = np.asarray([_check_real("fractions", x) for x in fractions], dtype=np.float64)
    k = np.asarray([_check_real("conductivities", x) for x in conductivities],
                   dtype=np.float64)
    if f.size == 0 or f.shape != k.shape:
        raise ValueError("fractions, conductivities: expected two non-empty sequences of the "
                         f"same length, got {f.size} and {k.size}")
    if np.any(f < 0) or np.any(f > 1) or abs(float(f.sum()) - 1.0) > 1e-9:
        raise ValueError(f"fractions: expected values in [0, 1] summing to 1, got {f.tolist()}")
    if np.any(k <= 0):
        raise ValueError(f"conductivities: expected values > 0 W/(m K), got {k.tolist()}")

    def bound(k_ref: float) -> float:
        return float(1.0 / np.sum(f / (k + 2.0 * k_ref)) - 2.0 * k_ref)

    present = k[f > 0]
    return bound(float(present.min())), bound(float(present.max()))


def laminate(thicknesses_m: Sequence[float], conductivities: Sequence[float],
             resistances: float | Sequence[float] = 0.0, *,
             direction: str = "normal") -> float:
    """Effective conductivity of a periodic laminate (stack of plane layers), W/(m K).

    Layer i has thickness ``l_i`` (m) and conductivity ``k_i`` (W/(m K)); ``L = sum l_i`` is the
    period. The n layers of one period have n interfaces (the last one joins layer n to layer 1 of
    the next period), interface j (after layer j) with resistance ``R_j`` (m^2 K/W).

    * ``direction="normal"`` (heat flux across the layers, series)::

          k = L / (sum_i l_i / k_i + sum_j R_j)

    * ``direction="parallel"`` (flux along the layers, arithmetic mean; the interface
      resistances carry no flux and do not enter)::

          k = sum_i l_i k_i / L

    Parameters
    ----------
    thicknesses_m : sequence of float
        Layer thicknesses in m, each > 0.
    conductivities : sequence of float
        Layer conductivities in W/(m K), each > 0 (``inf`` allowed).
    resistances : float or sequence of float, default 0
        Interface resistances in m^2 K/W, >= 0 (``inf`` allowed): a scalar applies to each of the
        n interfaces, a sequence must have length n.
    direction : {"normal", "parallel"}, keyword-only

    Returns
    -------
    float
        Effective conductivity in W/(m K).
    """
    lengths = np.atleast_1d(np.asarray(thicknesses_m, dtype=float))
    ks = np.atleast_1d(np.asarray(conductivities, dtype=float))
    if lengths.ndim != 1 or lengths.size == 0:
        raise ValueError("thicknesses_m must be a non-empty 1-D sequence")
    if ks.shape != lengths.shape:
        raise ValueError(f"conductivities must have one entry per layer ({lengths.size}), "
                         f"got {ks.size}")
    if not np.all(np.isfinite(lengths)) or np.any(lengths <= 0):
        raise ValueError("thicknesses_m must be finite and > 0")
    if np.any(np.isnan(ks)) or np.any(ks <= 0):
        raise ValueError("conductivities must be > 0 (inf allowed)")
    res = np.asarray(resistances, dtype=float)
    if res.ndim == 0:
        res = np.full(lengths.size, float(res))
    if res.shape != lengths.shape:
        raise ValueError(f"resistances must be a scalar or have one entry per interface "
                         f"({lengths.size} for {lengths.size} layers), got {res.size}")
    if np.any(np.isnan(res)) or np.any(res < 0):
        raise ValueError("resistances must be >= 0 (inf allowed)")
    total = float(lengths.sum())
    if direction == "normal":
        series = float(np.sum(lengths / ks) + np.sum(res))
        return math.inf if series == 0.0 else total / series
    if direction == "parallel":
        return float(np.sum(lengths * ks) / total)
    raise ValueError(f"direction must be 'normal' or 'parallel', got {direction!r}")
