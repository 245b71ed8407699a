"""A fitted model tested on new data: ``compare --validate`` and ``ladder --holdout``.

Monday's model, Tuesday's run: every parameter of the model stays fixed, only
the starting biases belong to the new record. A model fitted on one record of
a sensor predicts another record of the same sensor (consistent), and not one
of a sensor whose scale factor differs (the prediction error of the scale
factor is the worst test). Outside truth: the sensors are set, so the answer
is known; the held-out record never saw the fit.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gyroarray.cli import main
from gyroarray.compare import ModelComparison, split_measurement
from gyroarray.errors import InputError
from gyroarray.layout import Layout
from gyroarray.measurement import write_measurement
from gyroarray.sim.lab import lab_run
from gyroarray.sim.model import ModelEntry, NoiseModel

LAYOUT = Layout.conical(1, 5, math.radians(54.7356))


def _sensor(ppm, seed):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("scale_factor", 2, {"ppm": ppm})))
    return lab_run(model, LAYOUT, np.random.default_rng(seed), static_s=300.0, motion_s=240.0, tail_s=60.0)


@pytest.fixture(scope="module")
def monday():
    """The model fitted on Monday's run (scale factor 3000 ppm on gyro 2)."""
    _, after = ModelComparison(_sensor(3000.0, 1), n_runs=10).fit([("scale_factor", 2)])
    return NoiseModel(after.model.entries, description="fitted on Monday's run")


def test_the_same_sensor_is_predicted(monday):
    a = ModelComparison(_sensor(3000.0, 2), monday, n_runs=20).validate()
    assert a.consistent, [(t.effect, t.gyro, round(t.z, 1)) for t in a.tests if a.significant(t)]
    assert a.notes[0].startswith("validation: every parameter")
    assert a.model.entries == monday.entries                 # nothing refitted


def test_another_scale_factor_is_not_and_says_where(monday):
    a = ModelComparison(_sensor(4500.0, 3), monday, n_runs=20).validate()
    assert not a.consistent
    top = a.candidates[0]
    assert (top.effect, top.gyro) == ("scale_factor", 2)
    assert top.evidence.startswith("prediction error of the model's")
    # the error is the difference: 1500 ppm, within its 2σ or 10 %
    got, s = top.fit.params["ppm"], top.fit.sigma["ppm"]
    assert abs(got - 1500.0) <= max(2 * s, 150.0)


def test_validate_refuses_a_model_without_its_baseline():
    m = _sensor(3000.0, 2)
    with pytest.raises(InputError, match="needs a fitted model"):
        ModelComparison(m, NoiseModel((ModelEntry("scale_factor", 2, {"ppm": 3000.0}),)), n_runs=5).validate()


def test_cli_validate_and_holdout(monday, tmp_path, capsys):
    csv, _ = write_measurement(_sensor(3000.0, 4), tmp_path / "tuesday.csv")
    model = tmp_path / "monday.toml"
    model.write_text(monday.to_toml())
    code = main(["diagnose", str(csv), "--model", str(model), "--validate", "--runs", "10", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["validated"] and out["consistent"]
    assert "predicts" in out["verdict"] and "consistent" in out["verdict"]
    code = main(["diagnose", str(csv), "--validate"])
    assert code == 2 and "needs --model" in capsys.readouterr().err


def test_split_measurement_refuses_a_too_short_part():
    m = _sensor(3000.0, 5)
    first, rest = split_measurement(m, 0.4)
    assert first.time_s.size + rest.time_s.size == m.time_s.size and rest.time_s[0] > first.time_s[-1]
    with pytest.raises(InputError, match="--holdout"):
        split_measurement(m, 0.999)


def _filtered(cutoff_hz, seed):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("bandwidth", 3, {"cutoff_hz": cutoff_hz, "order": 2})))
    return lab_run(model, LAYOUT, np.random.default_rng(seed), static_s=300.0, motion_s=0.0, tail_s=0.0)


def test_a_filter_read_from_the_spectrum_is_compared_with_the_model_not_taken_as_an_error():
    """The spectrum gives a filter's cut-off itself, whatever the model holds: validation compares
    it with the model's (same sensor: no prediction error; another cut-off: the worst test)."""
    _, after = ModelComparison(_filtered(10.0, 1), n_runs=10).fit([("bandwidth", 3)])
    fitted = after.model
    same = ModelComparison(_filtered(10.0, 2), fitted, n_runs=10).validate()
    t = next(t for t in same.tests if t.effect == "bandwidth" and t.gyro == 3)
    assert t.extra.get("prediction_error") and not same.significant(t), t.evidence
    other = ModelComparison(_filtered(5.0, 2), fitted, n_runs=10).validate()
    worst = other.candidates[0]
    assert (worst.effect, worst.gyro) == ("bandwidth", 3) and other.significant(worst), worst.evidence
