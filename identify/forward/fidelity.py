"""Faithful-RVE correction of a forward model: the multi-fidelity step of identification.

A :class:`~itr_identify.forward.model.ForwardModel`'s reduced basis is fitted on cheap RVEs
(the settings' box and voxel) and carries how k_iso depends on the resistances. Its level
is wrong by the box's cut of the coarse tail and by the voxel's bias (issue 24: a 12 um box
at 0.25 um reads 10-12 % low for AlN-60 and 3 % for Al2O3-60). A :class:`FaithfulRVE` says
how to correct it at one point ``theta*``: per filler a box (the largest of the fillers of a
formulation), two voxel edges ``h < H`` of the same packing and packing seeds the cheap
replicas never use. Each faithful packing is solved at both voxels and its voxel bias removed
by Richardson extrapolation with the order ``p`` of the gap model's bias law
(:data:`BIAS_ORDER`, fitted in ``validation/results/voxel_bias_law.md``),

    k_0 = k_h + (k_h - k_H) / ((H / h)^p - 1),

and the model is multiplied by

    c = mean_j k_0,j(theta*) / k_model(theta*)          (dimensionless),

``k_model`` the cheap model's prediction (reduced basis times replica factor), so that the
corrected model equals the faithful ensemble estimate at ``theta*``. The correction's
relative standard uncertainty

    u_c^2 = s_f^2 / J + u_p^2

(``s_f`` the faithful packings' relative scatter of k_iso, estimated from their diagonal
entries as :attr:`ForwardModel.rve_scatter`; ``J`` packings; ``u_p`` half the change of
the extrapolated mean over ``p +- 2`` standard errors) enters the likelihood variance as
``(u_c k)^2`` (:mod:`itr_identify.inference.calibrate`). The identification repeats
calibration and correction at the new best point until it moves less than
:attr:`FaithfulRVE.move_tolerance` of its 90 % interval (:mod:`itr_identify.inference.pipeline`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from itr_fv.materials import is_default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve.from_powders import FAITHFUL_VOXEL_RATIO, cheap_rve, faithful_box, voxel_for
from itr_fv.rve.spec import RVESpec, voxels_per_edge

__all__ = ["CHEAP_RVE", "CHEAP_REPLICAS", "CHEAP_TOL", "FaithfulRVE", "Correction", "richardson",
           "direction_scatter", "BIAS_ORDER",
           "BIAS_ORDER_SE", "FIDELITY_LEVELS", "faithful_for", "fidelity_name", "cheap_rve_for"]

#: The cheap RVE of ``itr reproduce`` and ``itr identify`` (12 um box at 0.25 um), its
#: replicas (packing seeds 1, 2, 3) and the relative residual of its solves: what the reduced
#: basis stands for, and what the shipped corrections correct.
CHEAP_RVE = RVESpec(box_um=12.0, voxel_um=0.25)
CHEAP_REPLICAS = 3
CHEAP_TOL = 1e-8

#: Order p of the gap model's voxel bias k(h) = k_0 (1 - c h^p) and its standard error,
#: fitted on two Al2O3-60 packings re-voxelized from 0.25 to 0.0625 um
#: (``validation/results/voxel_bias_law.md``).
BIAS_ORDER = 1.292
BIAS_ORDER_SE = 0.065


def direction_scatter(k: np.ndarray) -> float:
    """Relative scatter of one RVE's k_iso from the diagonal entries ``k`` (RVEs, 3) of
    several RVEs: ``sd(all entries) / mean / sqrt(3)`` (three times the samples of the
    k_iso spread alone)."""
    k = np.asarray(k, dtype=np.float64).ravel()
    return float(k.std(ddof=1) / k.mean() / math.sqrt(3))


def richardson(k_fine: np.ndarray, k_coarse: np.ndarray, ratio: float,
               order: float) -> np.ndarray:
    """Voxel-bias-free estimate ``k_h + (k_h - k_H) / (ratio^order - 1)``, W/(m K).

    Parameters
    ----------
    k_fine, k_coarse : array
        The same packing at voxel ``h`` and ``H = ratio h``, W/(m K).
    ratio : float
        ``H / h`` (> 1).
    order : float
        Order of the bias (> 0).
    """
    if not ratio > 1:
        raise ValueError(f"ratio: expected H / h > 1, got {ratio!r}")
    if not order > 0:
        raise ValueError(f"order: expected > 0, got {order!r}")
    k_fine = np.asarray(k_fine, dtype=np.float64)
    return k_fine + (k_fine - np.asarray(k_coarse, dtype=np.float64)) / (ratio ** order - 1)


@dataclass(frozen=True)
class FaithfulRVE:
    """Where the faithful solves of a forward model's correction run.

    Attributes
    ----------
    boxes_um : tuple of (filler, box in um)
        Box edge per filler; a formulation takes the largest of its fillers'.
    voxel_um : float
        Fine voxel edge h, um.
    coarse_voxel_um : float
        Coarse voxel edge H > h of the same packing, um (Richardson partner).
    packings : int
        Faithful packings per formulation (>= 2: their scatter is part of the uncertainty).
    seed : int
        Packing seed of the first faithful packing (``seed + j``; redrawn with ``+ 100`` as
        :func:`itr_fv.rve.build_rve`); far from the cheap replicas' seeds.
    move_tolerance : float
        The correction is repeated until the best point moves less than this fraction of
        its 90 % interval (log10 width), every parameter.
    max_rounds : int
        Corrections at most (a run that stops there says so).
    name : str
        The fidelity level it belongs to (:data:`FIDELITY_LEVELS`), or ``"custom"``.
    shipped : bool
        Use a corrections table (:mod:`itr_identify.forward.shipped`) for every formulation
        it holds (its material system and cheap RVE must be the settings'); the others are
        corrected at runtime on these RVEs.
    corrections : str, optional
        The corrections table's file: a lab's own (``itr corrections build --system``)
        for its system; None: the one shipped with the package (the paper's system).
    """

    boxes_um: tuple[tuple[str, float], ...]
    voxel_um: float
    coarse_voxel_um: float
    packings: int = 2
    seed: int = 9001
    move_tolerance: float = 0.1
    max_rounds: int = 4
    name: str = "custom"
    shipped: bool = False
    corrections: str | None = None

    def __post_init__(self) -> None:
        if self.corrections is not None and not self.shipped:
            raise ValueError("corrections: a corrections file is read at a level that uses "
                             "tabled corrections (shipped)")
        boxes = tuple((str(f), float(b)) for f, b in dict(self.boxes_um).items())
        if not boxes:
            raise ValueError("boxes_um: expected a box per filler, got none")
        object.__setattr__(self, "boxes_um", boxes)
        if not (isinstance(self.voxel_um, (int, float)) and self.voxel_um > 0):
            raise ValueError(f"voxel_um: expected a positive edge in um, got {self.voxel_um!r}")
        if not (isinstance(self.coarse_voxel_um, (int, float))
                and self.coarse_voxel_um > self.voxel_um):
            raise ValueError(f"coarse_voxel_um: expected an edge in um larger than voxel_um "
                             f"({self.voxel_um:g}), got {self.coarse_voxel_um!r}")
        for _, box in boxes:
            voxels_per_edge(box, self.voxel_um)
            voxels_per_edge(box, self.coarse_voxel_um)
        if not (isinstance(self.packings, int) and self.packings >= 2):
            raise ValueError(f"packings: expected a whole number >= 2, got {self.packings!r}")
        if not 0 < self.move_tolerance <= 1:
            raise ValueError(f"move_tolerance: expected a fraction in (0, 1], got "
                             f"{self.move_tolerance!r}")
        if not (isinstance(self.max_rounds, int) and self.max_rounds >= 1):
            raise ValueError(f"max_rounds: expected a whole number >= 1, got "
                             f"{self.max_rounds!r}")

    @property
    def ratio(self) -> float:
        """``H / h``."""
        return self.coarse_voxel_um / self.voxel_um

    def box_for(self, fillers: Sequence[str]) -> float:
        """Box edge of a formulation holding ``fillers``, um (ValueError naming a filler
        without a box)."""
        boxes = dict(self.boxes_um)
        missing = [f for f in fillers if f not in boxes]
        if missing:
            raise ValueError(f"boxes_um: no faithful box for {', '.join(missing)} (have "
                             f"{', '.join(boxes)})")
        return max(boxes[f] for f in fillers)

    def spec_for(self, fillers: Sequence[str], cheap: RVESpec) -> RVESpec:
        """The faithful packing's specification: the cheap one's size cuts and film, this
        box, the fine voxel and this seed."""
        return cheap.with_(box_um=self.box_for(fillers), voxel_um=self.voxel_um,
                           seed=self.seed)

    def coarse_shape(self, fillers: Sequence[str]) -> tuple[int, int, int]:
        """Voxels per axis of the coarse re-voxelization."""
        n = voxels_per_edge(self.box_for(fillers), self.coarse_voxel_um)
        return (n, n, n)

    def to_dict(self) -> dict[str, Any]:
        """The level as settings; at a ``shipped`` level the faithful RVEs are those of a
        formulation the shipped corrections do not hold (``runtime_fallback``), not the
        shipped table's (what ran: :func:`itr_identify.reporting.level.level_record`)."""
        rves = {"boxes_um": dict(self.boxes_um), "voxel_um": self.voxel_um,
                "coarse_voxel_um": self.coarse_voxel_um, "packings": self.packings,
                "seed": self.seed, "move_tolerance": self.move_tolerance,
                "max_rounds": self.max_rounds}
        head = {"name": self.name, "shipped": self.shipped,
                **({"corrections": self.corrections} if self.corrections else {})}
        body = {"runtime_fallback": rves} if self.shipped else rves
        return {**head, **body, "bias_order": BIAS_ORDER, "bias_order_se": BIAS_ORDER_SE}


@dataclass
class Correction:
    """One faithful correction of a forward model, at :attr:`at`.

    Attributes
    ----------
    at : dict
        Parameter values it was computed at, m^2 K/W.
    box_um, voxel_um, coarse_voxel_um : float
        Faithful box and the two voxel edges, um.
    seeds : list of int
        Packing seeds of the faithful packings.
    k_model : float
        The cheap model's prediction at :attr:`at`, W/(m K).
    k_fine, k_coarse : ndarray (J, 3)
        Diagonal of k_eff per faithful packing at both voxels, W/(m K).
    """

    at: dict[str, float]
    box_um: float
    voxel_um: float
    coarse_voxel_um: float
    seeds: list[int]
    k_model: float
    k_fine: np.ndarray
    k_coarse: np.ndarray
    order: float = BIAS_ORDER
    order_se: float = BIAS_ORDER_SE
    extrapolated: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.k_fine = np.asarray(self.k_fine, dtype=np.float64)
        self.k_coarse = np.asarray(self.k_coarse, dtype=np.float64)
        self.extrapolated = richardson(self.k_fine, self.k_coarse,
                                       self.coarse_voxel_um / self.voxel_um, self.order)

    @property
    def k_faithful(self) -> float:
        """Mean voxel-bias-free k_iso of the faithful packings, W/(m K)."""
        return float(self.extrapolated.mean())

    @property
    def factor(self) -> float:
        """``k_faithful / k_model``, dimensionless."""
        return self.k_faithful / self.k_model

    @property
    def packing_scatter(self) -> float:
        """Relative scatter of one faithful packing's k_iso (direction-based)."""
        return direction_scatter(self.extrapolated)

    @property
    def order_uncertainty(self) -> float:
        """Half the relative change of :attr:`k_faithful` over ``order +- 2 order_se``."""
        ratio = self.coarse_voxel_um / self.voxel_um
        lo, hi = (richardson(self.k_fine, self.k_coarse, ratio, self.order + s).mean()
                  for s in (-2 * self.order_se, 2 * self.order_se))
        return float(abs(hi - lo) / 2 / self.k_faithful)

    @property
    def relative_sd(self) -> float:
        """``u_c``: relative standard uncertainty of :attr:`factor`."""
        n = self.k_fine.shape[0]
        return math.hypot(self.packing_scatter / math.sqrt(n), self.order_uncertainty)

    @property
    def voxel_bias(self) -> float:
        """Relative bias of the fine voxel, ``k_h / k_0 - 1`` (mean of the packings)."""
        return float(self.k_fine.mean() / self.k_faithful - 1)

    def to_dict(self) -> dict[str, Any]:
        return {"at": dict(self.at), "box_um": self.box_um, "voxel_um": self.voxel_um,
                "coarse_voxel_um": self.coarse_voxel_um, "seeds": list(self.seeds),
                "k_model": self.k_model, "k_fine_iso": self.k_fine.mean(axis=1).tolist(),
                "k_coarse_iso": self.k_coarse.mean(axis=1).tolist(),
                "k_faithful": self.k_faithful, "factor": self.factor,
                "relative_sd": self.relative_sd, "packing_scatter": self.packing_scatter,
                "order_uncertainty": self.order_uncertainty, "voxel_bias": self.voxel_bias}


#: The faithful RVEs of the named fidelity levels (``--fidelity``). ``quick``: none (the
#: cheap RVE's level, today's numbers at 12 um and 0.25 um); ``shipped``: the corrections
#: shipped with the package (converged boxes, ``identify/data/corrections.json``), runtime
#: corrections on the ``standard`` RVEs for a formulation they do not hold; ``standard``: 24
#: um boxes (Al2O3-60 is within 0.04 % of a 32 um box there; AlN is not, see the error
#: budget) at 0.2 and 0.25 um; ``paper``: the paper's 40 um box at 0.1 and 0.125 um.
FIDELITY_LEVELS: dict[str, FaithfulRVE | None] = {
    "quick": None,
    "shipped": FaithfulRVE((("Al2O3", 24.0), ("AlN", 24.0)), 0.2, 0.25, name="shipped",
                           shipped=True),
    "standard": FaithfulRVE((("Al2O3", 24.0), ("AlN", 24.0)), 0.2, 0.25, name="standard"),
    "paper": FaithfulRVE((("Al2O3", 40.0), ("AlN", 40.0)), 0.1, 0.125, name="paper"),
}


def faithful_for(level: str, system: MaterialSystem | None = None) -> FaithfulRVE | None:
    """The faithful RVE of a fidelity level (ValueError naming ``fidelity``) for ``system``.

    The paper's system (or one that solves as it does) takes the level's measured boxes
    (:data:`FIDELITY_LEVELS`); any other takes the boxes and voxels of its powders
    (:mod:`itr_fv.rve.from_powders`: per filler the smallest box whose size cut removes at
    most 1.5 % of its volume; the voxel pair 0.8 and 1 times the cheap voxel, at ``paper``
    half of those)."""
    if level not in FIDELITY_LEVELS:
        raise ValueError(f"fidelity: expected one of {', '.join(FIDELITY_LEVELS)}, got "
                         f"{level!r}")
    base = FIDELITY_LEVELS[level]
    if base is None or system is None or is_default_system(system):
        return base
    h = voxel_for(f.psd for f in system.fillers)
    if level == "paper":
        h = h / 2
    boxes = tuple((f.name, faithful_box(f.psd, h)) for f in system.fillers)
    return replace(base, boxes_um=boxes, voxel_um=round(FAITHFUL_VOXEL_RATIO * h, 12),
                   coarse_voxel_um=h)


def cheap_rve_for(system: MaterialSystem) -> RVESpec:
    """The cheap RVE of ``system``'s identification (:func:`itr_fv.rve.from_powders.
    cheap_rve`; the paper's system: :data:`CHEAP_RVE`, 12 um at 0.25 um)."""
    return cheap_rve(f.psd for f in system.fillers)


def fidelity_name(faithful: FaithfulRVE | None) -> str:
    """The level's name of a settings' faithful RVE (``quick`` for none)."""
    return "quick" if faithful is None else faithful.name

