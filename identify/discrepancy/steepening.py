"""Four candidate effects that make k(phi) rise more steeply than the base model.

Each has one physical parameter, a nominal value at which it is exactly the base model (the
same RVE, the same phase values) and, where it changes the packing, builds its OWN RVE per
value by packing the formulation again with the base replica's packing seed
(:meth:`~itr_identify.discrepancy.effects.Effect.rebuild` with a :class:`Repacker`), so two
values differ by the effect and not by a new draw of particles:

- :class:`FilmThinning` (``"film"``): a silicone film between touching particles that is
  squeezed out as the filler fraction rises (the packing's ``min_gap_um``);
- :class:`Agglomeration` (``"agglomeration"``): particles crowded into agglomerates with
  resin pockets between them (a denser packing emptied back to the nominal fraction);
- :class:`SizeBasis` (``"basis"``): Table 1's lognormal read between number- and
  volume-weighted (Hatch-Choate shift of the number median);
- :class:`InterphaseShell` (``"shell"``): a shell of bound polymer around every particle of
  a conductivity other than the matrix's, homogenised into the matrix at the shell's share
  of it (overlapping shells counted once).

All four keep the sample's nominal composition (filler and void volume fraction), so the
density (Archimedes) and the filler mass fraction (TGA) do not see them; a length (film,
shell) weighs less in a coarser powder, which a second powder of another size shows.
"""

from __future__ import annotations

import math
import warnings
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from itr_fv import Materials, Microstructure
from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve import FillerSpec, generate_rve
from itr_fv.rve.spec import RVESpec

from .candidate import Effect

__all__ = ["Repacker", "FilmThinning", "Agglomeration", "SizeBasis", "InterphaseShell",
           "STEEPENING_EFFECTS", "DENSE_FRACTION", "filler_fractions", "bruggeman"]

#: The densest random packing the workflow's RVE (12 um box, 0.25 um voxels) reaches for
#: Table 1's powders with every seed tried: 19 seeds each for Al2O3 and AlN pack at 0.62,
#: at 0.63 some fail, at 0.65 half (the packer jams). A film or an agglomerate of the
#: effects below is squeezed out or capped there, so that every value of their grids
#: packs with the base replica's seed.
DENSE_FRACTION = 0.62


