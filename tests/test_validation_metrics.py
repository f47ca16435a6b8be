"""Metrics of codegen.validation.metrics against hand-computed values."""
import math

import numpy as np
import pytest

from codegen.errors import SampleError
from codegen.validation import metrics as M

Y = np.array([1.0, 2.0, 3.0, 4.0])
YH = np.array([1.5, 1.0, 3.0, 6.0])          # errors: +0.5, -1, 0, +2


def test_seed000_statistics_by_hand():
    s = M.error_stats(Y, YH, unit="N m")
    assert s.e_mean == pytest.approx(3.5 / 4)                    # (0.5 + 1 + 0 + 2) / 4
    assert s.e_max == pytest.approx(2.0)
    mean = 1.5 / 4
    assert s.std == pytest.approx(math.sqrt(((0.5 - mean) ** 2 + (-1 - mean) ** 2 + mean ** 2
                                             + (2 - mean) ** 2) / 4))
    assert s.rms == pytest.approx(math.sqrt((0.25 + 1 + 0 + 4) / 4))
    assert (s.n, s.unit) == (4, "N m")
    assert M.mae(Y, YH) == M.mean_abs_error(Y, YH) == pytest.approx(0.875)
    assert M.rmsd(Y, YH) == M.rms_error(Y, YH) == pytest.approx(math.sqrt(5.25 / 4))
    assert M.max_abs_error(Y, YH) == 2.0 and M.std_error(Y, YH) == pytest.approx(s.std)


def test_degrees_flag():
    y = np.zeros(3)
    yh = np.array([math.pi / 180, -2 * math.pi / 180, 0.0])
    s = M.error_stats(y, yh, degrees=True)
    assert s.unit == "deg"
    assert s.e_max == pytest.approx(2.0) and s.e_mean == pytest.approx(1.0)
    assert M.rms_error(y, yh, degrees=True) == pytest.approx(math.sqrt(5 / 3))
    assert M.rms_error(y, yh) == pytest.approx(math.radians(math.sqrt(5 / 3)))


def test_seed003_eq32_by_hand():
    # ||y - yh||^2 = 5.25, ||y - mean y||^2 = 2.25 + .25 + .25 + 2.25 = 5
    assert M.nmse_percent(Y, YH) == pytest.approx(100 - 100 * 5.25 / 5)     # -5 %
    assert M.nmse_percent(Y, Y) == pytest.approx(100.0)
    assert M.nmse_percent(Y, np.full(4, Y.mean())) == pytest.approx(0.0)
    assert M.rmse_percent(Y, YH) == pytest.approx(100 * math.sqrt(5.25 / 4))


@pytest.mark.parametrize("bad", [
    (np.array([]), np.array([])),
    (np.array([1.0, np.nan]), np.array([1.0, 2.0])),
    (np.array([1.0, 2.0]), np.array([1.0, np.inf])),
    (np.array([1.0, 2.0]), np.array([1.0, 2.0, 3.0])),
    (np.ones((2, 2)), np.ones((2, 2))),
    (["a", "b"], [1.0, 2.0]),
])
def test_bad_input_is_typed(bad):
    with pytest.raises(M.MetricInputError):
        M.rms_error(*bad)
    with pytest.raises(SampleError):
        M.error_stats(*bad)


def test_nmse_constant_reference():
    with pytest.raises(M.MetricInputError, match="constant"):
        M.nmse_percent(np.ones(5), np.arange(5.0))


def test_stats_frozen():
    s = M.error_stats(Y, YH)
    with pytest.raises(AttributeError):
        s.rms = 0.0
    assert s.as_dict()["n"] == 4
