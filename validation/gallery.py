"""Standard microstructures for tests and studies: the common RVE set of the FV-vs-FFT
cross-validation and the lattice builders (defined once, used by the tests,
``validation/crossval.py`` and ``validation/bench_solvers.py``).

Every entry builds a (Microstructure, Materials) pair at a requested grid size; the
geometry (box, particles) does not depend on the grid, so ``size="ci"`` and
``size="full"`` are the same RVE at two resolutions. Interface resistances span the
paper's Table 4 range (1e-8 .. 5e-5 m^2 K/W), one case has R = inf (floating particles).

Dense packings use :func:`itr_fv.rve.generate_rve` when it is available, else the
collective-rearrangement packer :func:`itr_fv.rve.packing.pack_spheres` on lognormal radii.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from itr_fv.materials import Materials
from itr_fv.materials.paper_data import PAPER_SYSTEM
from itr_fv.rve.microstructure import Microstructure

__all__ = ["RVECase", "rve_cases", "build", "K_SILICONE", "K_AL2O3", "K_ALN", "PSD"]

#: the paper's conductivities, W/(m K) (:data:`itr_fv.materials.paper_data.PAPER_SYSTEM`)
K_SILICONE = PAPER_SYSTEM.matrix_conductivity
K_AL2O3 = PAPER_SYSTEM.filler("Al2O3").conductivity
K_ALN = PAPER_SYSTEM.filler("AlN").conductivity
#: lognormal number-weighted diameter distributions, ln(D / 1 um): (mu, sigma) of Table 1
PSD = {name: (p.mu, p.sigma) for name, p in PAPER_SYSTEM.size_distributions().items()}
UM = 1e-6


@dataclass(frozen=True)
class RVECase:
    """One RVE of the set.

    Attributes
    ----------
    name : str
        Short identifier.
    description : str
        What it is.
    ci : int
        Voxels per edge at CI size.
    full : int
        Voxels per edge at full size.
    make : callable
        ``make(n) -> (Microstructure, Materials)`` on an n^3 grid (n1 x 8 x 8 for the
        laminate).
    """

    name: str
    description: str
    ci: int
    full: int
    make: Callable[[int], tuple[Microstructure, Materials]]

    def build(self, size: str | int = "ci") -> tuple[Microstructure, Materials]:
        """(Microstructure, Materials) at ``size`` ("ci", "full" or a voxel count)."""
        n = self.ci if size == "ci" else self.full if size == "full" else int(size)
        return self.make(n)


def _mat(resistance: dict, fillers: tuple[str, ...] = ("Al2O3",)) -> Materials:
    k = PAPER_SYSTEM.conductivities(fillers)
    return Materials(k, resistance, matrix="silicone", contact="area")


# ------------------------------------------------------------------ geometries
def laminate(n: int, R: float = 1e-7, period_um: float = 4.0) -> tuple[Microstructure, Materials]:
    """Two-layer laminate along x (half Al2O3, half silicone), shape (n, 8, 8)."""
    mid = np.zeros((n, 8, 8), dtype=np.int32)
    mid[: n // 2] = 1
    ms = Microstructure.from_labels(mid, mid.copy(), voxel_m=period_um * UM / n,
                                    names=("silicone", "Al2O3"))
    return ms, _mat({("Al2O3", "silicone"): R})


_LATTICE = {"sc": np.array([[0.5, 0.5, 0.5]]),
            "bcc": np.array([[0.25, 0.25, 0.25], [0.75, 0.75, 0.75]]),
            "fcc": np.array([[0.25, 0.25, 0.25], [0.75, 0.75, 0.25], [0.75, 0.25, 0.75],
                             [0.25, 0.75, 0.75]])}


def sphere_array(kind: str, n: int, f: float, R: float, box_um: float = 4.0
                 ) -> tuple[Microstructure, Materials]:
    """SC/BCC/FCC array of Al2O3 spheres of volume fraction f in silicone (one unit cell)."""
    c = _LATTICE[kind] * box_um * UM
    a = (3.0 * f / (4.0 * math.pi * len(c))) ** (1.0 / 3.0) * box_um * UM
    ms = Microstructure.from_spheres(c, np.full(len(c), a), "Al2O3", box_m=box_um * UM,
                                     shape=n, matrix="silicone")
    return ms, _mat({("Al2O3", "silicone"): R, ("Al2O3", "Al2O3"): R})


#: Nearest-neighbour distance of each cubic lattice, in cell edges.
_NEAREST = {"sc": 1.0, "bcc": math.sqrt(3.0) / 2.0, "fcc": math.sqrt(2.0) / 2.0}


def touching_array(kind: str, radius_m: float, film_m: float, per_radius: int,
                   filler: str = "Al2O3", matrix: str = "silicone"
                   ) -> tuple[Microstructure, float]:
    """One cubic cell of a SC/BCC/FCC array of spheres whose nearest neighbours are a matrix
    film apart; returns the microstructure (about ``per_radius`` voxels per radius) and the
    volume fraction. The reference is :func:`itr_fv.analytic.sphere_array` at that fraction.
    """
    L = (2.0 * radius_m + film_m) / _NEAREST[kind]
    n = int(round(L / (radius_m / per_radius)))
    c = (_LATTICE[kind] - _LATTICE[kind][0] + 0.25) * L  # off the grid's symmetry planes
    ms = Microstructure.from_spheres(np.mod(c, L), np.full(len(c), radius_m), filler,
                                     box_m=L, shape=n, matrix=matrix)
    return ms, len(c) * 4.0 / 3.0 * math.pi * radius_m**3 / L**3


def _radii(rng: np.random.Generator, filler: str, volume_um3: float, d_max_um: float
           ) -> np.ndarray:
    """Lognormal diameters (Table 1) truncated at d_max until the volume is reached; radii um."""
    mu, sigma = PSD[filler]
    out, vol = [], 0.0
    while vol < volume_um3:
        d = math.exp(rng.normal(mu, sigma))
        if d > d_max_um or d < 0.5:
            continue
        out.append(0.5 * d)
        vol += math.pi / 6.0 * d ** 3
    return np.array(out)


def _rsa(rng: np.random.Generator, radii: np.ndarray, box: float, gap: float = 0.05
         ) -> np.ndarray:
    """Random sequential addition of non-overlapping spheres (largest first), centres um."""
    order = np.argsort(-radii)
    centres = np.empty((radii.size, 3))
    placed = 0
    for idx in order:
        for _ in range(20000):
            c = rng.uniform(0.0, box, 3)
            if placed:
                dx = centres[:placed] - c
                dx -= box * np.round(dx / box)
                if np.any(np.sqrt((dx * dx).sum(1)) < radii[order[:placed]] + radii[idx] + gap):
                    continue
            centres[placed] = c
            placed += 1
            break
        else:
            raise RuntimeError("random sequential addition failed; lower the fraction")
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)
    return centres[inv]


def random_rve(n: int, fillers: dict[str, float], box_um: float, seed: int,
               resistance: dict, dense: bool) -> tuple[Microstructure, Materials]:
    """Polydisperse random RVE: ``fillers`` maps phase -> volume fraction.

    ``dense=False``: random sequential addition. ``dense=True``: generate_rve when present
    (issue-2 generator), else :func:`itr_fv.rve.packing.pack_spheres`.
    """
    names = tuple(fillers)
    centres, r, mats = _particles(tuple(fillers.items()), box_um, seed, dense)
    ms = Microstructure.from_spheres(centres * UM, r * UM, list(mats), box_m=box_um * UM,
                                     shape=n, matrix="silicone")
    return ms, _mat(resistance, names)


@functools.lru_cache(maxsize=None)
def _particles(fillers: tuple[tuple[str, float], ...], box_um: float, seed: int, dense: bool
               ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Particle table (centres um, radii um, phase per particle), independent of the grid.

    Dense packings come from generate_rve at a fixed reference voxel of box/64 (so the
    particle set does not depend on the grid the RVE is later voxelized on).
    """
    if dense:
        try:
            from itr_fv.rve import FillerSpec, RVESpec, generate_rve
        except ImportError:
            generate_rve = None
        if generate_rve is not None:
            specs = [FillerSpec(f, mu=PSD[f][0], sigma=PSD[f][1], volume_fraction=v)
                     for f, v in fillers]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # box-size truncation notice
                ms = generate_rve(RVESpec(box_um, box_um / 64, max_diameter_box_ratio=1 / 3,
                                          max_sweeps=2_000_000), specs, seed)
            t = ms.particles
            return (t.centers_m / UM, t.radii_m / UM, tuple(str(m) for m in t.material))
    rng = np.random.default_rng(seed)
    radii, mats = [], []
    for f, v in fillers:
        r = _radii(rng, f, v * box_um ** 3, d_max_um=0.4 * box_um)
        radii.append(r)
        mats += [f] * r.size
    r = np.concatenate(radii)
    if dense:
        from itr_fv.rve.packing import pack_spheres
        centres = pack_spheres(r, box_um, rng, min_gap=0.0, inflate=1e-3,
                               max_iter=2_000_000).centers
    else:
        centres = _rsa(rng, r, box_um)
    return centres, r, tuple(mats)


