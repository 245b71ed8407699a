"""The fault effects (``fault_step``, ``fault_drift``, ``fault_stuck``, ``fault_noise``).

One module per fault effect, their common base (:mod:`~gyroarray.effects.faults.base`: onset, fit and
ranking shared by the four), their physics (:mod:`~gyroarray.effects.faults.physics`) and the
onset/size scans of the fit (:mod:`gyroarray.effects.faults.scan`). The
registry finds the effects here like those of :mod:`gyroarray.effects`.
"""
