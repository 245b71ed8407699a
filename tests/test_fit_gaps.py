"""``gyroarray fit --gaps`` (issue 42): the option ``allan`` and ``convert`` have, passed to the reader.

A numpy record: white noise of 0.05 deg/s at 50 Hz on one gyro, 6 000 samples with 1 % of the
packets dropped at random (as tests/test_allan_gaps.py builds it). Without ``--gaps`` the reader
refuses it at the first gap, naming ``--gaps``; with it the reader keeps the gaps, and the
comparison (chain/compare.py, ``ModelComparison._check_usable``) cuts the record at them into its
contiguous parts, stitched as it stitches still parts (each part its own offset, no Allan average
or random walk read across a gap), so the fit runs on the parts.

The end-to-end check is a record with 2 gaps: the same white noise, 6 000 samples, 50 (1 s) and
200 (4 s) samples dropped.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hostile import assert_contract, axes_sidecar, run_cli, write_measurement

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, read_measurement

RATE_HZ = 50.0
SIGMA_DEG_S = 0.05


@pytest.fixture(scope="module")
def gappy(tmp_path_factory):
    """(path of the gappy CSV, path of the same record without drops, dropped count)."""
    rng = np.random.default_rng(33)
    n = 6_000
    t = np.arange(n) / RATE_HZ
    g = rng.normal(0.0, SIGMA_DEG_S, (n, 1)) + 0.01
    keep = np.ones(n, bool)
    keep[rng.choice(np.arange(1, n - 1), n // 100, replace=False)] = False
    folder = tmp_path_factory.mktemp("fit_gaps")
    path = write_measurement(folder, "gappy", t[keep], g[keep], sidecar=axes_sidecar(1, RATE_HZ))
    full = write_measurement(folder, "full", t, g, sidecar=axes_sidecar(1, RATE_HZ))
    return path, full, n - int(keep.sum())


def test_without_gaps_the_reader_refuses_naming_gaps(gappy):
    path, _, dropped = gappy
    assert dropped == 60
    o = run_cli(["fit", path])
    assert_contract(o, "gappy.csv")
    assert o.code == 2
    assert "missing sample" in o.err and "--gaps" in o.err and "--repair" in o.err


def test_with_gaps_the_reader_keeps_them(gappy, monkeypatch):
    """The option reaches ``read_measurement`` (gaps=True) and the reader's refusal is gone (the
    fit itself stops at the comparison here: its 61 parts take 5 s, the fits of gaps are the tests
    below)."""
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core import measurement

    def stop(self):
        raise InputError("stopped after reading (test)")
    monkeypatch.setattr(ModelComparison, "_check_usable", stop)
    seen = []
    real = measurement.read_measurement

    def spy(*args, **kwargs):
        seen.append([kwargs.get("gaps"), None])
        seen[-1][1] = real(*args, **kwargs)
        return seen[-1][1]
    monkeypatch.setattr(measurement, "read_measurement", spy)
    path, _, dropped = gappy
    o = run_cli(["fit", path, "--gaps", "--json"])
    assert_contract(o)
    assert "missing sample" not in o.err and "stopped after reading" in o.err   # read, then stopped
    assert len(seen) == 1 and seen[0][0] is True
    m = seen[0][1]
    assert m.n_samples == 6_000 - dropped                    # nothing interpolated
    assert any("kept as they are" in n and f"({dropped} sample(s) missing" in n for n in m.notes)
    # without the option the call passes gaps=False and the reader refuses (the test above)
    seen.clear()
    assert run_cli(["fit", path]).code == 2
    assert len(seen) == 1 and seen[0] == [False, None]


#: The white level of the simulated gyro [deg/√h]: σ/√rate, σ in deg/s and 60 (deg/√h)/(deg/√s).
N_TRUE = SIGMA_DEG_S * 60.0 / math.sqrt(RATE_HZ)
#: The two dropped blocks of the 2-gap record, [start, stop) sample indices of the full record.
DROPS = ((1500, 1550), (4000, 4200))


def _arw(o) -> tuple[float, float]:
    """(N, its 1σ) [deg/√h] of ``fit --json``'s arw entry."""
    e = {e["effect"]: e for e in json.loads(o.out)["effects"]}["arw"]
    return e["params"]["n_deg_rt_h"], e["sigma"]["n_deg_rt_h"]


@pytest.fixture(scope="module")
def two_gaps(tmp_path_factory):
    """(the 2-gap CSV, the same kept samples concatenated on a uniform clock, samples kept)."""
    rng = np.random.default_rng(33)
    n = 6_000
    t = np.arange(n) / RATE_HZ
    g = rng.normal(0.0, SIGMA_DEG_S, (n, 1)) + 0.01
    keep = np.ones(n, bool)
    for a, b in DROPS:
        keep[a:b] = False
    k = int(keep.sum())
    folder = tmp_path_factory.mktemp("fit_two_gaps")
    path = write_measurement(folder, "gaps2", t[keep], g[keep], sidecar=axes_sidecar(1, RATE_HZ))
    joined = write_measurement(folder, "joined", t[:k], g[keep], sidecar=axes_sidecar(1, RATE_HZ))
    return path, joined, k


