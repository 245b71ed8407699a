"""The built-in effects' names, read from their classes, for code that means one effect.

Code outside :mod:`gyroarray.effects` that has to name one particular
effect (a datasheet number that *is* the angle random walk, a result key
that is an effect's name) takes the name from here rather than writing the
string, so that the effect's module stays the one place that spells it.
"""

from __future__ import annotations

from gyroarray.effects.arw import AngleRandomWalk
from gyroarray.effects.bandwidth import Bandwidth
from gyroarray.effects.bias_instability import BiasInstability
from gyroarray.effects.burst import Burst
from gyroarray.effects.constant_bias import ConstantBias
from gyroarray.effects.correlation import Correlation
from gyroarray.effects.faults.fault_noise import FaultNoise
from gyroarray.effects.g_sensitivity import GSensitivity
from gyroarray.effects.gauss_markov import GaussMarkov
from gyroarray.effects.misalignment import Misalignment
from gyroarray.effects.quantization import Quantization
from gyroarray.effects.rate_ramp import RateRamp
from gyroarray.effects.rrw import RateRandomWalk
from gyroarray.effects.scale_factor import ScaleFactor
from gyroarray.effects.scale_nonlinearity import ScaleNonlinearity
from gyroarray.effects.temperature_bias import TemperatureBias

__all__ = ["ARW", "RRW", "BIAS_INSTABILITY", "GAUSS_MARKOV", "QUANTIZATION", "RATE_RAMP",
           "TEMPERATURE_BIAS", "BANDWIDTH", "G_SENSITIVITY", "CORRELATION", "SCALE_FACTOR",
           "SCALE_NONLINEARITY", "MISALIGNMENT", "CONSTANT_BIAS", "BURST", "FAULT_NOISE"]

#: Angle random walk (white rate noise).
ARW: str = AngleRandomWalk.name
#: Rate random walk.
RRW: str = RateRandomWalk.name
#: Bias instability (flicker rate noise).
BIAS_INSTABILITY: str = BiasInstability.name
#: First-order Gauss–Markov rate noise.
GAUSS_MARKOV: str = GaussMarkov.name
#: Output quantization.
QUANTIZATION: str = Quantization.name
#: Rate ramp.
RATE_RAMP: str = RateRamp.name
#: Temperature-driven bias.
TEMPERATURE_BIAS: str = TemperatureBias.name
#: The gyros' own low-pass.
BANDWIDTH: str = Bandwidth.name
#: g-sensitivity (acceleration-driven bias).
G_SENSITIVITY: str = GSensitivity.name
#: Correlation between gyros' noises.
CORRELATION: str = Correlation.name
#: Scale-factor error.
SCALE_FACTOR: str = ScaleFactor.name
#: Scale nonlinearity.
SCALE_NONLINEARITY: str = ScaleNonlinearity.name
#: Axis misalignment.
MISALIGNMENT: str = Misalignment.name
#: Turn-on (constant) bias.
CONSTANT_BIAS: str = ConstantBias.name
#: A window of raised noise (dynamic Allan variance).
BURST: str = Burst.name
#: A gyro's noise fault (its noise level rises from a start time on).
FAULT_NOISE: str = FaultNoise.name
