"""The effect protocol under its former name: :mod:`gyroarray.effects.protocol` re-exported.

The protocol lives in ``gyroarray.effects.protocol`` (an effect owns its
simulate and its fit side, so the protocol sits with the effects, below the
simulator). This module keeps ``gyroarray.sim.protocol`` working for plugins
written against it: every name is the same object as there.
"""

from gyroarray.effects.protocol import *  # noqa: F401,F403
from gyroarray.effects.protocol import __all__  # noqa: F401
