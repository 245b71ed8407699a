"""Records longer than memory (issue 34, item 4): ``fuse`` streamed, ``diagnose`` on a window.

* ``fuse`` forced to stream (a tiny ``--max-memory``: chunks of 256 rows) writes the same fused
  rates and gives the same fused ADEV as in memory, to 1e-12, for a static estimator (gls, its
  noise fitted on the streamed record) and a steady-state Kalman filter (kf_array, from a model).
* ``diagnose`` on a record over the memory budget analyses the longest window that fits, names
  it, and gives on it what an in-memory ``diagnose`` of the same window cut by hand gives.
* What still cannot stream is refused in one line (exit 2).
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hostile import SIDECAR_3, assert_contract, axes_sidecar, run_cli
from gyroarray.chain.compare import COMPARISON_BYTES_PER_CELL, FIXED_BYTES
from gyroarray.chain.long_record import window_plan
from gyroarray.core.limits import memory_budget
from gyroarray.core.measurement import read_measurement

RATE = 50.0
MODEL = 'effects = [{effect = "arw", n_deg_rt_h = 0.4}, {effect = "rrw", k_deg_h_rt_h = 1500.0}]\n'


def _parquet(folder, name, t, g, sidecar):
    path = folder / f"{name}.parquet"
    cols = {"time_s": t, **{f"gyro{k + 1}": g[:, k] for k in range(g.shape[1])}}
    pq.write_table(pa.table(cols), path, row_group_size=1000)
    (folder / f"{name}.toml").write_text(sidecar)
    return path


def _array(tmp_path, n=6000):
    """Four gyros, white noise of different levels and a slow walk on a bias."""
    rng = np.random.default_rng(5)
    t = np.arange(n) / RATE
    g = (0.2 + np.array([0.05, 0.08, 0.04, 0.06]) * rng.standard_normal((n, 4))
         + np.cumsum(1e-3 * rng.standard_normal((n, 4)), axis=0))
    return _parquet(tmp_path, "arr", t, g, axes_sidecar(4))


def _fuse(path, out, *extra):
    o = run_cli(["fuse", path, "--out", out, "--json", *extra])
    assert o.code == 0, o.err
    return json.loads(o.out), read_measurement(out)


def test_streamed_fuse_equals_in_memory(tmp_path):
    path = _array(tmp_path)
    (tmp_path / "m.toml").write_text(MODEL)
    # the model as it is (in memory its levels are checked against the record first: issue 41)
    for est, extra in (("gls", []), ("kf_array", ["--model", tmp_path / "m.toml", "--off-levels", "model"])):
        whole, fw = _fuse(path, tmp_path / f"mem_{est}.parquet", "--estimator", est, *extra)
        streamed, fs = _fuse(path, tmp_path / f"str_{est}.csv.gz", "--estimator", est, *extra,
                             "--max-memory", "512K")
        assert "streamed" not in whole and streamed["streamed"]["chunk_rows"] * 3 < 6000
        assert any(n.startswith("streamed (reading it whole would need") for n in streamed["notes"])
        assert np.array_equal(fw.time_s, fs.time_s)
        scale = np.max(np.abs(fw.gyro_deg_s))
        np.testing.assert_allclose(fs.gyro_deg_s, fw.gyro_deg_s, rtol=1e-12, atol=1e-12 * scale)
        for ax in "xyz":
            a, b = whole["axes"][ax], streamed["axes"][ax]
            assert a["taus_s"] == b["taus_s"] and len(a["taus_s"]) == 12
            for key in ("adev_deg_h", "ci_low_deg_h", "ci_high_deg_h"):
                np.testing.assert_allclose(b[key], a[key], rtol=1e-12, atol=0)
            np.testing.assert_allclose(b["arw_deg_rt_h"], a["arw_deg_rt_h"], rtol=1e-12)
            assert a["best_single_gyro"] == b["best_single_gyro"]
        assert whole["gyros_used"] == streamed["gyros_used"] == [1, 2, 3, 4]
        np.testing.assert_allclose(streamed["design_noise"]["arw_deg_rt_h"],
                                   whole["design_noise"]["arw_deg_rt_h"], rtol=1e-12)
        # the sidecar of the streamed record reads back as the in-memory one's
        assert (tmp_path / f"str_{est}.toml").read_text().count("[fused]") == 1


def test_fuse_refuses_what_does_not_stream(tmp_path):
    path = _array(tmp_path, n=3000)
    for extra, words in ((["--estimator", "bound"], "fixed linear filter"),
                         (["--estimator", "svo"], "svo without --model"),
                         (["--estimator", "gls", "--validate"], "--validate needs the record in memory")):
        o = run_cli(["fuse", path, "--stream", *extra])
        assert_contract(o, "arr.parquet")
        assert o.code == 2 and words in o.err, o.err


def _window_budget(path, n_window: int) -> int:
    """The smallest --max-memory whose diagnose window of ``path`` is ``n_window`` samples."""
    def window(budget: int) -> int:
        with memory_budget(budget):
            plan = window_plan(path)
        return 10**9 if plan is None else plan.n_window
    lo, hi = FIXED_BYTES, FIXED_BYTES + 64 * COMPARISON_BYTES_PER_CELL * n_window
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if window(mid) < n_window else (lo, mid)
    assert window(hi) == n_window
    return hi


def test_diagnose_over_budget_analyses_a_window(tmp_path):
    rng = np.random.default_rng(7)
    n, n_w = 5000, 2500
    t = np.arange(n) / RATE
    g = 0.2 + 0.05 * rng.standard_normal((n, 3))
    g[:, 1] += 0.3 * np.sin(2 * np.pi * 7.0 * t)                   # something to find: a line
    path = _parquet(tmp_path, "long", t, g, SIDECAR_3)
    cut = _parquet(tmp_path, "cut", t[:n_w], g[:n_w], SIDECAR_3)
    budget = _window_budget(path, n_w)
    o = run_cli(["diagnose", path, "--json", "--runs", "20", "--max-memory", str(budget)])
    assert o.code == 0, o.err
    win = json.loads(o.out)
    ref = json.loads(run_cli(["diagnose", cut, "--json", "--runs", "20"]).out)
    assert win["window"]["samples"] == n_w and win["window"]["record_samples"] == n
    assert win["window"]["stop_s"] == n_w / RATE
    assert win["notes"][0].startswith("record of 0.0278 h over the memory budget")
    assert "diagnosed on its window 0–50 s (0.0139 h, samples 1–2500 of 5000)" in win["notes"][0]
    assert win["candidates"][0]["effect"] == ref["candidates"][0]["effect"]
    assert win["candidates"][0]["gyro"] == ref["candidates"][0]["gyro"]
    np.testing.assert_allclose(win["discrepancy"], ref["discrepancy"], rtol=1e-9)
    whole = win["whole_record"]["gyros"]
    assert set(whole) == {"1", "2", "3"}
    for d in whole.values():
        assert any(d["beyond_window"]) and len(d["model_deg_h"]) == len(d["adev_deg_h"])
    # the budget too small for the shortest window: one line, exit 2, the way out
    o = run_cli(["diagnose", path, "--max-memory", str(FIXED_BYTES + 100 * COMPARISON_BYTES_PER_CELL)])
    assert_contract(o, "long.parquet")
    assert o.code == 2 and "--max-memory" in o.err


def test_a_streamed_fuse_that_fails_late_leaves_the_old_pair(tmp_path, monkeypatch):
    """The fused record is written chunk by chunk before its ADEV is computed: a failure after
    that (here the phase files' ADEV) names nothing, so an existing record and its sidecar given
    with --force stay as they were, side by side, and no temporary file is left."""
    from gyroarray.chain import fuse_stream
    from gyroarray.core.errors import InputError
    from gyroarray.core.measurement import record_head
    path = _array(tmp_path, n=3000)
    out, side = tmp_path / "fused.parquet", tmp_path / "fused.toml"
    out.write_bytes(b"old record")
    side.write_text("old sidecar\n")
    before = sorted(p.name for p in tmp_path.iterdir())

    def boom(*args, **kwargs):
        raise InputError("no space left on device (test)")

    monkeypatch.setattr(fuse_stream, "phase_oadev", boom)
    head = record_head(path)
    with pytest.raises(InputError):
        fuse_stream.streamed_fuse(head, "gls", out=out, sidecar=side, force=True,
                                  work_bytes=1 << 19)
    assert out.read_bytes() == b"old record" and side.read_text() == "old sidecar\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    monkeypatch.undo()
    res = fuse_stream.streamed_fuse(head, "gls", out=out, sidecar=side, force=True,
                                    work_bytes=1 << 19)
    assert res["streamed"]["chunk_rows"] < 3000                  # it did stream
    assert read_measurement(out).n_samples == 3000 and "[fused]" in side.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == before
