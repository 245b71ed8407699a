"""Data pipelines are a property of the record, not of the sensor (issue 32).

A phone-like record written here with numpy and scipy, independently of the
library's simulator: white + Gauss–Markov noise at 1 kHz, a zero-phase
low-pass (an 8th-order Butterworth at 30 Hz run forward and back,
``scipy.signal.sosfiltfilt``) then every 10th sample kept (100 Hz), then each
sample held (replaced by the one before) with probability 5 %, independently
(so the held count is binomial; runs of 1–3 samples). Outside truth: the hold
probability and the filter's cut-off; the held samples of each gyro and the
ringing around them are no spikes, the record has no fault.

* :func:`~gyroarray.analysis.pipeline.detect_pipeline` reports nothing on
  clean white noise (no holds, no roll-off), and on the processed record a
  held fraction within the binomial interval of 5 % and a corner within
  ±10 % of 30 Hz; a record put onto 100 Hz stamps from 98 Hz by linear
  interpolation shows its 2 Hz beat; a stuck output, a clipped range, a
  coarse grid and a causal second-order low-pass are no pipeline.
* The outliers test reads the held record as a crowd of spikes (the
  reproduction of the issue: second-difference clusters far beyond their
  expectation) unless the samples next to the holds are left out.
* A noise change read where the pipeline does not act (holds bridged, below
  the roll-off) is seen when it is there and not when it is not.
* ``gyroarray diagnose --json`` names no outliers and no fault, and its verdict
  names the pipeline (holds and the roll-off); ``allan`` carries the same note.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal, stats

from gyroarray.analysis.pipeline import detect_pipeline, near_holds, passband_change
from gyroarray.effects.outliers import find_spikes
from hostile import SIDECAR_3, assert_contract, run_cli, write_measurement

FS_HI = 1000.0                # the fast stream [Hz]
DECIM = 10                    # kept: every 10th sample (100 Hz)
CUTOFF_HZ = 30.0              # the zero-phase filter's cut-off [Hz]
P_HOLD = 0.05                 # probability that a sample is held


def phone_record(rng: np.random.Generator, span_s: float, n_gyros: int = 3, p_hold: float = P_HOLD):
    """(outputs (m, n_gyros) [deg/s] at 100 Hz, held (m, n_gyros) bool): the pipeline above."""
    n = int(span_s * FS_HI)
    white = rng.normal(0.0, 0.05, (n, n_gyros))                          # deg/s per sample
    a = np.exp(-1.0 / (FS_HI * 20.0))                                    # GM, tau_c 20 s
    gm = signal.lfilter([1.0], [1.0, -a], rng.normal(0.0, 0.002, (n, n_gyros)), axis=0)
    x = white + gm + 0.1
    sos = signal.butter(8, CUTOFF_HZ, fs=FS_HI, output="sos")
    y = signal.sosfiltfilt(sos, x, axis=0)[::DECIM]
    m = y.shape[0]
    held = rng.random((m, n_gyros)) < p_hold
    held[0] = False
    src = np.maximum.accumulate(np.where(held, 0, np.arange(m)[:, None]), axis=0)
    return np.take_along_axis(y, src, axis=0), held


@pytest.fixture(scope="module")
def record():
    return phone_record(np.random.default_rng(5), 300.0)


def test_clean_white_noise_shows_no_pipeline():
    x = np.random.default_rng(1).normal(0.0, 0.05, (30000, 3))
    r = detect_pipeline(x, 0.01)
    assert not r.processed and not r.held and not r.filtered
    assert r.corner_hz is None and r.rolloff_hz is None
    assert all(h.n_held == 0 and not h.significant for h in r.holds)
    assert r.verdict() == ""


def test_quantized_white_noise_repeats_by_chance_only():
    # a coarse grid repeats values by chance (about 10 % here): not holds
    x = np.round(np.random.default_rng(2).normal(0.0, 1.0, (30000, 3)) * 3.0) / 3.0
    r = detect_pipeline(x, 0.01)
    assert min(h.fraction for h in r.holds) > 0.05
    assert not r.held


def test_a_stuck_output_and_a_clipped_range_are_not_holds():
    x = np.random.default_rng(4).normal(0.0, 1.0, (30000, 2))
    x[20000:, 0] = x[20000, 0]                   # stuck from 200 s on (a fault of the sensor)
    x[:, 1] = np.clip(x[:, 1], -1.5, 1.5)        # saturated: runs at the range's ends
    r = detect_pipeline(x, 0.01)
    assert not r.held, r.holds
    y = x.copy()
    y[1::40, 1] = y[0:-1:40, 1]                  # and with 2.5 % held samples: those are seen
    assert detect_pipeline(y, 0.01).holds[1].significant


def test_a_resampled_record_shows_its_beat():
    # white noise at 98 Hz put onto 100 Hz stamps by linear interpolation: the noise level beats
    # at |100 - 98| = 2 Hz (samples on an original one keep its variance, those between lose some)
    rng = np.random.default_rng(6)
    t0 = np.arange(58800) / 98.0
    x0 = rng.normal(0.0, 1.0, (t0.size, 3))
    t1 = np.arange(0.0, t0[-1], 0.01)
    y = np.stack([np.interp(t1, t0, x0[:, g]) for g in range(3)], axis=1)
    r = detect_pipeline(y, 0.01)
    assert r.resampled and abs(r.beat_hz - 2.0) < 0.01, r.beat_hz
    assert not r.held and not r.filtered
    assert "resampling by interpolation" in r.verdict() and "2 Hz" in r.verdict()
    assert not detect_pipeline(rng.normal(0.0, 1.0, (60000, 3)), 0.01).resampled


def test_a_causal_second_order_lowpass_is_not_a_brick_wall():
    x = np.random.default_rng(3).normal(0.0, 1.0, (30000, 3))
    y = signal.sosfilt(signal.butter(2, 20.0, fs=100.0, output="sos"), x, axis=0)
    assert not detect_pipeline(np.round(y * 1000.0) / 1000.0, 0.01).filtered


def test_processed_record_holds_and_rolloff(record):
    y, held = record
    r = detect_pipeline(y, 1.0 / (FS_HI / DECIM))
    m = y.shape[0]
    lo, hi = stats.binom.interval(0.999, m - 1, P_HOLD)
    for g, h in enumerate(r.holds):
        assert h.significant
        assert lo <= h.n_held <= hi, (g, h.n_held, lo, hi)
        assert abs(h.n_held - int(held[1:, g].sum())) <= 3        # only repeats at the extremes lost
        assert h.n_runs < h.n_held
    assert r.corner_hz is not None and abs(r.corner_hz / CUTOFF_HZ - 1.0) <= 0.10, r.corner_hz
    lo_hz, hi_hz = r.rolloff_hz
    assert lo_hz == r.corner_hz and CUTOFF_HZ < hi_hz < 0.92 * 50.0
    assert r.drop_decades >= 1.5
    text = r.verdict()
    assert "held samples" in text and "roll-off at" in text and f"{r.corner_hz:.3g} Hz" in text
    assert r.to_json_dict()["processed"] is True


def test_spikes_next_to_holds_are_not_outliers(record):
    y, _ = record
    x = y[:, 0]
    before = find_spikes(x)
    assert before.z > 3.0, before.z            # the issue: the holds read as a crowd of spikes
    after = find_spikes(x, skip=near_holds(x))
    assert after.z <= 3.0 and after.index.size == 0, (after.z, after.index.size)


def test_noise_change_read_below_the_rolloff(record):
    y, _ = record
    dt = 1.0 / (FS_HI / DECIM)
    r = detect_pipeline(y, dt)
    x = y[:, 1]
    half = x.size // 2
    _, z0 = passband_change(x, dt, half, r)
    assert z0 < 3.0, z0
    louder = x.copy()
    louder[half:] = louder[half:].mean() + 1.3 * (louder[half:] - louder[half:].mean())
    ratio, z1 = passband_change(louder, dt, half, r)
    assert z1 > 5.0 and 1.5 < ratio < 1.9, (ratio, z1)


@pytest.mark.slow   # diagnose and allan on a 150 s phone-like record (about 30 s): make score
def test_diagnose_names_the_pipeline_not_outliers_or_faults(tmp_path):
    y, _ = phone_record(np.random.default_rng(5), 150.0)
    t = np.arange(y.shape[0]) * (DECIM / FS_HI)
    path = write_measurement(tmp_path, "phone", t, y, sidecar=SIDECAR_3.replace("50.0", "100.0"))
    o = run_cli(["diagnose", path, "--json"], timeout=300)
    assert_contract(o, "phone")
    assert o.code == 0, o.err
    d = json.loads(o.out)
    named = [(c["effect"], c["gyro"]) for c in d["candidates"] if c["significant"]]
    assert not [e for e in named if e[0] == "outliers" or e[0].startswith("fault")], named
    assert not named, named                   # nothing forced on the processing
    pipe = d["pipeline"]
    assert pipe["processed"] and all(h["significant"] for h in pipe["holds"])
    assert abs(pipe["corner_hz"] / CUTOFF_HZ - 1.0) <= 0.10
    verdict = [n for n in d["notes"] if n.startswith("this record was processed by")]
    assert len(verdict) == 1 and "held samples" in verdict[0] and "roll-off at" in verdict[0]
    explained = {c["effect"] for c in d["candidates"] if c["explained_by"] == {"effect": "pipeline", "gyro": None}}
    assert "bandwidth" in explained
    o = run_cli(["allan", path, "--json"], timeout=300)
    assert_contract(o, "phone")
    a = json.loads(o.out)
    assert a["pipeline"]["processed"]
    assert any(n.startswith("this record was processed by") and "read the noise terms at τ above" in n
               for n in a["notes"])
