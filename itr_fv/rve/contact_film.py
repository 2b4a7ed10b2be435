"""The stated matrix film of touching particles: the same for every particle size and box.

The packer (:func:`itr_fv.rve.packing.pack_spheres`) leaves touching spheres a clearance of
``inflate/2 .. inflate`` times ``(R_i + R_j)`` beyond its ``min_gap`` (R = r + min_gap/2):
3-9 nm for 3-9 um particles, so a contact law that read the clearance as a film would put a
size-dependent numerical film into every contact. A :class:`ContactFilm` says which pairs the
packer left touching and the film they meet at; the contact geometry
(:mod:`itr_fv.discrete.contact_zones`, :func:`itr_fv.discrete.face_geometry.face_geometry`)
moves the image of the second sphere of such a pair along the line of centres by
:func:`clearance` for that contact only, so the film at the pair's closest point is exactly
``film_m``. Pairs further apart keep their geometric films. The voxels are not changed: the
move is a few nm against voxels of 100-250 nm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ContactFilm", "clearance", "CONTACT_GEOMETRY"]

#: The contact geometry of this module, as results made with it record it (the shipped
#: corrections' provenance): touching pairs at the stated film.
CONTACT_GEOMETRY = "stated film"


def clearance(gap0, r_a, r_b, packing_gap, tolerance, film):
    """The length to take off the distance of two spheres so that a touching pair meets at
    the stated film (m); 0 for a pair that does not touch.

    A pair touches when its closest gap ``gap0`` exceeds the packer's ``packing_gap`` by at
    most ``tolerance * (r_a + r_b + packing_gap)`` (the packer's contact distance). Written
    with arithmetic only, so the same function serves NumPy arrays and, compiled, the numba
    geometry kernels (:mod:`itr_fv.discrete._geometry_kernels`).

    Parameters
    ----------
    gap0 : float or ndarray
        Closest surface gap of the pair, m.
    r_a, r_b : float or ndarray
        Radii, m.
    packing_gap, tolerance, film : float
        The :class:`ContactFilm` fields (m, relative, m).

    Returns
    -------
    float or ndarray
        ``gap0 - film`` for touching pairs, else 0 (m).
    """
    excess = gap0 - packing_gap
    touching = (excess >= 0.0) * (excess <= tolerance * (r_a + r_b + packing_gap))
    return touching * (gap0 - film)


@dataclass(frozen=True)
class ContactFilm:
    """Which pairs touch, and the matrix film they meet at.

    Attributes
    ----------
    film_m : float
        The stated film of every touching pair, m (>= 0; 0: the particles meet through their
        two interface resistances alone).
    packing_gap_m : float
        The film the packer kept between particles (its ``min_gap``), m (>= 0).
    tolerance : float
        The packer's relative contact distance (its ``inflate``): a pair whose gap exceeds
        ``packing_gap_m`` by at most ``tolerance * (r_a + r_b + packing_gap_m)`` touches.
        0 (a table not from the packer): only pairs exactly at ``packing_gap_m`` touch.
    """

    film_m: float = 0.0
    packing_gap_m: float = 0.0
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        for name in ("film_m", "packing_gap_m", "tolerance"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.tolerance >= 0.1:
            raise ValueError(f"tolerance: expected the packer's small relative contact "
                             f"distance (< 0.1), got {self.tolerance!r}")

    @property
    def args(self) -> tuple[float, float, float]:
        """``(packing_gap, tolerance, film)``, the last three arguments of :func:`clearance`."""
        return self.packing_gap_m, self.tolerance, self.film_m

    def reach_m(self, r_max: float) -> float:
        """The largest gap (m) of a touching pair whose radii are at most ``r_max`` (m)."""
        return self.packing_gap_m + self.tolerance * (2.0 * r_max + self.packing_gap_m)

    def clearance(self, gap0, r_a, r_b):
        """:func:`clearance` of pairs with closest gap ``gap0`` and radii ``r_a``, ``r_b`` (m)."""
        return clearance(gap0, r_a, r_b, *self.args)

    def to_dict(self) -> dict[str, float]:
        return {"film_m": self.film_m, "packing_gap_m": self.packing_gap_m,
                "tolerance": self.tolerance}

    @classmethod
    def from_dict(cls, d: dict | None) -> "ContactFilm":
        """From :meth:`to_dict` (None or {}: the default, no stated film)."""
        return cls(**(d or {}))
