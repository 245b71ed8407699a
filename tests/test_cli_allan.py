"""`gyroarray allan` end to end on real and simulated measurements."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from gyroarray.cli.main import main

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
ADIS = SHARED / "measurements" / "real" / "adis16405_static.csv.gz"
AVAR = SHARED / "reference" / "avar_curves" / "adis16405_static_avar_rep1.csv"
PRACTICE = SHARED / "measurements" / "practice" / "p2_bias_instability.csv.gz"

needs_shared = pytest.mark.skipif(not ADIS.is_file(), reason="../shared (read-only project data) not beside the repo")


def run_json(capsys, *argv):
    code = main([*argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


@needs_shared
def test_adis_cli_matches_the_r_avar_package(capsys):
    out = run_json(capsys, "allan", str(ADIS))
    assert set(out["gyros"]) == {"1", "2", "3"}
    ref: dict[str, list] = {}
    with AVAR.open() as fh:
        for row in csv.DictReader(r for r in fh if not r.startswith("#")):
            ref.setdefault(row["channel"], []).append((float(row["tau_s"]), float(row["adev"])))
    for k, channel in (("1", "Gyro. X"), ("2", "Gyro. Y"), ("3", "Gyro. Z")):
        g = out["gyros"][k]
        ours = dict(zip(np.round(g["taus_s"], 9), np.asarray(g["adev_deg_h"]) / 3600.0))  # -> deg/s
        pairs = [(ours[round(t, 9)], a) for t, a in ref[channel] if round(t, 9) in ours]
        assert len(pairs) == len(ref[channel]) >= 17     # every dyadic tau of R is one of ours
        ours_v, ref_v = np.array(pairs).T
        # R's avar agrees with allantools/ours to ~6e-6 (its own float summation); 1e-4 as issued
        np.testing.assert_allclose(ours_v, ref_v, rtol=1e-4)
        fit = g["fit"]
        # ADIS16405 datasheet ARW is 2.0 deg/rt(h) typical; this unit fits 2.3-2.4 with sigma < 0.1
        assert 1.8 < fit["arw_deg_rt_h"] < 2.8 and fit["arw_deg_rt_h_sigma"] < 0.15
        assert all(lo <= a <= hi for lo, a, hi in zip(g["ci_low_deg_h"], g["adev_deg_h"], g["ci_high_deg_h"]))


@needs_shared
def test_practice_file_with_motion_uses_the_residual(capsys, tmp_path):
    png = tmp_path / "adev.png"
    out = run_json(capsys, "allan", str(PRACTICE), "--gyro", "3", "--taus", "0.02,0.2,2,20,40,80", "--plot", str(png))
    assert out["signal"].startswith("gyro output minus layout")
    assert list(out["gyros"]) == ["3"]
    assert out["gyros"]["3"]["taus_s"] == pytest.approx([0.02, 0.2, 2.0, 20.0, 40.0, 80.0], rel=1e-12)
    assert png.read_bytes()[:4] == b"\x89PNG"


@needs_shared
@pytest.mark.parametrize("argv,fragment", [
    (["--gyro", "4"], "out of range"),
    (["--taus", "many"], "--taus must be"),
    (["--taus", "1"], "give 2 to 10000"),
    (["--taus", "0.015,1"], "0.015"),
])
def test_allan_bad_options_exit_2(capsys, argv, fragment):
    code = main(["allan", str(ADIS), *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.count("\n") == 1 and fragment in err


def test_allan_missing_file_exit_2(capsys, tmp_path):
    code = main(["allan", str(tmp_path / "nope.csv"), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and "nope" in err and "Traceback" not in err


def test_a_walk_read_as_bias_instability_is_explained_against_fit():
    """allan's five-term fit at K = 0 with a bias instability while the +1/2 slope reads a walk
    (the ADIS16405's gyro 1: K 0 ± 64, B 33.4 deg/h, slope K 41.8): one note per such gyro that
    names both readings and `fit --add bias_instability`; none where the fit reads a walk."""
    from gyroarray.cli.allan import walk_in_bias_notes
    fits = {"1": {"fit": {"rrw_deg_h_rt_h": 0.0, "rrw_deg_h_rt_h_sigma": 64.0, "bi_deg_h": 33.4,
                          "slope_rrw_deg_h_rt_h": 41.8}},
            "2": {"fit": {"rrw_deg_h_rt_h": 120.0, "rrw_deg_h_rt_h_sigma": 40.0, "bi_deg_h": 20.0,
                          "slope_rrw_deg_h_rt_h": 110.0}},
            "3": {"fit": {"rrw_deg_h_rt_h": 0.0, "rrw_deg_h_rt_h_sigma": 5.0, "bi_deg_h": 0.0,
                          "slope_rrw_deg_h_rt_h": float("nan")}}}
    notes = walk_in_bias_notes(fits)
    assert len(notes) == 1 and notes[0].startswith("gyro 1:")
    assert "K 0 ± 64" in notes[0] and "33.4 deg/h" in notes[0] and "K ≈ 41.8" in notes[0]
    assert "fit --add bias_instability" in notes[0]
