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


def test_one_definition_by_hand():
    """signal_report: the figures of every validation table, with the unit they are in."""
    row = M.signal_report(Y, YH, unit="N")
    assert row["unit"] == "N" and "converted_from" not in row
    assert row["rms"] == pytest.approx(math.sqrt(5.25 / 4)) and row["mae"] == pytest.approx(0.875)
    assert row["max"] == 2.0 and row["bias"] == pytest.approx(1.5 / 4)
    assert row["std"] == pytest.approx(M.std_error(Y, YH))
    assert row["truth_rms"] == pytest.approx(math.sqrt(30 / 4))
    assert row["rms_percent"] == pytest.approx(100 * math.sqrt(5.25 / 30))
    assert row["nmse_percent"] == pytest.approx(-5.0) and row["samples"] == 4
    assert set(row) <= set(M.DEFINITIONS)


def test_only_plane_angles_are_converted_and_say_so():
    angle = M.signal_report(Y, YH, unit="rad")
    assert angle["unit"] == "deg" and angle["converted_from"] == "rad"
    assert angle["rms"] == pytest.approx(math.degrees(math.sqrt(5.25 / 4)))
    assert angle["rms_percent"] == pytest.approx(M.signal_report(Y, YH, unit="N")["rms_percent"])
    wheel = M.signal_report(Y, YH, unit="rad/s")            # a wheel speed (or a yaw rate) is no angle
    assert wheel["unit"] == "rad/s" and "converted_from" not in wheel
    assert wheel["rms"] == pytest.approx(math.sqrt(5.25 / 4))
    assert M.signal_report(Y, YH, unit=None)["unit"] is None
    assert M.signal_report(Y, YH, unit="-")["unit"] == "1"
    # a paper's table in the paper's units, from the same row
    assert M.convert(wheel, "deg/s")["rms"] == pytest.approx(math.degrees(wheel["rms"]))
    back = M.convert(angle, "rad")
    assert back["unit"] == "rad" and "converted_from" not in back and back["rms"] == pytest.approx(wheel["rms"])
    with pytest.raises(M.MetricInputError, match="do not convert"):
        M.convert(wheel, "m/s")


def test_a_zero_truth_has_no_percentages():
    row = M.signal_report(np.zeros(4), YH, unit="m")
    assert row["truth_rms"] == 0.0 and row["rms_percent"] is None and row["nmse_percent"] is None


def test_the_sums_of_a_stream_give_the_same_row():
    e, y = YH - Y, Y
    halves = [(e[:2], y[:2]), (e[2:], y[2:])]
    n = sum(a.size for a, _ in halves)
    mean = sum(a.sum() for a, _ in halves) / n
    row = M.report_from_sums("rad", n=n, abs_sum=sum(np.abs(a).sum() for a, _ in halves),
                             abs_max=max(np.abs(a).max() for a, _ in halves), sq_sum=sum((a * a).sum() for a, _ in halves),
                             mean=mean, m2=sum(((a - mean) ** 2).sum() for a, _ in halves),
                             truth_sq_sum=sum((b * b).sum() for _, b in halves),
                             truth_m2=float(((y - y.mean()) ** 2).sum()))
    whole = M.signal_report(Y, YH, unit="rad")
    assert row.keys() == whole.keys()
    assert all(row[k] == pytest.approx(whole[k]) for k in row if k not in ("unit", "converted_from"))


# --- the paired moving-block bootstrap of an RMS difference ---------------------------------------

def _bootstrap_by_loop(a, b, block, draws, seed):
    """The same resampling written plainly: k blocks at the generator's starts, both errors."""
    n = a.size
    k = n // block
    starts = np.random.default_rng(seed).integers(0, n - block + 1, size=(draws, k))
    d = []
    for row in starts:
        idx = np.concatenate([np.arange(s, s + block) for s in row])
        d.append(math.sqrt(np.mean(a[idx] ** 2)) - math.sqrt(np.mean(b[idx] ** 2)))
    return np.array(d)


def test_rms_difference_interval_against_a_plain_loop():
    rng = np.random.default_rng(7)
    a = np.convolve(rng.normal(size=700), np.ones(20) / 20, mode="same")       # correlated errors
    b = a + 0.05 * rng.normal(size=700)
    r = M.rms_difference_interval(a, b, block=50, draws=300, seed=3)
    d = _bootstrap_by_loop(a, b, 50, 300, 3)
    assert r["difference"] == pytest.approx(math.sqrt(np.mean(a ** 2)) - math.sqrt(np.mean(b ** 2)), rel=1e-12)
    assert r["low"] == pytest.approx(np.percentile(d, 2.5), rel=1e-9, abs=1e-15)
    assert r["high"] == pytest.approx(np.percentile(d, 97.5), rel=1e-9, abs=1e-15)
    assert r["share_below_zero"] == np.mean(d < 0)
    assert (r["block"], r["draws"], r["samples"], r["level"]) == (50, 300, 700, 0.95)
    assert M.rms_difference_interval(a, b, block=50, draws=300, seed=3) == r          # deterministic


def test_rms_difference_interval_of_equal_and_of_scaled_errors():
    e = np.sin(np.linspace(0.0, 20.0, 1000))
    same = M.rms_difference_interval(e, e.copy(), block=100)
    assert same["difference"] == same["low"] == same["high"] == 0.0 and same["share_below_zero"] == 0.0
    half = M.rms_difference_interval(0.5 * e, e, block=100)       # a is lower in every draw
    assert half["high"] < 0.0 and half["share_below_zero"] == 1.0
    assert half["low"] <= half["difference"] <= half["high"]


@pytest.mark.parametrize("a, b, block", [(np.ones(10), np.ones(9), 2), (np.ones(10), np.ones(10), 0),
                                         (np.ones(10), np.ones(10), 11), (np.ones((2, 5)), np.ones((2, 5)), 2)])
def test_rms_difference_interval_refuses_bad_arguments(a, b, block):
    with pytest.raises(ValueError):
        M.rms_difference_interval(a, b, block=block)