# ------------------------------------------------------------------ the set
_INF = math.inf


def rve_cases() -> list[RVECase]:
    """The common RVE set (fixed seeds, so every call builds the same RVEs)."""
    Rpm_al = ("Al2O3", "silicone")
    Rff_al = ("Al2O3", "Al2O3")
    return [
        RVECase("laminate", "Al2O3/silicone laminate 50/50, R = 1e-7", 32, 128,
                lambda n: laminate(n, 1e-7)),
        RVECase("sc_R0", "SC array f = 0.30, R = 0", 24, 64,
                lambda n: sphere_array("sc", n, 0.30, 0.0)),
        RVECase("sc_R5e-5", "SC array f = 0.30, R = 5e-5", 24, 64,
                lambda n: sphere_array("sc", n, 0.30, 5e-5)),
        RVECase("bcc_R0", "BCC array f = 0.40, R = 0", 24, 64,
                lambda n: sphere_array("bcc", n, 0.40, 0.0)),
        RVECase("bcc_R1e-8", "BCC array f = 0.40, R = 1e-8", 24, 64,
                lambda n: sphere_array("bcc", n, 0.40, 1e-8)),
        RVECase("fcc_R0", "FCC array f = 0.50, R = 0", 24, 64,
                lambda n: sphere_array("fcc", n, 0.50, 0.0)),
        RVECase("fcc_R1e-6", "FCC array f = 0.50, R = 1e-6", 24, 64,
                lambda n: sphere_array("fcc", n, 0.50, 1e-6)),
        RVECase("random30", "random 30 % Al2O3 (RSA), R_fp = 1e-7", 24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.30}, 16.0, 11,
                                     {Rpm_al: 1e-7, Rff_al: 1e-7}, dense=False)),
        RVECase("random30_Rinf", "random 30 % Al2O3 (RSA), R_fp = inf (floating particles)",
                24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.30}, 16.0, 11,
                                     {Rpm_al: _INF, Rff_al: _INF}, dense=False)),
        RVECase("al2o3_55", "dense 55 % Al2O3, R_fp = 5e-8, R_ff = 5e-7", 24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.55}, 16.0, 21,
                                     {Rpm_al: 5e-8, Rff_al: 5e-7}, dense=True)),
        RVECase("al2o3_60", "dense 60 % Al2O3, R_fp = 1e-7, R_ff = 1e-7", 24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.60}, 16.0, 22,
                                     {Rpm_al: 1e-7, Rff_al: 1e-7}, dense=True)),
        RVECase("al2o3_65", "dense 65 % Al2O3, R_fp = 1e-8, R_ff = 1e-5", 24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.65}, 16.0, 23,
                                     {Rpm_al: 1e-8, Rff_al: 1e-5}, dense=True)),
        RVECase("aln_60", "dense 60 % AlN, R_fp = 5e-6, R_ff = 1e-7", 24, 64,
                lambda n: random_rve(n, {"AlN": 0.60}, 24.0, 31,
                                     {("AlN", "silicone"): 5e-6, ("AlN", "AlN"): 1e-7},
                                     dense=True)),
        RVECase("hybrid_30_30", "dense 30 % Al2O3 + 30 % AlN, all five R in 1e-8..1e-6", 24, 64,
                lambda n: random_rve(n, {"Al2O3": 0.30, "AlN": 0.30}, 24.0, 41,
                                     {Rpm_al: 1e-7, Rff_al: 5e-7, ("AlN", "silicone"): 5e-8,
                                      ("AlN", "AlN"): 1e-6, ("Al2O3", "AlN"): 1e-8},
                                     dense=True)),
    ]


