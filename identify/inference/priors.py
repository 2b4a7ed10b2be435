"""The priors of the identification's joint posterior (:mod:`.joint`), stated and defended
once; the conductivities' and the film's are :class:`~.nuisance.InputPrior` and
:class:`~.nuisance.FilmPrior` (their defaults: :func:`~.nuisance.default_priors`).

**Resistances** (:class:`ResistancePrior`): log-uniform over 1e-9 to 1e-6 m^2 K/W.

- The floor, 1e-9: a perfectly bonded polymer-ceramic interface still resists by its phonon
  mismatch. The diffuse-mismatch bound on the softer side, ``R >= 4 / (C v)`` with the
  silicone's volumetric heat capacity ``C`` about 1.5e6 J/(m^3 K) and sound speed ``v``
  about 1000 m/s, is about 3e-9 m^2 K/W at full transmission; the floor lies a factor 3
  below it, so no physical value is cut off. Below about 5e-9 the measured conductivities
  of Table 3 hardly move with R (d ln k / d ln R about -0.02), so the floor sets the lower
  end of an interval the data leave open: the report says how the point and interval move
  when it moves a decade (``floor_sensitivity``).
- The ceiling, 1e-6: the resistance of a 25 nm air gap (0.026 W/(m K)) over the whole
  interface, a filler debonded everywhere; measured filler-polymer resistances lie between
  1e-9 and 1e-7.

**Model form** (:class:`ModelFormPrior`): the forward model's systematic error, structured
per filler system as an offset and a slope in the filler fraction (5 vol% units), relative
to k: normal, of sd 5 % (offset) and 3 % per 5 vol% (slope), sampled with the rest (not
point-estimated; their posterior says how much misfit the data show). What the model leaves
out (particle shape, the size distributions' fits, agglomeration, the film's variation) moves
k by a few per cent; 5 % and 3 % keep 10 % within two sds. ``hyper=True`` samples the two sds
too (half-normal priors of those scales): the data then weigh them, at the cost of a funnel
that slows the sampler about threefold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ResistancePrior", "ModelFormPrior", "DEFAULT_RESISTANCE", "DEFAULT_MODEL_FORM",
           "RB_MARGIN"]

#: The reduced bases' box reaches this factor beyond the resistance prior on each side, so
#: that a resistance scaled by the matrix conductivity (``lam R``, ``lam`` within three
#: prior sds of 1) stays inside it.
RB_MARGIN = 2.0


@dataclass(frozen=True)
class ResistancePrior:
    """Log-uniform prior of every filler-matrix resistance, m^2 K/W (module notes)."""

    low: float = 1e-9
    high: float = 1e-6

    def __post_init__(self) -> None:
        for key in ("low", "high"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 1e-12 <= v <= 1e-3):
                raise ValueError(f"resistance prior {key}: expected m^2 K/W in [1e-12, 1e-3], "
                                 f"got {v!r}")
        if not self.low < self.high:
            raise ValueError(f"resistance prior: expected low < high, got {self.low!r}, "
                             f"{self.high!r}")

    @property
    def log10_bounds(self) -> tuple[float, float]:
        return math.log10(self.low), math.log10(self.high)

    @property
    def rb_box(self) -> tuple[float, float]:
        """The reduced bases' box: the prior widened by :data:`RB_MARGIN` each side."""
        return self.low / RB_MARGIN, self.high * RB_MARGIN

    def with_floor(self, low: float) -> ResistancePrior:
        return ResistancePrior(low, self.high)


@dataclass(frozen=True)
class ModelFormPrior:
    """Half-normal scales of the model-form sds (module notes); ``on=False`` leaves the
    model-form term out (the fit's test, leave-one-out)."""

    offset_scale: float = 0.05
    slope_scale: float = 0.03
    on: bool = True
    hyper: bool = False

    def __post_init__(self) -> None:
        for key in ("offset_scale", "slope_scale"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and 0 < v < 0.5):
                raise ValueError(f"model form {key}: expected a relative sd in (0, 0.5), got "
                                 f"{v!r}")


DEFAULT_RESISTANCE = ResistancePrior()
DEFAULT_MODEL_FORM = ModelFormPrior()
