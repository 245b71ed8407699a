"""Records from the independent generator (``benchmarks/_indep_gen.py``), read as a user's files.

The generator was written from ``shared/spec`` alone (numpy and scipy, nothing
from gyroarray), so what is checked here is not that our simulator and our
fitter agree: the effect set and its parameters are the outside truth. The
generator's own closed-form checks (ARW, RRW, quantization, flicker floor,
Gauss–Markov, the filter's lag) are ``selfcheck``; one of them is asserted
below so a change in the generator cannot go unnoticed.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import _indep_gen as gen  # noqa: E402

from gyroarray.chain.compare import ModelComparison  # noqa: E402
from gyroarray.core.measurement import read_measurement  # noqa: E402


def _analysis(effect: str, seed: int, tmp_path):
    case = gen.make_case(effect, seed)
    m = read_measurement(gen.write_case(case, tmp_path))
    return case, ModelComparison(m, n_runs=10)


def test_generator_arw_meets_its_closed_form():
    """ADEV(1 s) of the generator's white rate noise is N/60 deg/s (IEEE 952), computed here by
    plain numpy; the 1σ of an ADEV estimate at τ = 1 s over 2000 s of 50 Hz samples is about
    1.6 % (EDF ~ 2000): 5 %."""
    rng = np.random.default_rng(3)
    dt, n_deg_rt_h = 0.02, 0.2
    x = gen.arw_sigma_rad_s(n_deg_rt_h, dt) * rng.standard_normal(100_000)
    m = int(round(1.0 / dt))
    c = np.concatenate([[0.0], np.cumsum(x)]) * dt
    d = c[2 * m:] - 2 * c[m:-m] + c[:-2 * m]
    adev = math.sqrt(np.mean(d ** 2) / 2.0) / (m * dt)
    assert adev == pytest.approx(math.radians(n_deg_rt_h / 60.0), rel=0.05)


@pytest.mark.slow   # a 7-14 s study of the independent generator: make score
def test_a_pure_delay_is_named_latency_not_a_filter(tmp_path):
    """Seed 500: an 11.2 ms delay on gyro 5. The motion explains it as well as a first-order
    filter at 11.6 Hz would (z 291.23 against 291.25); the noise spectrum, which that filter
    would cut to a quarter at 20 Hz, shows no roll-off (2Δℓ 3.3), so the delay ranks first and
    its fit gives the delay set (1σ 0.04 ms: 3σ)."""
    case, comp = _analysis("latency", 500, tmp_path)
    an = comp.analyse()
    top = an.candidates[0]
    assert (top.effect, top.gyro) == ("latency", case["gyro"]), [(t.effect, t.gyro, t.z) for t in an.candidates[:3]]
    bw = next(t for t in an.candidates if (t.effect, t.gyro) == ("bandwidth", case["gyro"]))
    assert "a delay, not a filter" in bw.evidence
    want = gen.effect_params(case)["delay_s"]
    got, sig = top.fit.params["delay_s"], top.fit.sigma["delay_s"]
    assert abs(got - want) <= max(3.0 * sig, 0.02 * want), (got, sig, want)


@pytest.mark.slow   # a 7-14 s study of the independent generator: make score
def test_a_line_near_nyquist_is_not_read_as_quantization(tmp_path):
    """Seed 510: a 0.051 deg/s line at 17.35 Hz on gyro 3 of a 50 Hz record lifts the ADEV at
    τ = 0.02 s as a τ^-1 slope would (quantization z 211 against the line's 179). With the line
    taken out, quantization is no longer seen, so the line ranks first; its amplitude and
    frequency are the generator's (1σ 4.6e-5 deg/s: 3σ)."""
    case, comp = _analysis("sinusoid", 510, tmp_path)
    an = comp.analyse()
    top = an.candidates[0]
    assert (top.effect, top.gyro) == ("sinusoid", case["gyro"]), [(t.effect, t.gyro, t.z) for t in an.candidates[:3]]
    q = next(t for t in an.candidates if (t.effect, t.gyro) == ("quantization", case["gyro"]))
    assert not an.significant(q) and "no longer seen" in q.evidence
    want = gen.effect_params(case)
    assert top.fit.params["freq_hz"] == pytest.approx(want["freq_hz"], abs=1e-3)
    assert abs(top.fit.params["amp_deg_s"] - want["amp_deg_s"]) <= 3.0 * top.fit.sigma["amp_deg_s"]


@pytest.mark.slow   # 19 s: make score
def test_g_sensitivity_with_lever_arms_and_accelerometer_columns(tmp_path, monkeypatch):
    """Seed 501 with the gyros at ±0.25 m (``positions_m``) and the specific force at the origin
    in ``acc_x/y/z``: the generator adds the spec's f_k = f_0 + α × r_k + ω × (ω × r_k) itself.
    gyroarray's fit takes the record to consistent with the vector set (each component within
    3σ, σ ≈ 0.0006 deg/s/g). With the generator's lever terms of the wrong sign the fit stays
    inconsistent (D 3.2: slope and tilt left on gyro 4), so the lever-arm convention is what
    this checks."""
    monkeypatch.setattr(gen, "LEVER_ARMS", True)
    case, comp = _analysis("g_sensitivity", 501, tmp_path)
    assert comp.m.has_acc and comp.m.layout.positions_m is not None
    g = case["gyro"]
    _, after = comp.fit([("g_sensitivity", g)])
    assert after.consistent, after.discrepancy
    fit = after.fits[("g_sensitivity", g)]
    got, sig = np.asarray(fit.params["deg_s_per_g"]), np.asarray(fit.sigma["deg_s_per_g"])
    want = np.asarray(gen.effect_params(case)["deg_s_per_g"])
    assert np.all(np.abs(got - want) <= 3.0 * sig), (got, sig, want)
