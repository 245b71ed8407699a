"""Hostile inputs for ``gyroarray fdi`` (issue 28): native aborts, unbounded windows,
degenerate arrays, extreme arguments.

Each reproduction of the issue is one test. Cases that once aborted the
process (``free(): double free`` from NNLS on an empty system) or needed
gigabytes run in a child process, so a regression fails the test instead of
killing the session; the 1 MHz case runs under an address-space limit.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from hostile import assert_contract, axes_sidecar, finite_numbers, run_cli, write_measurement

DT = 0.02
N = 3000
GIB = 2 ** 30


def _axes(n_gyros: int) -> np.ndarray:
    """The axes of :func:`hostile.axes_sidecar` (one elevation: identical gyros are consistent)."""
    a = 2 * np.pi * np.arange(n_gyros) / n_gyros
    return np.c_[0.8 * np.cos(a), 0.8 * np.sin(a), np.full(n_gyros, 0.6)]


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile_fdi")
    rng = np.random.default_rng(28)
    side = axes_sidecar(4)
    for n in (2, 3, 5, 7, 32, 33):
        write_measurement(folder, f"n{n}", np.arange(n) * DT, rng.normal(0, 0.05, (n, 4)), sidecar=side)
    t = np.arange(N) * DT
    write_measurement(folder, "healthy", t, rng.normal(0, 0.05, (N, 4)), sidecar=side)
    one = rng.normal(0, 0.05, N)
    write_measurement(folder, "identical", t, np.repeat(one[:, None], 4, axis=1), sidecar=side)
    write_measurement(folder, "constant", t, np.full((N, 4), 0.1), sidecar=side)
    w = np.c_[np.sin(t), np.cos(0.3 * t), 0.1 * t]                 # a moving body, no noise
    write_measurement(folder, "consistent", t, w @ _axes(4).T, sidecar=side)
    late = rng.normal(0, 0.05, (N, 4))
    late[:1000] = 0.1                # 10 Hz: the reference span is the first 750 samples, noise-free
    write_measurement(folder, "late_noise", np.arange(N) * 0.1, late, sidecar=axes_sidecar(4, 10.0))
    quant = np.where(rng.random((N, 4)) < 0.1, 0.061, 0.0)         # 1 LSB, noise below it
    write_measurement(folder, "quantised", t, quant, sidecar=side)
    fast = 20000
    write_measurement(folder, "fast_1mhz", np.arange(fast) * 1e-6, rng.normal(0, 0.05, (fast, 4)),
                      sidecar=axes_sidecar(4, 1e6))
    (folder / "model.toml").write_text('effects = [{effect = "arw", n_deg_rt_h = 0.1}, '
                                       '{effect = "rrw", k_deg_h_rt_h = 600.0}]\n')
    (folder / "tiny_arw.toml").write_text('effects = [{effect = "arw", n_deg_rt_h = 1e-300}]\n')
    return folder


def _child(argv, *, limit_bytes: int | None = None, timeout: float = 300.0):
    """``gyroarray.cli.main.main(argv)`` in a child Python (optionally under RLIMIT_AS)."""
    code = ("import sys; from gyroarray.cli.main import main; "
            f"sys.exit(main({[str(a) for a in argv]!r}))")

    def limit():
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    env = dict(os.environ, GYROARRAY_MAX_MEMORY=str(limit_bytes or 2 * GIB))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=timeout, preexec_fn=limit, env=env)


def _python(snippet: str, timeout: float = 120.0):
    """A snippet in a child Python: a native abort there is a failed test, not a dead session."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(snippet)], capture_output=True,
                          text=True, timeout=timeout)


def ok(o, name=None):
    assert_contract(o, name)
    assert o.code == 0, o.err
    out = o.json
    assert finite_numbers({k: v for k, v in out.items() if k != "minimum_detectable"})
    return out


def refused(o, name, *fragments):
    assert_contract(o, name)
    assert o.code == 2, o.out[:300]
    for f in fragments:
        assert f in o.err, o.err
    return o.err


# -- 1. no native abort: the minimum record length, refused up front ------------------------

