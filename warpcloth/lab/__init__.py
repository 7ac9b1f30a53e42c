"""The laboratory: experiments above the physics.

* :mod:`warpcloth.lab.testlist` and :mod:`warpcloth.lab.sweep`: XML test lists run to CSV (seed 4.3);
* :mod:`warpcloth.lab.maxdt`: the max-stable-dt search;
* :mod:`warpcloth.lab.bench`: the CPU vs CUDA benchmark;
* :mod:`warpcloth.lab.study`: the accuracy-aware study's driver, with :mod:`~warpcloth.lab.plan` (what it
  measures), :mod:`~warpcloth.lab.transients` (its cloth and transients), :mod:`~warpcloth.lab.configs`
  (the configurations), :mod:`~warpcloth.lab.measure` (the measurements), :mod:`~warpcloth.lab.accuracy`
  (references, metrics, floors), :mod:`~warpcloth.lab.results` (results.csv), :mod:`~warpcloth.lab.report`,
  :mod:`~warpcloth.lab.frontier` (Pareto fronts, budgets, fits) and :mod:`~warpcloth.lab.estimate` (``--estimate``);
* :mod:`warpcloth.lab.reference`: float64 references that warpcloth's float32 runs are measured
  against (NumPy forces, SciPy ``solve_ivp``, a Newton solve of the static equilibrium and of the
  equilibrium with frictionless contact; docs/reference.md), and :mod:`warpcloth.lab.reference_warp`
  (the float64 Warp RK4 above 12 x 12);
* :mod:`warpcloth.lab.parallel`: local worker processes and Ray tasks for sweeps and studies.

Nothing in :mod:`warpcloth`'s physics imports this package. The reference's names are imported
from their module (``from warpcloth.lab.reference import static_equilibrium``).
"""
