"""Property-based tests of the measurement reader and writer.

* Any valid measurement round-trips write -> read exactly: every array
  bit for bit (signed zeros, subnormals and the largest doubles included;
  rates within the 1e5 deg/s a gyro can see),
  conical layouts and sites exactly, explicit axes to 1e-15.
* Random corruption of a valid pair (byte flips, insertions, deletions,
  truncation; of the CSV text, of the gzip stream or of the sidecar) gives a
  Measurement or an InputError with a one-line message, never any other
  exception.

Examples are derived deterministically (``derandomize=True``, no example
database), so CI runs the same cases every time.
"""

from __future__ import annotations

import gzip
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.limits import MAX_RATE_DEG_S
from gyroarray.core.measurement import (GAP_FACTOR, Measurement, Site, read_measurement,
                                   write_measurement)
from gyroarray.core.units import deg_to_rad

CI = settings(max_examples=120, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

finite = st.floats(allow_nan=False, allow_infinity=False)   # incl. -0.0, subnormals, ±max
# rates a gyro or table can see (the reader refuses beyond MAX_RATE_DEG_S): -0.0 and subnormals included
rates = st.floats(-MAX_RATE_DEG_S, MAX_RATE_DEG_S, allow_nan=False, allow_infinity=False)


@st.composite
def layouts(draw) -> Layout:
    kind = draw(st.sampled_from(["cone", "axes", "triad"]))
    if kind == "triad":
        return Layout.triad()
    n = draw(st.integers(3, 8))
    if kind == "cone":
        alpha_deg = draw(st.floats(0.0, 180.0))
        return Layout.conical(draw(st.sampled_from([1, 2])), n, deg_to_rad(alpha_deg))
    raw = draw(arrays(np.float64, (n, 3), elements=st.floats(-1.0, 1.0)))
    norms = np.linalg.norm(raw, axis=1)
    assume(np.all(norms > 1e-3))
    return Layout.from_axes(raw / norms[:, None])


@st.composite
def times(draw, n: int) -> np.ndarray:
    """Strictly increasing times with steps within ±10 % of a nominal period."""
    t0 = draw(st.floats(-1e6, 1e6))
    dt = draw(st.floats(1e-4, 1e3))
    jitter = draw(arrays(np.float64, n - 1, elements=st.floats(0.9, 1.1)))
    t = t0 + np.concatenate(([0.0], np.cumsum(dt * jitter)))
    step = np.diff(t)
    assume(np.all(step > 0) and step.max() < GAP_FACTOR * np.median(step))
    return t


@st.composite
def measurements(draw, max_n: int = 30) -> Measurement:
    layout = draw(layouts())
    n = draw(st.integers(2, max_n))
    site = None
    if draw(st.booleans()):
        site = Site(deg_to_rad(draw(st.floats(-90.0, 90.0))),
                    deg_to_rad(draw(st.floats(-720.0, 720.0))))
    return Measurement(
        time_s=draw(times(n)),
        gyro_deg_s=draw(arrays(np.float64, (n, layout.n_gyros), elements=rates)),
        layout=layout,
        sample_rate_hz=draw(st.floats(1e-3, 1e6)),
        ref_deg_s=draw(st.none() | arrays(np.float64, (n, 3), elements=rates)),
        temp_c=draw(st.none() | arrays(np.float64, n, elements=finite)),
        site=site,
        description=draw(st.text(st.characters(codec="utf-8"), max_size=20)),
    )


def same_bits(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and np.array_equal(np.ascontiguousarray(a).view(np.uint64),
                                                 np.ascontiguousarray(b).view(np.uint64))


@CI
@given(m=measurements(), gz=st.booleans())
def test_write_read_round_trip_is_exact(m, gz):
    with tempfile.TemporaryDirectory() as d:
        csv_path, _ = write_measurement(m, Path(d) / ("run.csv.gz" if gz else "run.csv"))
        back = read_measurement(csv_path)
    for name in ("time_s", "gyro_deg_s", "ref_deg_s", "temp_c"):
        assert same_bits(getattr(back, name), getattr(m, name)), name
    if m.layout.scheme is not None:       # written as scheme / n_gyros / alpha_deg
        assert np.array_equal(back.layout.axes, m.layout.axes)
        assert (back.layout.scheme, back.layout.alpha_rad) == (m.layout.scheme,
                                                               m.layout.alpha_rad)
    np.testing.assert_allclose(back.layout.axes, m.layout.axes, rtol=0, atol=1e-15)
    assert back.site == m.site
    assert (back.sample_rate_hz, back.description) == (m.sample_rate_hz, m.description)


# -- corruption -------------------------------------------------------------
@st.composite
def corruptions(draw, size: int, body: int = 0):
    """Edits (kind, position, payload, length), applied in order; positions
    fall in ``[body, size)`` half of the time (the samples, not the header)."""
    edits = []
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "insert", "delete", "truncate"]))
        pos = draw(st.integers(0, max(size - 1, 0))
                   | st.integers(min(body, max(size - 1, 0)), max(size - 1, 0)))
        payload = draw(st.sampled_from([b",", b"\n", b"\r", b"#", b'"', b"nan", b"-", b"e9",
                                        b"\x00", b"\xff", b" ", b"[", b"=", b"1"])
                       | st.binary(min_size=1, max_size=4))
        edits.append((kind, pos, payload, draw(st.integers(1, 8))))
    return edits


def corrupt(data: bytes, edits) -> bytes:
    for kind, pos, payload, length in edits:
        pos = min(pos, len(data))
        if kind == "flip" and pos < len(data):
            data = data[:pos] + payload[:1] + data[pos + 1:]
        elif kind == "insert":
            data = data[:pos] + payload + data[pos:]
        elif kind == "delete":
            data = data[:pos] + data[pos + length:]
        elif kind == "truncate":
            data = data[:pos]
    return data


def _after_header(text: bytes) -> int:
    """Offset of the first sample line of a file written by write_measurement."""
    return text.find(b"\n", text.find(b"\n") + 1) + 1


def read_or_refuse(csv_path: Path, repair: bool) -> None:
    try:
        m = read_measurement(csv_path, repair=repair)
    except InputError as e:
        assert str(e) and "\n" not in str(e)
        return
    assert isinstance(m, Measurement) and m.n_samples >= 2


@CI
@given(m=measurements(max_n=12), data=st.data(),
       target=st.sampled_from(["csv", "gz text", "gz bytes", "sidecar"]), repair=st.booleans())
def test_corrupted_files_give_measurement_or_input_error(m, data, target, repair):
    gz = target.startswith("gz")
    with tempfile.TemporaryDirectory() as d:
        csv_path, toml_path = write_measurement(m, Path(d) / ("r.csv.gz" if gz else "r.csv"))
        victim = toml_path if target == "sidecar" else csv_path
        raw = victim.read_bytes()
        if target in ("csv", "gz text"):   # corrupt the text (then compress it again)
            text = gzip.decompress(raw) if gz else raw
            edits = data.draw(corruptions(len(text), body=_after_header(text)))
            victim.write_bytes(gzip.compress(corrupt(text, edits)) if gz
                               else corrupt(text, edits))
        else:
            victim.write_bytes(corrupt(raw, data.draw(corruptions(len(raw)))))
        read_or_refuse(csv_path, repair)
