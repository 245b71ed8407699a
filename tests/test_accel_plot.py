"""``allan --plot`` with ``--sensor acc|all``: the accelerometer's ADEV curves, bands and fits in
a panel of their own, in m/s² (issue 42).

What is checked is what the figure was drawn with, read back from its matplotlib artists (the
curve's Line2D data, the band's polygon vertices, the fit's Line2D), against the numbers of
``allan --sensor acc --json`` on the same record: the same computation drawn, so equal to
rounding (1e-12 relative; the JSON floats are the same doubles). No image comparison.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement
from gyroarray.reports import allan_plots
from hostile import assert_contract, run_cli

DT = 0.01                                               # [s], 100 Hz
N_A = 1e-3                                              # VRW [m/s²/√Hz] = 0.06 m/s/√h
K_A = 5.8e-5                                            # acc RW [m/s²/√s]
G0 = 9.80665                                            # [m/s²] gravity on z
N_SAMPLES = 60_000                                      # 10 min: 13 octave taus, a fast test


def _write(tmp_path, seed: int = 3):
    """A still record, 3 gyros (white, 1e-4 rad/√s) and acc_x..z: white N_A plus a walk K_A plus
    gravity on z (as tests/test_accel.py builds one, with plain numpy)."""
    rng = np.random.default_rng(seed)
    gyro = np.degrees(1e-4 / math.sqrt(DT) * rng.standard_normal((N_SAMPLES, 3)))        # [deg/s]
    acc = (N_A / math.sqrt(DT) * rng.standard_normal((N_SAMPLES, 3))
           + np.cumsum(K_A * math.sqrt(DT) * rng.standard_normal((N_SAMPLES, 3)), axis=0)
           + np.array([0.0, 0.0, G0]))
    m = Measurement(time_s=np.arange(N_SAMPLES) * DT, gyro_deg_s=gyro, layout=Layout(np.eye(3)),
                    sample_rate_hz=1.0 / DT, acc_m_s2=acc)
    csv, _ = write_measurement(m, tmp_path / "acc.csv")
    return csv


@pytest.fixture
def drawn(monkeypatch):
    """Every call of plot_allan_panels, with what it drew (the CLI imports it at call time)."""
    calls = []
    real = allan_plots.plot_allan_panels

    def spy(panels, path, **kw):
        out = real(panels, path, **kw)
        calls.append(out)
        return out
    monkeypatch.setattr(allan_plots, "plot_allan_panels", spy)
    return calls


def _close(a, b, rel=1e-12):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, (a.shape, b.shape)
    np.testing.assert_allclose(a, b, rtol=rel, atol=0.0)


def _check_acc_panel(panel: dict, acc_json: dict) -> None:
    assert panel["unit"] == "m/s²" and panel["ylabel"] == "Allan deviation [m/s²]"
    assert set(panel["curves"]) == {"acc_x", "acc_y", "acc_z"}
    for axis in "xyz":
        got, want = panel["curves"][f"acc_{axis}"], acc_json["axes"][axis]
        assert len(want["taus_s"]) >= 10
        _close(got["taus_s"], want["taus_s"])
        _close(got["deviation"], want["adev_m_s2"])
        _close(got["ci_low"], want["ci_low_m_s2"])
        _close(got["ci_high"], want["ci_high_m_s2"])
        # the dashed fit starts at the first tau; the JSON holds the fitted terms, not the
        # model's curve, so check it where white noise dominates: at τ = 0.01 s the walk is
        # K_a·√(τ/3)/(N_a/√τ) = 3e-4 of the white term, so the model is N_a/√τ within 5 %
        # (measured 0.1 %; an mg curve would be off by 102x, a gyro's by far more).
        fit = want["fit"]
        n_si = units.vrw_m_s_rt_h_to_si(fit["vrw_m_s_rt_h"])
        assert got["fit_taus_s"][0] == pytest.approx(want["taus_s"][0], rel=1e-12)
        assert got["fit"][0] == pytest.approx(n_si / math.sqrt(got["fit_taus_s"][0]), rel=0.05)


def test_allan_sensor_acc_plot_draws_the_json_numbers_in_m_s2(tmp_path, drawn):
    csv = _write(tmp_path)
    ref = run_cli(["allan", csv, "--sensor", "acc", "--json"])
    assert_contract(ref)
    acc_json = json.loads(ref.out)
    png = tmp_path / "acc.png"
    o = run_cli(["allan", csv, "--sensor", "acc", "--json", "--plot", png])
    assert_contract(o)
    assert o.code == 0
    out = json.loads(o.out)
    assert out["plot"] == str(png)
    with open(png, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert out["axes"] == acc_json["axes"]             # plotting changes nothing computed
    assert len(drawn) == 1
    path, what = drawn[0]
    assert path == png and list(what) == ["0"]         # the accelerometer's panel alone
    _check_acc_panel(what["0"], acc_json)
    # VRW resolved on every axis (60 000 samples of N_A): the legend of each fit says it
    assert all(out["axes"][a]["fit"]["vrw_m_s_rt_h_resolved"] for a in "xyz")


def test_allan_sensor_all_plot_has_a_gyro_panel_in_deg_h_and_an_acc_panel_in_m_s2(tmp_path, drawn):
    csv = _write(tmp_path, seed=4)
    acc_json = json.loads(run_cli(["allan", csv, "--sensor", "acc", "--json"]).out)
    png = tmp_path / "all.png"
    o = run_cli(["allan", csv, "--sensor", "all", "--json", "--plot", png])
    assert_contract(o)
    assert o.code == 0 and png.is_file()
    out = json.loads(o.out)
    assert len(drawn) == 1
    _, what = drawn[0]
    assert list(what) == ["0", "1"]
    gyros = what["0"]
    assert gyros["unit"] == "deg/h" and gyros["ylabel"] == "Allan deviation [deg/h]"
    assert set(gyros["curves"]) == {"gyro 1", "gyro 2", "gyro 3"}
    for k in "123":
        _close(gyros["curves"][f"gyro {k}"]["deviation"], out["gyros"][k]["adev_deg_h"])
        _close(gyros["curves"][f"gyro {k}"]["ci_high"], out["gyros"][k]["ci_high_deg_h"])
    _check_acc_panel(what["1"], acc_json)
    _check_acc_panel(what["1"], out["accelerometer"])


def test_plot_allan_panels_refuses_an_empty_panel(tmp_path):
    from gyroarray.core.errors import InputError
    with pytest.raises(InputError):
        allan_plots.plot_allan_panels([], tmp_path / "x.png")
    with pytest.raises(InputError):
        allan_plots.plot_allan_panels([allan_plots.accel_panel({})], tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()