@pytest.mark.parametrize("n", [2, 3, 5, 7])
def test_records_of_2_to_7_samples_are_refused_not_aborted(d, n):
    p = _child(["fdi", d / f"n{n}.csv"], timeout=120)
    assert p.returncode == 2, (p.returncode, p.stderr[-500:])         # was 134: double free
    line, = p.stderr.strip().splitlines()
    assert line.startswith(f"gyroarray: {d / f'n{n}.csv'}: ") and "at least 33 samples" in line
    assert f"the record has {n}" in line


def test_32_samples_refused_33_analysed(d):
    refused(run_cli(["fdi", d / "n32.csv"]), "n32.csv", "at least 33 samples")
    out = ok(run_cli(["fdi", d / "n33.csv", "--json"]))
    assert out["alarms"] == []


def test_minimum_length_holds_with_a_model_too(d):
    refused(run_cli(["fdi", d / "n7.csv", "--model", d / "model.toml"]), "n7.csv", "at least 33")


def test_native_calls_on_empty_systems_are_guarded():
    p = _python("""
        import numpy as np
        from gyroarray.analysis.noise_fit import whitened_nnls
        from gyroarray.analysis.psd_fit import _linear_ml
        from gyroarray.core.errors import InputError
        from gyroarray.estimators.fdi import _white_and_walk
        ident = lambda v: v
        a, x = whitened_nnls(np.zeros((0, 3)), np.zeros(0), ident)
        assert a.shape == (3,) and not a.any(), a
        a, x = whitened_nnls(np.zeros((4, 0)), np.ones(4), ident)
        assert a.shape == (0,), a
        g = np.c_[np.ones(4), np.zeros(4)]                      # one term never contributes
        a, _ = whitened_nnls(g, 2 * np.ones(4), ident)
        assert np.allclose(a, [2.0, 0.0]), a
        c, ll = _linear_ml(np.zeros(0), np.zeros((0, 2)), 10.0)
        assert c.shape == (2,) and ll == 0.0, (c, ll)
        c, ll = _linear_ml(np.ones(5), np.zeros((5, 0)), 10.0)
        assert c.shape == (0,) and np.isfinite(ll), (c, ll)
        assert _white_and_walk(np.zeros(64)) == (0.0, 0.0)
        try:
            _white_and_walk(np.ones(7))
        except InputError as err:
            assert "at least 16 samples" in str(err), err
        else:
            raise AssertionError("7 samples fitted")
        print("guarded")
    """)
    assert p.returncode == 0 and "guarded" in p.stdout, (p.returncode, p.stderr[-800:])


def test_nnls_guards_leave_valid_fits_unchanged():
    from scipy.optimize import nnls

    from gyroarray.analysis.noise_fit import whitened_nnls
    rng = np.random.default_rng(3)
    g = rng.random((12, 3)) + 0.1
    y = g @ np.array([1.0, 0.0, 2.5]) + 0.01 * rng.standard_normal(12)
    scale = np.linalg.norm(g, axis=0)
    want = nnls(g / scale, y)[0] / scale
    got, _ = whitened_nnls(g, y, lambda v: v)
    assert np.array_equal(got, want)


# -- 2. windows bounded in samples and by the record; memory checked before work -------------

def test_1mhz_record_runs_within_2_gib(d):
    p = _child(["fdi", d / "fast_1mhz.csv", "--json"], limit_bytes=2 * GIB, timeout=300)
    assert p.returncode == 0, (p.returncode, p.stderr[-800:])    # was 9.3 GB, then MemoryError
    out = json.loads(p.stdout)
    assert out["alarms"] == []
    drift = [n for n in out["notes"] if "drift within" in n]
    assert drift and float(drift[0].split("drift within ")[1].split(" s")[0]) <= 0.02   # the record


def test_window_lengths_are_capped_in_samples():
    from gyroarray.estimators.fdi import MAX_WINDOW_SAMPLES, design_parity
    from gyroarray.estimators.noise import ArrayNoise
    eye = np.eye(5)
    noise = ArrayNoise(np.full(5, 1e-4), np.full(5, 1e-6), eye, eye)
    H = _axes(5)
    des = design_parity(H, noise, 1e-6)                           # 600 s at 1 MHz: 6e8 samples
    assert max(max(v) for v in des.scales.values()) <= MAX_WINDOW_SAMPLES
    slow = design_parity(H, noise, 0.01)                          # 100 Hz: 600 s fits, unchanged
    assert slow.scales["drift"][-1] == 32768 and slow.scales["variance"][-1] == 2048


