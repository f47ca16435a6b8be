"""Logs in Parquet and MDF4 (issue 41): ``uiogen validate OBSERVER --data LOG`` reads the format the
file's first bytes say, takes the units the file states, puts channels at their own rates onto the
observer's sample time, and gives the figures of the same data as a CSV.

The runs use the ``stanford_sideslip`` observer (its committed design and built extension; the
observer file is copied with a ``[data]`` table, ``--project`` the checkout, as in test_log_checks)
on the first :data:`ROWS` rows of the shared Ferrari log: 30 s at 100 Hz hold the settle time, a
few corners and every physics check's excitation, and keep a run under a second (the whole
27,500 rows adds minutes over the suite for no other path). Every file is written by the real
library of its format (pyarrow, asammdf) and read back through ``validate``.
"""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from codegen.errors import ConfigurationError, DatasetError
from codegen.project import observer_file as observers
from codegen.validation import logs
from codegen.validation import logs
from codegen.validation import stanford as S
from codegen.validation.common import SETTLE_TIME

from conftest import require_shared

asammdf = pytest.importorskip("asammdf")            # the validation extra (make venv installs it)

pytestmark = pytest.mark.slow                       # runs a compiled extension (the fast lane has no build)

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
NAME = "stanford_sideslip"
ROWS = 3000
UNITS = {"delta": "rad", "yaw_rate": "rad/s", "ay": "m/s^2", "vx": "m/s", "beta_true": "rad"}
MAP = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx"}


