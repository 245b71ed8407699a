"""Optional ``acc_x/acc_y/acc_z`` columns and ``[layout] positions_m`` (measurement format).

Outside truth: the spec's text (three columns or none, m/s², positions N×3 in
metres), values written here by hand, and the table truth's own specific
force for what ``simulate`` exports. Refusals of bad files are in the bad
corpus (``partial_acc``, ``infinite_acc``, ``positions_*``).
"""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, read_measurement, write_measurement
from gyroarray.sim.scenario import load_scenario, simulate, simulate_to_files

CONE4 = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))
POS = [[0.025, 0.0, 0.03], [0.0, 0.025, 0.03], [-0.025, 0.0, 0.03], [0.0, -0.025, 0.03]]


def _measurement(acc=True, positions=True, n=40):
    rng = np.random.default_rng(2)
    layout = CONE4.with_positions(POS) if positions else CONE4
    return Measurement(time_s=np.arange(n) * 0.01, gyro_deg_s=rng.normal(size=(n, 4)),
                       layout=layout, sample_rate_hz=100.0, ref_deg_s=rng.normal(size=(n, 3)),
                       temp_c=25 + rng.normal(size=n),
                       acc_m_s2=rng.normal(0, 9.8, (n, 3)) if acc else None)


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz"])
def test_acc_and_positions_round_trip_exactly(tmp_path, suffix):
    m = _measurement()
    csv, toml = write_measurement(m, tmp_path / f"run{suffix}")
    back = read_measurement(csv)
    np.testing.assert_array_equal(back.acc_m_s2, m.acc_m_s2)
    np.testing.assert_array_equal(back.layout.positions_m, POS)
    np.testing.assert_array_equal(back.gyro_deg_s, m.gyro_deg_s)
    np.testing.assert_array_equal(back.temp_c, m.temp_c)
    assert back.has_acc and "positions_m" in toml.read_text()
    text = (gzip.decompress(csv.read_bytes()) if suffix.endswith("gz") else csv.read_bytes()).decode()
    assert text.splitlines()[1].endswith(",acc_x,acc_y,acc_z")


def test_without_them_readers_see_none(tmp_path):
    m = _measurement(acc=False, positions=False)
    csv, toml = write_measurement(m, tmp_path / "run.csv")
    back = read_measurement(csv)
    assert back.acc_m_s2 is None and not back.has_acc and back.layout.positions_m is None
    assert "acc_" not in csv.read_text() and "positions_m" not in toml.read_text()
    np.testing.assert_array_equal(back.layout.positions_or_zero, np.zeros((4, 3)))


def test_acc_columns_in_any_order_and_in_g(tmp_path):
    (tmp_path / "r.csv").write_text("time_s,acc_z,gyro1,acc_x,gyro2,gyro3,acc_y\n"
                                    "0.0,1.0,0.1,0.0,0.2,0.3,0.5\n0.1,-1.0,0.1,0.25,0.2,0.3,0.0\n")
    (tmp_path / "r.toml").write_text('sample_rate_hz = 10.0\n[layout]\nscheme = 1\nn_gyros = 3\n'
                                     'alpha_deg = 54.7356\n[units]\nacc = "g"\n')
    m = read_measurement(tmp_path / "r.csv")
    np.testing.assert_array_equal(m.acc_m_s2, 9.80665 * np.array([[0.0, 0.5, 1.0], [0.25, 0.0, -1.0]]))
    assert any("converted acc from g to m/s2" in note for note in m.notes)
    np.testing.assert_array_equal(m.gyro_deg_s, [[0.1, 0.2, 0.3]] * 2)


def test_positions_are_checked_in_code_too():
    with pytest.raises(InputError, match="positions_m has 3 rows but the layout has 4 gyros"):
        CONE4.with_positions(POS[:3])
    with pytest.raises(ValueError, match="acc_m_s2 must have shape"):
        Measurement(time_s=[0.0, 1.0], gyro_deg_s=np.zeros((2, 4)), layout=CONE4,
                    sample_rate_hz=1.0, acc_m_s2=np.zeros((2, 2)))


SCENARIO = """
name = "gs"
sample_rate_hz = 100.0
duration_s = 8.0
seed = 7
{acc}
effects = [{{ effect = "g_sensitivity", gyro = 2, deg_s_per_g = [0.0, 0.0, 0.1] }}]

[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
{positions}

[motion]
profile = "g_sensitivity_tumble"
"""


def test_simulate_writes_the_truths_specific_force_and_the_positions(tmp_path):
    path = tmp_path / "gs.toml"
    path.write_text(SCENARIO.format(acc="acc_columns = true", positions=f"positions_m = {POS}"))
    sc = load_scenario(path)
    csv, toml, result = simulate_to_files(sc, tmp_path / "out", cache=False)
    m = read_measurement(csv)
    np.testing.assert_array_equal(m.acc_m_s2, result.truth.specific_force_m_s2)
    np.testing.assert_array_equal(m.acc_m_s2[0], [0.0, 0.0, 9.80665])      # rest, level, z up
    np.testing.assert_array_equal(m.layout.positions_m, POS)
    # gyro 2 at rest reads its g-sensitivity: 0.1 deg/s per g on z, with f = [0, 0, g0]
    np.testing.assert_allclose(m.gyro_deg_s[:, 1], 0.1, rtol=1e-12)
    path.write_text(SCENARIO.format(acc="", positions=""))
    plain = simulate(load_scenario(path), cache=False).to_measurement()
    assert plain.acc_m_s2 is None and plain.layout.positions_m is None


def test_acc_columns_must_be_a_boolean(tmp_path):
    path = tmp_path / "gs.toml"
    path.write_text(SCENARIO.format(acc='acc_columns = "yes"', positions=""))
    with pytest.raises(InputError, match="acc_columns must be true or false") as info:
        load_scenario(path)
    assert info.value.line == 6 and info.value.column == "acc_columns"


def test_dropping_a_gyro_keeps_the_accelerometer_and_the_topics():
    """``without_gyros`` (``--exclude``, fdi's exclusions) keeps the record's accelerometer and
    topics: one topic per gyro follows its gyro, one IMU topic for the triad stays whole."""
    from gyroarray.core.layout import Layout
    from gyroarray.core.measurement import Measurement, without_gyros

    n = 50
    rng = np.random.default_rng(0)
    acc = rng.standard_normal((n, 3)) + [0.0, 0.0, 9.81]
    kw = dict(time_s=0.01 * np.arange(n), gyro_deg_s=rng.standard_normal((n, 3)), layout=Layout.triad(),
              sample_rate_hz=100.0, acc_m_s2=acc)
    one = without_gyros(Measurement(**kw, topics=("/imu0",)), [2])
    assert one.n_gyros == 2 and one.topics == ("/imu0",)
    np.testing.assert_array_equal(one.acc_m_s2, acc)
    per = without_gyros(Measurement(**kw, topics=("/a", "/b", "/c")), [2])
    assert per.topics == ("/a", "/c")
    np.testing.assert_array_equal(per.gyro_deg_s, kw["gyro_deg_s"][:, [0, 2]])
