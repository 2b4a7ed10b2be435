"""Formulation names (a name the material system gives, ``<filler>-<vol%>`` or
``<filler>-<wt%>wt`` parts) and the one matcher of the names users write:
:mod:`itr_fv.materials.formulation_names`, re-exported here where the inference modules and
the measurement readers have always found them."""

from itr_fv.materials.formulation_names import (
    MIN_PERCENT,
    UnknownFormulationError,
    formulation_name,
    fractions_of,
    reader_for,
)

__all__ = ["fractions_of", "formulation_name", "reader_for", "UnknownFormulationError",
           "MIN_PERCENT"]
