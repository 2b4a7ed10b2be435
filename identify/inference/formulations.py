"""Formulation names (a Table 2 name, or ``<filler>-<vol%>`` pairs) and the one matcher of the
names users write: :mod:`itr_fv.materials.formulation_names`, re-exported here where the inference
modules and the measurement readers have always found them."""

from itr_fv.materials.formulation_names import (
    MIN_PERCENT,
    UnknownFormulationError,
    formulation_name,
    fractions_of,
)

__all__ = ["fractions_of", "formulation_name", "UnknownFormulationError", "MIN_PERCENT"]
