"""The one RVE specification: box, voxel, size cuts, matrix film and packing seeds.

Every RVE the package packs is described by an :class:`RVESpec` and built by
:func:`itr_fv.rve.build_rve` (``build_rve(spec, fillers, replica)``). Campaign files, the
identification, the discrepancy workflow and the demo compose it (their own settings stay
theirs), so a box and voxel are checked by one rule with one message
(:func:`voxels_per_edge`), here and nowhere else.

The rule: both lengths are micrometres at the scale of a particle composite (at least
:data:`MIN_LENGTH_UM`, at most :data:`MAX_LENGTH_UM`; a length in metres, such as
``box_um = 6e-6``, is refused before anything is packed or solved); the box edge holds a
whole number of voxel edges, to 1e-6 relative, and at least :data:`MIN_VOXELS_PER_EDGE` of
them (fewer cannot resolve a sphere, and the FFT and AMG solvers' grids assume it).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from ..checks import unknown_key

__all__ = [
    "MAX_DIAMETER_BOX_RATIO",
    "MAX_LENGTH_UM",
    "MAX_SWEEPS",
    "MIN_DIAMETER_VOXELS",
    "MIN_LENGTH_UM",
    "MIN_VOXELS_PER_EDGE",
    "PACKING_ATTEMPTS",
    "SAMPLINGS",
    "SEED_STRIDE",
    "TAIL_QUANTILE",
    "RVESpec",
    "check_seed",
    "voxels_per_edge",
]

#: Fewest voxels along the box edge.
MIN_VOXELS_PER_EDGE = 8
#: Shortest box or voxel edge, um: one nanometre, below which heat conduction in the
#: matrix is no longer a continuum property.
MIN_LENGTH_UM = 1e-3
#: Longest box or voxel edge, um: one centimetre, beyond any sample of these composites.
MAX_LENGTH_UM = 1e4
#: Largest particle diameter / box edge unless a caller says otherwise: 0.45 keeps a sphere
#: clear of its own periodic image and cuts less of the coarse tail than 1/3 (the box-size
#: study, ``validation/results/box_size.md``).
MAX_DIAMETER_BOX_RATIO = 0.45
#: Number-probability cut of each far tail of a filler's size distribution.
TAIL_QUANTILE = 1e-4
#: Smallest particle diameter, in voxels of ``cut_voxel_um``: a particle must span about two
#: voxels to be resolved.
MIN_DIAMETER_VOXELS = 2.0
#: Jacobi sweeps the packer may take before it gives up (``RuntimeError``).
MAX_SWEEPS = 400_000
#: How the diameters are drawn: ``"stratified"`` (one-dimensional Latin hypercube sampling of
#: the truncated number distribution, the default) or ``"iid"`` (independent draws).
SAMPLINGS = ("stratified", "iid")
#: Packings tried per replica before :func:`itr_fv.rve.build_rve` gives up.
PACKING_ATTEMPTS = 12
#: Seed step between the attempts of one replica (replica ``r``, attempt ``a``: seed
#: ``spec.seed + r + SEED_STRIDE * a``), larger than any replica count in use so that the
#: attempts of one replica never take another replica's seed.
SEED_STRIDE = 100


def _is_number(value: Any) -> bool:
    return (not isinstance(value, bool) and isinstance(value, (int, float))
            and math.isfinite(value))


def check_seed(value: Any, name: str = "seed") -> int:
    """A packing seed: a whole number >= 0 (a NumPy integer is taken as its int).

    Raises
    ------
    ValueError
        Anything else (a bool, a float, a negative number), with ``name`` in the message.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise ValueError(f"{name}: expected a whole number >= 0, got {value!r}")
    return int(value)


