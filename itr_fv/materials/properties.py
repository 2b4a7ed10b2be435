"""Phase conductivities and interface resistances (the material side of the discrete model)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..checks import phase_name as _check_name
from ..checks import real_number
from .parameters import UNITS, parameter_name, parse_parameter

__all__ = ["Materials", "CONTACT_MODELS"]

#: Models of the faces between two different particles (see :mod:`itr_fv.discrete.model`).
CONTACT_MODELS = ("gap", "area")


def _sorted_pairs(table: dict[frozenset, float]) -> dict[tuple[str, str], float]:
    """{frozenset pair: value} as {(first, second) in sorted order: value}."""
    out = {}
    for key, v in table.items():
        names = sorted(key)
        out[(names[0], names[-1])] = v
    return out


class Materials:
    """Conductivity of every phase and resistance of every interface type.

    Parameters
    ----------
    conductivity : mapping of str to float
        Thermal conductivity of each phase, W/(m K); finite and > 0.
    resistance : mapping of (str, str) to float
        Interfacial thermal resistance (Kapitza resistance) per unordered pair of phase
        names, m^2 K/W; >= 0, ``math.inf`` for an insulating interface. A pair of two
        different phases is the particle-matrix (or particle-particle of two fillers)
        interface; a same-name pair ``(A, A)`` is the contact resistance between two
        *different* particles of phase A. Faces inside one particle or inside the matrix
        carry no resistance.
    matrix : str
        Name of the matrix (continuous) phase; must be a key of ``conductivity``.
    contact : {"gap", "area"}
        Model of the faces between two *different* particles (see :mod:`itr_fv.discrete.model`).
        ``"gap"`` (default): the paper's Eq. 6 applied locally, the two particle-matrix
        resistances and the true matrix film between the analytic spheres,
        ``s (R_b,p + R_b,q + d(x_f) / k_m)``; no same-pair entry is needed and k_eff
        converges under voxel refinement (``validation/results/resolution.md``). Needs the
        particle geometry (``Microstructure.from_spheres`` or ``generate_rve``) when particles
        share voxel faces. Against the multipole reference on nearly touching SC/BCC/FCC
        arrays: within 1.7 % at h = a/16, within 3.0 % at h = a/12
        (``validation/results/gap_model.md``).
        ``"area"``: the paper's per-area contact resistance ``R(A, B)`` of the table, whose
        value belongs to the voxel size it was identified at (a
        :class:`~itr_fv.checks.VoxelContactWarning` says so when contact faces exist); also
        the model for plain label images with touching particles.
    contact_conductance : mapping of (str, str) to float, optional
        Solid contact spot per touching particle pair, W/K, by unordered pair of filler
        phases (e.g. ``{("Al2O3", "Al2O3"): 2e-6}``): spread over that contact's faces in
        parallel with the film, so that the total per contact does not depend on the voxel.
        ``contact="gap"`` only.

    Examples
    --------
    >>> mat = Materials(conductivity={"silicone": 0.18, "Al2O3": 30.0},
    ...                 resistance={("Al2O3", "silicone"): 2.2e-8, ("Al2O3", "Al2O3"): 2e-7},
    ...                 matrix="silicone")
    >>> mat.resistance_between("silicone", "Al2O3")
    2.2e-08
    """

    def __init__(
        self,
        conductivity: Mapping[str, float],
        resistance: Mapping[tuple[str, str], float] | None = None,
        matrix: str = "matrix",
        contact: str = "gap",
        contact_conductance: Mapping[tuple[str, str], float] | None = None,
    ) -> None:
        if not isinstance(conductivity, Mapping) or len(conductivity) == 0:
            raise ValueError("conductivity: expected a non-empty mapping {phase name: W/(m K)}")
        k: dict[str, float] = {}
        for name, value in conductivity.items():
            _check_name(name, "conductivity")
            v = real_number(value, f"conductivity[{name!r}]")
            if not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"conductivity[{name!r}] must be finite and > 0 W/(m K), "
                                 f"got {v!r}")
            k[name] = v
        r: dict[frozenset, float] = {}
        for pair, value in (resistance or {}).items():
            if not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2:
                raise ValueError(f"resistance: keys must be pairs of phase names, got {pair!r}")
            a, b = (_check_name(p, "resistance") for p in pair)
            for p in (a, b):
                if p not in k:
                    raise ValueError(f"resistance[{pair!r}]: unknown phase {p!r} "
                                     f"(known: {sorted(k)})")
            v = real_number(value, f"resistance[{pair!r}]")
            if math.isnan(v) or v < 0.0:
                raise ValueError(f"resistance[{pair!r}] must be >= 0 m^2 K/W or inf, got {v!r}")
            key = frozenset((a, b))
            if key in r and r[key] != v:
                raise ValueError(f"resistance: pair {pair!r} given twice with different values")
            r[key] = v
        if not isinstance(matrix, str) or matrix not in k:
            raise ValueError(f"matrix: {matrix!r} is not a phase of conductivity "
                             f"(known: {sorted(k)})")
        if contact not in CONTACT_MODELS:
            raise ValueError(f"contact: expected one of {CONTACT_MODELS}, got {contact!r}")
        spots: dict[frozenset, float] = {}
        for pair, value in (contact_conductance or {}).items():
            if not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2:
                raise ValueError(f"contact_conductance: keys must be pairs of phase names, "
                                 f"got {pair!r}")
            for p in pair:
                if _check_name(p, "contact_conductance") not in k or p == matrix:
                    raise ValueError(f"contact_conductance[{pair!r}]: {p!r} is not a filler "
                                     f"phase (fillers: {sorted(set(k) - {matrix})})")
            v = real_number(value, f"contact_conductance[{pair!r}]")
            if not math.isfinite(v) or v < 0.0:
                raise ValueError(f"contact_conductance[{pair!r}] must be finite and >= 0 W/K, "
                                 f"got {v!r}")
            spots[frozenset(pair)] = v
        if spots and contact != "gap":
            raise ValueError("contact_conductance: contact spots belong to contact='gap'; "
                             f"got contact={contact!r}")
        self._k = k
        self._r = r
        self.matrix = matrix
        self.contact = contact
        self._spots = spots

    # ------------------------------------------------------------------ access
    @property
    def conductivity(self) -> dict[str, float]:
        """Copy of the conductivity table, W/(m K)."""
        return dict(self._k)

    @property
    def resistance(self) -> dict[tuple[str, str], float]:
        """Copy of the resistance table with sorted pair keys, m^2 K/W."""
        return _sorted_pairs(self._r)

    @property
    def phases(self) -> tuple[str, ...]:
        return tuple(self._k)

    @property
    def contact_conductance(self) -> dict[tuple[str, str], float]:
        """Copy of the contact-spot table with sorted pair keys, W/K."""
        return _sorted_pairs(self._spots)

    def spot_conductance(self, a: str, b: str) -> float:
        """Contact-spot conductance of a touching pair of phases ``a``, ``b`` (W/K; 0 if none)."""
        return self._spots.get(frozenset((a, b)), 0.0)

    def resistance_between(self, a: str, b: str) -> float:
        """Resistance of the interface between phases ``a`` and ``b`` (m^2 K/W).

        Raises
        ------
        ValueError
            If the pair is not in the table (the message names the pair).
        """
        key = frozenset((a, b))
        if key not in self._r:
            first, second = sorted((a, b))
            raise ValueError(f"resistance: the microstructure needs the pair ({first!r}, "
                             f"{second!r}) but the resistance table has no entry for it")
        return self._r[key]

    def with_values(self, conductivity: Mapping[str, float] | None = None,
                    resistance: Mapping[tuple[str, str], float] | None = None,
                    contact_conductance: Mapping[tuple[str, str], float] | None = None
                    ) -> "Materials":
        """New ``Materials`` with some values replaced (the geometry-free parameter update)."""
        spots = self.contact_conductance
        for pair, v in (contact_conductance or {}).items():
            spots = {p: val for p, val in spots.items() if frozenset(p) != frozenset(pair)}
            spots[tuple(pair)] = v
        k = dict(self._k)
        k.update(conductivity or {})
        r = self.resistance
        for pair, v in (resistance or {}).items():
            r = {p: val for p, val in r.items() if frozenset(p) != frozenset(pair)}
            r[tuple(pair)] = v
        return Materials(k, r, self.matrix, contact=self.contact, contact_conductance=spots)

    # ------------------------------------------------------- flat parameters
    def to_parameters(self) -> dict[str, float]:
        """The values under the package's flat names (:mod:`itr_fv.materials.parameters`).

        ``k_<phase>`` for every phase, ``R_<A>_<B>`` for every pair with the matrix, and for
        pairs of fillers ``Rff_<A>_<B>`` (``contact="area"``; the gap model does not use
        them) and ``Gc_<A>_<B>`` (contact spots, ``contact="gap"``).
        """
        out = {parameter_name("k", name): v for name, v in self._k.items()}
        for (a, b), v in self.resistance.items():
            if self.matrix in (a, b):
                out[parameter_name("R", a, b)] = v
            elif self.contact == "area":
                out[parameter_name("Rff", a, b)] = v
        for (a, b), v in self.contact_conductance.items():
            out[parameter_name("Gc", a, b)] = v
        return out

    @classmethod
    def from_parameters(cls, parameters: Mapping[str, float], matrix: str, *,
                        contact: str = "gap") -> "Materials":
        """A ``Materials`` from flat parameter names (see :meth:`to_parameters`).

        Raises
        ------
        ValueError
            Naming the parameter: a malformed name, ``R_`` without the matrix, ``Rff_``
            under the gap model, ``Gc_`` under the per-area model, a phase without ``k_``.
        """
        if not isinstance(parameters, Mapping):
            raise ValueError("parameters: expected a mapping {name: value}")
        k, r, spots = {}, {}, {}
        for name, value in parameters.items():
            kind, phases = parse_parameter(name)
            v = real_number(value, f"parameter {name!r}")
            bad = (not math.isfinite(v) or v <= 0) if kind == "k" else \
                (math.isnan(v) or v < 0 or (kind == "Gc" and math.isinf(v)))
            if bad:
                rule = {"k": "finite and > 0", "Gc": "finite and >= 0"}.get(kind, ">= 0 or inf")
                raise ValueError(f"parameter {name!r} must be {rule} {UNITS[kind]}, got {v!r}")
            if kind == "k":
                k[phases[0]] = value
            elif kind == "R":
                if matrix not in phases:
                    raise ValueError(f"parameter {name!r}: R_ is a filler-matrix resistance and "
                                     f"names the matrix {matrix!r}; contacts between particles "
                                     "are Rff_ (contact='area') or Gc_ (contact='gap')")
                r[phases] = value
            elif kind == "Rff":
                if contact != "area":
                    raise ValueError(f"parameter {name!r}: a per-area contact resistance belongs "
                                     f"to contact='area', not {contact!r}")
                r[phases] = value
            else:
                spots[phases] = value
        missing = {p for pair in (*r, *spots) for p in pair} - set(k)
        if missing:
            raise ValueError(f"parameters: no conductivity for phase(s) {sorted(missing)} "
                             f"(add k_{sorted(missing)[0]})")
        return cls(k, r, matrix, contact=contact, contact_conductance=spots or None)

    def with_parameters(self, parameters: Mapping[str, float]) -> "Materials":
        """New ``Materials`` with the named flat parameters replaced."""
        merged = {**self.to_parameters(), **dict(parameters)}
        return Materials.from_parameters(merged, self.matrix, contact=self.contact)

    # ----------------------------------------------------- tables for the solver
    def tables(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """Conductivity vector and resistance matrix indexed by material id.

        Parameters
        ----------
        names : sequence of str
            ``names[i]`` is the phase of material id ``i`` of a microstructure.

        Returns
        -------
        k : ndarray, shape (m,)
            W/(m K).
        R : ndarray, shape (m, m)
            m^2 K/W; ``nan`` where the table has no entry (only an error if a face needs it).
        """
        for n in names:
            if n not in self._k:
                raise ValueError(f"materials: the microstructure's phase {n!r} has no conductivity "
                                 f"(known: {sorted(self._k)})")
        m = len(names)
        k = np.array([self._k[n] for n in names], dtype=np.float64)
        R = np.full((m, m), np.nan)
        for i in range(m):
            for j in range(m):
                key = frozenset((names[i], names[j]))
                if key in self._r:
                    R[i, j] = self._r[key]
        return k, R

    def __repr__(self) -> str:
        spots = f", contact_conductance={self.contact_conductance!r}" if self._spots else ""
        return (f"Materials(conductivity={self._k!r}, resistance={self.resistance!r}, "
                f"matrix={self.matrix!r}, contact={self.contact!r}{spots})")
