"""Where it fails: the localisation wired into compare (diagnose, compare, ladder, the report).

Records: a 4-gyro cone (ARW 0.3 deg/√h, RRW 5 deg/h/√h) at 100 Hz, 300 s:
still 100 s, a 30 deg/s swing at 0.5 Hz about (1,1,1)/√3, a 20 deg/s swing
at 1.3 Hz about (1,−1,0)/√2 (minimum-jerk envelopes), still again; a
reference rate and a warming temperature. Simulated with gyroarray's
simulator; the filter that is NOT in the library is applied outside it, with
scipy: ``filtfilt`` of a 4th-order Butterworth at 10 Hz on gyros 2 and 3 (a
zero-phase decimation filter, the "Samsung" case of issue 15). The expected
cut-off is the −3 dB point of that filter's magnitude from ``scipy.signal.freqz``
(|H|² for a forward-backward pass); correlations are checked against a plain
``np.corrcoef`` of the same block means.

False alarms: the clean record of seeds 2-11, localised even though
consistent, gives no finding (measured; the family-wise rate is 1 %).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from swings import two_swings

FS = 100.0
DT = 1.0 / FS
N_SAMPLES = 30_000
LAYOUT = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))
FILTER = signal.butter(4, 10.0, fs=FS)            # (b, a), applied with filtfilt
FILTERED = (2, 3)


def _record(seed: int, zero_phase: bool) -> Measurement:
    t = np.arange(N_SAMPLES) * DT
    w = two_swings(t, (100.0, 180.0), (190.0, 270.0))
    model = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": 0.3},
                                              {"effect": "rrw", "k_deg_h_rt_h": 5.0}]}, n_gyros=4)
    y = simulate_readings(model, w, LAYOUT, DT, np.random.default_rng(seed), time_s=t)
    if zero_phase:
        cols = [g - 1 for g in FILTERED]
        y[:, cols] = signal.filtfilt(*FILTER, y[:, cols], axis=0)
    return Measurement(time_s=t, gyro_deg_s=np.degrees(y), layout=LAYOUT, sample_rate_hz=FS,
                       ref_deg_s=np.degrees(w), temp_c=25.0 + 5.0 * t / t[-1])


def _minus_3db_hz() -> float:
    """−3 dB point of the forward-backward filter, |H(f)|² = 1/√2 (freqz on a fine grid)."""
    f = np.linspace(1.0, 40.0, 390_001)
    h2 = np.abs(signal.freqz(*FILTER, worN=f, fs=FS)[1]) ** 2
    return float(f[np.argmin(np.abs(h2 - 1 / math.sqrt(2)))])


@pytest.fixture(scope="module")
def samsung():
    m = _record(1, zero_phase=True)
    comp = ModelComparison(m, n_runs=20)
    return m, comp, comp.diagnose()


@pytest.fixture(scope="module")
def clean():
    comp = ModelComparison(_record(2, zero_phase=False), n_runs=20)
    return comp, comp.diagnose()


def test_zero_phase_decimation_filter_is_a_lowpass_that_does_not_lag(samsung):
    _, _, a = samsung
    assert not a.consistent
    top = a.localisation[0]
    assert top["kind"] == "lowpass" and top["gyros"] == list(FILTERED)
    d = top["details"]
    # 9.01 Hz from freqz; measured 8.77 here, 0.973-1.001 of it over seeds 1-6 (the
    # roll-off is seen over ~3 tenth-decade bins before it reaches 20 dB): 5 %
    assert d["cutoff_hz"] == pytest.approx(_minus_3db_hz(), rel=0.05)
    assert f"low-pass at ≈ {d['cutoff_hz']:.3g} Hz" in top["sentence"]
    assert "not causal: no lag on motion" in top["sentence"] and d["causal"] is False
    # a causal filter of that magnitude lags ~60 ms; measured -0.03 ± 0.02 ms
    assert abs(d["lag_s"]) < 4 * d["lag_se_s"] + 1e-4 < 0.1 * d["expected_lag_s"]
    # the magnitude is what bandwidth reads (its candidate comes first), and the missing lag is said
    assert a.candidates[0].effect == "bandwidth" and a.candidates[0].gyro in FILTERED
    assert "bandwidth (significant or in the model on gyros 2, 3): it is causal" in top["sentence"]
    for f in a.localisation:       # never Gauss-Markov or a burst, no noise-level change at rest
        assert "Gauss" not in f["sentence"] and "burst" not in f["sentence"]
        assert f["kind"] != "time_window" or f["details"]["moving_fraction"] > 0
        assert set(f["gyros"]) <= set(FILTERED)
    # the text shows the ranked findings instead of the one sentence
    text = "\n".join(a.where_it_fails())
    assert text.startswith("where it fails") and "not causal" in text and "none of the" not in text
    out = json.loads(json.dumps(a.to_json_dict(), allow_nan=False))
    assert out["localisation"][0]["kind"] == "lowpass"


@pytest.mark.slow   # a ladder on a filtered record (12 s): make score
def test_ladder_does_not_mimic_the_filter_with_noise_effects(samsung):
    # without the localisation the ladder added gauss_markov, outliers and quantization on
    # gyros 2 and 3 (D 152 -> 99.5): effects that only mimic a filter the library does not have
    _, comp, _ = samsung
    steps = comp.ladder(max_steps=3)
    final = steps[-1][1]
    assert len(steps) == 1 and not final.consistent
    assert final.localisation[0]["kind"] == "lowpass" and final.localisation[0]["details"]["causal"] is False
    assert any(n.startswith("the ladder adds no noise effect on gyros 2, 3") for n in final.notes)


def test_clean_record_gives_no_findings_and_the_correlations_are_plain_ones(clean):
    comp, a = clean
    assert a.consistent and a.localisation == [] and a.to_json_dict()["localisation"] == []
    forced = comp.localise(a, force=True)
    assert forced.localised.findings == () and forced.localisation == []
    assert {c.channel for c in forced.localised.correlations} == {
        "time", "rate", "rate²", "angular acceleration", "temperature", "dT/dt"}
    # every correlation is Pearson's r of 500 block means
    E = a.residual_rad_s
    b = E.shape[0] // 500
    u = np.asarray(comp.ref) @ comp.H.T
    channels = {"rate": u, "rate²": u ** 2, "temperature": np.asarray(comp.temp)}
    for c in forced.localised.correlations:
        if c.channel not in channels:
            continue
        x = channels[c.channel]
        x = x if x.ndim == 1 else x[:, c.gyro - 1]
        r = np.corrcoef(E[:, c.gyro - 1].reshape(-1, b).mean(axis=1), x.reshape(-1, b).mean(axis=1))[0, 1]
        assert c.r == pytest.approx(r, abs=1e-12)
    comp.localise(a)                 # back to what diagnose gives


def test_report_shows_the_localisation_only_when_there_are_findings(samsung, clean):
    from gyroarray.chain.compare_figures import compare_figures
    from gyroarray.reports.compare_report import section_unexplained
    from gyroarray.reports.report import Doc
    _, comp, a = samsung
    doc = Doc("t")
    section_unexplained(doc, a, comp, compare_figures(comp, [(None, a)]))
    assert [n for n, _ in doc.figures] == ["localise_psd", "localise_channels"]
    assert all(png[:8] == b"\x89PNG\r\n\x1a\n" for _, png in doc.figures)
    text = "\n".join(doc.html)
    assert "Where it fails" in text and "not causal: no lag on motion" in text
    doc = Doc("t")
    section_unexplained(doc, clean[1], clean[0], compare_figures(clean[0], [(None, clean[1])]))
    assert doc.figures == [] and "Nothing left unexplained" in "\n".join(doc.html)


def test_cli_diagnose_json_carries_the_localisation(samsung, tmp_path, capsys):
    from gyroarray.cli.main import main
    m, _, _ = samsung
    csv, _ = write_measurement(m, tmp_path / "samsung.csv")
    assert main(["diagnose", str(csv), "--runs", "10", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    top = d["localisation"][0]
    assert top["kind"] == "lowpass" and top["gyros"] == list(FILTERED)
    assert top["details"]["causal"] is False and "not causal" in top["sentence"]
