"""Discrepancy workflow: where the calibrated model misses the measurements, and why.

1. **Forward tables** (:mod:`.tables`). Per single-filler formulation, one RVE (the first
   replica of :class:`itr_identify.forward.model.ForwardModel`, gap contact model) is
   solved with the full solver on a grid of the filler-matrix resistance
   ``R_<f>_silicone`` for the base model and, for every candidate of :mod:`.effects`, on
   that grid times the candidate's parameter grid. The other replicas, solved at one
   resistance, give the RVE-to-RVE scatter and scale the first replica to the replica mean
   (as :mod:`itr_identify.forward.model`).
2. **Calibration of each model** (:mod:`.fit`; base: one ``R`` per filler; candidate:
   those plus the effect's parameter) on a fine grid (cubic interpolation of ``ln k``
   between the solved points, no extrapolation), Gaussian likelihood per measurement group
   (a formulation, or a formulation at one sample thickness): replicate error
   ``s / sqrt(n)`` (``s`` pooled over a filler's formulations, :func:`.fit.groups_of`) and
   one RVE error ``sigma_rve k`` shared by a formulation's groups.
3. **Disagreement** (:mod:`.decision`). The base model's chi-square against its degrees of
   freedom (p-value), standardised residuals per group and their structure: trend with the
   filler fraction per filler, offset between fillers, trend with the thickness.
4. **Selection** (:mod:`.decision`). Candidates ranked by their log Bayes factor over the
   base model (:attr:`.fit.ModelFit.log_evidence`: the likelihood integrated over the
   resistances and the effect's prior). One is *named* when it exceeds the threshold
   calibrated on the table (:mod:`.naming_threshold`: the quantile of the largest log Bayes
   factor on noise-only tables drawn from the base model that keeps false naming at
   :attr:`.settings.DiscrepancySettings.false_naming_rate`), leaves no significant residual,
   needs no resistance at the edge of its grid and does not pull a stated input beyond three
   of its sds; candidates close to it are a *tie* with the measurement that separates them;
   a significant base residual that no candidate removes is an *unexplained* discrepancy.
   The result is frozen (:class:`.outcome.Discrepancy`).

Two-filler formulations are left out (their forward table would need a grid over both
resistances); the report lists them. :mod:`.settings` holds the workflow's settings,
:mod:`.synthetic` measurements made with the full solver (the recovery tests and studies);
the report is :mod:`itr_identify.reporting.discrepancy_report`, the job
:mod:`itr_identify.workflows.discrepancy`.
"""