# --------------------------------------------------------------------------- packing
@dataclass(frozen=True)
class Repacker:
    """``pack(**changes)`` of :meth:`Effect.rebuild`: one replica of a formulation packed
    again, with the same packing seed, with ``changes``.

    ``changes`` are RVESpec fields (``min_gap_um=...``; checked there), ``fractions``
    (``{filler: volume fraction}`` in place of the formulation's) and ``median_scale``
    (a factor on every diameter of a filler's size distribution: a float for all fillers
    or ``{filler: factor}``). One packing attempt with :attr:`spec`'s seed, the one that
    packed the base replica: a packing that fails raises (RuntimeError from the packer,
    ValueError beyond the packing-limit estimate or the voxel's resolution), it is never
    redrawn with another seed (another draw of particles would differ from the base by
    more than the effect).

    Attributes
    ----------
    spec : RVESpec
        The base replica's specification with ``seed`` the seed that packed it.
    fractions : mapping of str to float
        The formulation's filler volume fractions.
    basis : {"number", "volume"}
        Weighting of Table 1's lognormal (``ForwardSettings.psd_basis``).
    system : MaterialSystem
        The matrix and the fillers' size distributions (default: the package's).
    """

    spec: RVESpec
    fractions: Mapping[str, float]
    basis: str = "number"
    system: MaterialSystem = field(default_factory=default_system)

    @property
    def matrix(self) -> str:
        """The matrix phase."""
        return self.system.matrix

    @classmethod
    def of(cls, model, replica: int = 0) -> "Repacker":
        """The repacker of replica ``replica`` of a packed
        :class:`~itr_identify.forward.model.ForwardModel` (its settings, fractions and
        the seed that packed the replica, :attr:`ForwardModel.seeds`)."""
        s = model.settings
        seed = int(model.seeds[replica]) if len(model.seeds) > replica else s.seed + replica
        return cls(s.rve.with_(seed=seed), dict(model.fractions), s.psd_basis, s.system)

    def fillers(self, fractions: Mapping[str, float] | None = None,
                median_scale: float | Mapping[str, float] | None = None) -> list[FillerSpec]:
        """The fillers of a packing: the system's size distributions at ``fractions``
        (default the formulation's), every diameter of filler ``f`` times
        ``median_scale[f]``."""
        fr = dict(self.fractions if fractions is None else fractions)
        if median_scale is None:
            scale = {}
        elif isinstance(median_scale, Mapping):
            scale = dict(median_scale)
        else:
            scale = {f: float(median_scale) for f in fr}
        unknown = sorted(set(scale) - set(fr))
        if unknown:
            raise ValueError(f"median_scale: {unknown[0]!r} is not a filler of the packing "
                             f"({sorted(fr)})")
        out = []
        for f, v in fr.items():
            spec = FillerSpec.of(f, self.system.filler(f).psd, v, number_read_as=self.basis)
            s = scale.get(f, 1.0)
            if not (isinstance(s, (int, float)) and math.isfinite(s) and s > 0):
                raise ValueError(f"median_scale[{f!r}]: expected a factor > 0, got {s!r}")
            if s != 1.0:
                # every diameter times s: ln D shifts by ln s in either weighting
                spec = replace(spec, mu=spec.mu + math.log(s))
            out.append(spec)
        return out

    def __call__(self, *, fractions: Mapping[str, float] | None = None,
                 median_scale: float | Mapping[str, float] | None = None,
                 **rve_changes) -> Microstructure:
        unknown = sorted(set(rve_changes) - set(RVESpec.field_names()))
        if unknown:
            raise ValueError(f"{unknown[0]}: not a change a repacking knows (RVESpec "
                             f"fields, fractions, median_scale)")
        # the repacking's contacts meet at its min_gap_um, not the base's film_um
        spec = self.spec.with_(**{"film_um": None, **rve_changes})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)   # the box cut: in the report
            return generate_rve(spec, self.fillers(fractions, median_scale), spec.seed,
                                matrix=self.matrix)


def filler_fractions(ms: Microstructure) -> dict[str, float]:
    """Volume fraction of every filler of a packed RVE from its spheres (the packer draws
    the diameters to the target volume exactly, so these are the formulation's)."""
    t = ms.particles
    if t is None:
        raise ValueError("ms: the effect needs the sphere geometry of the RVE (a packed "
                         "microstructure)")
    vol = 4.0 / 3.0 * math.pi * np.asarray(t.radii_m, dtype=float) ** 3
    box = float(np.prod(ms.box_m))
    mats = np.asarray(t.material)
    # rounded: the sums miss the drawn target by a few ulp
    return {str(m): round(float(vol[mats == m].sum() / box), 12)
            for m in dict.fromkeys(mats.tolist())}


def _periodic_distance(points: np.ndarray, centre: np.ndarray, box: np.ndarray) -> np.ndarray:
    d = points - centre
    d -= box * np.round(d / box)
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def bruggeman(share: float, k_inclusion: float, k_host: float) -> float:
    """Symmetric (Bruggeman) effective-medium conductivity of two phases at volume shares
    ``share`` and ``1 - share``: the phase of ``k_inclusion`` percolates at a share of 1/3."""
    b = (3.0 * share - 1.0) * k_inclusion + (2.0 - 3.0 * share) * k_host
    return 0.25 * (b + math.sqrt(b * b + 8.0 * k_inclusion * k_host))


