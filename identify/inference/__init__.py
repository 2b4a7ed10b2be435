"""From measurements to interface resistances: measurement tables
(:mod:`~itr_identify.inference.measurements`), formulation names
(:mod:`~itr_identify.inference.formulations`), the posterior
(:mod:`~itr_identify.inference.calibrate`), the paper's screening
(:mod:`~itr_identify.inference.screen`), full-solver validation
(:mod:`~itr_identify.inference.validate`) and the staged pipeline
(:mod:`~itr_identify.inference.pipeline`)."""
