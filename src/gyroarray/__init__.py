"""gyroarray: a simulation benchmark for redundant (skewed, conical) MEMS gyro arrays.

Sub-packages (each a top-level folder of the repository):

* ``gyroarray`` (folder ``gyroarray/``): units, layouts and GDOP design
  analysis, measurement files, the CLI.
* ``gyroarray.analysis`` (``analysis/``): statistics shared by simulation
  fitting and reports (Allan/Hadamard deviation, confidence intervals, noise
  fits).
* ``gyroarray.sim``, ``gyroarray.estimators``, ``gyroarray.sweep``,
  ``gyroarray.reports``: rate table and noise injector, fusion estimators,
  scenario files, reports.

Units: SI inside (rad, rad/s, s); datasheet units (deg/√h, deg/h, deg/h/√h)
only at the edges, through the named converters of :mod:`gyroarray.core.units`.
"""

__version__ = "0.1.0"
