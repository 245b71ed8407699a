"""The gyro's own filter and g-sensitivity under their former name: :mod:`gyroarray.sensor` re-exported.

The pure functions of the ``bandwidth`` and ``g_sensitivity`` effects live in
``gyroarray.sensor`` (the bottom of the package: the effects and the fitters
read them too). Every name is the same object as there.
"""

from gyroarray.sensor import *  # noqa: F401,F403
from gyroarray.sensor import __all__  # noqa: F401
