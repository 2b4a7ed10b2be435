"""The base of every candidate effect of the discrepancy workflow (:class:`Effect`): one
physical parameter, its nominal value and grid, and the hooks through which it changes the
RVE, its phases, the tester's reading, the error shared by a formulation, a sample's
composition and its equivalent in another powder. The library is
:mod:`itr_identify.discrepancy.effects` and :mod:`itr_identify.discrepancy.steepening`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from itr_fv import Materials, Microstructure

__all__ = ["Effect"]


@dataclass(frozen=True)
class Effect:
    """One candidate effect (a base class: each subclass overrides one of
    :meth:`materials`, :meth:`microstructure`, :meth:`apparent`).

    Attributes
    ----------
    key : str
        Short name (command line: ``--effects``).
    name : str
    parameter : str
        Name of its parameter (with the unit in it).
    nominal : float
        The value at which the model is the base model.
    values : tuple of float
        Grid on which the full model is solved (the nominal value among them); the
        workflow interpolates between them and does not extrapolate.
    signature : str
        The pattern it leaves in the residuals.
    separate_by : str
        The measurement that tells it apart from the effects of the same signature.
    kind : {"material", "geometry", "measurement", "variance"}
    log_scale : bool
        Interpolate (and calibrate) in the logarithm of the parameter.
    physical_range : (float, float) or None
        Where the parameter is physically expected, where narrower than the grid: a fit
        outside it is reported and not named (None: the grid is that range).
    scales_resistance : bool
        The effect acts, for one powder and any size of it, as a factor on the interface
        resistances: no measurement of k, density or mass fraction tells it from them, so
        it is kept out of the tied set and said so (:mod:`.tie_breaking`).
    """

    key: str
    name: str
    parameter: str
    nominal: float
    values: tuple[float, ...]
    signature: str
    separate_by: str
    kind: str = "material"
    log_scale: bool = False
    physical_range: tuple[float, float] | None = None
    scales_resistance: bool = False

    def __post_init__(self) -> None:
        v = np.asarray(self.values, dtype=float)
        if v.size < 3 or np.any(np.diff(v) <= 0) or not np.all(np.isfinite(v)):
            raise ValueError(f"values: the grid of {self.name!r} must hold at least 3 finite, "
                             f"increasing values, got {self.values!r}")
        if not v[0] <= self.nominal <= v[-1]:
            raise ValueError(f"nominal: {self.nominal!r} lies outside the grid of "
                             f"{self.name!r} ({v[0]!r}..{v[-1]!r})")

    def prior_weights(self, axis: np.ndarray) -> np.ndarray:
        """The effect's prior on the points of ``axis`` (a grid of its parameter, evenly
        spaced in the scale it is calibrated in: :attr:`log_scale`), normalised to sum to 1.

        Uniform in that scale over :attr:`physical_range` (the whole grid where none is
        stated), with half-normal tails outside it whose width is a quarter of the range:
        a value just outside the range is less likely, not impossible (the naming rule
        weighs it by this prior, :func:`itr_identify.discrepancy.fit.fit_model`)."""
        axis = np.asarray(axis, dtype=float)
        lo, hi = self.physical_range or (self.values[0], self.values[-1])
        scale = np.log if self.log_scale and lo > 0 else (lambda x: x)
        x = scale(np.maximum(axis, 1e-300)) if scale is np.log else axis
        a, b = scale(lo), scale(hi)
        width = 0.25 * (b - a) if b > a else 1.0
        outside = np.where(x < a, a - x, np.where(x > b, x - b, 0.0))
        w = np.exp(-0.5 * (outside / width) ** 2)
        return w / w.sum()

    @property
    def needs_thickness(self) -> bool:
        """Whether the effect can only be seen in measurements at several thicknesses."""
        return False

    @property
    def solved(self) -> bool:
        """Whether its values need full solves (it changes the RVE or its phases)."""
        return self.kind in ("material", "geometry")

    def formulation_sd(self, slope: np.ndarray, value: np.ndarray) -> np.ndarray:
        """Relative standard deviation of an error shared by one formulation's
        measurements, from ``slope`` = d ln k / d phi of the model at that formulation
        (phi a volume fraction) and the effect's ``value`` (default: none)."""
        return np.zeros(np.broadcast(slope, value).shape)

    def fraction_sd(self, value: float | np.ndarray) -> float | np.ndarray:
        """Standard deviation of a formulation's actual filler volume fraction about the
        effect's, an error shared by all of the formulation's observations (default: 0)."""
        return 0.0 * np.asarray(value, dtype=float)

    def materials(self, base: Materials, value: float) -> Materials:
        """Phase values under the effect (default: unchanged)."""
        return base

    def materials_in(self, microstructure: Microstructure, base: Materials,
                     value: float) -> Materials:
        """Phase values under the effect in ``microstructure`` (default:
        :meth:`materials`; an effect whose phase values depend on the RVE's composition
        overrides this)."""
        return self.materials(base, value)

    def microstructure(self, base: Microstructure, value: float, seed: int) -> Microstructure:
        """The RVE under the effect (default: unchanged)."""
        return base

    def rebuild(self, pack: Callable[..., Microstructure], base: Microstructure, value: float,
                seed: int) -> Microstructure:
        """The RVE under the effect at ``value``, for an effect that packs its own RVE.

        ``pack(**changes)`` packs the formulation of ``base`` again, the same replica with
        the same packing seed, with ``changes``: RVESpec fields (``min_gap_um``),
        ``fractions`` (``{filler: volume fraction}``) or ``median_scale`` (a factor on a
        filler's diameters; :class:`itr_identify.discrepancy.steepening.Repacker`). A value
        that cannot be packed raises ValueError naming the effect and the value. ``seed``
        seeds the effect's own random choices. Default: :meth:`microstructure` of
        ``base``."""
        return self.microstructure(base, value, seed=seed)

    def apparent(self, k: np.ndarray, thickness_m: np.ndarray, value: float) -> np.ndarray:
        """The conductivity the tester reports for a sample of conductivity ``k``
        (default: ``k``)."""
        return k

    def composition(self, fraction: float | np.ndarray, value: float | np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """(filler volume fraction, void volume fraction) of a sample whose nominal filler
        volume fraction is ``fraction``, under the effect at ``value`` (default: nominal
        filler, no voids). The density and the filler mass fraction of a sample follow
        from them (:mod:`itr_identify.discrepancy.observables`)."""
        f = np.asarray(fraction, dtype=float)
        shape = np.broadcast(f, np.asarray(value, dtype=float)).shape
        return np.broadcast_to(f, shape).astype(float), np.zeros(shape)

    def size_equivalent(self, value: float | np.ndarray, scale: float
                        ) -> float | np.ndarray:
        """The effect's value in the RVE of the nominal powder that acts as ``value`` does
        in a powder of every diameter ``scale`` times larger (same distribution shape).

        Conduction in an RVE scaled by ``scale`` with the same conductivities is that of
        the nominal RVE with every interface resistance divided by ``scale`` (a resistance
        acts through ``R k / a``); a bulk property is the same in both (default: the value
        unchanged). An effect carried by a length or a conductance per contact overrides
        this."""
        return value

    def describe(self) -> dict:
        return {"key": self.key, "name": self.name, "parameter": self.parameter,
                "nominal": self.nominal,
                "grid": list(self.values), "kind": self.kind, "signature": self.signature,
                "physical_range": (list(self.physical_range) if self.physical_range
                                   else None),
                "separate_by": self.separate_by}