class _Repacking:
    """What the repacking effects share: a checked value and a repacking that fails with
    the effect and the value named."""

    def _check_value(self, value: float, lo: float, hi: float, *, open_lo: bool = False
                     ) -> float:
        v = float(value)
        ok = math.isfinite(v) and (lo < v if open_lo else lo <= v) and v <= hi
        if not ok:
            bound = f"({lo:g}, {hi:g}]" if open_lo else f"[{lo:g}, {hi:g}]"
            raise ValueError(f"value: {self.parameter} = {value!r} of {self.key!r} lies "
                             f"outside {bound}")
        return v

    def _repack(self, pack: Callable[..., Microstructure], value: float,
                **changes) -> Microstructure:
        try:
            return pack(**changes)
        except (RuntimeError, ValueError) as exc:
            how = " with the base replica's seed" if isinstance(exc, RuntimeError) else ""
            raise ValueError(f"{self.key}: the RVE at {self.parameter} = {value:g} cannot "
                             f"be packed{how} ({exc})") from exc


# --------------------------------------------------------------------------- the effects
@dataclass(frozen=True)
class FilmThinning(_Repacking, Effect):
    """A silicone film of thickness ``d`` between touching particles, squeezed out as the
    filler fraction rises towards the packing limit: ``d(phi) = d55 (phi_0 - phi) / (phi_0 -
    0.55)``, linear in the fraction and zero at and above ``phi_0`` =
    :attr:`squeezed_fraction` (:data:`DENSE_FRACTION`, 0.62: the densest packing the RVE
    reaches with every seed), with ``d55``, the film at 55 vol% in nm, the parameter (0.29
    ``d55`` at 60 vol%, 0 at 62 and 65 vol%). Nominal 0: touching particles in contact
    through their two interface resistances alone (the packer's clearance is not a film:
    :mod:`itr_fv.rve.contact_film`).

    The RVE is packed again with ``min_gap_um = d(phi)`` (phi the formulation's filler
    fraction; it replaces the base specification's film, 0 by default): under the gap
    contact model every contact then conducts through ``2 R_b + d / k_m`` with ``d`` the
    true film between the spheres. Physical range: PDMS adsorbs on oxide and nitride
    surfaces in bound layers of about 1-5 nm (glassy, immobilised chains; thicker, looser
    loops reach 10 nm), and a film between two particles holds the layers of both, so
    films of a few nm up to about 10 nm at 55 vol% are plausible; 20 nm bounds the grid.
    """

    key: str = "film"
    name: str = "silicone film between particles thinning with the fraction"
    parameter: str = "film_at_55vol_nm"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 2.0, 5.0, 10.0, 20.0)
    signature: str = ("k lowered most at the lowest filler fraction, where the film is "
                      "thickest, and not at all towards the packing limit: a steeper rise "
                      "with the fraction, for both fillers")
    separate_by: str = ("a second powder of another size: a film of a fixed thickness "
                        "acts through d / (k_m a) and weighs more in the finer powder; "
                        "density (Archimedes) and filler mass fraction (TGA) stay nominal, "
                        "unlike a fraction loss or porosity")
    kind: str = "geometry"
    physical_range: tuple[float, float] | None = (0.0, 10.0)
    #: The fraction the law is stated at (the parameter is the film there).
    reference_fraction: float = 0.55
    #: The fraction at which the film is squeezed out.
    squeezed_fraction: float = DENSE_FRACTION

    def film_um(self, fraction: float | np.ndarray, value: float | np.ndarray
                ) -> np.ndarray:
        """The film, um, at filler volume fraction ``fraction`` for ``value`` nm at 55 vol%."""
        phi = np.asarray(fraction, dtype=float)
        slope = (self.squeezed_fraction - phi) / (self.squeezed_fraction
                                                  - self.reference_fraction)
        return np.maximum(np.asarray(value, dtype=float) * 1e-3 * slope, 0.0)

    def size_equivalent(self, value, scale):
        # a length: the same film in a powder `scale` times larger acts as value / scale
        return np.asarray(value, dtype=float) / scale

    def rebuild(self, pack, base, value, seed):
        v = self._check_value(value, 0.0, math.inf)
        if v == self.nominal:
            return base
        film = float(self.film_um(sum(filler_fractions(base).values()), v))
        if film <= 0.0:
            return base
        return self._repack(pack, v, min_gap_um=film)


