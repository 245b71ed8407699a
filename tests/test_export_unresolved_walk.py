"""Issue 42 on real bags: a walk the record did not resolve, and a file the record's band refuses.

robot_localization's ``test1.bag`` (a Husky, 395 s, 138 s still) is too short for ``fit`` to
resolve any gyro's rate random walk: the model holds K = 0 with a 1σ beside it (5573, 3133 and
10867 deg/h/√h). Every consumer needs a walk > 0: Kalibr's reader refuses 0, the others freeze
the bias at its first value. So the export writes the walk's one-sided 95 % upper bound, K =
1.645σ (:data:`gyroarray.chain.export.WALK_BOUND_Z`), says so in the header and the JSON, and a
model whose zero walk has no σ (typed by hand) is refused as before. The accelerometer's terms
that no axis resolved take the same bound.

On the same bag the accelerometer's short-τ ADEV (vibration on the still parts) lies above its
white line, so ``--verify --record`` fails there; it then says the smallest ``--inflate`` that
lifts the file to the record's ADEV at every failing τ, and with that factor the same check
passes (the file then lies at or above the measured ADEV, so at or above its lower band edge:
deterministic, whatever the record's draw).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gyroarray.chain import export as ex
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement
from gyroarray.effects.model import AccelNoise, NoiseModel
from hostile import run_cli

RATE_HZ = 100.0
SIGMA_K = 5573.473157891089          # test1.bag gyro 1's fitted 1σ of K [deg/h/√h], K held at 0

UNRESOLVED = ('effects = [{effect = "arw", n_deg_rt_h = 22.84}, '
              f'{{effect = "rrw", k_deg_h_rt_h = 0.0, sigma = {{k_deg_h_rt_h = {SIGMA_K}}}}}]\n')
NO_SIGMA = 'effects = [{effect = "arw", n_deg_rt_h = 22.84}, {effect = "rrw", k_deg_h_rt_h = 0.0}]\n'
ACCEL = AccelNoise(axes=("x", "y", "z"), n_m_s_rt_h=(1.9, 0.44, 3.3),
                   unresolved={"k_m_s2_rt_h": {"x": {"estimate": 0.0, "sigma": 0.5},
                                               "y": {"estimate": 0.0, "sigma": 0.43},
                                               "z": {"estimate": 0.1, "sigma": 3.76}}}, record_s=137.9)


def _model(tmp_path, effects: str, accel: AccelNoise | None = ACCEL, name: str = "m.toml"):
    path = tmp_path / name
    path.write_text('description = "test"\n' + effects)
    model = NoiseModel.from_toml(path)
    if accel is not None:
        path.write_text(NoiseModel(model.entries, description="test", accelerometer=accel).to_toml())
        model = NoiseModel.from_toml(path)
    return model, path


@pytest.mark.parametrize("fmt", ex.FORMATS)
def test_an_unresolved_gyro_walk_is_written_as_its_95_percent_upper_bound(tmp_path, fmt):
    model, _ = _model(tmp_path, UNRESOLVED)
    exp = ex.build_export(model, "worst", fmt, RATE_HZ)
    k_si = units.rrw_deg_h_rt_h_to_rad_s_rt_s(SIGMA_K)
    assert exp.noise.walk_is_bound
    assert math.isclose(exp.noise.k_rad_s_rt_s, 1.6448536269514722 * k_si, rel_tol=1e-12)
    w = exp.summary["walk"]
    assert w["upper_bound"] is True and math.isclose(w["fit_sigma_deg_h_rt_h"], SIGMA_K, rel_tol=1e-9)
    assert math.isclose(w["k_deg_h_rt_h"], 1.6448536269514722 * SIGMA_K, rel_tol=1e-9)
    assert "walk: NOT RESOLVED" in exp.text and "one-sided 95 % upper bound" in exp.text
    rb = ex.read_back(exp.text, fmt, RATE_HZ)         # the consumer's parser rules: no problem now
    assert rb.problems == ()
    assert math.isclose(rb.si["gyro_k"], 1.6448536269514722 * k_si, rel_tol=ex.READ_BACK_RTOL)
    # the accelerometer's walk, resolved on no axis: each axis's bound, the worst of them (z's)
    assert math.isclose(exp.accel.k_m_s3_rt_hz,
                        units.accel_rw_m_s2_rt_h_to_si(0.1 + 1.6448536269514722 * 3.76), rel_tol=1e-12)
    assert "NOT RESOLVED on any axis" in exp.accel.partial["k_m_s2_rt_h"]
    assert exp.summary["missing_fields"] == []


def test_a_zero_walk_without_a_sigma_is_still_refused_or_failed(tmp_path):
    model, _ = _model(tmp_path, NO_SIGMA)
    with pytest.raises(InputError, match="gyroscope_random_walk of 0 is refused by Kalibr's reader"):
        ex.build_export(model, "worst", "kalibr", RATE_HZ)
    exp = ex.build_export(model, "worst", "vins", RATE_HZ)
    assert not exp.noise.walk_is_bound and exp.summary["walk"]["upper_bound"] is False
    rb = ex.read_back(exp.text, "vins", RATE_HZ)
    assert any("a walk <= 0" in p for p in rb.problems)


def test_a_resolved_walk_is_the_estimate(tmp_path):
    model, _ = _model(tmp_path, 'effects = [{effect = "arw", n_deg_rt_h = 1.0}, '
                                '{effect = "rrw", k_deg_h_rt_h = 40.0, sigma = {k_deg_h_rt_h = 5.0}}]\n')
    exp = ex.build_export(model, "worst", "kalibr", RATE_HZ)
    assert not exp.noise.walk_is_bound
    assert math.isclose(exp.noise.k_rad_s_rt_s, units.rrw_deg_h_rt_h_to_rad_s_rt_s(40.0), rel_tol=1e-12)
    assert "# walk: NOT RESOLVED" not in exp.text


def test_verify_names_the_inflation_that_lifts_the_file_to_the_record_and_it_then_passes(tmp_path):
    # a numpy record whose white noise is twice the model's (N 2 against 1 deg/√h; walk 0.5 deg/h/√h
    # both): the file is below the record's band at the short τ, by about 0.5×
    rng = np.random.default_rng(7)
    n, dt = 60_000, 1.0 / RATE_HZ
    n_si = units.arw_deg_rt_h_to_rad_rt_s(2.0)
    gyro = np.degrees(n_si / math.sqrt(dt) * rng.standard_normal((n, 3)))
    # the accelerometer: white at 0.3 m/s/√h in the record, 1 m/s/√h (and a walk) in the model: the
    # file is above the record's band there at every τ, so only the gyro fails
    acc = units.vrw_m_s_rt_h_to_si(0.3) / math.sqrt(dt) * rng.standard_normal((n, 3)) + [0.0, 0.0, 9.80665]
    rec = Measurement(time_s=np.arange(n) * dt, gyro_deg_s=gyro, layout=Layout(np.eye(3)), sample_rate_hz=RATE_HZ,
                      acc_m_s2=acc)
    csv, _ = write_measurement(rec, tmp_path / "rec.csv")
    _, path = _model(tmp_path, 'effects = [{effect = "arw", n_deg_rt_h = 1.0}, {effect = "rrw", k_deg_h_rt_h = 0.5}]\n',
                     accel=AccelNoise(axes=("x", "y", "z"), n_m_s_rt_h=(1.0,) * 3, k_m_s2_rt_h=(0.1,) * 3))
    argv = ["export", path, "--format", "vins", "--rate-hz", RATE_HZ, "--out", tmp_path / "v.yaml",
            "--verify", "--record", csv, "--gyro", 1, "--force"]
    o = run_cli(argv + ["--json"], timeout=300)
    assert "Traceback" not in o.err and o.code == 1, (o.code, o.err)     # 1: verify failed
    need = json.loads(o.out)["verify"]["record"]["inflate_needed"]
    # 1 / the smallest file/measured ratio: about 2 (the record's N over the file's), within the
    # scatter of the shortest-τ ADEV points over 10 min (a few %)
    assert 1.8 < need < 2.3, need
    o = run_cli(argv, timeout=300)
    assert f"an --inflate that lifts the file to the record's ADEV at every failing τ: {need:.3g}" in o.out
    o = run_cli(argv + ["--inflate", repr(need * (1 + 1e-5)), "--json"], timeout=300)
    assert o.code == 0, o.out[-2000:]
    assert json.loads(o.out)["verify"]["passed"] is True
