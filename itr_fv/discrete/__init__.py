"""The discrete model both solvers solve (stated in :mod:`itr_fv.discrete.model`): face
geometry, contact zones, cut cells, the interface laws, the 7-point operator with its load
and fluxes, connectivity, and the :class:`~itr_fv.discrete.problem.DiscreteProblem` that
holds one geometry for many parameter sets."""
