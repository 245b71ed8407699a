"""Issue 46's Done-when command as typed: ``design --recommend --family free --n ... --rho-range
... --failures 1 --json`` gives no gyro noise. The non-cone families are designed by geometry
alone (their GDOP and bound ratio are the same for any equal gyros), so the command runs with a
unit gyro and says so; with a cone family the noise is still required (its ranking is by the
noise model), and the refusal says which families need none."""

from __future__ import annotations

import json
import math

import pytest

from hostile import run_cli


def test_free_layouts_without_noise_are_designed_by_geometry_and_said_so():
    o = run_cli(["design", "--recommend", "--family", "free", "--n", "6", "--rho-range=0,0.5",
                 "--estimators", "gls", "--horizon-s", "60", "--json"], timeout=600)
    assert o.code == 0, o.err
    res = json.loads(o.out)
    assert any(n.startswith("no gyro noise given: the layouts are designed and ranked by geometry alone")
               for n in res["notes"])
    free = [x for x in res["layouts"] if x["family"] == "free" and x["n"] == 6]
    assert len(free) == 1
    # the free optimum of N = 6 on the floor 3·√((1 − ρ)/6) over [0, 0.5] (numpy: the floor at
    # ρ = 0 is √1.5 = 1.2247; the search reaches it within 0.1 %, tests/test_layout_sphere.py)
    assert free[0]["bound_ratio"] == pytest.approx(1.0, abs=1e-3)
    assert free[0]["worst_gdop"] == pytest.approx(3.0 * math.sqrt(1.0 / 6.0), rel=1e-3)
    assert res["assumptions"]["arw"]["source"].startswith("unit gyro (no noise given")


def test_a_cone_family_without_noise_is_refused_naming_the_geometry_families():
    o = run_cli(["design", "--recommend", "--family", "cone1,free", "--n", "6"])
    assert o.code == 2 and "give the gyro noise" in o.err
    assert "only --family free, triads or faces design by geometry without it" in o.err
    o = run_cli(["design", "--recommend", "--n", "6"])
    assert o.code == 2 and "give the gyro noise" in o.err and "geometry" not in o.err
