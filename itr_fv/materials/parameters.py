"""The package's one flat parameter naming (campaign files, Parquet columns, surrogates,
identification).

=====================  ==================================================================
name                   meaning
=====================  ==================================================================
``k_<phase>``          thermal conductivity of a phase, W/(m K)
``R_<A>_<B>``          interface resistance between a filler and the matrix, m^2 K/W
                       (the two phase names sorted, e.g. ``R_Al2O3_silicone``)
``Gc_<A>_<B>``         contact-spot conductance per touching pair of particles of fillers
                       A and B, W/K (``contact="gap"`` only)
``Rff_<A>_<B>``        the paper's per-area contact resistance between particles of fillers
                       A and B, m^2 K/W (``contact="area"`` only)
=====================  ==================================================================

Phase names never hold ``_`` (see :func:`itr_fv.checks.phase_name`), so a name splits
unambiguously. :meth:`itr_fv.Materials.to_parameters` and
:meth:`itr_fv.Materials.from_parameters` convert between a :class:`~itr_fv.Materials` and
such a mapping.
"""

from __future__ import annotations

__all__ = ["KINDS", "UNITS", "parameter_name", "parse_parameter", "is_log_scaled"]

#: Parameter kinds and the number of phase names each takes (a conductivity names one phase,
#: the rest two). Every interface law reads kinds of this table only, and together they read
#: all of it (:data:`itr_fv.discrete.interface_law.PARAMETER_KINDS` checks both on import).
KINDS = {"k": 1, "R": 2, "Gc": 2, "Rff": 2}
#: Unit of each kind.
UNITS = {"k": "W/(m K)", "R": "m^2 K/W", "Gc": "W/K", "Rff": "m^2 K/W"}


def parameter_name(kind: str, *phases: str) -> str:
    """The flat name of a parameter, e.g. ``parameter_name("R", "silicone", "Al2O3")`` ->
    ``"R_Al2O3_silicone"`` (pair names sorted)."""
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {sorted(KINDS)}, got {kind!r}")
    if len(phases) != KINDS[kind]:
        raise ValueError(f"phases: {kind} takes {KINDS[kind]} phase name(s), got {phases!r}")
    names = sorted(phases) if len(phases) == 2 else list(phases)
    return "_".join([kind, *names])


def parse_parameter(name: str) -> tuple[str, tuple[str, ...]]:
    """``(kind, phases)`` of a flat parameter name; ValueError naming it if malformed."""
    if not isinstance(name, str):
        raise ValueError(f"parameter name: expected a string, got {name!r}")
    kind, _, rest = name.partition("_")
    parts = tuple(rest.split("_")) if rest else ()
    if kind not in KINDS or len(parts) != KINDS[kind] or not all(parts):
        raise ValueError(f"parameter {name!r}: expected k_<phase>, R_<A>_<B>, Gc_<A>_<B> or "
                         "Rff_<A>_<B>")
    if len(parts) == 2 and list(parts) != sorted(parts):
        raise ValueError(f"parameter {name!r}: the two phase names go in sorted order "
                         f"({parameter_name(kind, *parts)!r})")
    return kind, parts


def is_log_scaled(name: str) -> bool:
    """Whether a parameter is natural on a log scale (resistances and conductances of
    interfaces and contacts: they span decades), not a bulk conductivity."""
    return parse_parameter(name)[0] != "k"
