"""Fuzzing the CLI with generated measurement files, noise models and scenarios (issue 17 item 1).

Strategies build what a careless lab or a hostile user could hand over:
measurement files with random time steps (uniform, jittered, repeated,
subnormal, epoch-sized offsets), constant, near-constant, spiked and
extreme-magnitude columns; scenario files whose effects take random
parameters (zero, tiny, huge, negative) and random rates and durations.

The property (:func:`hostile.assert_contract`): exit 0 with finite numbers,
or exit 2 with one line naming the file; never exit 1, never a traceback,
never a hang.

``make test`` runs a bounded number of examples (derandomized: the same
cases every run); ``make fuzz`` runs many more (``GYROARRAY_FUZZ_EXAMPLES``,
random seeds, ``diagnose`` included).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyroarray.effects import REGISTRY
from hostile import assert_contract, axes_sidecar, finite_numbers, run_cli, write_measurement

LONG = int(os.environ.get("GYROARRAY_FUZZ_EXAMPLES", "0"))
# GYROARRAY_FUZZ_EXAMPLES is the total of a `make fuzz` run, shared out among the fuzz tests:
# 17 % each to the allan and simulate tests here, 3 % to diagnose (each example is a whole
# diagnosis), 4 % to each of the thirteen commands of tests/test_fuzz_args.py, 3 % to each of
# the two reader tests of tests/test_fuzz_readers.py
FUZZ = settings(max_examples=max(LONG * 17 // 100, 1) if LONG else 25, deadline=None, derandomize=not LONG, database=None,
                suppress_health_check=list(HealthCheck))

MAGNITUDES = [0.0, 5e-324, 1e-310, 1e-12, 1e-3, 1.0, 99999.0, 1e5 * (1 + 1e-15), 1e200, 1e308]
STEPS = [5e-324, 1e-12, 1e-9, 1e-3, 0.01, 0.02, 1.0, 3600.0, 1e300]


@st.composite
def columns(draw, n: int, rng: np.random.Generator) -> np.ndarray:
    kind = draw(st.sampled_from(["noise", "constant", "near_constant", "spike", "ramp", "zeros"]))
    scale = draw(st.sampled_from(MAGNITUDES))
    if kind == "noise":
        return rng.normal(0.0, 1.0, n) * scale
    if kind == "constant":
        return np.full(n, scale)
    if kind == "near_constant":            # one LSB toggling
        return np.where(rng.random(n) < 0.1, scale + 0.061, scale)
    if kind == "spike":
        col = rng.normal(0.0, 0.01, n)
        col[draw(st.integers(0, n - 1))] = draw(st.sampled_from(MAGNITUDES)) * draw(st.sampled_from([1, -1]))
        return col
    if kind == "ramp":
        return np.linspace(-scale, scale, n)
    return np.zeros(n)


@st.composite
def time_stamps(draw, n: int, rng: np.random.Generator) -> np.ndarray:
    step = draw(st.sampled_from(STEPS))
    t0 = draw(st.sampled_from([0.0, -5.0, 1.7e9, 1e15]))
    t = t0 + np.arange(n) * step
    shape = draw(st.sampled_from(["uniform", "jitter", "duplicate", "gap", "backwards"]))
    if shape == "jitter":
        t = t + rng.uniform(-0.2, 0.2, n) * step
    elif shape == "duplicate" and n > 3:
        i = draw(st.integers(1, n - 2))
        t[i] = t[i - 1]
    elif shape == "gap" and n > 3:
        i = draw(st.integers(1, n - 2))
        t[i:] += draw(st.sampled_from([2, 4, 10])) * step
    elif shape == "backwards" and n > 3:
        i = draw(st.integers(1, n - 2))
        t[i], t[i + 1] = t[i + 1], t[i]
    return t


@st.composite
def measurements(draw, folder: Path, min_n: int = 2, max_n: int = 400):
    n = draw(st.integers(min_n, max_n))
    n_gyros = draw(st.integers(1, 4))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = draw(time_stamps(n, rng))
    g = np.column_stack([draw(columns(n, rng)) for _ in range(n_gyros)])
    rate = draw(st.sampled_from([50.0, 1.0, 1e-300, 1e300]))
    name = f"m{draw(st.integers(0, 10**9))}"
    return write_measurement(folder, name, t, g, sidecar=axes_sidecar(n_gyros, rate),
                             gz=draw(st.booleans()))


@pytest.fixture(scope="module", autouse=True)
def _truth_cache(tmp_path_factory):
    """The rate-table truth of generated scenarios cached in a temporary folder."""
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(tmp_path_factory.mktemp("truth"))
    yield
    if old is None:
        os.environ.pop("GYROARRAY_CACHE", None)
    else:
        os.environ["GYROARRAY_CACHE"] = old


def check(o, path):
    assert_contract(o, Path(path).name)
    if o.code == 0:
        res = o.json
        assert finite_numbers(res.get("gyros", {})), res


@FUZZ
@given(data=st.data())
def test_allan_on_generated_measurements(data):
    with tempfile.TemporaryDirectory() as tmp:
        path = data.draw(measurements(Path(tmp)))
        repair = data.draw(st.booleans())
        o = run_cli(["allan", path, "--json"] + (["--repair"] if repair else []), timeout=120)
        check(o, path)


@pytest.mark.skipif(not LONG, reason="diagnose fuzzing is long: make fuzz")
@settings(max_examples=max(LONG * 3 // 100, 5), deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_diagnose_on_generated_measurements(data):
    with tempfile.TemporaryDirectory() as tmp:
        path = data.draw(measurements(Path(tmp), min_n=2048, max_n=3000))
        o = run_cli(["diagnose", path, "--runs", "3", "--json"], timeout=300)
        assert_contract(o, Path(path).name)
        if o.code == 0:
            d = o.json["discrepancy"]
            assert d is not None and np.isfinite(d)


# -- scenarios and noise models ---------------------------------------------------------

PARAMS = {                      # effect -> its required numeric parameters (spec names), from the registry
    e.name: [p.name for p in e.params if p.kind == "scalar" and p.required] for e in REGISTRY.values()
    if any(p.kind == "scalar" and p.required for p in e.params)
}
VALUES = [0, 1e-300, 1e-6, 0.5, 3.0, 100.0, 1e6, 1e12, 1e300, -1.0, -1e300]


@st.composite
def effect_lines(draw) -> str:
    effect = draw(st.sampled_from(sorted(PARAMS)))
    params = ", ".join(f"{p} = {draw(st.sampled_from(VALUES))!r}" for p in PARAMS[effect])
    gyro = draw(st.sampled_from(["", "gyro = 2, ", "gyro = 9, "]))
    return f'{{ effect = "{effect}", {gyro}{params} }}'


@FUZZ
@given(data=st.data())
def test_simulate_generated_scenarios(data, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fz")
    effects = ", ".join(data.draw(st.lists(effect_lines(), max_size=3)))
    rate = data.draw(st.sampled_from([1e-3, 2.0, 20.0, 1e4, 1e7]))
    duration = data.draw(st.sampled_from([None, 1e-3, 5.0, 10.0, 1e9]))
    (folder / "p.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 10.0\n')
    path = folder / "sc.toml"
    path.write_text(f'name = "sc"\nsample_rate_hz = {rate!r}\nseed = 3\n'
                    + ("" if duration is None else f"duration_s = {duration!r}\n")
                    + f"effects = [{effects}]\n[layout]\nscheme = 1\nn_gyros = 4\nalpha_deg = 54.7356\n"
                    + '[motion]\nprofile = "p.toml"\n')
    o = run_cli(["simulate", path, "--out", folder / "out", "--json"], timeout=120)
    assert_contract(o, "sc.toml")
    if o.code == 0:
        from gyroarray.core.measurement import read_measurement
        m = read_measurement(folder / "out" / "sc.csv.gz")
        assert np.all(np.isfinite(m.gyro_deg_s))