@dataclass(frozen=True)
class Agglomeration(_Repacking, Effect):
    """Particles crowded into agglomerates with resin pockets between them: the
    formulation packed at the crowded fraction ``phi_c = min(phi / a, max(phi, phi_max))``
    (same seed), then the particles nearest two pocket centres (the body-centred sites
    ``(1/4, 1/4, 1/4) L`` and ``(3/4, 3/4, 3/4) L`` of the periodic box, a lattice of
    pockets 0.87 L apart) removed until the filler fraction is ``phi`` again (to one
    particle). The parameter ``a`` is the crowding factor (the nominal fraction over the
    agglomerates'); nominal 1, the base packing.

    The agglomerates are capped at ``phi_max`` = :attr:`crowded_max` =
    :data:`DENSE_FRACTION` (0.62), the densest random packing the 12 um RVE reaches with
    every seed: no agglomerate is denser than a random close packing, so towards the
    packing limit the crowding has no room and the effect fades (at 55 vol% the grid's
    a = 0.85 packs the agglomerates at 0.62 with 11 % of the volume in pockets; at 62 vol%
    and above the RVE is the base one). ``phi / a`` itself, the brief's construction,
    cannot be packed at 60-65 vol% for a below 0.97-1.
    """

    key: str = "agglomeration"
    name: str = "agglomerates with resin pockets"
    parameter: str = "crowding_factor"
    nominal: float = 1.0
    values: tuple[float, ...] = (0.85, 0.9, 0.95, 1.0)
    signature: str = ("k raised by a few per cent at moderate filler fractions (crowded "
                      "particles touch more), fading to nothing towards the packing limit "
                      "(no room for crowding): a flatter, not a steeper, rise; noisy in "
                      "the parameter (each value is another packing)")
    separate_by: str = ("a second powder of another size: crowding is scale-free and acts "
                        "the same in both powders, unlike a film or a shell of fixed "
                        "thickness; density (Archimedes) and filler mass fraction (TGA) "
                        "stay nominal, unlike a fraction loss or porosity")
    kind: str = "geometry"
    #: The densest agglomerate (volume fraction).
    crowded_max: float = DENSE_FRACTION

    def crowded_fraction(self, fraction: float, value: float) -> float:
        """The filler fraction of the agglomerates for a formulation at ``fraction``."""
        return min(fraction / value, max(fraction, self.crowded_max))

    @staticmethod
    def pocket_centres_m(box_m: np.ndarray) -> np.ndarray:
        """Centres of the resin pockets, m, (2, 3)."""
        box = np.asarray(box_m, dtype=float)
        return np.array([0.25, 0.75])[:, None] * box[None, :]

    def rebuild(self, pack, base, value, seed):
        a = self._check_value(value, 0.0, 1.0, open_lo=True)
        if a == self.nominal:
            return base
        fr = filler_fractions(base)
        phi = sum(fr.values())
        phi_c = self.crowded_fraction(phi, a)
        if phi_c <= phi * (1.0 + 1e-9):
            return base
        crowded = self._repack(pack, a, fractions={f: v * phi_c / phi for f, v in fr.items()})
        t = crowded.particles
        box = crowded.box_m
        dist = np.min([_periodic_distance(t.centers_m, c, box)
                       for c in self.pocket_centres_m(box)], axis=0)
        order = np.argsort(dist, kind="stable")          # nearest a pocket first
        vol = np.asarray(t.radii_m, dtype=float) ** 3
        target = (1.0 - phi / phi_c) * vol.sum()
        cum = np.concatenate([[0.0], np.cumsum(vol[order])])
        n = int(np.argmin(np.abs(cum - target)))         # the removal closest to phi
        keep = np.ones(len(vol), dtype=bool)
        keep[order[:n]] = False
        return Microstructure.from_spheres(t.centers_m[keep], t.radii_m[keep],
                                           list(np.asarray(t.material)[keep]), box,
                                           crowded.shape, matrix=base.names[0],
                                           contact=t.contact)