def with_contact(mat: Materials, contact: str,
                 contact_conductance: dict | None = None) -> Materials:
    """The same materials under another contact model (``"area"`` or ``"gap"``).

    For ``"gap"`` the same-phase and filler-filler pairs are dropped (the gap model takes
    the particle-matrix resistances and the film instead).
    """
    if contact == mat.contact and not contact_conductance:
        return mat
    resistance = mat.resistance
    if contact == "gap":
        resistance = {p: v for p, v in resistance.items() if mat.matrix in p}
    return Materials(mat.conductivity, resistance, mat.matrix, contact=contact,
                     contact_conductance=contact_conductance)


def build(name: str, size: str | int = "ci", contact: str | None = None,
          contact_conductance: dict | None = None) -> tuple[Microstructure, Materials]:
    """(Microstructure, Materials) of the case called ``name``.

    Parameters
    ----------
    name : str
        A case of :func:`rve_cases`.
    size : "ci", "full" or int
        Grid: the case's CI or full size, or voxels per edge.
    contact : {"area", "gap"}, optional
        Contact model (default: the case's own, ``"area"``); see :func:`with_contact`.
    contact_conductance : dict, optional
        Contact spots (W/K per filler pair) with ``contact="gap"``.
    """
    for case in rve_cases():
        if case.name == name:
            ms, mat = case.build(size)
            if contact is not None:
                mat = with_contact(mat, contact, contact_conductance)
            return ms, mat
    raise ValueError(f"name: unknown RVE {name!r}")
