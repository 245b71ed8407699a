"""MDEV, overlapping HDEV and TOTDEV beside OADEV, pooled over parts and across gaps, the lag-1
noise identification and the modified-variance EDF (issue 33, item 5).

Outside checks: allantools (test dependency) to 1e-10 relative, the Stable32 result files and
the NBS14 published values in ../shared/reference/stable32 to their printed digits.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from gyroarray.analysis.allan import confidence_interval, edf_greenhall
from gyroarray.analysis.deviations import (analyse_parts, canonical_kind, contiguous_segments,
                                           edf_of, noise_id_lag1, pooled_deviation)
from gyroarray.core.errors import InputError

at = pytest.importorskip("allantools")
from allantools import ci as at_ci  # noqa: E402  (after the importorskip)

STABLE32 = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "stable32"
needs_shared = pytest.mark.skipif(not STABLE32.is_dir(), reason="../shared/reference not beside the repo")
AT_FN = {"oadev": at.oadev, "mdev": at.mdev, "hdev": at.hdev, "ohdev": at.ohdev, "totdev": at.totdev}
KINDS = tuple(AT_FN)


def _record(n=4000, seed=1):
    rng = np.random.default_rng(seed)
    return rng.normal(size=n) + 0.01 * np.cumsum(rng.normal(size=n)) + 1e-4 * np.arange(n)


def _printed(value: float, printed: str) -> bool:
    """``value`` rounds to ``printed`` (a Stable32 %.4e field): within half its last digit."""
    mant, exp = printed.lower().split("e")
    ulp = 10.0 ** (int(exp) - (len(mant.split(".")[1]) if "." in mant else 0))
    return abs(value - float(printed)) <= 0.5 * ulp * (1 + 1e-9)


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_equals_allantools(kind):
    y, tau0 = _record(), 0.01
    r = pooled_deviation([y], tau0, kind, "octave")
    taus, dev, _, ns = AT_FN[kind](y, rate=1 / tau0, data_type="freq", taus=r.taus_s)
    # allantools leaves out a non-overlapping HDEV of a single term (the last octave); we keep it
    k = taus.size
    assert k >= r.taus_s.size - (kind == "hdev") and np.allclose(taus, r.taus_s[:k], rtol=1e-12)
    assert np.max(np.abs(r.dev[:k] / dev - 1)) < 1e-10
    assert np.array_equal(r.n_terms[:k], ns.astype(int))


def test_hdev_is_the_non_overlapping_hadamard():
    """``hdev`` is Stable32's HDEV (issue 42: it was the overlapping one, 23 % off HDEV)."""
    assert canonical_kind("hdev") == "hdev" and canonical_kind("ohdev") == "ohdev"
    y = _record()
    h = pooled_deviation([y], 1.0, "hdev", [1, 8, 64])
    o = pooled_deviation([y], 1.0, "ohdev", [1, 8, 64])
    assert h.dev[0] == pytest.approx(o.dev[0], rel=1e-12)        # the same at m = 1
    assert h.n_terms[1:].tolist() == [(y.size // m) - 2 for m in (8, 64)]
    assert o.n_terms[1:].tolist() == [y.size + 1 - 3 * m for m in (8, 64)]
    with pytest.raises(InputError, match="unknown deviation kind"):
        canonical_kind("adev2")


def _stable32_rows(path: Path):
    rows = [ln.split() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return [(float(r[1]), int(r[2]), r[5], float(r[4]), float(r[6]), int(r[3])) for r in rows]


@needs_shared
@pytest.mark.parametrize("kind", KINDS)
def test_phase_dat_all_taus_to_stable32_printed_digits(kind):
    x = np.loadtxt(STABLE32 / "phasedat" / "PHASE.DAT", comments="#")
    rows = _stable32_rows(STABLE32 / "phasedat" / f"phase_dat_{kind}.txt")
    r = pooled_deviation([np.diff(x)], 1.0, kind, [t for t, *_ in rows])    # rate = phase steps
    bad = [(t, v, p) for (t, n, p, *_), v in zip(rows, r.dev) if not _printed(v, p)]
    assert not bad, bad[:5]
    assert [n for _, n, *_ in rows] == r.n_terms.tolist()


@lru_cache(maxsize=1)
def _gps_phase() -> np.ndarray:
    return np.loadtxt(STABLE32 / "gps" / "gps_1pps_phase_data.txt.gz", comments="#")


@needs_shared
@pytest.mark.parametrize("kind", KINDS)
def test_gps_octave_to_stable32_printed_digits(kind):
    x = _gps_phase()
    rows = _stable32_rows(STABLE32 / "gps" / f"stable32_{kind.upper()}_octave.txt")
    r = pooled_deviation([np.diff(x)], 1.0, kind, [t for t, *_ in rows])
    bad = [(t, v, p) for (t, n, p, *_), v in zip(rows, r.dev) if not _printed(v, p)]
    assert not bad, bad[:5]


@needs_shared
def test_nbs14_published_values():
    y = np.loadtxt(STABLE32 / "nbs14" / "nbs14_1000pt_frequency.txt", comments="#")
    ref = {}
    for line in (STABLE32 / "nbs14" / "nbs14_reference_deviations.csv").read_text().splitlines()[1:]:
        ds, dev, tau, value, *_ = line.split(",")
        ref[(ds, dev, float(tau))] = value
    for kind, name in (("oadev", "OADEV"), ("mdev", "MDEV"), ("hdev", "HDEV"), ("ohdev", "OHDEV"),
                       ("totdev", "TOTDEV")):
        r = pooled_deviation([y], 1.0, kind, [1.0, 10.0, 100.0])
        for t, v in zip(r.taus_s, r.dev):
            printed = ref[("nbs14_1000pt", name, t)]
            digits = len(printed.replace(".", "").lstrip("0"))
            assert float(f"{v:.{digits}g}") == pytest.approx(float(printed), rel=1e-12), (kind, t, v)


@needs_shared
@pytest.mark.parametrize("kind", ["mdev", "totdev"])
def test_confidence_bounds_beside_stable32(kind):
    """The new kinds' EDF (Greenhall modified / SP 1065 Table 7) reproduce Stable32's 1-sigma bounds."""
    x = np.loadtxt(STABLE32 / "phasedat" / "PHASE.DAT", comments="#")
    rows = _stable32_rows(STABLE32 / "phasedat" / f"phase_dat_{kind}_octave.txt")
    m = np.array([int(round(t)) for t, *_ in rows])
    nu = edf_of(kind, x.size, m, np.array([a for *_, a in rows]))
    lo, hi = confidence_interval(np.array([float(p) for _, _, p, *_ in rows]), nu)
    assert np.allclose(lo, [r[3] for r in rows], rtol=1e-3)
    assert np.allclose(hi, [r[4] for r in rows], rtol=1e-3)


@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_modified_edf_equals_allantools(alpha):
    for m in (1, 3, 10, 40, 200, 320):
        ours = float(edf_greenhall(1001, m, alpha, 2, modified=True))
        ref = at_ci.edf_greenhall(alpha, 2, m, 1001, overlapping=True, modified=True)
        assert ours == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("kind", KINDS)
def test_pooled_parts_equal_weighted_pooling_of_allantools(kind):
    """Per-part mean removed, sums pooled: the count-weighted mean of each part's variance."""
    rng = np.random.default_rng(7)
    parts = [rng.normal(size=n) + rng.normal() * 50 for n in (1500, 700, 2600)]
    tau0 = 0.02
    r = pooled_deviation(parts, tau0, kind, "octave")
    num, den = np.zeros(r.m.size), np.zeros(r.m.size)
    for p in parts:
        taus, dev, _, ns = AT_FN[kind](p, rate=1 / tau0, data_type="freq", taus=r.taus_s)
        idx = np.searchsorted(r.taus_s, taus)
        assert np.allclose(r.taus_s[idx], taus)
        num[idx] += ns * dev ** 2
        den[idx] += ns
    assert np.array_equal(den.astype(int), r.n_terms)
    assert np.max(np.abs(r.dev / np.sqrt(num / den) - 1)) < 1e-10
    # no difference spans a boundary: joining the parts end to end (offsets of 50) gives another curve
    joined = pooled_deviation([np.concatenate(parts)], tau0, kind, r.taus_s)
    assert np.max(np.abs(joined.dev / r.dev - 1)) > 0.1


def test_gaps_split_into_segments_and_pool():
    """A record with dropped packets: contiguous segments, pooled, equal to allantools on each."""
    rng = np.random.default_rng(3)
    n, dt = 5000, 0.01
    keep = np.ones(n, bool)
    keep[[1200, 1201, 1202, 3100]] = False            # 2 gaps, 4 samples missing
    t = np.arange(n)[keep] * dt
    y = rng.normal(size=n)[keep]
    segments, missing = contiguous_segments(t, dt)
    assert segments == [(0, 1200), (1200, 3097), (3097, 4996)] and missing == 4
    r = pooled_deviation([y[a:b] for a, b in segments], dt, "oadev", "octave")
    num, den = np.zeros(r.m.size), np.zeros(r.m.size)
    for a, b in segments:
        taus, dev, _, ns = at.oadev(y[a:b], rate=1 / dt, data_type="freq", taus=r.taus_s)
        idx = np.searchsorted(r.taus_s, taus)
        num[idx] += ns * dev ** 2
        den[idx] += ns
    assert np.max(np.abs(r.dev / np.sqrt(num / den) - 1)) < 1e-10
    assert contiguous_segments(np.arange(10) * dt) == ([(0, 10)], 0)


@pytest.mark.parametrize("dmax", [2, 3])
def test_lag1_noise_id_equals_allantools(dmax):
    rng = np.random.default_rng(11)
    w = rng.normal(size=20000)
    for y in (w, np.cumsum(w), np.diff(w), w + 0.03 * np.cumsum(rng.normal(size=w.size))):
        for m in (1, 4, 32, 256):
            ours = noise_id_lag1([y], m, dmax=dmax)
            a_int, a, d, rho = at_ci.autocorr_noise_id(y, m, data_type="freq", dmax=dmax)
            assert (ours["alpha"], ours["d"]) == (a_int, d)
            assert ours["rho"] == pytest.approx(rho, rel=1e-9, abs=1e-12)
            assert ours["alpha_float"] == pytest.approx(a, rel=1e-9, abs=1e-12)
    assert noise_id_lag1([w[:100]], 8) is None             # 12 blocks: too few to tell


def test_lag1_noise_id_names_the_power_laws():
    rng = np.random.default_rng(5)
    w = rng.normal(size=40000)
    assert noise_id_lag1([w], 16)["alpha"] == 0                 # white FM (ARW)
    assert noise_id_lag1([np.cumsum(w)], 16)["alpha"] == -2     # random-walk FM (RRW)
    assert noise_id_lag1([np.diff(w)], 1)["alpha"] == 2         # white PM (quantization-like)


@pytest.mark.parametrize("kind", ["mdev", "ohdev", "totdev"])
def test_analyse_parts_reports_noise_id_and_edf_formula(kind):
    rng = np.random.default_rng(2)
    arw = 1e-3
    parts = [arw / np.sqrt(0.01) * rng.normal(size=n) for n in (20000, 9000)]
    a = analyse_parts(parts, 0.01, "octave", kind)
    d = a.to_json_dict()
    assert d["kind"] == kind and d["parts"] == 2
    assert "Greenhall" in d["edf_method"] or "SP 1065" in d["edf_method"]
    assert d["fit_from"] == ("ohdev" if kind == "ohdev" else "oadev")
    assert len(d["noise_id"]) == len(d["taus_s"])
    ids = [n["alpha"] for n in d["noise_id"][:6]]
    assert ids == [0] * 6, ids                                  # white FM at short tau
    assert np.all(np.asarray(d["ci_low_deg_h"]) < np.asarray(d["adev_deg_h"]))
    assert a.fit.coefficient("n")[0] == pytest.approx(arw, rel=0.05)