@dataclass(frozen=True)
class SizeBasis(_Repacking, Effect):
    """The weighting of Table 1's size distributions: the lognormal's (mu, sigma) read as
    number-weighted (the default, theta = 0) or volume-weighted (theta = 1, a laser
    diffraction analyser's default), between them the number median times
    ``exp(-3 sigma^2 theta)`` (Hatch-Choate: the volume median is the number median times
    ``exp(3 sigma^2)``; 1.44 for Al2O3, 2.84 for AlN). Every diameter of the RVE is smaller
    at theta > 0: the RVE is packed again (same seed) with the shifted distribution.

    In the continuum the shift is exactly a resistance scale: an RVE whose diameters are all
    ``s`` times the base's conducts as the base RVE with every interface resistance over
    ``s`` (``R k / a``), so for one filler the effect trades against its resistance, and
    what the repacking adds beyond ``R exp(3 sigma^2 theta)`` is the RVE's own cut of the
    distribution (the box cuts less of a finer powder) and its voxel resolution. The repack
    is the candidate the workflow's ``psd_basis = "volume"`` forward model would be.

    The grid stops at 0.9: at theta = 1 AlN's number distribution puts 6.4 % of its
    particles below two 0.25 um voxels (the packer refuses more than 5 %); at 0.9, 4.5 %.
    A finer voxel reaches theta = 1 (give ``values`` up to 1). The base must read Table 1
    as number-weighted (``ForwardSettings.psd_basis = "number"``, the default).
    """

    key: str = "basis"
    name: str = "size distribution read as volume-weighted"
    parameter: str = "volume_basis_share"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 0.3, 0.6, 0.9)
    signature: str = ("smaller particles, so more interface per volume: k lowered by about "
                      "the same factor at every fraction (0.87 at theta = 0.9 for Al2O3), "
                      "nearly a larger resistance; the rest is the RVE's different cut of "
                      "the distribution")
    separate_by: str = ("the powder's size distribution measured in both weightings "
                        "(image analysis by number, laser diffraction by volume); a second "
                        "powder does not: at every size the shift is a factor on R")
    kind: str = "geometry"
    scales_resistance: bool = True

    def median_scale(self, filler: str, value: float,
                     system: MaterialSystem | None = None) -> float:
        """Factor on the number median (on every diameter) of ``filler`` at ``value`` (its
        sigma from ``system``, default the package's)."""
        sigma = (system or default_system()).filler(filler).psd.sigma
        return math.exp(-3.0 * sigma ** 2 * float(value))

    def rebuild(self, pack, base, value, seed):
        theta = self._check_value(value, 0.0, 1.0)
        if theta == self.nominal:
            return base
        scale = {f: self.median_scale(f, theta, pack.system) for f in filler_fractions(base)}
        return self._repack(pack, theta, median_scale=scale)


