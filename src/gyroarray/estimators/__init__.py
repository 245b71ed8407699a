"""Pluggable fusion estimators (issue 4): gyro readings (n, N) -> body rates (n, 3).

Built-in estimators (``available()`` lists them with the installed plugins):

========== ================================================================
name       method
========== ================================================================
kf_array   paper 003 steady-state KF on [body rate; gyro biases]
kf_single  paper 002 single-gyro KF [rate, bias] per gyro, then OLS
ols        ordinary least squares per sample (optional low-pass)
gls        generalized least squares per sample (optional low-pass)
naive      mean of the back-projected readings per axis, no model
svo        variance-optimal static weights for one averaging time tau_s
           (GLS on the gyros' Allan covariance at tau_s; issue 31, 3a)
bound      time-varying KF + RTS smoother (offline), and the CRB
fdi        parity-space fault detection and isolation; GLS without the
           isolated gyro (a detector whose estimate is the recovered rate)
========== ================================================================

Usage::

    from gyroarray.estimators import get_estimator
    est = get_estimator("kf_array")(bandwidth_hz=10.0).fit(layout, noise_model, dt_s)
    omega_hat = est.estimate(readings_rad_s)          # (n, 3) [rad/s]
"""

from gyroarray.estimators.base import (ENTRY_POINT_GROUP, Estimator, NotFittedError, available,
                                       get_estimator, make, register, unregister)
from gyroarray.estimators.bound import OfflineBound, efficiency
from gyroarray.estimators.fdi import FaultDetector
from gyroarray.estimators.kf_array import ArrayKF
from gyroarray.estimators.kf_single import (SingleGyroKF, bandwidth_hz, paper002_relation,
                                            single_gyro_gain)
from gyroarray.estimators.noise import ArrayNoise, array_noise
from gyroarray.estimators.simple import GLS, OLS, Naive

__all__ = ["ENTRY_POINT_GROUP", "Estimator", "NotFittedError", "available", "get_estimator", "make",
           "register", "unregister", "OfflineBound", "efficiency", "FaultDetector", "ArrayKF", "SingleGyroKF", "bandwidth_hz",
           "paper002_relation", "single_gyro_gain", "ArrayNoise", "array_noise", "GLS", "OLS",
           "Naive"]