def test_the_comparison_cuts_the_record_at_its_gaps(two_gaps):
    """The parts are the contiguous runs (indices of the stitched record), each where it was in
    the measurement [s], and the notes count gaps, missing samples and parts."""
    from gyroarray.chain.compare import ModelComparison
    path, _, k = two_gaps
    comp = ModelComparison(read_measurement(path, gaps=True))
    assert comp.parts == [(0, 1500), (1500, 3950), (3950, 5750)] and comp.n == k == 5750
    # the measurement's own clock: part 2 starts 1 s (50 samples) later, part 3 another 4 s later
    assert np.allclose(comp.parts_s, [(0.0, 30.0), (31.0, 80.0), (84.0, 120.0)], rtol=0, atol=1e-9)
    assert comp.gap_summary() == {"gaps": 2, "missing_samples": 250, "parts": 3, "samples": 5750}
    # the stitched clock is uniform (what the simulator and the fits read)
    assert np.allclose(comp.t, np.arange(k) / RATE_HZ, rtol=0, atol=1e-12)
    notes = comp._record_notes()
    assert any("2 gap(s) in time_s (250 sample(s) missing): fitted on its 3 contiguous part(s)" in x
               for x in notes), notes


def test_jitter_between_the_gaps_is_still_refused():
    """A step of 1.3 periods is neither a gap (over 1.5) nor within the quarter-step jitter."""
    from gyroarray.chain.compare import ModelComparison
    t = np.arange(3000) / RATE_HZ
    t[1000:] += 0.3 / RATE_HZ
    t[2000:] += 3.0 / RATE_HZ                                 # and a real gap
    m = Measurement(time_s=t, gyro_deg_s=np.random.default_rng(4).normal(0.0, SIGMA_DEG_S, (3000, 1)),
                    layout=Layout.from_axes([[0.0, 0.0, 1.0]]), sample_rate_hz=RATE_HZ)
    with pytest.raises(InputError, match="not uniform"):
        ModelComparison(m)


def test_fit_with_two_gaps_gives_the_white_level(two_gaps):
    path, _, k = two_gaps
    o = run_cli(["fit", path, "--gaps", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    n_fit, sigma = _arw(o)
    # white noise: N² estimated from k samples is a χ² of about k degrees of freedom, so
    # σ_N / N = 1/√(2k) = 0.93 % (k = 5750), 0.0040 deg/√h; the fit's own 1σ agrees to 5 %
    sigma_derived = N_TRUE / math.sqrt(2 * k)
    assert sigma == pytest.approx(sigma_derived, rel=0.05)
    # 3σ: a 99.7 % two-sided interval (this record: 0.4149, 2.4σ below 0.4243, as the sample's own
    # standard deviation is: 0.4150)
    assert abs(n_fit - N_TRUE) <= 3.0 * sigma_derived
    res = json.loads(o.out)
    assert any("2 gap(s) in time_s kept as they are (250 sample(s) missing" in x for x in res["notes"])
    # the fit says what it read: 3 contiguous parts of the 5750 samples
    assert res["gaps"] == {"gaps": 2, "missing_samples": 250, "parts": 3, "samples": k}
    assert any("fitted on its 3 contiguous part(s), %d samples" % k in x for x in res["notes"])


@pytest.mark.slow
def test_fit_with_gaps_agrees_with_the_parts_joined(two_gaps):
    """Against the fit of the same samples joined without the gaps (the parts put end to end on a
    uniform clock, one record). Not the same bits, and it should not be: the gaps fit reads no
    Allan average across a join and sets each part's mean to the first's, the joined record reads
    across both joins. The two estimates share every sample; they differ only through the Allan
    clusters that span a join, at averaging m 2·(2m − 1) of about k, a share f = 4m/k; the
    difference of the two readings is about √f of the estimate's σ: 0.1σ at m = 16 (τ = 0.32 s),
    the longest τ the white level weighs much. Asserted within 0.3σ (3 × that); measured
    3e-5 relative, 0.003σ."""
    path, joined, k = two_gaps
    n_gaps, sigma = _arw(run_cli(["fit", path, "--gaps", "--json"]))
    o = run_cli(["fit", joined, "--json"])
    assert o.code == 0, o.err
    n_joined, _ = _arw(o)
    assert abs(n_gaps - n_joined) <= 0.3 * sigma
    assert n_gaps != n_joined                                 # the parts are read as parts


@pytest.mark.slow
def test_fit_with_many_gaps_fits_the_white_noise(gappy):
    """The 1 % random drops: 61 parts of about 100 samples (2 s) each."""
    path, full, dropped = gappy
    o = run_cli(["fit", path, "--gaps", "--json"])
    assert o.code == 0, o.err
    n_fit, _ = _arw(o)
    ref = run_cli(["fit", full, "--json"])
    want, sigma = _arw(ref)
    # the full record's fit: 0.4159 ± 0.0038 (1σ; 1/√(2·6000) of N, derived as above). The gaps fit
    # reads 99 % of the same samples cut into 61 parts; as in the 2-gap case below, the readings
    # differ through the Allan clusters across a join, a share f = 2·(2m − 1)·60/k ≈ 0.63 at m = 16,
    # about √f = 0.8σ: asserted within 2.5σ (3 × that), measured 0.54σ. The full record within 3σ
    # of the truth (99.7 %).
    assert abs(n_fit - want) <= 2.5 * sigma
    assert abs(want - N_TRUE) <= 3.0 * N_TRUE / math.sqrt(2 * 6_000)
