"""Resampling a channel onto the observer's grid (codegen/validation/logfiles.py), by itself: ``hold``
and ``linear`` never read a sample from the future, and ``linear`` is the channel delayed by its
largest step. Pure numpy, no compiled step: the fast lane runs it (the logs through ``validate``:
test_log_formats)."""
from pathlib import Path

import numpy as np
import pytest

from codegen.errors import DatasetError
from codegen.validation import logfiles


@pytest.mark.parametrize("method", ["hold", "linear"])
def test_resampling_never_reads_a_sample_from_the_future(method):
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.015, 0.025, 400))                  # a jittery 50 Hz channel
    x = rng.standard_normal(t.size)
    grid = np.arange(t[0] + 0.03, t[-1], 0.01)
    ch = logfiles.Channel(Path("x.mf4"), "x", t, x, None, method)
    before, latency = logfiles.resample(ch, grid, 0.01)
    cut = t.size // 2
    x2 = x.copy()
    x2[cut:] += 100.0                                               # the future, changed
    after, _ = logfiles.resample(logfiles.Channel(Path("x.mf4"), "x", t, x2, None, method), grid, 0.01)
    past = grid < t[cut] - 1e-9
    assert np.array_equal(before[past], after[past])
    assert not np.array_equal(before[~past], after[~past])
    assert latency == (ch.max_step if method == "linear" else 0.0)


def test_linear_is_the_channel_delayed_by_its_step():
    t = 0.02 * np.arange(100)
    ch = logfiles.Channel(Path("x.mf4"), "x", t, 3.0 * t, None, "linear")
    grid = np.arange(0.02, 1.9, 0.01)
    values, latency = logfiles.resample(ch, grid, 0.01)
    assert latency == pytest.approx(0.02)
    assert np.allclose(values, 3.0 * (grid - 0.02))




def test_a_gap_is_refused_and_a_slow_channel_is_not():
    t = 0.02 * np.arange(50)
    logfiles.Channel(Path("x.mf4"), "x", t, np.zeros(50), None, "hold")            # 50 Hz: no gap
    with pytest.raises(DatasetError, match=r"x.mf4: channel 'x': gap of 0.06 s after t = 0.4 s \(3 x its median"):
        logfiles.Channel(Path("x.mf4"), "x", np.r_[t[:21], t[23:]], np.zeros(48), None, "hold")