def test_fdi_over_the_memory_budget_is_refused_before_work(d):
    err = refused(run_cli(["fdi", d / "healthy.csv", "--max-memory", "2M"]), "healthy.csv",
                  "fault detection on 3000 samples x 4 gyros", "--max-memory")
    assert "split the record" in err


# -- 3. degenerate arrays: no fault (the parity is zero: no single-gyro fault exists) ---------

@pytest.mark.parametrize("case", ["identical", "constant", "consistent"])
def test_noise_free_consistent_arrays_have_no_fault(d, case):
    out = ok(run_cli(["fdi", d / f"{case}.csv", "--json"]))
    assert out["alarms"] == []                                    # was a "noise" alarm
    assert any("exactly consistent" in n for n in out["notes"])
    assert all(v["step_deg_s"] is None for v in out["minimum_detectable"].values())


@pytest.mark.parametrize("case", ["identical", "constant", "consistent"])
def test_noise_free_consistent_arrays_have_no_fault_with_a_model(d, case):
    out = ok(run_cli(["fdi", d / f"{case}.csv", "--model", d / "model.toml", "--json"]))
    assert out["alarms"] == []
    md = out["minimum_detectable"]["1"]
    assert md["step_deg_s"] is not None and md["step_deg_s"] > 0


def test_noise_free_record_plots(d, tmp_path):
    png = tmp_path / "id.png"
    o = run_cli(["fdi", d / "identical.csv", "--plot", png])
    assert_contract(o)
    assert o.code == 0 and png.stat().st_size > 1000


def test_noise_free_reference_span_without_model_is_refused(d):
    refused(run_cli(["fdi", d / "late_noise.csv"]), "late_noise.csv", "no noise", "--model")


def test_quantised_outputs_are_not_a_fault(d):
    out = ok(run_cli(["fdi", d / "quantised.csv", "--json"]))       # was a noise ratio of 1e7
    assert out["alarms"] == []


def test_healthy_record_still_has_no_fault(d):
    out = ok(run_cli(["fdi", d / "healthy.csv", "--json"]))
    assert out["alarms"] == [] and not any("exactly consistent" in n for n in out["notes"])


# -- 4. extreme arguments: one line naming the argument and its range ------------------------

@pytest.mark.parametrize("value", ["1e-300", "1e-13", "1e300", "1801", "0", "-1", "-0.0"])
def test_far_per_h_out_of_range_is_one_line_with_the_range(d, value):
    err = refused(run_cli(["fdi", d / "healthy.csv", f"--far-per-h={value}"]), "--far-per-h")
    assert "1e-12" in err and "1800" in err, err                 # 1% of 180000 samples/h


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_far_per_h_not_finite(d, value):
    refused(run_cli(["fdi", d / "healthy.csv", f"--far-per-h={value}"]), "--far-per-h", "finite")


@pytest.mark.parametrize("value", ["1e-12", "1800"])
def test_far_per_h_at_the_ends_of_its_range_answers(d, value):
    out = ok(run_cli(["fdi", d / "healthy.csv", f"--far-per-h={value}", "--json"]))
    assert out["far_per_h"] == float(value)


def test_model_with_an_unrepresentable_arw_names_the_model(d):
    refused(run_cli(["fdi", d / "healthy.csv", "--model", d / "tiny_arw.toml"]), "tiny_arw.toml",
            "not positive definite")


def test_detector_refuses_an_impossible_rate_outside_the_cli():
    from gyroarray.core.errors import InputError
    from gyroarray.estimators.fdi import FaultDetector
    from gyroarray.core.layout import Layout
    from gyroarray.effects.model import NoiseModel
    lay = Layout.from_axes(_axes(5))
    m = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": 0.1}]})
    for far in (1e-300, 1e300):
        with pytest.raises(InputError, match="far_per_h must be between"):
            FaultDetector(far_per_h=far).fit(lay, m, 0.01)
    assert math.isfinite(FaultDetector(far_per_h=1e-12).fit(lay, m, 0.01).thresholds_["step"])
