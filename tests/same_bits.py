"""Datasets compared bit for bit: the sweep tests' shared check."""

from __future__ import annotations

import numpy as np
import pandas as pd


def assert_same_bits(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Equal frames, floats compared by their bits (NaN included)."""
    assert list(a.columns) == list(b.columns) and len(a) == len(b) > 0
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    for col in a.columns:
        if a[col].dtype == np.float64:
            assert np.array_equal(a[col].to_numpy().view(np.uint64),
                                  b[col].to_numpy().view(np.uint64)), col