def voxels_per_edge(box_um: Any, voxel_um: Any) -> int:
    """Voxels along the box edge, by the package's one rule.

    Parameters
    ----------
    box_um, voxel_um : float
        Box edge and voxel edge, um.

    Returns
    -------
    int
        ``box_um / voxel_um``, a whole number >= :data:`MIN_VOXELS_PER_EDGE`.

    Raises
    ------
    ValueError
        A length that is not a finite number > 0 or lies outside [:data:`MIN_LENGTH_UM`,
        :data:`MAX_LENGTH_UM`] (named), or a box that does not hold a
        whole number >= 8 of voxels (``box_um/voxel_um: ...``; the same message wherever an
        RVE is specified).
    """
    for name, value in (("box_um", box_um), ("voxel_um", voxel_um)):
        if not _is_number(value) or value <= 0:
            raise ValueError(f"{name}: expected a length > 0 in um, got {value!r}")
        if value < MIN_LENGTH_UM:
            raise ValueError(f"{name}: {value:g} um is below a nanometre, where conduction is "
                             f"no continuum; lengths are in micrometres (if {value:g} is in "
                             f"metres, it is {value * 1e6:g} um)")
        if value > MAX_LENGTH_UM:
            raise ValueError(f"{name}: {value:g} um is above a centimetre; lengths are in "
                             f"micrometres (if {value:g} is in nm, it is {value / 1e3:g} um)")
    n = box_um / voxel_um
    if abs(n - round(n)) > 1e-6 * n or round(n) < MIN_VOXELS_PER_EDGE:
        raise ValueError(f"box_um/voxel_um: a {box_um:g} um box holds {n:.6g} voxels of "
                         f"{voxel_um:g} um; it must hold a whole number >= "
                         f"{MIN_VOXELS_PER_EDGE} of them")
    return int(round(n))


