"""The space of formulations ``itr design`` screens, and its surrogate over the posterior.

A design space is one or two fillers and a range of total filler fraction; with two fillers
each point is a blend, ``share`` the first filler's part of the filler (0 to 1). The
surrogate is the posterior draws of ln k at a few anchor formulations (every posterior draw's
own value, :func:`~.predictive.model_draws`), interpolated draw by draw over the space:
quadratic (Lagrange) through three totals (the range's ends and middle) and, with two fillers,
through three shares (each filler alone and 1:1), tensor-product. Every draw of the posterior
is one smooth k over the space, so a point's probability of reaching a target carries the
resistances, inputs, correction and model-form uncertainty together; what the interpolation
leaves out is checked where it matters, at the chosen formulation, by its own model and full
solves (:mod:`itr_identify.workflows.design`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from itr_fv.materials.formulation_names import MIN_PERCENT

__all__ = ["DesignSpace", "Choice", "choose", "lagrange_weights"]

#: Largest total filler fraction a design may ask for (random close packing of spheres).
MAX_TOTAL = 0.70


def lagrange_weights(nodes: Sequence[float], x: np.ndarray) -> np.ndarray:
    """(len(x), len(nodes)) weights of the Lagrange polynomial through ``nodes`` at ``x``."""
    nodes = np.asarray(nodes, dtype=float)
    x = np.atleast_1d(np.asarray(x, dtype=float))
    w = np.ones((x.size, nodes.size))
    for i, xi in enumerate(nodes):
        for j, xj in enumerate(nodes):
            if i != j:
                w[:, i] *= (x - xj) / (xi - xj)
    return w


@dataclass(frozen=True)
class DesignSpace:
    """Fillers and a total filler fraction range, on a grid (frozen).

    Attributes
    ----------
    fillers : tuple of str
        One or two fillers of the material system.
    total : (float, float)
        Lowest and highest total filler volume fraction (0 to :data:`MAX_TOTAL`).
    total_step : float
        Grid step of the total fraction (volume fraction; default 0.005 = 0.5 vol%).
    share_step : float
        Grid step of the first filler's share of the filler (two fillers; default 0.05).
    """

    fillers: tuple[str, ...]
    total: tuple[float, float]
    total_step: float = 0.005
    share_step: float = 0.05

    def __post_init__(self) -> None:
        f = tuple(self.fillers)
        if not 1 <= len(f) <= 2 or len(set(f)) != len(f):
            raise ValueError(f"fillers: expected one or two distinct fillers, got {f!r}")
        object.__setattr__(self, "fillers", f)
        lo, hi = (float(v) for v in self.total)
        if not (0 < lo <= hi <= MAX_TOTAL):
            raise ValueError(f"total: expected 0 < low <= high <= {100 * MAX_TOTAL:g} vol%, "
                             f"got {100 * lo:g}-{100 * hi:g}")
        object.__setattr__(self, "total", (lo, hi))
        for name in ("total_step", "share_step"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0 < v <= 1 and math.isfinite(v)):
                raise ValueError(f"{name}: expected a step in (0, 1], got {v!r}")

    @property
    def anchor_totals(self) -> tuple[float, ...]:
        lo, hi = self.total
        return (lo,) if hi - lo < 1e-12 else (lo, 0.5 * (lo + hi), hi)

    @property
    def anchor_shares(self) -> tuple[float, ...]:
        return (1.0,) if len(self.fillers) == 1 else (1.0, 0.5, 0.0)

    def anchors(self) -> list[tuple[float, float]]:
        """(share, total) of every anchor formulation, shares outer."""
        return [(s, t) for s in self.anchor_shares for t in self.anchor_totals]

    def totals(self) -> np.ndarray:
        lo, hi = self.total
        n = int(round((hi - lo) / self.total_step))
        return np.round(np.linspace(lo, lo + n * self.total_step, n + 1), 10) \
            if n else np.array([lo])

    def shares(self) -> np.ndarray:
        if len(self.fillers) == 1:
            return np.array([1.0])
        n = int(round(1 / self.share_step))
        return np.linspace(1.0, 0.0, n + 1)

    def fractions(self, share: float, total: float) -> dict[str, float]:
        """The fillers' volume fractions of a point (a filler below the smallest part a
        name can hold is left out)."""
        parts = {self.fillers[0]: share * total}
        if len(self.fillers) == 2:
            parts[self.fillers[1]] = (1 - share) * total
        return {f: v for f, v in parts.items() if 100 * v >= MIN_PERCENT}

    def name(self, share: float, total: float) -> str:
        """The formulation name of a point (percent to 0.01)."""
        return "-".join(f"{f}-{round(100 * v, 2):g}"
                        for f, v in self.fractions(share, total).items())

    def interpolate(self, at_anchors: np.ndarray, shares: np.ndarray, totals: np.ndarray
                    ) -> np.ndarray:
        """Values at the anchors (:meth:`anchors` order, shape (A, N)) interpolated to the
        grid ``shares`` x ``totals``: (len(shares), len(totals), N)."""
        ns, nt = len(self.anchor_shares), len(self.anchor_totals)
        vals = np.asarray(at_anchors, dtype=float).reshape(ns, nt, -1)
        ws = lagrange_weights(self.anchor_shares, shares) if ns > 1 else np.ones((len(shares), 1))
        wt = lagrange_weights(self.anchor_totals, totals) if nt > 1 else np.ones((len(totals), 1))
        return np.einsum("ai,bj,ijn->abn", ws, wt, vals)

    def to_dict(self) -> dict:
        return {"fillers": list(self.fillers), "total_vol_pct": [100 * v for v in self.total],
                "total_step_vol_pct": 100 * self.total_step, "share_step": self.share_step,
                "anchors": [self.name(s, t) for s, t in self.anchors()]}


@dataclass(frozen=True)
class Choice:
    """The cheapest point reaching the target with the probability asked (frozen).

    Attributes
    ----------
    share, total : float
        The point (the first filler's share; total volume fraction).
    name : str
        Its formulation name.
    probability : float
        Predictive probability that its measured mean reaches the target.
    cost : float
        Its cost (sum over fillers of cost per vol% times vol%).
    median : float
    interval : (float, float)
        Its predictive median and 90 % interval, W/(m K).
    """

    share: float
    total: float
    name: str
    probability: float
    cost: float
    median: float
    interval: tuple[float, float]

    def to_dict(self) -> dict:
        return {"formulation": self.name, "share_of_first_filler": self.share,
                "total_vol_pct": 100 * self.total, "probability": self.probability,
                "cost": self.cost, "median": self.median, "interval_90": list(self.interval),
                "unit": "W/(m K)"}


def costs(space: DesignSpace, shares: np.ndarray, totals: np.ndarray,
          cost: Mapping[str, float] | None) -> np.ndarray:
    """(len(shares), len(totals)) cost of each point: per filler its cost per vol% times its
    vol% (default 1 each: the total filler)."""
    c = {f: 1.0 for f in space.fillers} | dict(cost or {})
    first = 100 * shares[:, None] * totals[None, :]
    out = c[space.fillers[0]] * first
    if len(space.fillers) == 2:
        out = out + c[space.fillers[1]] * (100 * totals[None, :] - first)
    return out


def choose(space: DesignSpace, draws: np.ndarray, shares: np.ndarray, totals: np.ndarray, *,
           target: float, probability: float, cost: Mapping[str, float] | None = None
           ) -> tuple[Choice | None, np.ndarray, np.ndarray]:
    """The cheapest grid point whose measured-mean draws ``draws`` (S, T, N) reach
    ``target`` with ``probability`` (ties: the more probable); returns it (None where no
    point does), the probability map (S, T) and the cost map (S, T)."""
    p = (draws >= target).mean(axis=2)
    c = costs(space, shares, totals, cost)
    ok = p >= probability
    if not ok.any():
        return None, p, c
    masked = np.where(ok, c, np.inf)
    best = np.flatnonzero(masked == masked.min())
    i, j = np.unravel_index(best[np.argmax(p.ravel()[best])], p.shape)
    lo, med, hi = np.quantile(draws[i, j], [0.05, 0.5, 0.95])
    s, t = float(shares[i]), float(totals[j])
    return (Choice(s, t, space.name(s, t), float(p[i, j]), float(c[i, j]), float(med),
                   (float(lo), float(hi))), p, c)
