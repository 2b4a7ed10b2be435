"""Dense periodic RVEs of lognormal polydisperse spheres (paper Sec. 2.4).

:func:`generate_rve` draws number-weighted lognormal diameters for one or more fillers
(:class:`FillerSpec`, Table 1 parameters), packs them without overlap in a periodic cube
(:func:`itr_fv.rve.packing.pack_spheres`) up to the target volume fraction of every filler,
and voxelizes them with particle ids (:meth:`Microstructure.from_spheres`).

The quality report (:class:`RVEReport`) is returned next to the microstructure when
``return_report=True`` -- ``ms, report = generate_rve(..., return_report=True)`` -- and
is not attached to the microstructure.

Size truncation
---------------
Diameters are drawn from the lognormal truncated to ``[d_lo, d_hi]`` per filler:

* ``d_hi = min(ppf(1 - tail_quantile), max_diameter_box_ratio * box_um, spec.d_max_um)``:
  the far tail only (default ``tail_quantile = 1e-4``, i.e. fewer than one particle in a
  typical RVE), unless the periodic box forces a smaller cut -- a particle larger than a
  third of the box would interact with its own images. When that box cut removes more than
  1 % of a filler's volume a ``UserWarning`` says how much (AlN of Table 1 in a 40 um box:
  about 30 % of its volume lies in particles above 13.3 um).
* ``d_lo = max(ppf(tail_quantile), min_diameter_voxels * voxel_um, spec.d_min_um)``: a
  particle must span about two voxels to be resolved. If this cut removes more than 1 % of
  a filler's volume or 5 % of its particles, the voxel is too coarse: ``ValueError``.

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
from .packing import pack_spheres, pairs_within_gap
from .spec import RVESpec, voxels_per_edge

__all__ = ["FillerSpec", "FillerReport", "RVEReport", "generate_rve", "packing_limit",
           "build_rve", "PackedRVE", "SizeCut", "size_cut", "stage_bar"]


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
        (see the module notes); ``d_max_um`` above a third of the box is an error.
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
    def from_table1(cls, material: str, volume_fraction: float, **kwargs: object) -> "FillerSpec":
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
           number_read_as: str = "number") -> "FillerSpec":
        """Filler of a stated size distribution (a material system's): a volume-basis
        statement as stated; a number-basis one read in ``number_read_as`` (the basis
        question of the paper's Table 1, ``ForwardSettings.psd_basis``)."""
        basis = number_read_as if psd.basis == "number" else psd.basis
        return cls(material, psd.mu, psd.sigma, volume_fraction, basis=basis)

    @property
    def psd(self) -> LogNormalPSD:
        """Number-weighted distribution of the diameters (um)."""
        return LogNormalPSD(float(self.mu), float(self.sigma), self.basis).to_number()


@dataclass
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


@dataclass
class RVEReport:
    """Quality report of :func:`generate_rve`.

    Attributes
    ----------
    fillers : list of FillerReport
        Per filler: target / analytic (sphere volumes) / voxel volume fraction, truncation
        used (cuts, um, and the number and volume shares of the untruncated distribution
        they remove), the fit of the generated diameters (``mu_fit``, ``sigma_fit``: plain
        lognormal MLE; ``*_fit_truncated``: MLE of the truncated lognormal, estimating the
        parent) and the Kolmogorov-Smirnov statistic and p-value of the generated diameters
        against the truncated target distribution.
    phi_total, phi_rcp_estimate, sigma_ln_mixture : float
        Total target fraction, the packing-limit estimate and the standard deviation of
        ``ln D`` it was evaluated at.
    n_overlaps : int
        Pairs closer than ``min_gap_um`` in the exact check of the final table (0).
    smallest_gap_um : float
        Smallest surface gap between two particles, um.
    contact_gap_um : float
        Threshold for the coordination number, um.
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
    """

    seed: int
    box_um: float
    voxel_um: float
    shape: tuple[int, int, int]
    min_gap_um: float
    fillers: list[FillerReport]
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
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dictionary."""
        d = asdict(self)
        d["shape"] = list(self.shape)
        return d

    def summary(self) -> str:
        """Multi-line human-readable summary."""
        lines = [f"RVE {self.box_um:g} um, voxel {self.voxel_um:g} um {self.shape}, seed "
                 f"{self.seed}: {self.n_particles} particles, phi {self.phi_total:.4f} "
                 f"(limit estimate {self.phi_rcp_estimate:.3f} at sigma_ln "
                 f"{self.sigma_ln_mixture:.3f})",
                 f"  overlaps {self.n_overlaps}, smallest gap {self.smallest_gap_um:.3g} um, "
                 f"coordination {self.coordination_number:.2f} (gap < {self.contact_gap_um:g} "
                 f"um), voxel-face contacts {self.voxel_face_contacts}",
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
    batch = max(1, int(round(target_um3 / mean_v)))
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


def _cut_arguments(tail_quantile: float, min_diameter_voxels: float,
                   max_diameter_box_ratio: float) -> tuple[float, float, float]:
    """The size-cut arguments of :func:`generate_rve`, checked (ValueError naming one)."""
    tq = _num(tail_quantile, "tail_quantile")
    if not 0.0 < tq < 0.05:
        raise ValueError(f"tail_quantile must lie in (0, 0.05), got {tail_quantile!r}")
    mdv = _num(min_diameter_voxels, "min_diameter_voxels")
    if mdv < 0:
        raise ValueError(f"min_diameter_voxels must be >= 0, got {min_diameter_voxels!r}")
    ratio = _num(max_diameter_box_ratio, "max_diameter_box_ratio")
    if not 0.0 < ratio < 0.5:
        raise ValueError(f"max_diameter_box_ratio must lie in (0, 0.5), got {ratio!r}")
    return tq, mdv, ratio


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


def size_cut(spec: FillerSpec, box_um: float, voxel_um: float, *,
             tail_quantile: float = 1e-4, min_diameter_voxels: float = 2.0,
             max_diameter_box_ratio: float = 1.0 / 3.0) -> SizeCut:
    """The size truncation :func:`generate_rve` applies to one filler (module notes, "Size
    truncation"): the range ``[d_lo, d_hi]`` of the drawn diameters and the number and
    volume shares of the lognormal below and above it.

    Raises
    ------
    ValueError
        Bad cut arguments, an explicit ``d_max_um`` above ``max_diameter_box_ratio`` of the
        box, or a voxel too coarse for the small particles of the filler.
    """
    tq, mdv, ratio = _cut_arguments(tail_quantile, min_diameter_voxels, max_diameter_box_ratio)
    L, h = float(box_um), float(voxel_um)
    s, psd = spec, spec.psd
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
def generate_rve(specs: Sequence[FillerSpec] | FillerSpec, box_um: float, voxel_um: float,
                 seed: int, min_gap_um: float = 0.0, matrix: str = "silicone", *,
                 materials: Iterable[str] | None = None, tail_quantile: float = 1e-4,
                 min_diameter_voxels: float = 2.0, max_diameter_box_ratio: float = 1.0 / 3.0,
                 contact_gap_um: float | None = None, film_um: float | None = None,
                 inflate: float = 1e-3,
                 max_iter: int = 400_000, sampling: str = "stratified",
                 return_report: bool = False, progress: bool = True
                 ) -> Microstructure | tuple[Microstructure, RVEReport]:
    """Dense periodic RVE of non-overlapping lognormal polydisperse spheres.

    Parameters
    ----------
    specs : FillerSpec or sequence of FillerSpec
        Filler types with their size distribution and target volume fraction.
    box_um : float
        Edge of the periodic cube, um (the paper: 40).
    voxel_um : float
        Voxel edge, um; ``box_um / voxel_um`` must be an integer.
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed gives the same particle table
        bit for bit (on the same platform and library versions).
    min_gap_um : float
        Thinnest matrix film between two particles, um (>= 0): a physical parameter of the
        composite, the silicone film that separates touching particles. Under the gap contact
        model (``Materials(contact="gap")``) it is the film of every contact, whose
        resistance ``2 R_b + d / k_m`` it enters: the pairs the packer leaves touching meet
        at exactly this film, whatever their size (the particle table's
        :class:`~itr_fv.rve.contact_film.ContactFilm`; the packer's clearance of
        ``inflate/2 .. inflate`` times the radii is taken out of the contact geometry).
        0 (default): particles in contact through their two interface resistances alone.
        The report's ``gap_counts`` gives the distribution of the packed gaps.
    matrix : str
        Name of the matrix phase.
    materials : iterable of str or Materials, optional
        Known phase names (e.g. the keys of ``Materials.conductivity`` or a ``Materials``
        object): every filler and the matrix must be among them.
    tail_quantile : float
        Number-probability cut of each far tail of the size distribution (see module notes).
    min_diameter_voxels : float
        Smallest particle diameter, in voxels.
    max_diameter_box_ratio : float
        Largest particle diameter as a fraction of the box (default 1/3).
    contact_gap_um : float, optional
        Gap threshold for the coordination number, um (default ``voxel_um / 2``).
    film_um : float, optional
        The film touching particles meet at, um (default ``min_gap_um``); the packing does
        not depend on it.
    inflate : float
        Relative safety margin of the packer's contact distance (see
        :func:`itr_fv.rve.packing.pack_spheres`).
    max_iter : int
        Sweep limit of the packer.
    sampling : {"stratified", "iid"}
        ``"stratified"`` (default): the expected number of diameters is drawn by
        one-dimensional Latin hypercube sampling of the (truncated) number distribution, so
        a few hundred particles already reproduce mu and sigma closely (the KS p-values are
        then near 1, as expected of a sample more even than an independent one);
        ``"iid"``: independent draws.
    return_report : bool
        Return ``(ms, report)`` instead of ``ms``.
    progress : bool
        Progress bars (:func:`stage_bar`, on stderr) for the packing and the voxelization
        when they last over :data:`PROGRESS_DELAY_S`; False: none. Either way the packing
        returns to Python every few tens of milliseconds, so Ctrl-C and a SIGTERM handler
        that raises stop it at once.

    Returns
    -------
    Microstructure or (Microstructure, RVEReport)
        Voxel image (material and particle ids, particle table in metres).

    Raises
    ------
    ValueError
        Bad arguments (named in the message), a total fraction beyond the packing-limit
        estimate, a voxel too coarse for the particles, an explicit ``d_max_um`` above a
        third of the box, an unknown material.
    RuntimeError
        The packer did not reach a non-overlapping state within ``max_iter`` sweeps.
    """
    t_start = time.perf_counter()
    # ------------------------------------------------------------ arguments
    if isinstance(specs, FillerSpec):
        specs = [specs]
    if isinstance(specs, (str, bytes)) or not isinstance(specs, Sequence) or len(specs) == 0:
        raise ValueError("specs: expected a FillerSpec or a non-empty sequence of FillerSpec")
    specs = list(specs)
    for s in specs:
        if not isinstance(s, FillerSpec):
            raise ValueError(f"specs: expected FillerSpec items, got {type(s).__name__}")
    nvox = voxels_per_edge(box_um, voxel_um)
    L, h = float(box_um), float(voxel_um)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    gap = _num(min_gap_um, "min_gap_um")
    if gap < 0:
        raise ValueError(f"min_gap_um must be >= 0 um, got {min_gap_um!r}")
    stated = gap if film_um is None else _num(film_um, "film_um")
    if stated < 0:
        raise ValueError(f"film_um must be >= 0 um, got {film_um!r}")
    if not isinstance(matrix, str) or not matrix:
        raise ValueError(f"matrix: expected a phase name, got {matrix!r}")
    _cut_arguments(tail_quantile, min_diameter_voxels, max_diameter_box_ratio)
    if sampling not in ("stratified", "iid"):
        raise ValueError(f"sampling: expected 'stratified' or 'iid', got {sampling!r}")
    cgap = 0.5 * h if contact_gap_um is None else _num(contact_gap_um, "contact_gap_um")
    if cgap < 0:
        raise ValueError(f"contact_gap_um must be >= 0 um, got {contact_gap_um!r}")
    if materials is not None:
        known = set(getattr(materials, "phases", None) or materials)
        for s in specs:
            if s.material not in known:
                raise ValueError(f"specs: unknown material {s.material!r} (known: {sorted(known)})")
        if matrix not in known:
            raise ValueError(f"matrix: unknown material {matrix!r} (known: {sorted(known)})")
    for s in specs:
        if s.material == matrix:
            raise ValueError(f"specs: filler material {s.material!r} is the matrix phase")
    phi_total = float(sum(s.volume_fraction for s in specs))
    if phi_total >= 1.0:
        raise ValueError(f"specs: volume fractions sum to {phi_total:.4g} >= 1")

    # ------------------------------------------------------------ truncation
    cuts: list[tuple[float, float]] = []
    shares: list[tuple[float, float, float, float]] = []
    warn: list[str] = []
    for s in specs:
        cut = size_cut(s, L, h, tail_quantile=tail_quantile,
                       min_diameter_voxels=min_diameter_voxels,
                       max_diameter_box_ratio=max_diameter_box_ratio)
        if cut.box_limited and cut.volume_high > 0.01:
            psd = s.psd
            msg = (f"{s.material}: the {L:g} um box limits diameters to {cut.d_hi_um:.3g} um "
                   f"(box/{1 / max_diameter_box_ratio:.3g}); the cut removes "
                   f"{cut.volume_high:.1%} of the volume ({cut.number_high:.2%} of the "
                   f"particles) of the lognormal (mu={psd.mu}, sigma={psd.sigma}) -- the RVE "
                   "under-represents its coarse particles")
            warnings.warn(msg, UserWarning, stacklevel=2)
            warn.append(msg)
        cuts.append((cut.d_lo_um, cut.d_hi_um))
        shares.append((cut.number_low, cut.number_high, cut.volume_low, cut.volume_high))

    phi_rcp, sig_mix = packing_limit(specs, cuts)
    if phi_total > phi_rcp:
        raise ValueError(f"specs: total volume fraction {phi_total:.4g} exceeds the estimated "
                         f"random-close-packing limit {phi_rcp:.4f} of these size "
                         f"distributions (Farr 2013 lognormal fit at sigma_ln = {sig_mix:.3f})")

    # ------------------------------------------------------------ sampling
    rng = np.random.default_rng(int(seed))
    t0 = time.perf_counter()
    diam: list[np.ndarray] = []
    for s, (lo, hi) in zip(specs, cuts):
        diam.append(_draw_to_volume(s.psd, s.volume_fraction * L ** 3, lo, hi, rng,
                                    sampling == "stratified"))
    d_all = np.concatenate(diam)
    owner = np.concatenate([np.full(d.size, k, dtype=np.int64) for k, d in enumerate(diam)])
    t_sample = time.perf_counter() - t0

    # ------------------------------------------------------------ packing
    with stage_bar("packing", progress) as bar:
        res = pack_spheres(0.5 * d_all, L, rng, min_gap=gap, inflate=inflate,
                           max_iter=max_iter, progress=bar)
    if not res.converged:
        raise RuntimeError(f"packing did not converge in {res.iterations} sweeps (largest "
                           f"relative overlap {res.max_rel_overlap:.3g}) at total fraction "
                           f"{phi_total:.4f}; the limit estimate is {phi_rcp:.4f} -- lower the "
                           f"fractions or raise max_iter")
    centers = res.centers
    t1 = time.perf_counter()
    pi, pj, g = pairs_within_gap(centers, 0.5 * d_all, L, max(cgap, gap) + 1e-9 * L)
    n_bad = int(np.count_nonzero(g < gap))
    if n_bad:
        raise RuntimeError(f"packing left {n_bad} pairs closer than min_gap_um={gap:g} um")
    t_check = time.perf_counter() - t1

    # ------------------------------------------------------------ voxelize
    t2 = time.perf_counter()
    mats = [specs[k].material for k in owner]
    with stage_bar("voxelizing", progress) as bar:
        ms = Microstructure.from_spheres(
            centers * 1e-6, 0.5 * d_all * 1e-6, mats, box_m=L * 1e-6, shape=nvox,
            matrix=matrix, contact=ContactFilm(film_m=stated * 1e-6, packing_gap_m=gap * 1e-6,
                                               tolerance=float(inflate)), progress=bar)
    t_vox = time.perf_counter() - t2
    if not return_report:
        return ms

    # ------------------------------------------------------------ report
    t3 = time.perf_counter()
    counts = label_counts(ms.particle_ids, d_all.size + 1)[1:]
    nvox3 = float(nvox) ** 3
    from scipy import stats  # here, not at import: 0.9 s every command would wait for

    fillers: list[FillerReport] = []
    for k, s in enumerate(specs):
        d = diam[k]
        lo, hi = cuts[k]
        psd = s.psd
        mu_f, s_f = fit_sample(d) if d.size > 1 else (math.log(d[0]), 0.0)
        mu_t, s_t = fit_truncated_sample(d, lo, hi) if d.size > 2 else (mu_f, s_f)
        ks = stats.kstest(d, psd.truncated_cdf(lo, hi))
        nl, nh, vl, vh = shares[k]
        fillers.append(FillerReport(
            material=s.material, target_fraction=float(s.volume_fraction),
            analytic_fraction=float(np.sum(math.pi / 6 * d ** 3) / L ** 3),
            voxel_fraction=float(counts[owner == k].sum() / nvox3),
            n_particles=int(d.size), mu_target=psd.mu, sigma_target=psd.sigma,
            d_lo_um=lo, d_hi_um=hi, cut_number_low=nl, cut_number_high=nh,
            cut_volume_low=vl, cut_volume_high=vh, d_min_drawn_um=float(d.min()),
            d_max_drawn_um=float(d.max()), mu_fit=mu_f, sigma_fit=s_f,
            mu_fit_truncated=mu_t, sigma_fit_truncated=s_t,
            ks_statistic=float(ks.statistic), ks_pvalue=float(ks.pvalue)))
    n_contact = int(np.count_nonzero(g < cgap))
    _, _, g_all = pairs_within_gap(centers, 0.5 * d_all, L, GAP_BINS_UM[-1])
    gap_counts = {f"<{b:g} um": int(np.count_nonzero(g_all < b)) for b in GAP_BINS_UM}
    report = RVEReport(
        seed=int(seed), box_um=L, voxel_um=h, shape=(nvox,) * 3, min_gap_um=gap,
        fillers=fillers, phi_total=phi_total, phi_rcp_estimate=phi_rcp,
        sigma_ln_mixture=sig_mix, n_particles=int(d_all.size), n_overlaps=n_bad,
        smallest_gap_um=float(g.min()) if g.size else math.inf, contact_gap_um=cgap,
        n_contact_pairs=n_contact, coordination_number=2.0 * n_contact / d_all.size,
        voxel_face_contacts=_face_contacts(ms.particle_ids), iterations=res.iterations,
        neighbour_builds=res.neighbour_builds, gap_counts=gap_counts, warnings=warn)
    report.seconds = {"sample": t_sample, "pack": res.seconds, "check": t_check,
                      "voxelize": t_vox, "report": time.perf_counter() - t3,
                      "total": time.perf_counter() - t_start}
    return ms, report


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
            ms = generate_rve(fillers, box_um=spec.box_um, voxel_um=spec.voxel_um, seed=seed,
                              min_gap_um=spec.min_gap_um, film_um=spec.film_um,
                              matrix=matrix, tail_quantile=spec.tail_quantile,
                              max_diameter_box_ratio=spec.max_diameter_box_ratio,
                              min_diameter_voxels=spec.min_diameter_voxels,
                              progress=progress)
        return PackedRVE(ms, seed)

    for seed in retries:
        try:
            return pack(seed)
        except RuntimeError:
            continue
    return pack(last)
