"""``gyroarray export --inflate measured`` (issue 42): the inflation measured against a reference
pose topic, wired into the CLI.

The record is tests/test_inflation.py's (its module-level builders): a gyro triad whose white
density grows with the rate, N(ω) = N0·(1 + 2·|ω|), 10 s still then one pass over rate plateaus
of 0.3, 1 and 2 rad/s, written as a ROS1 bag with /imu and /mocap/pose. The outside truth of
the factor is :func:`gyroarray.chain.inflation.inflation_for_export` called directly (tested
there against the truth of the record); here: the CLI passes it the exported axis's N, K and
index, the file carries the factor on the gyro's numbers (not the accelerometer's) and the
four header lines, the JSON the summary, the text one line; the refusals.
"""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from gyroarray.chain.inflation import inflation_for_export
from gyroarray.core import units
from hostile import assert_contract, run_cli
from test_inflation import K, N0, record, write_bag

RATE_HZ = 200.0
TOPIC = "/mocap/pose"
#: The model's gyros 1-3 (x, y, z): gyro 2 has 1.2× the white density, so it is the worst.
N_SCALE = (1.0, 1.2, 1.0)
ACCEL = ('\n[accelerometer]\naxes = ["x", "y", "z"]\nn_m_s_rt_h = [0.05, 0.05, 0.05]\n'
         'k_m_s2_rt_h = [0.002, 0.002, 0.002]\n')


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """(folder, bag, model): the 85 s bag (17 000 IMU messages) and a 3-gyro model."""
    folder = tmp_path_factory.mktemp("inflate_measured")
    rec = record(np.random.default_rng(42), static_s=10.0, plateau_s=25.0, cycles=1)
    bag = write_bag(folder / "mocap.bag", rec)
    k = units.rrw_rad_s_rt_s_to_deg_h_rt_h(K)
    entries = []
    for g, s in enumerate(N_SCALE, start=1):
        n = units.arw_rad_rt_s_to_deg_rt_h(s * N0)
        entries += [f'{{effect = "arw", gyro = {g}, n_deg_rt_h = {n!r}}}',
                    f'{{effect = "rrw", gyro = {g}, k_deg_h_rt_h = {k!r}}}']
    model = folder / "m.toml"
    model.write_text(f"effects = [{', '.join(entries)}]\n" + ACCEL)
    return folder, bag, model


def _model_si(gyro: int) -> tuple[float, float]:
    """The model's N [rad/√s], K [rad/s/√s] of ``gyro`` as the export reads them (via the units)."""
    n = units.arw_rad_rt_s_to_deg_rt_h(N_SCALE[gyro - 1] * N0)
    return (float(units.arw_deg_rt_h_to_rad_rt_s(n)),
            float(units.rrw_deg_h_rt_h_to_rad_s_rt_s(units.rrw_rad_s_rt_s_to_deg_h_rt_h(K))))


def _field(text: str, key: str) -> float:
    m = re.search(rf"^\s*{re.escape(key)}:\s*([-+0-9.eE]+)", text, re.M)
    assert m, (key, text)
    return float(m.group(1))


def _export(model, out, *extra):
    return run_cli(["export", model, "--format", "kalibr", "--rate-hz", RATE_HZ, "--out", out, "--json",
                    *extra])


def _measured(bag, *extra):
    return ["--inflate", "measured", "--reference", bag, "--reference-topic", TOPIC, *extra]


def test_worst_axis_factor_file_header_and_text(files):
    folder, bag, model = files
    out = folder / "worst.yaml"
    o = _export(model, out, *_measured(bag, "--time-offset-s", "0"))
    assert_contract(o)
    assert o.code == 0, o.err
    assert o.json["gyro"] == 2                      # the worst axis: gyro 2 (y), index 2
    n2, k2 = _model_si(2)
    want, want_summary, want_lines = inflation_for_export(bag, bag, TOPIC, n2, k2, 2, time_offset_s=0.0,
                                                          rng=np.random.default_rng(0))
    got = o.json["inflate_measured"]
    # the same function on the same inputs: the same float (1e-12 leaves only the JSON round trip)
    assert got["factor"] == pytest.approx(want, rel=1e-12)
    assert o.json["inflate"] == pytest.approx(want, rel=1e-12)
    assert got["axis"] == "gyro 2 (y)" == want_summary["axis"]
    assert got["reference"] == str(bag) and got["reference_topic"] == TOPIC
    # N(ω) = N0(1 + 2|ω|) on plateaus from 0.3 rad/s up: in motion the density is ≥ 1.6·N0 over
    # the model's 1.2·N0, so the factor is > 1 (the test fails if it is not applied)
    assert want > 1.1
    # the file: the model's gyro numbers × the factor (written to 7 digits), the accelerometer's ×1
    plain_out = folder / "plain.yaml"
    plain = _export(model, plain_out)
    assert plain.code == 0, plain.err
    text, plain_text = out.read_text(), plain_out.read_text()
    assert _field(text, "gyroscope_noise_density") == pytest.approx(want * n2, rel=1e-6)
    assert _field(text, "gyroscope_random_walk") == pytest.approx(want * k2, rel=1e-6)
    assert o.json["values"]["gyroscope_noise_density"] == pytest.approx(want * n2, rel=1e-12)
    assert o.json["values"]["gyroscope_random_walk"] == pytest.approx(want * k2, rel=1e-12)
    for key in ("accelerometer_noise_density", "accelerometer_random_walk"):
        assert _field(text, key) == _field(plain_text, key)
    assert o.json["accel_inflate"] == 1.0
    # the header: the library's four lines as comments, naming the bag and the topic
    for line in want_lines:
        assert f"# {line}\n" in text
    assert want_lines[0].startswith(f"inflation: measured x{want:.4g}") and str(bag) in want_lines[0]
    assert TOPIC in want_lines[0]
    head = [x for x in text.splitlines() if not x.startswith("#")]
    assert not any("measured" in x for x in head)           # only comments carry them
    # the text output (one line of it)
    t = run_cli(["export", model, "--format", "kalibr", "--rate-hz", RATE_HZ, "--out", folder / "t.yaml",
                 *_measured(bag, "--time-offset-s", "0")])
    assert t.code == 0, t.err
    assert f"inflation ×{want:.4g} measured from {bag} topic {TOPIC} (gyro 2 (y); held-out NIS" in t.out


