"""Dense periodic RVEs of lognormal polydisperse spheres (paper Sec. 2.4).

:func:`generate_rve` (``generate_rve(spec, fillers, seed)``) draws number-weighted lognormal
diameters for one or more fillers (:class:`FillerSpec`, Table 1 parameters), packs them
without overlap in the periodic cube of an :class:`~itr_fv.rve.spec.RVESpec`
(:func:`itr_fv.rve.packing.pack_spheres`) up to the target volume fraction of every filler,
and voxelizes them with particle ids (:meth:`Microstructure.from_spheres`). Every setting
of the RVE (box, voxel, size cuts, films, sampling, sweep limit) is a field of the spec,
with its one default and its check there.

:func:`generate_rve_with_report` returns the same microstructure with its quality report
(:class:`RVEReport`, frozen); the report is not attached to the microstructure.
:func:`build_rve` packs replica ``r`` of a spec with the spec's seeds (and redraws a failed
packing): the package's own way to build an RVE.

Size truncation
---------------
Diameters are drawn from the lognormal truncated to ``[d_lo, d_hi]`` per filler:

* ``d_hi = min(ppf(1 - tail_quantile), max_diameter_box_ratio * box_um, filler.d_max_um)``:
  the far tail only (default ``tail_quantile = 1e-4``, i.e. fewer than one particle in a
  typical RVE), unless the periodic box forces a smaller cut -- a particle larger than
  about half the box would interact with its own images (default ratio 0.45,
  :data:`~itr_fv.rve.spec.MAX_DIAMETER_BOX_RATIO`). When that box cut removes more than
  1 % of a filler's volume a ``UserWarning`` says how much (AlN of Table 1 in a 40 um box
  at ratio 1/3: about 30 % of its volume lies in particles above 13.3 um).
* ``d_lo = max(ppf(tail_quantile), min_diameter_voxels * voxel_um, filler.d_min_um)``: a
  particle must span about two voxels (of ``cut_voxel_um``) to be resolved. If this cut
  removes more than 1 % of a filler's volume or 5 % of its particles, the voxel is too
  coarse: ``ValueError``.

The cuts and the shares (number and volume) of the untruncated distribution they remove
are reported per filler; :func:`size_cut` computes them for one filler without packing
(the figures and reports quote its shares).

Packing limit
-------------
The sum of the target fractions must stay below the random-close-packing estimate of
:func:`itr_fv.materials.psd.phi_rcp_lognormal` (Farr 2013) evaluated at the standard deviation of
``ln D`` of the number-weighted, truncated mixture of all fillers; a target above it raises
``ValueError`` that states the estimate. (For a mixture of two lognormals this is an
approximation of the Farr-Groot model; near the limit the packer may also fail, which
raises ``RuntimeError``.)
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import numpy as np
from scipy import special

from ..checks import finite_number as _num
from ..materials.paper_data import psd_lognormal
from ..materials.psd import (
    LogNormalPSD,
    fit_sample,
    fit_truncated_sample,
    phi_rcp_lognormal,
)
from .contact_film import ContactFilm
from .microstructure import Microstructure, grid_slabs, label_counts
from .packing import PackingResult, pack_spheres, pairs_within_gap
from .spec import (
    MAX_DIAMETER_BOX_RATIO,
    MIN_DIAMETER_VOXELS,
    TAIL_QUANTILE,
    RVESpec,
    check_seed,
)

__all__ = [
    "FillerReport",
    "FillerSpec",
    "PackedRVE",
    "RVEReport",
    "SizeCut",
    "build_rve",
    "generate_rve",
    "generate_rve_with_report",
    "packing_limit",
    "size_cut",
    "stage_bar",
]


@dataclass(frozen=True)
class FillerSpec:
    """One filler type of an RVE.

    Parameters
    ----------
    material : str
        Phase name of the filler (e.g. ``"Al2O3"``), non-empty.
    mu : float
        Mean of ``ln(D / 1 um)`` (Table 1).
    sigma : float
        Standard deviation of ``ln(D / 1 um)``, > 0.
    volume_fraction : float
        Target absolute volume fraction of this filler in the RVE, 0 < f < 1.
    basis : {"number", "volume"}
        Weighting of ``mu``/``sigma``; Table 1 is number-weighted (the default). A
        volume-weighted pair (laser diffraction) is converted with Hatch-Choate.
    d_min_um, d_max_um : float, optional
        Explicit truncation of the diameters, um (> 0). The generator may cut further
        (see the module notes); ``d_max_um`` above the spec's ``max_diameter_box_ratio``
        of the box is an error.
    """

    material: str
    mu: float
    sigma: float
    volume_fraction: float
    basis: str = "number"
    d_min_um: float | None = None
    d_max_um: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.material, str) or not self.material.strip():
            raise ValueError(f"material: expected a non-empty phase name, got {self.material!r}")
        _num(self.mu, "mu")
        s = _num(self.sigma, "sigma")
        if s <= 0:
            raise ValueError(f"sigma must be > 0, got {s!r}")
        f = _num(self.volume_fraction, "volume_fraction")
        if not 0.0 < f < 1.0:
            raise ValueError(f"volume_fraction must lie in (0, 1), got {f!r}")
        if self.basis not in ("number", "volume"):
            raise ValueError(f"basis: expected 'number' or 'volume', got {self.basis!r}")
        for name in ("d_min_um", "d_max_um"):
            v = getattr(self, name)
            if v is not None and _num(v, name) <= 0:
                raise ValueError(f"{name} must be > 0 um, got {v!r}")
        if (self.d_min_um is not None and self.d_max_um is not None
                and self.d_min_um >= self.d_max_um):
            raise ValueError(f"d_min_um ({self.d_min_um}) must be below d_max_um ({self.d_max_um})")

    @classmethod
    def from_table1(cls, material: str, volume_fraction: float, **kwargs: object) -> FillerSpec:
        """Filler with the paper's Table 1 distribution (``"Al2O3"`` or ``"AlN"``): a
        shorthand for scripts and tests; the package's own code takes a filler's sizes from
        its material system."""
        table1 = psd_lognormal()
        if material not in table1:
            raise ValueError(f"material: unknown filler {material!r} (Table 1 has "
                             f"{sorted(table1)})")
        mu, sigma = table1[material]
        return cls(material, mu, sigma, volume_fraction, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def of(cls, material: str, psd: LogNormalPSD, volume_fraction: float, *,
           number_read_as: str = "number") -> FillerSpec:
        """Filler of a stated size distribution (a material system's): a volume-basis
        statement as stated; a number-basis one read in ``number_read_as`` (the basis
        question of the paper's Table 1, ``ForwardSettings.psd_basis``)."""
        basis = number_read_as if psd.basis == "number" else psd.basis
        return cls(material, psd.mu, psd.sigma, volume_fraction, basis=basis)

    @property
    def psd(self) -> LogNormalPSD:
        """Number-weighted distribution of the diameters (um)."""
        return LogNormalPSD(float(self.mu), float(self.sigma), self.basis).to_number()


@dataclass(frozen=True)
class FillerReport:
    """Per-filler numbers of :class:`RVEReport` (diameters in um, fractions absolute)."""

    material: str
    target_fraction: float
    analytic_fraction: float
    voxel_fraction: float
    n_particles: int
    mu_target: float
    sigma_target: float
    d_lo_um: float
    d_hi_um: float
    cut_number_low: float
    cut_number_high: float
    cut_volume_low: float
    cut_volume_high: float
    d_min_drawn_um: float
    d_max_drawn_um: float
    mu_fit: float
    sigma_fit: float
    mu_fit_truncated: float
    sigma_fit_truncated: float
    ks_statistic: float
    ks_pvalue: float


@dataclass(frozen=True)
class RVEReport:
    """Quality report of an RVE (:func:`generate_rve_with_report`), frozen.

    Attributes
    ----------
    seed : int
        The packing seed.
    box_um, voxel_um : float
        Box and voxel edge, um.
    shape : tuple of int
        Voxels per axis.
    min_gap_um : float
        Thinnest matrix film the packer kept between two particles, um.
    fillers : tuple of FillerReport
        Per filler: target / analytic (sphere volumes) / voxel volume fraction, truncation
        used (cuts, um, and the number and volume shares of the untruncated distribution
        they remove), the fit of the generated diameters (``mu_fit``, ``sigma_fit``: plain
        lognormal MLE; ``*_fit_truncated``: MLE of the truncated lognormal, estimating the
        parent) and the Kolmogorov-Smirnov statistic and p-value of the generated diameters
        against the truncated target distribution.
    phi_total, phi_rcp_estimate, sigma_ln_mixture : float
        Total target fraction, the packing-limit estimate and the standard deviation of
        ``ln D`` it was evaluated at.
    n_particles : int
        Particles of all fillers.
    n_overlaps : int
        Pairs closer than ``min_gap_um`` in the exact check of the final table (0).
    smallest_gap_um : float
        Smallest surface gap between two particles, um.
    contact_gap_um : float
        Threshold for the coordination number: half a voxel, um.
    n_contact_pairs : int
        Particle pairs with surface gap below ``contact_gap_um``.
    coordination_number : float
        ``2 n_contact_pairs / n_particles``.
    voxel_face_contacts : int
        Voxel faces between two different particles (periodic).
    gap_counts : dict of str to int
        Distribution of the surface gaps between particle pairs: the number of pairs with a
        gap below each of ``GAP_BINS_UM`` (keys such as ``"<0.005 um"``), cumulative.
    iterations, neighbour_builds : int
        Packing sweeps and neighbour-list rebuilds.
    seconds : dict
        Wall time per stage (``sample``, ``pack``, ``check``, ``voxelize``, ``report``,
        ``total``), s.
    warnings : tuple of str
        The warnings of the build (the box cutting a filler's coarse tail).
    """

    seed: int
    box_um: float
    voxel_um: float
    shape: tuple[int, int, int]
    min_gap_um: float
    fillers: tuple[FillerReport, ...]
    phi_total: float
    phi_rcp_estimate: float
    sigma_ln_mixture: float
    n_particles: int
    n_overlaps: int
    smallest_gap_um: float
    contact_gap_um: float
    n_contact_pairs: int
    coordination_number: float
    voxel_face_contacts: int
    iterations: int
    neighbour_builds: int
    gap_counts: dict[str, int] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dictionary."""
        d = asdict(self)
        d["shape"] = list(self.shape)
        d["fillers"] = list(d["fillers"])
        d["warnings"] = list(d["warnings"])
        return d

    def summary(self) -> str:
        """Multi-line human-readable summary."""
        lines = [(f"RVE {self.box_um:g} um, voxel {self.voxel_um:g} um {self.shape}, seed "
                  f"{self.seed}: {self.n_particles} particles, phi {self.phi_total:.4f} "
                  f"(limit estimate {self.phi_rcp_estimate:.3f} at sigma_ln "
                  f"{self.sigma_ln_mixture:.3f})"),
                 (f"  overlaps {self.n_overlaps}, smallest gap {self.smallest_gap_um:.3g} um, "
                  f"coordination {self.coordination_number:.2f} (gap < "
                  f"{self.contact_gap_um:g} um), voxel-face contacts {self.voxel_face_contacts}"),
                 "  pairs with a gap " + ", ".join(f"{k}: {v}"
                                                   for k, v in self.gap_counts.items()),
                 f"  packing {self.iterations} sweeps, {self.neighbour_builds} list builds; "
                 + ", ".join(f"{k} {v:.2f} s" for k, v in self.seconds.items())]
        for f in self.fillers:
            lines.append(
                f"  {f.material}: target {f.target_fraction:.4f} analytic "
                f"{f.analytic_fraction:.4f} voxel {f.voxel_fraction:.4f}; n={f.n_particles}; "
                f"D in [{f.d_lo_um:.3g}, {f.d_hi_um:.3g}] um (cut number "
                f"{f.cut_number_low:.2%}/{f.cut_number_high:.2%}, volume "
                f"{f.cut_volume_low:.2%}/{f.cut_volume_high:.2%}); fit mu {f.mu_fit:.3f} "
                f"sigma {f.sigma_fit:.3f} (target {f.mu_target:.3f}/{f.sigma_target:.3f}; "
                f"truncated MLE {f.mu_fit_truncated:.3f}/{f.sigma_fit_truncated:.3f}); KS D "
                f"{f.ks_statistic:.4f} p {f.ks_pvalue:.3f}")
        lines.extend(f"  warning: {w}" for w in self.warnings)
        return "\n".join(lines)


# --------------------------------------------------------------------------- helpers
def _trunc_ln_moments(mu: float, sigma: float, zl: float, zh: float) -> tuple[float, float]:
    """Mean and variance of ln D for a normal in ln D truncated to z in [zl, zh]."""
    p = special.ndtr(zh) - special.ndtr(zl)
    phl = math.exp(-0.5 * zl * zl) / math.sqrt(2 * math.pi) if math.isfinite(zl) else 0.0
    phh = math.exp(-0.5 * zh * zh) / math.sqrt(2 * math.pi) if math.isfinite(zh) else 0.0
    zlp = zl * phl if math.isfinite(zl) else 0.0
    zhp = zh * phh if math.isfinite(zh) else 0.0
    m = (phl - phh) / p
    v = 1.0 + (zlp - zhp) / p - m * m
    return mu + sigma * m, sigma * sigma * v


def packing_limit(specs: Sequence[FillerSpec], cuts: Sequence[tuple[float, float]] | None = None
                  ) -> tuple[float, float]:
    """Random-close-packing estimate for a set of fillers.

    Farr's lognormal fit (:func:`itr_fv.materials.psd.phi_rcp_lognormal`) evaluated at the standard
    deviation of ``ln D`` of the number-weighted mixture (each filler truncated to its
    ``cuts`` ``(d_lo_um, d_hi_um)`` when given).

    Returns
    -------
    (phi_rcp, sigma_ln)
    """
    ws, ms, vs = [], [], []
    for k, s in enumerate(specs):
        psd = s.psd
        lo, hi = cuts[k] if cuts is not None else (0.0, math.inf)
        zl = (math.log(lo) - psd.mu) / psd.sigma if lo > 0 else -math.inf
        zh = (math.log(hi) - psd.mu) / psd.sigma if math.isfinite(hi) else math.inf
        m, v = _trunc_ln_moments(psd.mu, psd.sigma, zl, zh)
        mean_vol = math.pi / 6 * psd.truncated_moment_um(3.0, lo, hi)
        ws.append(s.volume_fraction / mean_vol)
        ms.append(m)
        vs.append(v)
    w = np.array(ws) / sum(ws)
    m = np.array(ms)
    mean = float(np.sum(w * m))
    var = float(np.sum(w * (np.array(vs) + m * m)) - mean * mean)
    sig = math.sqrt(max(var, 0.0))
    return phi_rcp_lognormal(sig), sig


def _draw_to_volume(psd: LogNormalPSD, target_um3: float, lo: float, hi: float,
                    rng: np.random.Generator, stratified: bool) -> np.ndarray:
    """Number-weighted diameters whose sphere volumes add up to ``target_um3`` exactly.

    The first batch holds the expected number of particles (stratified when asked, in
    random order), further batches are independent draws. Diameters are taken in order
    until the target volume is passed; the last one is then replaced by the diameter that
    closes the gap exactly when that lies in ``[lo, hi]``; otherwise the last draw is
    dropped and all diameters are scaled by the (tiny, < (lo / D)^3) factor that hits the
    target.
    """
    mean_v = math.pi / 6 * psd.truncated_moment_um(3.0, lo, hi)
    batch = max(1, round(target_um3 / mean_v))
    parts: list[np.ndarray] = []
    total = 0.0
    first = True
    while True:
        d = psd.sample(batch, rng, lo, hi, stratified=stratified and first)
        first = False
        v = math.pi / 6 * d ** 3
        cum = total + np.cumsum(v)
        k = int(np.searchsorted(cum, target_um3))
        if k < d.size:
            parts.append(d[:k + 1])
            break
        parts.append(d)
        total = float(cum[-1])
        batch = max(16, batch // 4)
    d = np.concatenate(parts)
    before = float(np.sum(math.pi / 6 * d[:-1] ** 3))
    rest = target_um3 - before
    d_rest = (6.0 * rest / math.pi) ** (1.0 / 3.0) if rest > 0 else 0.0
    if d_rest >= lo:
        d[-1] = min(d_rest, hi)
    else:
        d = d[:-1]
    vol = float(np.sum(math.pi / 6 * d ** 3))
    if d.size == 0:
        raise ValueError("volume_fraction: the target volume is smaller than one particle")
    return d * (target_um3 / vol) ** (1.0 / 3.0)


class SizeCut(NamedTuple):
    """The diameters one filler's RVE draws (:func:`size_cut`), um, and the shares of its
    untruncated number-weighted lognormal that the two cuts remove (fractions, 0-1)."""

    d_lo_um: float
    d_hi_um: float
    number_low: float
    number_high: float
    volume_low: float
    volume_high: float
    #: Whether ``d_hi_um`` is the box's limit ``max_diameter_box_ratio * box_um`` (the box
    #: cut) rather than the far tail or the spec's ``d_max_um``.
    box_limited: bool


def size_cut(filler: FillerSpec, box_um: float, voxel_um: float, *,
             tail_quantile: float = TAIL_QUANTILE,
             min_diameter_voxels: float = MIN_DIAMETER_VOXELS,
             max_diameter_box_ratio: float = MAX_DIAMETER_BOX_RATIO) -> SizeCut:
    """The size truncation :func:`generate_rve` applies to one filler (module notes, "Size
    truncation"): the range ``[d_lo, d_hi]`` of the drawn diameters and the number and
    volume shares of the lognormal below and above it.

    Parameters
    ----------
    filler : FillerSpec
        The filler and its size distribution.
    box_um, voxel_um : float
        Box and voxel edge, um (an :class:`RVESpec`'s pair).
    tail_quantile, max_diameter_box_ratio : float
        As in :class:`RVESpec` (the same defaults, checked by it).
    min_diameter_voxels : float
        Smallest particle diameter, in voxels (>= 0; :attr:`RVESpec.min_diameter_voxels`).

    Returns
    -------
    SizeCut

    Raises
    ------
    ValueError
        Bad cut arguments (named), an explicit ``d_max_um`` above ``max_diameter_box_ratio``
        of the box, or a voxel too coarse for the small particles of the filler.
    """
    RVESpec(box_um, voxel_um, max_diameter_box_ratio=max_diameter_box_ratio,
            tail_quantile=tail_quantile)
    mdv = _num(min_diameter_voxels, "min_diameter_voxels")
    if mdv < 0:
        raise ValueError(f"min_diameter_voxels must be >= 0, got {min_diameter_voxels!r}")
    return _size_cut(filler, float(box_um), float(voxel_um), float(tail_quantile), mdv,
                     float(max_diameter_box_ratio))


def _spec_cut(filler: FillerSpec, spec: RVESpec) -> SizeCut:
    """:func:`size_cut` of a filler in the RVE of ``spec`` (already checked)."""
    return _size_cut(filler, float(spec.box_um), float(spec.voxel_um),
                     float(spec.tail_quantile), float(spec.min_diameter_voxels),
                     float(spec.max_diameter_box_ratio))


def _size_cut(s: FillerSpec, L: float, h: float, tq: float, mdv: float,
              ratio: float) -> SizeCut:
    """:func:`size_cut` of checked arguments: box ``L`` and voxel ``h`` (um), tail quantile
    ``tq``, smallest diameter ``mdv`` voxels, largest ``ratio`` of the box."""
    psd = s.psd
    if s.d_max_um is not None and s.d_max_um > ratio * L * (1 + 1e-12):
        raise ValueError(f"box_um: a box of {L:g} um is too small for particles up to "
                         f"d_max_um = {s.d_max_um:g} um of {s.material} (the box must be at "
                         f"least {1 / ratio:.3g} x d_max)")
    hi = min(float(psd.ppf(1.0 - tq)), ratio * L,
             s.d_max_um if s.d_max_um is not None else math.inf)
    lo_vox = mdv * h
    lo = max(float(psd.ppf(tq)), lo_vox, s.d_min_um if s.d_min_um is not None else 0.0)
    if lo >= hi:
        raise ValueError(f"voxel_um: with {mdv:g}-voxel minimum diameter ({lo_vox:g} um) "
                         f"nothing of {s.material} remains below d_hi = {hi:.3g} um")
    n_lo_vox, _ = psd.mass_outside(lo_vox, math.inf, 0.0)
    v_lo_vox, _ = psd.mass_outside(lo_vox, math.inf, 3.0)
    if v_lo_vox > 0.01 or n_lo_vox > 0.05:
        raise ValueError(
            f"voxel_um: {h:g} um voxels cannot resolve the small particles of {s.material} "
            f"that matter: diameters below {mdv:g} voxels = {lo_vox:g} um hold "
            f"{v_lo_vox:.1%} of its volume and {n_lo_vox:.1%} of its particles "
            f"(limits 1 % and 5 %); use a smaller voxel")
    nl, nh = psd.mass_outside(lo, hi, 0.0)
    vl, vh = psd.mass_outside(lo, hi, 3.0)
    box_limited = hi <= ratio * L * (1 + 1e-12) and abs(hi - ratio * L) < 1e-9 * L
    return SizeCut(lo, hi, nl, nh, vl, vh, bool(box_limited))


def _face_contacts(pid: np.ndarray) -> int:
    """Voxel faces between two different particles (periodic), counted slab by slab."""
    n = 0
    for rows in grid_slabs(pid.shape):
        p = pid[rows]
        below = pid[np.arange(rows.start + 1, rows.stop + 1) % pid.shape[0]]
        for q in (below, np.roll(p, -1, axis=1), np.roll(p, -1, axis=2)):
            n += int(np.count_nonzero((p != q) & (p > 0) & (q > 0)))
    return n


#: Upper edges of the gap distribution of ``RVEReport.gap_counts``, um.
GAP_BINS_UM = (0.002, 0.005, 0.02, 0.1, 0.5)

#: A stage of :func:`generate_rve` shows its progress bar once it has run this long, s.
PROGRESS_DELAY_S = 1.0

#: Steps of a stage's progress bar.
_BAR_STEPS = 1000


@contextmanager
def stage_bar(desc: str, enabled: bool = True) -> Iterator[Callable[[float], None] | None]:
    """A progress bar for one stage of an RVE build, fed with the fraction done.

    A ``tqdm`` bar (``tqdm.auto``: stderr in a terminal) that appears only once the stage
    has lasted :data:`PROGRESS_DELAY_S` (fast stages print nothing) and is removed when it
    ends; it shows the percentage, elapsed and remaining time.

    Parameters
    ----------
    desc : str
        The stage (``"packing"``, ``"voxelizing"``).
    enabled : bool
        False: no bar, the block gets None.

    Yields
    ------
    callable or None
        ``update(fraction)``, fraction in [0, 1].
    """
    if not enabled:
        yield None
        return
    from tqdm.auto import tqdm

    with tqdm(total=_BAR_STEPS, desc=desc, delay=PROGRESS_DELAY_S, leave=False,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]") as bar:
        def update(fraction: float) -> None:
            step = min(_BAR_STEPS, int(fraction * _BAR_STEPS))
            if step > bar.n:
                bar.update(step - bar.n)

        yield update


# --------------------------------------------------------------------------- main
#: The packer's relative clearance of the contact distance (``inflate`` of
#: :func:`itr_fv.rve.packing.pack_spheres`): spheres it leaves touching are
#: ``inflate/2 .. inflate`` times ``R_i + R_j`` apart beyond ``min_gap_um``, a clearance the
#: particle table's :class:`~itr_fv.rve.contact_film.ContactFilm` takes out of the contacts.
_INFLATE = 1e-3


@dataclass(frozen=True)
class _Packed:
    """What one RVE build made: the microstructure and what its report is computed from.

    Diameters ``diameters[k]`` (um) of filler ``k`` with the size cut ``cuts[k]``;
    ``owner`` the filler of every particle (particle table order); ``gaps`` the surface
    gaps (um) of the pairs closer than ``max(contact_gap_um, min_gap_um)``; ``seconds``
    the wall time of the stages so far, s.
    """

    spec: RVESpec
    seed: int
    fillers: tuple[FillerSpec, ...]
    cuts: tuple[SizeCut, ...]
    phi_total: float
    phi_rcp: float
    sigma_ln: float
    diameters: tuple[np.ndarray, ...]
    owner: np.ndarray
    centers_um: np.ndarray
    packing: PackingResult
    gaps_um: np.ndarray
    microstructure: Microstructure
    warnings: tuple[str, ...]
    seconds: dict[str, float]
    started: float

    @property
    def all_diameters(self) -> np.ndarray:
        """Diameters of all particles in particle table order, um."""
        return np.concatenate(self.diameters)

    @property
    def contact_gap_um(self) -> float:
        """The coordination number's contact threshold: half a voxel, um."""
        return 0.5 * float(self.spec.voxel_um)


def _checked_fillers(fillers: Sequence[FillerSpec] | FillerSpec, matrix: str,
                     materials: Iterable[str] | None) -> tuple[FillerSpec, ...]:
    """The fillers as a tuple, checked against each other, the matrix and the known phases
    (ValueError naming ``fillers``, ``matrix`` or ``materials``)."""
    if isinstance(fillers, FillerSpec):
        fillers = [fillers]
    if (isinstance(fillers, (str, bytes)) or not isinstance(fillers, Sequence)
            or len(fillers) == 0):
        raise ValueError("fillers: expected a FillerSpec or a non-empty sequence of FillerSpec")
    for s in fillers:
        if not isinstance(s, FillerSpec):
            raise ValueError(f"fillers: expected FillerSpec items, got {type(s).__name__}")
    if not isinstance(matrix, str) or not matrix:
        raise ValueError(f"matrix: expected a phase name, got {matrix!r}")
    if materials is not None:
        known = set(getattr(materials, "phases", None) or materials)
        for s in fillers:
            if s.material not in known:
                raise ValueError(f"fillers: unknown material {s.material!r} (known: "
                                 f"{sorted(known)})")
        if matrix not in known:
            raise ValueError(f"matrix: unknown material {matrix!r} (known: {sorted(known)})")
    for s in fillers:
        if s.material == matrix:
            raise ValueError(f"fillers: filler material {s.material!r} is the matrix phase")
    phi_total = float(sum(s.volume_fraction for s in fillers))
    if phi_total >= 1.0:
        raise ValueError(f"fillers: volume fractions sum to {phi_total:.4g} >= 1")
    return tuple(fillers)


def _size_cuts(spec: RVESpec, fillers: Sequence[FillerSpec]
               ) -> tuple[tuple[SizeCut, ...], tuple[str, ...]]:
    """Every filler's size cut, and the warnings (also issued as ``UserWarning``) of the
    fillers whose coarse tail the box cuts by more than 1 % of their volume."""
    cuts, said = [], []
    for s in fillers:
        cut = _spec_cut(s, spec)
        if cut.box_limited and cut.volume_high > 0.01:
            psd = s.psd
            msg = (f"{s.material}: the {float(spec.box_um):g} um box limits diameters to "
                   f"{cut.d_hi_um:.3g} um (box/{1 / spec.max_diameter_box_ratio:.3g}); the cut "
                   f"removes {cut.volume_high:.1%} of the volume ({cut.number_high:.2%} of "
                   f"the particles) of the lognormal (mu={psd.mu}, sigma={psd.sigma}) -- the "
                   "RVE under-represents its coarse particles")
            warnings.warn(msg, UserWarning, stacklevel=4)  # at generate_rve's caller
            said.append(msg)
        cuts.append(cut)
    return tuple(cuts), tuple(said)


def _check_packing_limit(fillers: Sequence[FillerSpec], cuts: Sequence[SizeCut]
                         ) -> tuple[float, float, float]:
    """``(phi_total, phi_rcp, sigma_ln)``: the fillers' total fraction, below the packing
    limit estimate ``phi_rcp`` at the mixture's ``sigma_ln`` (else ValueError)."""
    phi_total = float(sum(s.volume_fraction for s in fillers))
    phi_rcp, sig_mix = packing_limit(fillers, [(c.d_lo_um, c.d_hi_um) for c in cuts])
    if phi_total > phi_rcp:
        raise ValueError(f"fillers: total volume fraction {phi_total:.4g} exceeds the estimated "
                         f"random-close-packing limit {phi_rcp:.4f} of these size "
                         f"distributions (Farr 2013 lognormal fit at sigma_ln = {sig_mix:.3f})")
    return phi_total, phi_rcp, sig_mix


def _draw_diameters(spec: RVESpec, fillers: Sequence[FillerSpec], cuts: Sequence[SizeCut],
                    rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Every filler's diameters (um), in filler order from one stream of ``rng``, their
    sphere volumes adding up to its volume fraction of the box."""
    box3 = float(spec.box_um) ** 3
    return tuple(_draw_to_volume(s.psd, s.volume_fraction * box3, c.d_lo_um, c.d_hi_um, rng,
                                 spec.sampling == "stratified")
                 for s, c in zip(fillers, cuts))


def _pack(spec: RVESpec, radii_um: np.ndarray, rng: np.random.Generator,
          limits: tuple[float, float], progress: bool) -> PackingResult:
    """The packed spheres (RuntimeError when the packer does not converge within
    ``spec.max_sweeps``; ``limits`` = total fraction and its packing-limit estimate, for the
    message)."""
    with stage_bar("packing", progress) as bar:
        res = pack_spheres(radii_um, float(spec.box_um), rng,
                           min_gap=float(spec.min_gap_um), inflate=_INFLATE,
                           max_iter=spec.max_sweeps, progress=bar)
    if not res.converged:
        raise RuntimeError(f"packing did not converge in {res.iterations} sweeps (largest "
                           f"relative overlap {res.max_rel_overlap:.3g}) at total fraction "
                           f"{limits[0]:.4f}; the limit estimate is {limits[1]:.4f} -- lower "
                           f"the fractions or raise max_sweeps")
    return res


def _near_gaps(spec: RVESpec, centers_um: np.ndarray, radii_um: np.ndarray) -> np.ndarray:
    """Surface gaps (um) of the pairs within half a voxel or ``min_gap_um``, from the exact
    check (RuntimeError when a pair is closer than ``min_gap_um``)."""
    L, gap = float(spec.box_um), float(spec.min_gap_um)
    reach = max(0.5 * float(spec.voxel_um), gap) + 1e-9 * L
    _, _, g = pairs_within_gap(centers_um, radii_um, L, reach)
    n_bad = int(np.count_nonzero(g < gap))
    if n_bad:
        raise RuntimeError(f"packing left {n_bad} pairs closer than min_gap_um={gap:g} um")
    return g


def _voxelize(spec: RVESpec, centers_um: np.ndarray, radii_um: np.ndarray,
              materials: Sequence[str], matrix: str, progress: bool) -> Microstructure:
    """The voxel image of the spheres (um in, the microstructure in metres), with the
    contact film of ``spec``."""
    film = ContactFilm(film_m=float(spec.contact_film_um) * 1e-6,
                       packing_gap_m=float(spec.min_gap_um) * 1e-6, tolerance=_INFLATE)
    with stage_bar("voxelizing", progress) as bar:
        return Microstructure.from_spheres(
            centers_um * 1e-6, radii_um * 1e-6, materials, box_m=float(spec.box_um) * 1e-6,
            shape=spec.n, matrix=matrix, contact=film, progress=bar)


def _build(spec: RVESpec, fillers: Sequence[FillerSpec] | FillerSpec, seed: int,
           matrix: str, materials: Iterable[str] | None, progress: bool) -> _Packed:
    """Check, cut, draw, pack, check and voxelize: the work of :func:`generate_rve`."""
    t_start = time.perf_counter()
    if not isinstance(spec, RVESpec):
        raise ValueError(f"spec: expected an RVESpec, got {type(spec).__name__}")
    seed = check_seed(seed)
    fillers = _checked_fillers(fillers, matrix, materials)
    cuts, said = _size_cuts(spec, fillers)
    limits = _check_packing_limit(fillers, cuts)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    diam = _draw_diameters(spec, fillers, cuts, rng)
    d_all = np.concatenate(diam)
    owner = np.concatenate([np.full(d.size, k, dtype=np.int64) for k, d in enumerate(diam)])
    t1 = time.perf_counter()
    res = _pack(spec, 0.5 * d_all, rng, limits[:2], progress)
    t2 = time.perf_counter()
    gaps = _near_gaps(spec, res.centers, 0.5 * d_all)
    t3 = time.perf_counter()
    ms = _voxelize(spec, res.centers, 0.5 * d_all, [fillers[k].material for k in owner],
                   matrix, progress)
    seconds = {"sample": t1 - t0, "pack": res.seconds, "check": t3 - t2,
               "voxelize": time.perf_counter() - t3}
    return _Packed(spec, seed, fillers, cuts, *limits, diam, owner, res.centers, res, gaps,
                   ms, said, seconds, t_start)


def generate_rve(spec: RVESpec, fillers: Sequence[FillerSpec] | FillerSpec, seed: int, *,
                 matrix: str = "silicone", materials: Iterable[str] | None = None,
                 progress: bool = True) -> Microstructure:
    """Dense periodic RVE of non-overlapping lognormal polydisperse spheres.

    Parameters
    ----------
    spec : RVESpec
        Box and voxel edge, um, the size cuts (``tail_quantile``,
        ``max_diameter_box_ratio``, the two-voxel fine cut of ``cut_voxel_um``), the
        thinnest matrix film the packer keeps between two particles (``min_gap_um``), the
        film touching particles meet at (``film_um``, default ``min_gap_um``), the drawing
        of the diameters (``sampling``) and the packer's sweep limit (``max_sweeps``). Its
        ``seed`` is not used: the packing seed is ``seed``.

        ``min_gap_um`` is a physical parameter of the composite, the silicone film that
        separates touching particles: under the gap contact model
        (``Materials(contact="gap")``) it is the film of every contact, whose resistance
        ``2 R_b + d / k_m`` it enters; the pairs the packer leaves touching meet at exactly
        this film, whatever their size (the particle table's
        :class:`~itr_fv.rve.contact_film.ContactFilm`; the packer's clearance is taken out
        of the contact geometry). 0 (default): particles in contact through their two
        interface resistances alone.
    fillers : FillerSpec or sequence of FillerSpec
        Filler types with their size distribution and target volume fraction.
    seed : int
        Seed of ``numpy.random.default_rng`` (>= 0); the same seed gives the same particle
        table bit for bit (on the same platform and library versions).
    matrix : str
        Name of the matrix phase.
    materials : iterable of str or Materials, optional
        Known phase names (e.g. the keys of ``Materials.conductivity`` or a ``Materials``
        object): every filler and the matrix must be among them.
    progress : bool
        Progress bars (:func:`stage_bar`, on stderr) for the packing and the voxelization
        when they last over :data:`PROGRESS_DELAY_S`; False: none. Either way the packing
        returns to Python every few tens of milliseconds, so Ctrl-C and a SIGTERM handler
        that raises stop it at once.

    Returns
    -------
    Microstructure
        Voxel image (material and particle ids, particle table in metres).
        :func:`generate_rve_with_report` gives the same microstructure with its quality
        report.

    Raises
    ------
    ValueError
        Bad arguments (named in the message; the settings of ``spec`` are checked when it
        is made), a total fraction beyond the packing-limit estimate, a voxel too coarse
        for the particles, an explicit ``d_max_um`` above ``max_diameter_box_ratio`` of the
        box, an unknown material.
    RuntimeError
        The packer did not reach a non-overlapping state within ``spec.max_sweeps`` sweeps.
    """
    return _build(spec, fillers, seed, matrix, materials, progress).microstructure


def generate_rve_with_report(spec: RVESpec, fillers: Sequence[FillerSpec] | FillerSpec,
                             seed: int, *, matrix: str = "silicone",
                             materials: Iterable[str] | None = None, progress: bool = True
                             ) -> tuple[Microstructure, RVEReport]:
    """:func:`generate_rve` and the quality report of the RVE it packed.

    Parameters
    ----------
    spec, fillers, seed, matrix, materials, progress
        As in :func:`generate_rve` (the same arguments give the same microstructure).

    Returns
    -------
    microstructure : Microstructure
    report : RVEReport
        Fractions, size cuts and fits per filler, packing limit, gaps and contacts, timings.
    """
    packed = _build(spec, fillers, seed, matrix, materials, progress)
    return packed.microstructure, _report(packed)


# --------------------------------------------------------------------------- report
def _filler_reports(packed: _Packed) -> tuple[FillerReport, ...]:
    """Per filler: fractions (target, analytic, voxel), size cut and the fit of the drawn
    diameters."""
    from scipy import stats  # here, not at import: 0.9 s every command would wait for

    ms = packed.microstructure
    counts = label_counts(ms.particle_ids, packed.owner.size + 1)[1:]
    nvox3 = float(packed.spec.n) ** 3
    box3 = float(packed.spec.box_um) ** 3
    out = []
    for k, (s, d, cut) in enumerate(zip(packed.fillers, packed.diameters, packed.cuts)):
        psd = s.psd
        lo, hi = cut.d_lo_um, cut.d_hi_um
        mu_f, s_f = fit_sample(d) if d.size > 1 else (math.log(d[0]), 0.0)
        mu_t, s_t = fit_truncated_sample(d, lo, hi) if d.size > 2 else (mu_f, s_f)
        ks = stats.kstest(d, psd.truncated_cdf(lo, hi))
        out.append(FillerReport(
            material=s.material, target_fraction=float(s.volume_fraction),
            analytic_fraction=float(np.sum(math.pi / 6 * d ** 3) / box3),
            voxel_fraction=float(counts[packed.owner == k].sum() / nvox3),
            n_particles=int(d.size), mu_target=psd.mu, sigma_target=psd.sigma,
            d_lo_um=lo, d_hi_um=hi, cut_number_low=cut.number_low,
            cut_number_high=cut.number_high, cut_volume_low=cut.volume_low,
            cut_volume_high=cut.volume_high, d_min_drawn_um=float(d.min()),
            d_max_drawn_um=float(d.max()), mu_fit=mu_f, sigma_fit=s_f,
            mu_fit_truncated=mu_t, sigma_fit_truncated=s_t,
            ks_statistic=float(ks.statistic), ks_pvalue=float(ks.pvalue)))
    return tuple(out)


def _report(packed: _Packed) -> RVEReport:
    """The quality report of one build."""
    t0 = time.perf_counter()
    spec, d_all, g = packed.spec, packed.all_diameters, packed.gaps_um
    fillers = _filler_reports(packed)
    cgap = packed.contact_gap_um
    n_contact = int(np.count_nonzero(g < cgap))
    _, _, g_all = pairs_within_gap(packed.centers_um, 0.5 * d_all, float(spec.box_um),
                                   GAP_BINS_UM[-1])
    gap_counts = {f"<{b:g} um": int(np.count_nonzero(g_all < b)) for b in GAP_BINS_UM}
    face_contacts = _face_contacts(packed.microstructure.particle_ids)
    seconds = {**packed.seconds, "report": time.perf_counter() - t0,
               "total": time.perf_counter() - packed.started}
    return RVEReport(
        seed=packed.seed, box_um=float(spec.box_um), voxel_um=float(spec.voxel_um),
        shape=spec.shape, min_gap_um=float(spec.min_gap_um), fillers=fillers,
        phi_total=packed.phi_total, phi_rcp_estimate=packed.phi_rcp,
        sigma_ln_mixture=packed.sigma_ln, n_particles=int(d_all.size),
        n_overlaps=int(np.count_nonzero(g < spec.min_gap_um)),
        smallest_gap_um=float(g.min()) if g.size else math.inf, contact_gap_um=cgap,
        n_contact_pairs=n_contact, coordination_number=2.0 * n_contact / d_all.size,
        voxel_face_contacts=face_contacts, iterations=packed.packing.iterations,
        neighbour_builds=packed.packing.neighbour_builds, gap_counts=gap_counts,
        seconds=seconds, warnings=packed.warnings)


class PackedRVE(NamedTuple):
    """An RVE of :func:`build_rve` and the packing seed that made it."""

    microstructure: Microstructure
    seed: int


def build_rve(spec: RVESpec, fillers: Sequence[FillerSpec] | FillerSpec, replica: int, *,
              matrix: str = "silicone", warn_box_cut: bool = True,
              progress: bool = True) -> PackedRVE:
    """Pack replica ``replica`` of an RVE: the package's one way to build one.

    Parameters
    ----------
    spec : RVESpec
        Box, voxel, size cuts, matrix film and the seed of replica 0.
    fillers : FillerSpec or sequence of FillerSpec
        Filler types with their size distributions and volume fractions.
    replica : int
        Replica number (>= 0): packing seed ``spec.seed + replica``.
    matrix : str
        Name of the matrix phase.
    warn_box_cut : bool
        Let :func:`generate_rve`'s warning about the box cutting the coarse tail through
        (False where the caller reports the cut itself).
    progress : bool
        :func:`generate_rve`'s progress bars (shown only for stages that last over a
        second).

    Returns
    -------
    PackedRVE
        ``(microstructure, seed)``. A packing that does not reach the fractions (dense
        fillers, small boxes) is redrawn with the next seed of :meth:`RVESpec.seeds`
        (``+ 100`` each time); ``seed`` is the one that succeeded.

    Raises
    ------
    ValueError
        Bad fillers for this box and voxel (see :func:`generate_rve`).
    RuntimeError
        No packing succeeded in :data:`~itr_fv.rve.spec.PACKING_ATTEMPTS` draws.
    """
    if not isinstance(spec, RVESpec):
        raise ValueError(f"spec: expected an RVESpec, got {type(spec).__name__}")
    *retries, last = spec.seeds(replica)

    def pack(seed: int) -> PackedRVE:
        with warnings.catch_warnings():
            if not warn_box_cut:
                warnings.simplefilter("ignore", UserWarning)
            ms = generate_rve(spec, fillers, seed=seed, matrix=matrix, progress=progress)
        return PackedRVE(ms, seed)

    for seed in retries:
        try:
            return pack(seed)
        except RuntimeError:
            continue
    return pack(last)