@dataclass(frozen=True)
class RVESpec:
    """What an RVE is, apart from its fillers: checked on construction.

    Attributes
    ----------
    box_um : float
        Edge of the periodic cube, um (the paper: 40).
    voxel_um : float
        Voxel edge, um (the paper: 0.1); ``box_um / voxel_um`` a whole number >= 8.
    max_diameter_box_ratio : float
        Largest particle diameter / box edge, in (0, 0.5) (default
        :data:`MAX_DIAMETER_BOX_RATIO`, 0.45).
    min_gap_um : float
        Thinnest matrix film the packer keeps between two particles, um (>= 0). Under the
        gap contact model it is the film of every contact unless ``film_um`` states another.
    film_um : float, optional
        The film touching particles meet at, um (>= 0; None: ``min_gap_um``). The packing
        does not depend on it: specifications that differ only here hold the same particles
        and voxels, with other contact films.
    tail_quantile : float
        Number-probability cut of each far tail of the size distribution, in (0, 0.05)
        (default :data:`TAIL_QUANTILE`, 1e-4).
    seed : int
        Packing seed of replica 0; replica ``r`` packs with ``seed + r`` (and, if that
        packing fails, ``seed + r + 100``, ``+ 200``, ...).
    cut_voxel_um : float, optional
        The voxel edge whose two-voxel minimum diameter cuts the size distribution's fine
        tail (None: ``voxel_um``). The cut is the only thing the voxel changes in a
        packing, so two specifications that differ only in ``voxel_um`` and share
        ``cut_voxel_um`` hold the same particles, voxelized twice (the pair a voxel-bias
        extrapolation needs).
    sampling : {"stratified", "iid"}
        How the diameters are drawn (:data:`SAMPLINGS`): ``"stratified"`` (default) draws
        the expected number of diameters by one-dimensional Latin hypercube sampling of the
        truncated number distribution, so a few hundred particles already reproduce mu and
        sigma closely (KS p-values near 1, as expected of a sample more even than an
        independent one); ``"iid"``: independent draws.
    max_sweeps : int
        Jacobi sweeps the packer may take (>= 1, default :data:`MAX_SWEEPS`); a packing
        that has not converged by then raises ``RuntimeError`` (:func:`itr_fv.rve.build_rve`
        then redraws with the next seed). A converged packing does not depend on it.
    """

    box_um: float
    voxel_um: float
    max_diameter_box_ratio: float = MAX_DIAMETER_BOX_RATIO
    min_gap_um: float = 0.0
    tail_quantile: float = TAIL_QUANTILE
    seed: int = 1
    cut_voxel_um: float | None = None
    film_um: float | None = None
    sampling: str = SAMPLINGS[0]
    max_sweeps: int = MAX_SWEEPS

    def __post_init__(self) -> None:
        voxels_per_edge(self.box_um, self.voxel_um)
        r = self.max_diameter_box_ratio
        if not _is_number(r) or not 0 < r < 0.5:
            raise ValueError(f"max_diameter_box_ratio: expected a value in (0, 0.5), got {r!r}")
        if not _is_number(self.min_gap_um) or self.min_gap_um < 0:
            raise ValueError(f"min_gap_um: expected a film >= 0 um, got {self.min_gap_um!r}")
        q = self.tail_quantile
        if not _is_number(q) or not 0 < q < 0.05:
            raise ValueError(f"tail_quantile: expected a value in (0, 0.05), got {q!r}")
        object.__setattr__(self, "seed", check_seed(self.seed))  # a NumPy integer: its int
        f = self.film_um
        if f is not None and (not _is_number(f) or f < 0 or f > 1.0):
            raise ValueError(f"film_um: expected a film in [0, 1] um or None, got {f!r}")
        c = self.cut_voxel_um
        if c is not None and (not _is_number(c) or not c > 0):
            raise ValueError(f"cut_voxel_um: expected a voxel edge > 0 um or None, got {c!r}")
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"sampling: expected one of {SAMPLINGS}, got {self.sampling!r}")
        m = self.max_sweeps
        if isinstance(m, bool) or not isinstance(m, int) or m < 1:
            raise ValueError(f"max_sweeps: expected a whole number >= 1, got {m!r}")

    @property
    def min_diameter_voxels(self) -> float:
        """The fine-tail cut in voxels of :attr:`voxel_um`: two voxels of
        :attr:`cut_voxel_um` (default: of this voxel)."""
        cut = self.voxel_um if self.cut_voxel_um is None else self.cut_voxel_um
        return MIN_DIAMETER_VOXELS * cut / self.voxel_um

    @property
    def contact_film_um(self) -> float:
        """The film touching particles meet at, um (``film_um``, else ``min_gap_um``)."""
        return self.min_gap_um if self.film_um is None else self.film_um

    @property
    def n(self) -> int:
        """Voxels per box edge."""
        return voxels_per_edge(self.box_um, self.voxel_um)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(n, n, n)``."""
        return (self.n,) * 3

    def seeds(self, replica: int) -> list[int]:
        """Packing seeds tried for ``replica``, in order (:data:`PACKING_ATTEMPTS`)."""
        if isinstance(replica, bool) or not isinstance(replica, int) or replica < 0:
            raise ValueError(f"replica: expected a whole number >= 0, got {replica!r}")
        return [self.seed + replica + SEED_STRIDE * a for a in range(PACKING_ATTEMPTS)]

    def with_(self, **changes: Any) -> RVESpec:
        """A copy with ``changes`` (checked again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form; ``RVESpec.from_dict(spec.to_dict()) == spec``
        (``cut_voxel_um``, ``film_um``, ``sampling`` and ``max_sweeps`` only where they
        differ from their defaults: the forms of earlier specifications stay)."""
        d = asdict(self)
        for optional in _OPTIONAL_FIELDS:
            if d[optional] == _DEFAULTS[optional]:
                del d[optional]
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RVESpec:
        """The spec of :meth:`to_dict`'s form (unknown keys: ValueError naming the key)."""
        unknown = unknown_key(data, cls.field_names(), detail=" of an RVE specification")
        if unknown:
            raise ValueError(unknown)
        return cls(**data)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """The names of the specification's fields."""
        return tuple(f.name for f in fields(cls))


#: Fields :meth:`RVESpec.to_dict` leaves out at their defaults (added after the first
#: specifications were written).
_OPTIONAL_FIELDS = ("cut_voxel_um", "film_um", "sampling", "max_sweeps")
_DEFAULTS = {f.name: f.default for f in fields(RVESpec)}