def test_axis_mean_pools_and_record_names_the_imu(files):
    """--axis mean: gyro index 0 (the axes pooled) with the mean N, K; --record: the IMU record."""
    folder, bag, model = files
    imu = shutil.copy(bag, folder / "imu_copy.bag")
    o = _export(model, folder / "mean.yaml", "--axis", "mean", "--record", imu,
                *_measured(bag, "--time-offset-s", "0"))
    assert o.code == 0, o.err
    n_mean = float(np.mean([_model_si(g)[0] for g in (1, 2, 3)]))
    want, summary, lines = inflation_for_export(imu, bag, TOPIC, n_mean, _model_si(1)[1], 0,
                                                time_offset_s=0.0)
    m = o.json["inflate_measured"]
    assert m["factor"] == pytest.approx(want, rel=1e-12)
    assert m["axis"] == "the axes pooled" and m["measurement"] == str(imu)
    assert f"against {imu}" in (folder / "mean.yaml").read_text()
    assert o.json["values"]["gyroscope_noise_density"] == pytest.approx(want * n_mean, rel=1e-12)


def test_verify_reads_back_and_compares_the_inflated_values(files):
    """The round trip of --verify compares the file's (inflated) numbers: what it re-identifies is
    the file's N, the model × the factor."""
    folder, bag, model = files
    o = _export(model, folder / "v.yaml", "--verify", *_measured(bag, "--time-offset-s", "0"))
    assert o.code == 0, o.out + o.err                       # read back as meant, round trip passed
    f = o.json["inflate"]
    c = o.json["verify"]["coefficients"]["arw_deg_rt_h"]
    # the value the file means, from the numbers read back (written with 7 digits: 5e-7 relative):
    # √(N² + K²dt²/6) with N, K × f; K·dt/√6 ≈ 2e-8 next to N ≈ 2e-3 (1e-10 relative): f × the
    # model's ARW to 1e-6 (without the factor it would be off by f - 1 > 0.1)
    n2 = units.arw_rad_rt_s_to_deg_rt_h(_model_si(2)[0])
    assert c["file"] == pytest.approx(f * n2, rel=1e-6)
    # the read-back values equal the inflated summary (no "the model means" problem)
    assert not any("the model means" in p for p in o.json["verify"]["problems"])
    # the re-identified ARW of 7200 s simulated at 200 Hz is within 3σ of the file's (the check)
    assert abs(c["z"]) <= 3.0
    # --verify --record: the record's band is compared with the file's ADEV as read back, the
    # model's × f at every τ (both N and K scale by f, so the file's white + walk ADEV does)
    rec = _export(model, folder / "vr.yaml", "--verify", "--record", bag, *_measured(bag, "--time-offset-s", "0"))
    plain = _export(model, folder / "vr_plain.yaml", "--verify", "--record", bag)
    for x in (rec, plain):                 # exit 1 only when the check fails (this record moves)
        assert x.code == (0 if x.json["verify"]["passed"] else 1), x.err
    got = np.asarray(rec.json["verify"]["record"]["gyros"][0]["file_deg_h"])
    base = np.asarray(plain.json["verify"]["record"]["gyros"][0]["file_deg_h"])
    assert rec.json["verify"]["record"]["gyros"][0]["what"] == "gyro 2"
    np.testing.assert_allclose(got / base, f, rtol=1e-6)    # 7 written digits each


@pytest.mark.parametrize("extra,fragment", [
    (["--inflate", "measured"], "--reference"),
    (["--inflate", "measured", "--reference", "BAG"], "--reference-topic"),
    (["--reference", "BAG", "--reference-topic", TOPIC], "--inflate measured"),
    (["--inflate", "2", "--reference-topic", TOPIC], "--inflate measured"),
    (["--imu-topic", "/imu"], "--inflate measured"),
    (["--inflate", "measured", "--reference", "BAG", "--reference-topic", "/vicon/pose"], "/vicon/pose"),
    (["--inflate", "measured", "--reference", "BAG", "--reference-topic", "/imu"], "sensor_msgs/msg/Imu"),
    (["--inflate", "measured", "--reference", "BAG", "--reference-topic", TOPIC, "--time-offset-s", "soon"],
     "--time-offset-s"),
])
def test_refusals_in_one_line_and_nothing_written(files, extra, fragment):
    folder, bag, model = files
    out = folder / "refused.yaml"
    o = _export(model, out, *[str(bag) if x == "BAG" else x for x in extra])
    assert_contract(o)
    assert o.code == 2 and fragment in o.err, o.err
    assert not out.exists()


def test_a_file_that_is_no_bag_is_refused(files):
    folder, _, model = files
    junk = folder / "junk.bag"
    junk.write_bytes(b"not a bag at all\n" * 10)
    out = folder / "junk.yaml"
    o = _export(model, out, *_measured(junk))
    assert_contract(o, "junk.bag")
    assert o.code == 2 and not out.exists()
