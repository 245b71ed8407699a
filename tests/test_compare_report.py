"""gyroarray compare report: the ladder's numbers on the page, self-contained HTML, a browser renders it.

One simulated measurement for the module (4 gyros, 100 Hz, 8 min: 4 min
static, then swings of 20 deg/s about z (0.2 Hz) and x (0.13 Hz), a 5 °C
temperature ramp; ARW 0.2 deg/√h and RRW 5 deg/h/√h on every gyro, a
3000 ppm scale-factor error on gyro 2), laddered once with 10 Monte-Carlo
runs; a static record without reference rate for the no-reference report.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import signal

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement
from gyroarray.reports.browser import find_chromium, render_check
from gyroarray.chain.compare_figures import binned, fitted_bias, model_asd_deg_h, Regressors
from gyroarray.reports.compare_report import write_compare_report
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, deg_s_to_rad_s, rad_s_to_deg_h, rad_s_to_deg_s

N_GYROS = 4
RATE_HZ = 100.0
SF_PPM = 3000.0
ARW = 0.2            # deg/√h
RRW = 5.0            # deg/h/√h


def _measurement(static_s: float, moving_s: float, *, ref: bool = True, seed: int = 3) -> Measurement:
    dt = 1.0 / RATE_HZ
    n = int(round((static_s + moving_s) / dt))
    t = np.arange(n) * dt
    w = np.zeros((n, 3))
    mv = t >= static_s
    w[mv, 2] = deg_s_to_rad_s(20.0) * np.sin(2 * math.pi * 0.2 * (t[mv] - static_s))
    w[mv, 0] = deg_s_to_rad_s(20.0) * np.sin(2 * math.pi * 0.13 * (t[mv] - static_s))
    temp = 25.0 + 5.0 * t / t[-1]
    layout = Layout.conical(1, N_GYROS, math.radians(54.7356))
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": ARW}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": RRW}),
                        ModelEntry("scale_factor", 2, {"ppm": SF_PPM})))
    y = simulate_readings(model, w, layout, dt, np.random.default_rng(seed), time_s=t, temp_c=temp)
    return Measurement(time_s=t, gyro_deg_s=rad_s_to_deg_s(y), layout=layout, sample_rate_hz=RATE_HZ,
                       ref_deg_s=rad_s_to_deg_s(w) if ref else None, temp_c=temp,
                       description="simulated for the report test")


@pytest.fixture(scope="module")
def ladder():
    comp = ModelComparison(_measurement(240.0, 240.0), n_runs=10)
    return comp, comp.ladder()


@pytest.fixture(scope="module")
def written(ladder, tmp_path_factory):
    comp, steps = ladder
    root = tmp_path_factory.mktemp("compare_report")
    res = write_compare_report(comp, steps, root / "c.html", root / "c.md")
    return root, res


@pytest.fixture(scope="module")
def noref(tmp_path_factory):
    comp = ModelComparison(_measurement(120.0, 0.0, ref=False), n_runs=10)
    a = comp.analyse()
    root = tmp_path_factory.mktemp("compare_report_noref")
    res = write_compare_report(comp, [(None, a)], root / "n.html")
    return comp, a, root, res


def test_ladder_finds_the_scale_factor(ladder):
    # the premise of the page: start inconsistent, one step (scale_factor on gyro 2) to consistent
    _, steps = ladder
    assert [s[0] for s in steps] == [None, ("scale_factor", 2)]
    assert steps[0][1].discrepancy > 5 and steps[-1][1].consistent


def test_report_shows_the_numbers_of_every_step(ladder, written):
    _, steps = ladder
    root, res = written
    text = (root / "c.html").read_text()
    assert res["discrepancy"] == [a.discrepancy for _, a in steps]
    assert [s["added"] for s in res["steps"]] == [None, ["scale_factor", 2]]
    final = steps[-1][1].discrepancy
    # headline: the big number of the final step, and where the ladder started
    assert re.search(rf'class="big ok">D = {final:.3g}</div>', text)
    assert f"Started at D = {steps[0][1].discrepancy:.3g}" in text
    assert "consistent with the model: yes" in text
    # the ladder table: one row per step, scale_factor on gyro 2 in the second
    for i, (_, a) in enumerate(steps):
        assert re.search(rf"<tr[^>]*><td>{i}</td><td>[^<]*</td><td>[^<]*</td><td>{a.discrepancy:.3g}</td>",
                         text), i
    assert re.search(r"<tr><td>1</td><td>scale_factor</td><td>2</td><td>[0-9.]+</td><td>yes</td></tr>", text)
    assert 'class="flag"><td>0</td><td>start</td>' in text          # the inconsistent start is red
    assert "Nothing left unexplained" in text


def test_report_effects_table_has_the_fitted_values(written):
    root, _ = written
    md = (root / "c.md").read_text()
    m = re.search(r"\| scale_factor \| 2 \| ppm \| ([-0-9.]+) ± ([0-9.e+-]+) \| ppm \|", md)
    assert m, md
    v, s = float(m.group(1)), float(m.group(2))
    # the simulated 3000 ppm within 5σ of the fit (σ ≈ 26 ppm for 4 min of 20 deg/s swings)
    assert 0 < s < 100 and abs(v - SF_PPM) < 5 * s
    arw = [float(x) for x in re.findall(r"^\| \d \| ([0-9.]+) ± [0-9.e+-]+ \| ", md, re.MULTILINE)]
    # 8 min of 100 Hz: σ(N)/N ≈ 0.3 %; 5 % allows for the static-part-only calibration
    assert len(arw) == N_GYROS and np.allclose(arw, ARW, rtol=0.05)


def test_report_files_are_self_contained(written):
    root, res = written
    text = (root / "c.html").read_text()
    srcs = re.findall(r'<img src="([^"]+)"', text)
    # ladder, ADEV first + final, per-gyro regressors, PSD, cross-correlation, ARW track
    assert res["figures"] == len(srcs) == N_GYROS + 6
    assert res["figure_names"] == (["ladder", "adev_first"] + [f"regressors_g{g}" for g in range(1, 5)]
                                   + ["psd", "xcorr", "arw_track", "adev_final"])
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r"https?://", text) and not re.search(r'(src|href)="//', text)
    assert "<script" not in text.lower()
    assert res["html_bytes"] == (root / "c.html").stat().st_size < 8e6
    md = (root / "c.md").read_text()
    figs = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(figs) == res["figures"] and all((root / f).is_file() for f in figs)
    assert all((root / f).read_bytes()[:4] == b"\x89PNG" for f in figs)
    assert all(f.startswith("c_figures/") for f in figs)
    assert "| step | effect added | gyro | discrepancy D | consistent |" in md


@pytest.mark.skipif(find_chromium() is None, reason="chromium not installed: apt-get install chromium")
def test_report_renders_in_chromium(written):
    root, res = written
    check = render_check(root / "c.html")
    assert check.ok, check.summary()
    assert check.images_total == check.images_loaded == res["figures"]
    assert check.console_errors == [] and check.network_requests == []


def test_no_reference_report_has_no_rate_panels(noref):
    comp, a, root, res = noref
    assert Regressors(comp, a).keys == ["temp", "time"]
    text = (root / "n.html").read_text()
    # one step: no ladder, no second ADEV figure; one regressor figure per gyro
    assert res["figure_names"] == (["adev_first"] + [f"regressors_g{g}" for g in range(1, 5)]
                                   + ["psd", "xcorr", "arw_track"])
    assert len(re.findall(r'<img src="data:image/png;base64,', text)) == res["figures"] == 8
    assert "The error falling" not in text and "rate about its axis" not in text
    assert "No reference rate: the rate panels are left out." in text
    assert res["markdown"] is None
    assert f"D = {a.discrepancy:.3g}" in text


@pytest.mark.skipif(find_chromium() is None, reason="chromium not installed: apt-get install chromium")
def test_no_reference_report_renders_in_chromium(noref):
    _, _, root, res = noref
    check = render_check(root / "n.html")
    assert check.ok, check.summary()
    assert check.images_loaded == res["figures"]


def test_bad_arguments_are_refused(ladder, noref, tmp_path):
    comp, steps = ladder
    with pytest.raises(InputError, match="must end in .html"):
        write_compare_report(comp, steps, tmp_path / "r.pdf")
    with pytest.raises(InputError, match="must end in .md"):
        write_compare_report(comp, steps, tmp_path / "r.html", tmp_path / "r.txt")
    with pytest.raises(InputError, match="non-empty list"):
        write_compare_report(comp, [], tmp_path / "r.html")
    with pytest.raises(InputError, match="another measurement"):
        write_compare_report(comp, [(None, noref[1])], tmp_path / "r.html")
    with pytest.raises(TypeError):
        write_compare_report(comp, steps, tmp_path / "r.html", titel="x")   # unknown keyword
    assert not (tmp_path / "r.html").exists()


def test_fitted_bias_and_binning():
    # a bias linear in time on static samples is recovered exactly between the first and
    # last block centres (block means of a line sit on the line); moving samples are skipped
    dt = 0.01
    t = np.arange(30000) * dt
    static = (t < 100) | (t >= 200)
    E = np.column_stack([1e-5 * t, -2e-5 * t + 1e-4])
    E[~static] += 1.0                                     # what a dynamic part would add
    b = fitted_bias(E, t, static)
    inside = (t >= 15) & (t <= 284.99)          # first and last block centres: 14.995, 284.995 s
    assert np.allclose(b[inside, 0], 1e-5 * t[inside], rtol=0, atol=1e-12)
    assert np.allclose(b[inside, 1], -2e-5 * t[inside] + 1e-4, rtol=0, atol=1e-12)
    # binned means of y = 2x + white noise: slope 2, standard errors σ/√count
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, 200000)
    y = 2 * x + rng.normal(0, 0.5, x.size)
    xc, m, se = binned(x, y)
    assert xc.size == 24
    assert np.allclose(m, 2 * xc, atol=5 * se.max())
    assert np.allclose(se, 0.5 / np.sqrt(x.size * 0.99 / 24), rtol=0.1)


def test_model_white_level_matches_welch():
    # the ARW line of the spectrum panel against scipy's Welch estimate of simulated white noise:
    # 2^17 samples, nperseg 4096 (64 averages × 2049 bins): the mean over bins is within 0.5 %
    n_deg_rt_h, dt = 0.2, 0.01
    sigma = arw_deg_rt_h_to_rad_rt_s(n_deg_rt_h) / math.sqrt(dt)
    x = np.random.default_rng(1).normal(0, sigma, 2 ** 17)
    _, p = signal.welch(x, fs=1 / dt, nperseg=4096)
    level = rad_s_to_deg_h(math.sqrt(np.mean(p[1:-1])))
    assert model_asd_deg_h(np.array([1.0]), n_deg_rt_h, 0.0)[0] == pytest.approx(level, rel=0.01)
    assert model_asd_deg_h(np.array([1.0]), n_deg_rt_h, 0.0)[0] == pytest.approx(
        math.sqrt(2) * 60 * n_deg_rt_h, rel=1e-12)
