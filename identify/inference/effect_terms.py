"""Candidate physical effects as terms of the identification's joint model (issue 60).

An effect the model may lack is not a second model with its own tables and corrections: it
is extra parameters of the one joint model of :mod:`.joint` (the same reduced bases, the
same shipped corrections, the same likelihood, priors and nuisance inputs), entering where
its physics enters:

``ratio``      ln k += ln r_f(R_f, x): the effect's ratio on the first replica of the
               formulation's cheap RVE (its own full solves, :mod:`itr_identify.discrepancy.
               joint_effects`) on a grid of log10 R and the parameter ``x``, bilinear; R_f the
               formulation's resistance as the joint model reads it (scaled by the matrix
               conductivity; a two-filler formulation's fraction-weighted mean of its two);
``porosity``   the matrix's conductivity of the formulation times the Maxwell-Eucken factor
               of air voids at the void fraction's share of the matrix, through the model's
               exact matrix scaling;
``matrix``     the matrix conductivity's prior widened from the stated sd to the effect's
               physical range (the parameter is the model's own ``ln k_<matrix>``);
``tester``     the tester's apparent conductivity ``k / (1 + R_c k <1/t>)``, ``t`` the
               samples' thicknesses (or an assumed one);
``batch``      a formulation's own error of relative sd ``sd |d ln k / d phi|`` (the slope from
               the fraction ratio table), added to the likelihood's variance;
``thinning``   the model's film (``film_nm``, the film at the reference fraction) thinning
               linearly with the filler fraction to zero at the end point ``phi_end`` (a
               parameter: the fraction where the powder's packing squeezes the film out).

Each effect also says what it does to a sample's composition (filler and void volume
fraction), which the density column reads (:meth:`BoundEffect.composition`).

Every parameter has a prior over its physical range with the range's source
(:class:`EffectParameter`); the nominal value (no effect) lies in it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "AIR_CONDUCTIVITY",
    "KINDS",
    "BoundEffect",
    "EffectParameter",
    "JointEffect",
    "RatioTable",
]

#: Conductivity of the air in voids, W/(m K).
AIR_CONDUCTIVITY = 0.026
#: How an effect enters the joint model (module notes).
KINDS = ("ratio", "porosity", "matrix", "tester", "batch", "thinning")


@dataclass(frozen=True)
class EffectParameter:
    """One parameter of an effect and its prior, uniform over its physical range.

    Attributes
    ----------
    name : str
        Its column in the joint space (with the unit in it).
    low, high : float
        The physical range (the prior's support).
    nominal : float
        The value at which the effect is absent (inside the range).
    source : str
        Where the range comes from.
    """

    name: str
    low: float
    high: float
    nominal: float
    source: str

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise ValueError(f"{self.name}: expected a finite range low < high, got "
                             f"{self.low!r}, {self.high!r}")
        if not self.low <= self.nominal <= self.high:
            raise ValueError(f"{self.name}: the nominal value {self.nominal!r} lies outside "
                             f"its range {self.low!r} - {self.high!r}")


@dataclass(frozen=True, eq=False)
class RatioTable:
    """``ln(k_effect / k_base)`` of one formulation on a grid of log10 R (m^2 K/W) and the
    effect's parameter, bilinear in both and held at the grid's edges.

    Attributes
    ----------
    log10_r : ndarray
        (nR,) increasing.
    x : ndarray
        (nx,) increasing parameter values (the nominal among them, where the ratio is 0).
    ln_ratio : ndarray
        (nR, nx).
    """

    log10_r: np.ndarray
    x: np.ndarray
    ln_ratio: np.ndarray

    def __post_init__(self) -> None:
        r, x, t = (np.asarray(a, dtype=float) for a in (self.log10_r, self.x, self.ln_ratio))
        if r.ndim != 1 or x.ndim != 1 or t.shape != (r.size, x.size):
            raise ValueError(f"ln_ratio: expected shape ({r.size}, {x.size}) over log10_r and "
                             f"x, got {t.shape}")
        if r.size < 2 or x.size < 2 or np.any(np.diff(r) <= 0) or np.any(np.diff(x) <= 0):
            raise ValueError("log10_r, x: expected at least 2 increasing values each")
        if not np.all(np.isfinite(t)):
            raise ValueError("ln_ratio: expected finite values")

    def __call__(self, log10_r: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The ratio's logarithm at the points ``(log10_r, x)`` (broadcast together)."""
        r = np.asarray(self.log10_r, dtype=float)
        g = np.asarray(self.x, dtype=float)
        t = np.asarray(self.ln_ratio, dtype=float)
        i, a = _cell(r, np.asarray(log10_r, dtype=float))
        j, b = _cell(g, np.asarray(x, dtype=float))
        return ((1 - a) * (1 - b) * t[i, j] + a * (1 - b) * t[i + 1, j]
                + (1 - a) * b * t[i, j + 1] + a * b * t[i + 1, j + 1])

    def slope_at_nominal(self, log10_r: np.ndarray, nominal: float) -> np.ndarray:
        """d ln k / d x at ``nominal`` (one-sided, towards the grid's other points)."""
        g = np.asarray(self.x, dtype=float)
        k = int(np.argmin(np.abs(g - nominal)))
        other = k - 1 if k > 0 else k + 1
        lr = np.asarray(log10_r, dtype=float)
        return (self(lr, np.full(lr.shape, g[other])) - self(lr, np.full(lr.shape, g[k]))) \
            / (g[other] - g[k])


def _cell(axis: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the grid cell holding each of ``v`` and the position inside it, held at the
    edges."""
    t = np.interp(v, axis, np.arange(axis.size, dtype=float))
    i = np.minimum(np.floor(t).astype(int), axis.size - 2)
    return i, t - i


@dataclass(frozen=True, eq=False)
class JointEffect:
    """One candidate effect as terms of the joint model (module notes).

    Attributes
    ----------
    key, name : str
        Short name (``itr identify --effect``) and the report's name.
    kind : str
        One of :data:`KINDS`.
    parameters : tuple of EffectParameter
        The sampled parameters it adds (``matrix``: the one whose prior it widens).
    ratios : dict
        Per formulation its :class:`RatioTable` (``ratio``; ``batch``: the fraction
        factor's, whose slope at 1 gives d ln k / d phi).
    signature, separate_by : str
        The pattern it leaves in the residuals; the measurement that tells it apart.
    reference_fraction : float
        ``thinning``: the filler fraction at which ``film_nm`` is the film.
    thickness_m : float
        ``tester``: the thickness assumed where a table states none, m.
    composition_role : str or None
        What the parameter does to a sample's composition: ``"filler_factor"`` (the
        filler fraction times it), ``"voids"`` (a void fraction of the composite) or None.
    """

    key: str
    name: str
    kind: str
    parameters: tuple[EffectParameter, ...]
    signature: str
    separate_by: str
    ratios: dict = field(default_factory=dict)
    reference_fraction: float = 0.55
    thickness_m: float = 1e-3
    composition_role: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind: expected one of {KINDS}, got {self.kind!r}")
        if not self.parameters:
            raise ValueError(f"parameters: the effect {self.key!r} needs one at least")
        if self.kind in ("ratio", "batch") and not self.ratios:
            raise ValueError(f"ratios: the {self.kind} effect {self.key!r} needs a ratio "
                             "table per formulation")

    @property
    def parameter(self) -> EffectParameter:
        """Its (first) parameter."""
        return self.parameters[0]

    def space_entries(self, existing: Mapping[str, tuple[str, float, float]]
                      ) -> tuple[dict[str, tuple[str, float, float]],
                                 list[tuple[str, str, float, float]]]:
        """(priors it replaces, parameters it adds) in the joint space's terms."""
        if self.kind == "matrix":
            p = self.parameter
            if p.name not in existing:
                raise ValueError(f"{self.key}: the joint space has no {p.name!r} to widen "
                                 "(is the matrix conductivity held?)")
            return {p.name: ("uniform", p.low, p.high)}, []
        if self.kind == "thinning" and "film_nm" not in existing:
            raise ValueError(f"{self.key}: the joint space has no film (film_nm) to thin")
        return {}, [(p.name, "uniform", p.low, p.high) for p in self.parameters]

    def bind(self, order: list[str], fractions: Mapping[str, Mapping[str, float]],
             parameters: Mapping[str, tuple[str, ...]], *, matrix_conductivity: float,
             inverse_thickness: Mapping[str, float] | None = None) -> BoundEffect:
        """The effect on the formulations of one likelihood (in its ``order``)."""
        missing = [f for f in order if self.kind in ("ratio", "batch") and f not in self.ratios]
        if missing:
            raise ValueError(f"ratios: the effect {self.key!r} has no ratio table of "
                             f"{missing[0]!r}")
        return BoundEffect(self, list(order), {f: dict(fractions[f]) for f in order},
                           {f: tuple(parameters[f]) for f in order}, matrix_conductivity,
                           dict(inverse_thickness or {}))


@dataclass(eq=False)
class BoundEffect:
    """A :class:`JointEffect` on one likelihood's formulations: what it does to ln k, to the
    matrix conductivity, to the tester's reading, to the variance, to the film and to a
    sample's composition, each (F, N) over the formulations and the points."""

    effect: JointEffect
    order: list[str]
    fractions: dict[str, dict[str, float]]
    parameters: dict[str, tuple[str, ...]]
    matrix_conductivity: float
    inverse_thickness: dict[str, float]

    def __post_init__(self) -> None:
        self.phi = np.array([sum(self.fractions[f].values()) for f in self.order])

    def _x(self, cols: Mapping[str, np.ndarray]) -> np.ndarray:
        return np.asarray(cols[self.effect.parameter.name], dtype=float)

    def log10_r(self, cols: Mapping[str, np.ndarray], ln_lam: np.ndarray) -> np.ndarray:
        """(F, N) each formulation's resistance as its reduced basis reads it: log10 of the
        (fraction-weighted geometric mean) resistance scaled by the matrix conductivity."""
        out = []
        for i, f in enumerate(self.order):
            ps = self.parameters[f]
            if not ps:
                out.append(np.full(ln_lam.shape[1], np.nan))
                continue
            w = np.array([self.fractions[f].get(_filler_of(p), 1.0) for p in ps])
            w = w / w.sum()
            out.append(sum(wi * cols[f"log10 {p}"] for wi, p in zip(w, ps))
                       + ln_lam[i] / math.log(10))
        return np.array(out)

    def ln_matrix_shift(self, cols: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """(F, N) ln of the factor on each formulation's matrix conductivity."""
        if self.effect.kind != "porosity":
            return np.zeros((len(self.order), n))
        p = self._x(cols)[None, :]
        share = np.clip(p / np.maximum(1 - self.phi[:, None], 1e-12), 0.0, 0.6)
        ratio = AIR_CONDUCTIVITY / self.matrix_conductivity
        beta = (ratio - 1) / (ratio + 2)
        return np.log((1 + 2 * beta * share) / (1 - beta * share))

    def ln_k_shift(self, cols: Mapping[str, np.ndarray], log10_r: np.ndarray) -> np.ndarray:
        """(F, N) ln k added by a ratio effect."""
        out = np.zeros(log10_r.shape)
        if self.effect.kind != "ratio":
            return out
        x = self._x(cols)
        for i, f in enumerate(self.order):
            if self.parameters[f]:
                out[i] = self.effect.ratios[f](log10_r[i], x)
        return out

    def film_factor(self, cols: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """(F, N) the film of each formulation over the model's ``film_nm`` (1 but under
        ``thinning``)."""
        if self.effect.kind != "thinning":
            return np.ones((len(self.order), n))
        end = self._x(cols)[None, :]
        ref = self.effect.reference_fraction
        return np.clip((end - self.phi[:, None]) / np.maximum(end - ref, 1e-9), 0.0, None)

    def apparent(self, k: np.ndarray, cols: Mapping[str, np.ndarray]) -> np.ndarray:
        """(F, N) what the tester reads of the conductivities ``k``."""
        if self.effect.kind != "tester":
            return k
        inv_t = np.array([self.inverse_thickness.get(f, 1.0 / self.effect.thickness_m)
                          for f in self.order])[:, None]
        return k / (1.0 + self._x(cols)[None, :] * k * inv_t)

    def series_shape(self, cols: Mapping[str, np.ndarray], formulation: str,
                     apparent: np.ndarray, thickness_m: np.ndarray) -> np.ndarray:
        """(T-1, N) what the tester reads at each thickness of a series (m, thinnest first)
        over what it reads at the thinnest, for ``formulation`` read as ``apparent`` (N,)
        at its samples' mean 1/thickness (1 for every effect but the tester's contact: the
        model's own errors multiply every thickness alike and cancel)."""
        t = np.asarray(thickness_m, dtype=float)
        if self.effect.kind != "tester":
            return np.ones((t.size - 1, apparent.size))
        rc = self._x(cols)
        k = apparent / (1.0 - rc * apparent * self.inverse_thickness.get(formulation, 0.0))
        seen = k[None, :] / (1.0 + rc[None, :] * k[None, :] / t[:, None])
        return seen[1:] / seen[:1]

    def relative_variance(self, cols: Mapping[str, np.ndarray], log10_r: np.ndarray
                          ) -> np.ndarray:
        """(F, N) a formulation's own relative error variance added by the effect."""
        if self.effect.kind != "batch":
            return np.zeros(log10_r.shape)
        sd = self._x(cols)
        out = np.zeros(log10_r.shape)
        for i, f in enumerate(self.order):
            if self.parameters[f]:
                slope = self.effect.ratios[f].slope_at_nominal(log10_r[i], 1.0) / self.phi[i]
                out[i] = (slope * sd) ** 2
        return out

    def composition(self, cols: Mapping[str, np.ndarray], n: int
                    ) -> tuple[np.ndarray, np.ndarray]:
        """(filler volume fraction, void volume fraction), each (F, N), of the samples."""
        phi = np.repeat(self.phi[:, None], n, axis=1)
        voids = np.zeros_like(phi)
        role = self.effect.composition_role
        if role == "filler_factor":
            phi = phi * self._x(cols)[None, :]
        elif role == "voids":
            voids = voids + self._x(cols)[None, :]
        return phi, voids


def _filler_of(parameter: str) -> str:
    """The filler of a flat resistance name ``R_<filler>_<matrix>``."""
    parts = parameter.split("_")
    return parts[1] if len(parts) >= 3 else parameter
