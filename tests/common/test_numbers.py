"""The one number formatter and the one stored-value conversion (:mod:`mbh._harness.common.numbers`)."""

from __future__ import annotations

import math

import pandas as pd

from mbh._harness.common.numbers import as_float, float_or_nan, format_number


def test_format_number():
    assert [format_number(v) for v in (None, math.nan, pd.NA, 1.23456, 5, math.inf, 1e-12)] == \
        ["-", "-", "-", "1.23", "5", "inf", "1e-12"]
    assert format_number(1.23456, digits=2) == "1.2"


def test_as_float_and_float_or_nan():
    assert [as_float(v) for v in (None, math.nan, "NaN", pd.NA, math.inf, "x", "2.5", 3)] == \
        [None, None, None, None, None, None, 2.5, 3.0]
    assert math.isnan(float_or_nan(None)) and math.isnan(float_or_nan(pd.NA))
    assert float_or_nan(math.inf) == math.inf and float_or_nan("2") == 2.0
