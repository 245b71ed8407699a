"""``gyroarray allan --gaps``: a record with dropped packets is analysed, not refused (issue 33, item 5).

Outside truth: allantools' ``oadev`` on each contiguous piece of the record, the pieces' Allan
variances pooled with their counts of terms (no averaging window straddles a gap). The record
is written with numpy: white noise at 50 Hz with 1 % of its packets dropped at random.
"""

from __future__ import annotations

import json

import allantools
import numpy as np
import pytest

from gyroarray.analysis.deviations import contiguous_segments
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement
from hostile import assert_contract, axes_sidecar, run_cli, write_measurement

RATE_HZ = 50.0


@pytest.fixture(scope="module")
def gappy(tmp_path_factory):
    """(path, kept time stamps, kept rates [deg/s], dropped): 6 000 samples, 60 packets dropped."""
    rng = np.random.default_rng(33)
    n = 6_000
    t = np.arange(n) / RATE_HZ
    g = rng.normal(0.0, 0.05, (n, 1)) + 0.01
    keep = np.ones(n, bool)
    keep[rng.choice(np.arange(1, n - 1), n // 100, replace=False)] = False
    folder = tmp_path_factory.mktemp("gaps")
    path = write_measurement(folder, "gappy", t[keep], g[keep], sidecar=axes_sidecar(1, RATE_HZ))
    return path, t[keep], g[keep, 0], n - int(keep.sum())


def _pooled_allantools(t, x, taus):
    """The ADEV [deg/h] of rate ``x`` [deg/s] pooled over its contiguous pieces (of >= 4 samples,
    as allan keeps them), each piece's oadev from allantools weighted by its count of terms."""
    step = np.diff(t)
    cut = np.flatnonzero(step > 1.5 / RATE_HZ)
    edges = [0, *(cut + 1).tolist(), t.size]
    num, den = np.zeros(len(taus)), np.zeros(len(taus))
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < 4:
            continue
        m = np.rint(taus * RATE_HZ).astype(int)
        ok = 2 * m + 1 <= b - a + 1                   # the piece's phase has b - a + 1 points
        if not ok.any():
            continue
        # each m's sum of squared second differences is (its count) · (its variance), the count
        # n + 1 - 2m (allantools leaves out a single term's result: it is put back from the sum)
        phase = np.concatenate(([0.0], np.cumsum(x[a:b]) / RATE_HZ))
        tau_ok = taus[ok]
        try:
            t_out, dev, _, ns = allantools.oadev(phase, rate=RATE_HZ, data_type="phase", taus=tau_ok)
        except UserWarning:                            # every τ has a single term
            t_out, dev, ns = np.array([]), np.array([]), np.array([])
        for tau, v, k in zip(t_out, dev, ns):
            i = int(np.argmin(np.abs(taus - tau)))
            num[i] += k * v ** 2
            den[i] += k
        for i in np.flatnonzero(ok):
            if not np.isclose(t_out, taus[i], rtol=1e-9).any():                   # left out by allantools: one term, by hand
                mm = m[i]
                d = phase[2 * mm:] - 2 * phase[mm:-mm] + phase[:-2 * mm]
                num[i] += np.sum(d ** 2) / (2.0 * (mm / RATE_HZ) ** 2)
                den[i] += d.size
    return 3600.0 * np.sqrt(num / den)


def test_gap_adev_equals_allantools_pooled_over_the_pieces(gappy):
    path, t, x, dropped = gappy
    o = run_cli(["allan", path, "--gaps", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    d = json.loads(o.out)
    segments, missing = contiguous_segments(t, 1.0 / RATE_HZ)
    assert missing == dropped == 60
    info = d["analysed_parts"]
    assert info["gaps"] == len(segments) - 1 and info["missing_samples"] == dropped
    assert any("gap(s)" in n and f"{dropped} sample(s) missing" in n for n in d["notes"])
    g = d["gyros"]["1"]
    taus = np.asarray(g["taus_s"])
    want = _pooled_allantools(t, x, taus)
    np.testing.assert_allclose(g["adev_deg_h"], want, rtol=1e-9)
    # and white noise of 0.05 deg/s at 50 Hz: σ(τ) = 0.05·√(0.02/τ) deg/s, within 3.5 half-widths
    # of the 68 % CIs where many pieces hold the τ (beyond 1 s only the 5 longest pieces do, and
    # the lag-1 noise type that sets the EDF rests on one of them: not checked there)
    truth = 3600.0 * 0.05 * np.sqrt(1.0 / (RATE_HZ * taus))
    lo, hi = np.asarray(g["ci_low_deg_h"]), np.asarray(g["ci_high_deg_h"])
    half = 0.5 * (hi - lo)
    short = taus < 1.0
    assert short.sum() >= 6
    assert np.all(np.abs(np.asarray(g["adev_deg_h"]) - truth)[short] < 3.5 * half[short])


def test_the_text_names_the_gaps(gappy):
    path, t, _, dropped = gappy
    o = run_cli(["allan", path, "--gaps"])
    assert o.code == 0, o.err
    segments, _ = contiguous_segments(t, 1.0 / RATE_HZ)
    assert f"{len(segments) - 1} gap(s) in the time stamps ({dropped} sample(s) missing)" in o.out
    assert "nothing interpolated" in o.out


def test_without_the_flag_the_refusal_names_repair_and_gaps(gappy):
    path, *_ = gappy
    o = run_cli(["allan", path])
    assert_contract(o, "gappy.csv")
    assert o.code == 2
    assert "--repair" in o.err and "--gaps" in o.err and "missing sample" in o.err


def test_the_reader_keeps_the_stamps_as_they_are(gappy):
    path, t, x, dropped = gappy
    m = read_measurement(path, gaps=True)
    np.testing.assert_array_equal(m.time_s, t)
    np.testing.assert_array_equal(m.gyro_deg_s[:, 0], x)
    assert any("kept as they are" in n and f"({dropped} sample(s) missing" in n for n in m.notes)
    with pytest.raises(InputError, match="--gaps"):
        read_measurement(path)