#: The shell share of the matrix per (microstructure, thickness), computed once.
_SHARES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class InterphaseShell(Effect):
    """An interphase shell of thickness :attr:`thickness_um` (0.25 um) around every particle
    (bound or cross-linked silicone, the coupling agent's layer) whose conductivity is the
    parameter times the matrix's; nominal 1 (the shell is matrix).

    What it models: the shell homogenised into the matrix. The shell's share ``s`` of the
    matrix is measured on the RVE's spheres (the matrix within ``t`` of a particle surface,
    overlapping shells counted once, on a grid of at most ``t / 2``), and the matrix phase
    takes the Bruggeman conductivity of silicone and shell at that share
    (:func:`bruggeman`; the shell percolates at s = 1/3). At higher filler fraction the
    shells overlap and fill more of the (smaller) matrix: ``s`` rises from 0.49 at 55 vol% to
    0.68 at 65 vol% for Al2O3 (AlN: 0.44 at 55, 0.56 at 62 vol%) in the 12 um RVE, and a
    conductive shell raises k relatively more (factor 4, R = 2e-8 m^2 K/W, 0.5 um voxels:
    k x 1.84 at 55 vol%, x 2.01 at 60, x 2.20 at 65 vol%): a steepening. The films at the
    contacts take the same homogenised value.

    Not resolved in the voxels: the solve engine rebuilds every RVE from its sphere table
    (:class:`itr_surrogate.requests.RVEData`), and :meth:`Microstructure.from_spheres` gives
    a voxel inside two concentric spheres to the larger one, so a core-shell particle has
    no sphere form; a shell as a phase of its own labels would also turn every
    filler-shell face into a particle contact under the gap contact model. The
    homogenisation spreads the shell over the matrix evenly where it sits next to the
    particles, so it understates its weight in the gaps between near particles.
    """

    key: str = "shell"
    name: str = "interphase shell around the particles"
    parameter: str = "shell_conductivity_factor"
    nominal: float = 1.0
    values: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0)
    signature: str = ("a gain that grows with the filler fraction (the shells overlap and "
                      "fill more of the matrix), larger relatively for the finer powder")
    separate_by: str = ("a second powder of another size: a shell of fixed thickness fills "
                        "less of the matrix of a coarser powder; density (Archimedes) and "
                        "filler mass fraction (TGA) stay nominal")
    kind: str = "material"
    log_scale: bool = True
    #: Bound or oriented polymer conducts up to a few times the bulk's.
    physical_range: tuple[float, float] | None = (1.0, 4.0)
    thickness_um: float = 0.25

    def size_equivalent(self, value, scale):
        # a thin shell acts through its excess conductance per area (f - 1) k_m t against
        # k_m a: in a powder `scale` times larger, as (f - 1) / scale in the nominal one
        return 1.0 + (np.asarray(value, dtype=float) - 1.0) / scale

    def shell_share(self, ms: Microstructure) -> float:
        """The shell's share of the matrix of ``ms`` (kept per microstructure)."""
        key = self.thickness_um
        cached = _SHARES.get(ms, {})
        if key in cached:
            return cached[key]
        t = ms.particles
        if t is None:
            raise ValueError("ms: the shell needs the sphere geometry of the RVE")
        shape = np.array(ms.shape)
        h = ms.voxel_m * 1e6
        refine = max(1, math.ceil(2.0 * h / self.thickness_um - 1e-9))
        fine = tuple(int(n) for n in shape * refine)
        thick = self.thickness_um * 1e-6
        if np.any(2 * (t.radii_m + thick) >= ms.box_m.min()):
            raise ValueError(f"thickness_um: a shell of {self.thickness_um:g} um makes a "
                             "particle larger than half the box")

        def solid(extra: float) -> float:
            grown = Microstructure.from_spheres(t.centers_m, t.radii_m + extra, "shell",
                                                ms.box_m, fine, matrix=ms.names[0])
            return float(np.count_nonzero(grown.particle_ids)) / grown.particle_ids.size

        core = solid(0.0)
        share = (solid(thick) - core) / max(1.0 - core, 1e-12)
        _SHARES.setdefault(ms, {})[key] = share
        return share

    def materials_in(self, microstructure: Microstructure, base: Materials,
                     value: float) -> Materials:
        f = float(value)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"value: {self.parameter} = {value!r} of {self.key!r} must be "
                             "a factor > 0")
        if f == self.nominal:
            return base
        k_m = base.conductivity[base.matrix]
        share = self.shell_share(microstructure)
        return base.with_values(conductivity={base.matrix: bruggeman(share, f * k_m, k_m)})


#: The four, in the order the library lists them.
STEEPENING_EFFECTS = (FilmThinning, Agglomeration, SizeBasis, InterphaseShell)