def _observer(folder: Path, units: bool = True, time: str = '"t"', **changes) -> Path:
    """The observer file with a [data] map of the Stanford columns, with their units or without
    (``units=False``: the file's units are used); ``time``: the map's time entry; ``changes``:
    SIGNAL = "inline table"."""
    text = (ROOT / "model_defs" / "observers" / f"{NAME}.toml").read_text()
    params = re.search(r'(?m)^parameters = "([^"]+)"', text).group(1)
    (folder / params).write_text((ROOT / "model_defs" / "params" / params).read_text())
    entries = {k: f'{{ column = "{c}"' + (f', unit = "{UNITS[c]}"' if units else "") + " }" for k, c in MAP.items()}
    entries["beta"] = '{ column = "beta_true"' + (', unit = "rad"' if units else "") + " }"
    entries.update(changes)
    text += f"\n[data]\ntime = {time}\n\n[data.inputs]\n"
    text += "".join(f"{k} = {v}\n" for k, v in entries.items() if k != "beta")
    text += f"\n[data.truth]\nbeta = {entries['beta']}\n"
    path = folder / f"{NAME}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """The log's slice as columns, its CSV, the mapped observer file and the CSV's result."""
    require_shared(S.STANFORD_PATH, "shared Stanford log")
    folder = tmp_path_factory.mktemp("formats")
    table = pcsv.read_csv(S.STANFORD_PATH).slice(0, ROWS)
    pcsv.write_csv(table, folder / "log.csv")
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    observer = _observer(folder)
    csv = logs.run(observers.get(str(observer), project=ROOT), str(folder / "log.csv"))
    return {"folder": folder, "table": table, "cols": cols, "observer": observer, "csv": csv}


def _run(observer: Path, log: Path, **kw) -> dict:
    return logs.run(observers.get(str(observer), project=ROOT), str(log), **kw)


def _mdf(path: Path, channels: dict) -> Path:
    """An MDF 4.10 file, one channel group per channel: ``{name: (t, x, unit)}``."""
    mdf = asammdf.MDF(version="4.10")
    for name, (t, x, unit) in channels.items():
        mdf.append([asammdf.Signal(np.asarray(x, float), np.asarray(t, float), name=name, unit=unit)])
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


def _stanford_mdf(path: Path, cols: dict, **override) -> Path:
    t = cols["t"]
    channels = {c: (t, cols[c], u) for c, u in UNITS.items()}
    channels.update(override)
    return _mdf(path, channels)


def _cli_error(observer: Path, log: Path) -> str:
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", str(observer), "--data", str(log),
                           "--project", str(ROOT)], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("uiogen: error: DatasetError: ") and str(log) in err, err
    return err


# --- the same data, three formats, the same figures --------------------------------------------------

def test_parquet_gives_the_csv_figures_batch_by_batch(data, tmp_path):
    log = tmp_path / "log.parquet"
    pq.write_table(data["table"], log, row_group_size=700)          # several row groups, batches across them
    res = _run(data["observer"], log, batch_rows=512)
    csv = data["csv"]
    assert res["format"] == "parquet" and res["samples"] == ROWS
    assert abs(res["observer"]["beta"]["rms"] - csv["observer"]["beta"]["rms"]) <= 1e-12
    assert np.array_equal(res["signals"]["beta"], csv["signals"]["beta"])


def test_parquet_units_from_the_field_metadata_are_converted(data, tmp_path):
    # degrees, deg/s, g and km/h in the file, said by each field's metadata; the map gives no unit
    into = {"delta": ("deg", 180 / np.pi), "yaw_rate": ("deg/s", 180 / np.pi), "ay": ("g", 1 / 9.80665),
            "vx": ("km/h", 3.6), "beta_true": ("rad", 1.0), "t": ("ms", 1e3)}
    cols = data["cols"]
    fields = [pa.field(c, pa.float64(), metadata={"unit": u}) for c, (u, _) in into.items()]
    table = pa.Table.from_arrays([pa.array(cols[c] * f) for c, (_, f) in into.items()], schema=pa.schema(fields))
    log = tmp_path / "units.parquet"
    pq.write_table(table, log)
    res = _run(_observer(tmp_path, units=False), log)
    assert res["observer"]["beta"]["rms"] == pytest.approx(data["csv"]["observer"]["beta"]["rms"], rel=1e-9)
    assert res["warnings"] == []


def test_mdf_on_the_observer_grid_gives_the_csv_figures(data, tmp_path):
    log = _stanford_mdf(tmp_path / "log.mf4", data["cols"])
    res = _run(_observer(tmp_path, units=False), log)        # the units are the channels'
    assert res["format"] == "mdf" and res["samples"] == ROWS
    assert abs(res["observer"]["beta"]["rms"] - data["csv"]["observer"]["beta"]["rms"]) <= 1e-12
    assert np.array_equal(res["signals"]["beta"], data["csv"]["signals"]["beta"])
    assert {r["method"] for r in res["resampling"].values()} == {"as recorded"}


def test_mdf_channels_at_200_100_and_50_hz(data, tmp_path):
    """a_y at 200 Hz (the 100 Hz samples and the midpoints between them), v_x at 50 Hz (every other
    sample): a_y held at the grid times is its 100 Hz samples again; v_x is held one step in two, 10 ms
    old, an error of |a_x| x 10 ms (under 0.1 m/s at 26 m/s, 0.4 %) in half the steps. The sideslip RMS
    moves by far less than 1 %, but it moves (the hold is applied, not skipped)."""
    cols = data["cols"]
    t = cols["t"]
    t200 = np.repeat(t, 2)[:-1] + np.tile([0.0, 0.005], t.size)[:-1]
    log = _stanford_mdf(tmp_path / "multi.mf4", cols, ay=(t200, np.interp(t200, t, cols["ay"]), "m/s^2"),
                        vx=(t[::2], cols["vx"][::2], "m/s"))
    res = _run(_observer(tmp_path, units=False), log)
    rms, ref = res["observer"]["beta"]["rms"], data["csv"]["observer"]["beta"]["rms"]
    assert 0 < abs(rms - ref) < 0.01 * ref, (rms, ref)
    assert res["resampling"]["ay"]["method"] == "hold" and res["resampling"]["ay"]["rate_hz"] == pytest.approx(200)
    assert res["resampling"]["vx"]["rate_hz"] == pytest.approx(50)
    assert any("'vx' is sampled at 50 Hz, slower than the observer's 100 Hz" in w for w in res["warnings"])
    assert "resampled onto the observer's sample time: 'ay' 200 Hz, hold; 'vx' 50 Hz, hold" in logs.format_table(res)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_csv_or_parquet_log_at_200_hz_is_put_on_the_observer_grid(data, tmp_path, suffix):
    """A table at twice the observer's rate (the 100 Hz samples and the midpoints between them): held
    at the grid times it is the 100 Hz log again, to the last bit. Before, the time check refused it
    (the log's period 0.005 s is not the observer's 0.01 s)."""
    cols = data["cols"]
    t = cols["t"]
    t200 = np.repeat(t, 2)[:-1] + np.tile([0.0, 0.005], t.size)[:-1]
    table = pa.table({c: np.interp(t200, t, cols[c]) if c != "t" else t200 for c in data["table"].column_names})
    log = tmp_path / f"log200{suffix}"
    pcsv.write_csv(table, log) if suffix == ".csv" else pq.write_table(table, log)
    res = _run(data["observer"], log, block_bytes=1 << 14) if suffix == ".csv" else _run(data["observer"], log)
    assert res["samples"] == ROWS
    assert np.array_equal(res["signals"]["beta"], data["csv"]["signals"]["beta"])
    assert {r["method"] for r in res["resampling"].values()} == {"hold"}
    assert all(r["rate_hz"] == pytest.approx(200) for r in res["resampling"].values())


def test_a_csv_log_at_50_hz_is_held_and_said(data, tmp_path):
    """Every other row: each value held one step in two; the sideslip moves by less than 5 %, the
    warning names every column slower than the observer; times in ms (the map's unit) convert first."""
    cols = data["cols"]
    table = data["table"].take(np.arange(0, ROWS, 2))
    table = table.set_column(table.column_names.index("t"), "t", pa.array(cols["t"][::2] * 1e3))
    log = tmp_path / "log50.csv"
    pcsv.write_csv(table, log)
    res = _run(_observer(tmp_path, time='{ column = "t", unit = "ms" }'), log)
    rms, ref = res["observer"]["beta"]["rms"], data["csv"]["observer"]["beta"]["rms"]
    assert 0 < abs(rms - ref) < 0.05 * ref, (rms, ref)
    assert res["samples"] == ROWS - 1
    for c in ("delta", "yaw_rate", "ay", "vx"):
        assert any(f"{c!r} is sampled at 50 Hz, slower than the observer's 100 Hz" in w for w in res["warnings"])


def test_linear_reports_its_latency(data, tmp_path):
    cols = data["cols"]
    t = cols["t"]
    log = _stanford_mdf(tmp_path / "slow.mf4", cols, vx=(t[::2], cols["vx"][::2], "m/s"))
    res = _run(_observer(tmp_path, units=False, v_x='{ column = "vx", resample = "linear" }'), log)
    assert res["resampling"]["vx"]["method"] == "linear"
    assert res["resampling"]["vx"]["latency_s"] == pytest.approx(0.02, rel=1e-6)
    rms, ref = res["observer"]["beta"]["rms"], data["csv"]["observer"]["beta"]["rms"]
    assert 0 < abs(rms - ref) < 0.01 * ref, (rms, ref)


def test_a_rate_change_is_a_warning(data, tmp_path):
    cols = data["cols"]
    t = cols["t"]
    tc = np.r_[t[:2000], np.arange(t[2000], t[-1], 0.0125)]         # 100 Hz, then 80 Hz: no gap, another rate
    log = _stanford_mdf(tmp_path / "rate.mf4", cols, delta=(tc, np.interp(tc, t, cols["delta"]), "rad"))
    res = _run(_observer(tmp_path, units=False), log)
    said = [w for w in res["warnings"] if w.startswith("channel 'delta' changes its rate")]
    assert len(said) == 1 and "(80 Hz) from t = " in said[0] and "(100 Hz) over the log" in said[0], res["warnings"]


# --- typed errors: one line naming the file and the channel ---------------------------------------------

def test_a_channel_unit_of_the_wrong_kind(data, tmp_path):
    cols = data["cols"]
    log = _stanford_mdf(tmp_path / "kind.mf4", cols, ay=(cols["t"], cols["ay"], "deg/s"))
    err = _cli_error(_observer(tmp_path, units=False), log)
    assert "channel 'ay' (y_a_y) has unit 'deg/s' in the file, a unit of angular rate" in err, err
    assert "the model's unit is 'm/s^2', a unit of acceleration" in err, err


def test_a_missing_channel_lists_the_closest_names(data, tmp_path):
    log = _stanford_mdf(tmp_path / "log.mf4", data["cols"])
    err = _cli_error(_observer(tmp_path, units=False, y_r='{ column = "yawrate" }'), log)
    assert "missing channel(s) ['yawrate']" in err and "closest in the file 'yaw_rate'" in err, err


def test_a_channel_with_a_gap(data, tmp_path):
    cols = data["cols"]
    keep = np.r_[0:1000, 1010:ROWS]                                  # 10 samples (0.1 s) of a_y lost
    log = _stanford_mdf(tmp_path / "gap.mf4", cols, ay=(cols["t"][keep], cols["ay"][keep], "m/s^2"))
    err = _cli_error(_observer(tmp_path, units=False), log)
    assert "channel 'ay': gap of 0.11 s after t = " in err and "11 x its median period 0.01 s" in err, err


def test_map_unit_and_file_unit_disagree(data, tmp_path):
    log = _stanford_mdf(tmp_path / "log.mf4", data["cols"])
    err = _cli_error(_observer(tmp_path, y_a_y='{ column = "ay", unit = "g" }'), log)
    assert "channel 'ay' (y_a_y) has unit 'm/s^2' in the file but 'g' in the observer file's [data] map" in err, err


def test_an_unknown_file_unit_is_refused_unless_the_map_states_it(data, tmp_path):
    cols = data["cols"]
    log = _stanford_mdf(tmp_path / "odd.mf4", cols, vx=(cols["t"], cols["vx"], "furlong/fortnight"))
    with pytest.raises(DatasetError, match=r"channel 'vx' \(v_x\) has unit 'furlong/fortnight' in the file, which "
                                           r"uiogen does not know; allowed: rad, deg"):
        _run(_observer(tmp_path, units=False), log)
    res = _run(_observer(tmp_path, units=False, v_x='{ column = "vx", unit = "m/s" }'), log)
    assert abs(res["observer"]["beta"]["rms"] - data["csv"]["observer"]["beta"]["rms"]) <= 1e-12


@pytest.mark.parametrize("suffix", [".parquet", ".mf4"])
def test_a_damaged_file_is_one_line(data, tmp_path, suffix):
    whole = tmp_path / f"whole{suffix}"
    if suffix == ".parquet":
        pq.write_table(data["table"], whole)
    else:
        _stanford_mdf(whole, data["cols"])
    log = tmp_path / f"cut{suffix}"
    log.write_bytes(whole.read_bytes()[:5000])                      # a copy cut short: the magic, then nothing
    err = _cli_error(_observer(tmp_path, units=False), log)
    assert f"cannot read {log}: not a readable {'Parquet' if suffix == '.parquet' else 'MDF'} file (" in err, err


def test_out_of_a_log_in_the_shared_format(data, tmp_path):
    """The shared format runs through the same loop as a mapped log: --out writes its outputs too, the run's own."""
    out = tmp_path / "est.parquet"
    res = logs.run(NAME, str(data["folder"] / "log.csv"), out=out)
    table = pq.read_table(out)
    t, beta = table.column("time").to_numpy(), table.column("beta").to_numpy()
    assert res["out"] == str(out) and np.array_equal(t, data["cols"]["t"])
    assert int(np.count_nonzero(table.column("status").to_numpy())) == res["status_flags"]
    # the written sideslip is the one the table reports: the same RMS against the reference
    err = np.degrees(beta - data["cols"]["beta_true"])
    assert abs(np.sqrt(np.mean(err ** 2)) - res["observer"]["beta"]["rms"]) <= 1e-12


def test_a_resample_method_not_known(tmp_path):
    with pytest.raises(ConfigurationError, match=r"\[data.inputs.v_x\] resample = \"cubic\": hold .* or linear"):
        observers.get(str(_observer(tmp_path, v_x='{ column = "vx", resample = "cubic" }')), project=ROOT)


# --- --out: the outputs and status, read back by the library of their format ------------------------------

@pytest.mark.parametrize("suffix", [".mf4", ".parquet"])
def test_out_is_read_back(data, tmp_path, suffix):
    log = _stanford_mdf(tmp_path / "log.mf4", data["cols"])
    out = tmp_path / "res" / f"estimates{suffix}"
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", str(_observer(tmp_path, units=False)),
                           "--data", str(log), "--out", str(out), "--project", str(ROOT), "--json"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["out"] == str(out) and sorted(p.name for p in out.parent.iterdir()) == [out.name]   # no temporary
    ref = data["csv"]
    t = data["cols"]["t"]
    if suffix == ".mf4":
        mdf = asammdf.MDF(out)
        beta, status = mdf.get("beta"), mdf.get("status")
        mdf.close()
        times, values, unit, flags = beta.timestamps, beta.samples, beta.unit, status.samples
    else:
        table = pq.read_table(out)
        times, values = table.column("time").to_numpy(), table.column("beta").to_numpy()
        unit = table.schema.field("beta").metadata[b"unit"].decode()
        flags = table.column("status").to_numpy()
        assert table.schema.field("time").metadata[b"unit"] == b"s"
    assert np.array_equal(times, t)                                  # the log's own times, not from 0
    assert unit == "rad"                                             # the model's unit of beta
    assert int(np.count_nonzero(flags)) == ref["status_flags"] and flags.size == ROWS
    # the written sideslip is the run's: its error against the reference after the settle time is the CSV's RMS
    err = np.degrees(values - data["cols"]["beta_true"])[t - t[0] >= SETTLE_TIME]
    assert abs(np.sqrt(np.mean(err ** 2)) - ref["observer"]["beta"]["rms"]) <= 1e-12


def test_out_is_not_written_when_the_run_is_refused(data, tmp_path):
    cols = data["cols"]
    keep = np.r_[0:1000, 1010:ROWS]
    log = _stanford_mdf(tmp_path / "gap.mf4", cols, ay=(cols["t"][keep], cols["ay"][keep], "m/s^2"))
    (tmp_path / "out").mkdir()
    old = tmp_path / "out" / "estimates.parquet"
    old.write_bytes(b"the previous results")
    with pytest.raises(DatasetError, match="gap"):
        _run(_observer(tmp_path, units=False), log, out=old)
    assert old.read_bytes() == b"the previous results" and [p.name for p in old.parent.iterdir()] == [old.name]


def test_out_with_a_suffix_it_cannot_write(data, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", str(data["observer"]), "--data",
                           str(data["folder"] / "log.csv"), "--out", str(tmp_path / "est.csv"), "--project", str(ROOT)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and proc.stderr.startswith("uiogen: error: ConfigurationError: --out "), proc.stderr
    assert "allowed: .mf4, .mdf, .parquet, .pq" in proc.stderr and not (tmp_path / "est.csv").exists()


# --- ROS 2 bags (rosbags: sqlite3 and mcap storage) ----------------------------------------------------------

TOPICS = {"delta": ("/steer.data", "rad"), "y_r": ("/imu.angular_velocity.z", "rad/s"),
          "y_a_y": ("/imu.linear_acceleration.y", "m/s^2"), "v_x": ("/speed.data", "m/s"),
          "beta": ("/ref.data", "rad")}


def _bag(path: Path, storage: str, cols: dict, speed_every: int = 1) -> Path:
    """The Stanford slice as a ROS 2 bag: an Imu topic with header stamps (yaw rate, a_y), Float64 topics
    without (steering, speed, the reference: timed by the recording); the speed every ``speed_every``-th row."""
    rosbags = pytest.importorskip("rosbags")                         # noqa: F841 -- the validation extra
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.LATEST)
    T = store.types
    imu, f64 = "sensor_msgs/msg/Imu", "std_msgs/msg/Float64"
    with Writer(path, version=8, storage_plugin=getattr(StoragePlugin, storage)) as w:
        conn = {topic: w.add_connection(topic, kind, typestore=store)
                for topic, kind in (("/imu", imu), ("/steer", f64), ("/speed", f64), ("/ref", f64))}
        zeros = np.zeros(9)
        for k, t in enumerate(cols["t"]):
            ns = int(round(t * 1e9))
            stamp = T["builtin_interfaces/msg/Time"](ns // 10 ** 9, ns % 10 ** 9)
            vec = T["geometry_msgs/msg/Vector3"]
            msg = T[imu](T["std_msgs/msg/Header"](stamp, "base_link"), T["geometry_msgs/msg/Quaternion"](0, 0, 0, 1),
                         zeros, vec(0.0, 0.0, cols["yaw_rate"][k]), zeros, vec(0.0, cols["ay"][k], 0.0), zeros)
            w.write(conn["/imu"], ns, store.serialize_cdr(msg, imu))
            for topic, c in (("/steer", "delta"), ("/ref", "beta_true")) + ((("/speed", "vx"),)
                                                                         if k % speed_every == 0 else ()):
                w.write(conn[topic], ns, store.serialize_cdr(T[f64](float(cols[c][k])), f64))
    return path


def _bag_observer(folder: Path, **changes) -> Path:
    entries = {k: f'{{ column = "{c}", unit = "{u}" }}' for k, (c, u) in TOPICS.items()}
    entries.update(changes)
    return _observer(folder, **entries)


@pytest.mark.parametrize("storage", ["SQLITE3", "MCAP"])
def test_a_ros2_bag_on_the_grid_gives_the_csv_figures(data, tmp_path, storage):
    log = _bag(tmp_path / "bag", storage, data["cols"])
    res = _run(_bag_observer(tmp_path), log)
    assert res["format"] == "rosbag2" and res["samples"] == ROWS
    assert abs(res["observer"]["beta"]["rms"] - data["csv"]["observer"]["beta"]["rms"]) <= 1e-12
    assert np.array_equal(res["signals"]["beta"], data["csv"]["signals"]["beta"])


def test_a_ros2_bag_at_two_rates(data, tmp_path):
    log = _bag(tmp_path / "bag", "MCAP", data["cols"], speed_every=2)
    res = _run(_bag_observer(tmp_path), log)
    rms, ref = res["observer"]["beta"]["rms"], data["csv"]["observer"]["beta"]["rms"]
    assert 0 < abs(rms - ref) < 0.01 * ref, (rms, ref)                # as the MDF4 log's 50 Hz speed
    assert res["resampling"]["/speed.data"]["rate_hz"] == pytest.approx(50)


def test_a_ros2_field_or_topic_missing(data, tmp_path):
    log = _bag(tmp_path / "bag", "SQLITE3", data["cols"])
    err = _cli_error(_bag_observer(tmp_path, y_r='{ column = "/imu.angular_velocity.zz", unit = "rad/s" }'), log)
    assert "channel '/imu.angular_velocity.zz': the message has no field 'angular_velocity.zz' (closest: 'z'" in err
    err = _cli_error(_bag_observer(tmp_path, v_x='{ column = "/sped.data", unit = "m/s" }'), log)
    assert "missing topic(s) ['/sped'] ('/sped': closest in the file '/speed'" in err, err
