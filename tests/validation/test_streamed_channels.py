"""MDF4 logs and ROS 2 bags are put on the observer's grid chunk by chunk (codegen/validation/logfiles.py,
issue 41: "large files streamed"): the values are those of the channels held whole (``time_base``,
``on_grid``, ``resample``) to the last bit, for every method and rate, while the reader never holds more
than a chunk of the grid and the samples around it. Files written by asammdf and rosbags; no compiled
step (the fast lane runs it)."""
from pathlib import Path

import numpy as np
import pytest

from codegen.validation import logfiles

asammdf = pytest.importorskip("asammdf")            # the validation extra (make venv installs it)

TS = 0.01
CHUNK = 97                                           # grid samples per chunk: not a divisor of anything


def _signals():
    """Four channels over 10 s: on the grid, at 200 Hz (linear), at 50 Hz (hold), and at 100 Hz 3 ms off
    the grid (hold): every path of the resampling."""
    rng = np.random.default_rng(4)
    t100 = 1.0 + TS * np.arange(1000)
    out = {"on": (t100, rng.standard_normal(t100.size), "hold"),
           "fast": (1.0 + 0.005 * np.arange(2000), rng.standard_normal(2000), "linear"),
           "slow": (1.0 + 0.02 * np.arange(500), rng.standard_normal(500), "hold"),
           "off": (t100 + 0.003, rng.standard_normal(t100.size), "hold")}
    return out


def _whole(p: Path, signals: dict):
    """The grid and the values of the channels held whole."""
    chans = [logfiles.Channel(p, n, t, x, None, m) for n, (t, x, m) in signals.items()]
    grid = logfiles.time_base(chans, TS)
    values = {}
    for c in chans:
        x = logfiles.on_grid(c, grid, TS)
        values[c.name] = x if x is not None else logfiles.resample(c, grid, TS)[0]
    return grid, values


def _streamed(reader, time_key="t"):
    parts, firsts = [], []
    for first, cols in reader.chunks():
        firsts.append(first)
        parts.append(cols)
    assert firsts == list(np.cumsum([0] + [c[time_key].size for c in parts[:-1]]))
    return {k: np.concatenate([c[k] for c in parts]) for k in parts[0]}


@pytest.fixture
def held(monkeypatch):
    """The most samples any channel's held part reached."""
    most = {"n": 0}
    cover = logfiles._Held.cover

    def counting(self, until):
        cover(self, until)
        most["n"] = max(most["n"], self.t.size)
    monkeypatch.setattr(logfiles._Held, "cover", counting)
    return most


def test_an_mdf_log_streamed_is_the_log_held_whole(tmp_path, monkeypatch, held):
    monkeypatch.setattr(logfiles, "MDF_FRAGMENT", 4096)          # 512 records a fragment: many of them
    signals = _signals()
    path = tmp_path / "log.mf4"
    mdf = asammdf.MDF(version="4.10")
    for name, (t, x, _) in signals.items():                     # a channel group per channel (per rate)
        mdf.append([asammdf.Signal(x, t, name=name, unit="m/s")])
    mdf.save(path, overwrite=True)
    mdf.close()
    reader = logfiles.MdfLog(path, {n: "m/s" for n in signals}, "t", {n: m for n, (_, _, m) in signals.items()},
                             TS, CHUNK)
    got = _streamed(reader)
    grid, values = _whole(path, signals)
    assert np.array_equal(got["t"], grid)
    for name in signals:
        assert np.array_equal(got[name], values[name]), name
    assert {n: r["method"] for n, r in reader.resampling.items()} == {
        "on": "as recorded", "fast": "linear", "slow": "hold", "off": "hold"}
    assert reader.rows == grid.size and reader.file_units == {n: "m/s" for n in signals}
    # bounded: a chunk of the grid (and the fragment that carried it), never a whole channel (2000 samples)
    assert 0 < held["n"] <= 2 * CHUNK + 2 * 4096 // 16, held["n"]


def test_a_ros2_bag_streamed_is_the_bag_held_whole(tmp_path, monkeypatch, held):
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    monkeypatch.setattr(logfiles, "BAG_BATCH", 64)
    signals = _signals()
    store = get_typestore(Stores.LATEST)
    f64 = "std_msgs/msg/Float64"
    events = sorted((int(round(t * 1e9)), name, float(v)) for name, (ts, xs, _) in signals.items()
                    for t, v in zip(ts, xs))
    with Writer(tmp_path / "bag", version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = {name: w.add_connection(f"/{name}", f64, typestore=store) for name in signals}
        for ns, name, v in events:                               # timed by the recording, in time order
            w.write(conn[name], ns, store.serialize_cdr(store.types[f64](v), f64))
    channels = {f"/{n}.data": "m/s" for n in signals}
    reader = logfiles.BagLog(tmp_path / "bag", channels, "t", {f"/{n}.data": m for n, (_, _, m) in signals.items()},
                             TS, CHUNK)
    got = _streamed(reader)
    # the bag's times are whole nanoseconds: the channels held whole at those times
    whole = {n: (np.array([ns for ns, m, _ in events if m == n]) * 1e-9, x, m) for n, (_, x, m) in signals.items()}
    grid, values = _whole(tmp_path / "bag", whole)
    assert np.array_equal(got["t"], grid)
    for name in signals:
        assert np.array_equal(got[f"/{name}.data"], values[name]), name
    assert reader.resampling["/on.data"]["method"] == "as recorded"
    assert 0 < held["n"] <= 2 * CHUNK + 4 * 64, held["n"]


@pytest.mark.parametrize("fault", ["repeated time", "gap", "non-finite", "rate change"])
def test_a_channel_judged_in_parts_is_judged_as_a_whole(fault):
    """Its faults and facts (the refusal, its sample and count; the rate change, the short steps) do not
    depend on where the parts end: 1000 samples fed whole and cut in 1, 7 and 333-sample parts."""
    t, x = 0.01 * np.arange(3000), np.zeros(3000)
    if fault == "repeated time":
        t[1500] = t[1499]
    elif fault == "gap":
        t[2000:] += 0.05
    elif fault == "non-finite":
        x[[10, 2500]] = np.nan
    else:
        t[2000:] = t[2000] + 0.0125 * np.arange(1000)          # 100 Hz, then 80 Hz

    def judged(size):
        c = logfiles.Sampling(Path("x.mf4"), "x", None, "hold")
        for k in range(0, t.size, size):
            c.feed(t[k:k + size], x[k:k + size])
        try:
            c.finish()
        except logfiles.DatasetError as exc:
            return str(exc)
        return (c.period, c.max_step, c.short, c.rate_change and c.rate_change[::2], c.start, c.end)
    whole = judged(t.size)
    assert all(judged(size) == whole for size in (1, 7, 333)), [judged(s) for s in (1, 7, 333)]
    if fault != "rate change":
        assert isinstance(whole, str) and "x.mf4: channel 'x'" in whole, whole
    else:
        assert whole[3] == (20.0, pytest.approx(0.0125)), whole
