"""Uncertain inputs and their statistics (pure NumPy/SciPy, SALib, GSTools).

* :mod:`.distributions` — the marginal distributions of the ``[[uncertainty.parameter]]``
  tables (normal, lognormal, uniform, truncated normal) and the probability they put
  outside a key's physical range;
* :mod:`.sampling` — designs in the unit hypercube (Monte Carlo, Latin hypercube, Sobol'/
  Saltelli), the Gaussian copula of the correlation matrix, the samples of the marginals;
* :mod:`.statistics` — percentiles with bootstrap intervals, exceedance probabilities with
  Wilson intervals, Sobol' indices, the convergence of the estimates;
* :mod:`.fields` — random fields of a soil layer's stiffness or density on the element
  centres (GSTools), seeded per realisation.

The case keys (``[uncertainty]``) are read by :mod:`railvib_hpc.validation` (the checks),
:mod:`railvib_hpc.problem` (the random fields) and :mod:`railvib_hpc.studies.uncertainty`
(the study); this package takes plain values, never the case.
"""
