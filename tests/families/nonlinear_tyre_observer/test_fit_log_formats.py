"""`uiogen fit --data` and `--judge` read the shared format in the files `uiogen validate --data` reads by
name (issue 41): the shared Ferrari half written as MDF4 (asammdf: channels with their units, every one at
100 Hz) and as Parquet (pyarrow) gives the CSV's fit to the last printed digit, through the reader of
validate (codegen.validation.stanford.open_log). The yaw acceleration is the log's recorded `yaw_acc`.

An observer file with a `[data]` map: the fit reads every format validate reads through the same map and reader
(codegen.validation.logs.MappedLog): the half as a ROS 2 bag (rosbags, MCAP) and as a DBC-encoded BLF (cantools,
python-can; IEEE double signals) gives the fit of the same rows as a CSV without `yaw_acc`, the yaw acceleration
derived from the yaw rate in both and said.
"""
import re
from pathlib import Path

import numpy as np
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from codegen import cli
from codegen.families.nonlinear_tyre_observer import fit
from codegen.validation import stanford

from conftest import require_shared

asammdf = pytest.importorskip("asammdf")            # the validation extra (make venv installs it)

NAME = "stanford_sideslip_nonlinear_tyre"
SAMPLES = "0:3000"                                   # 30 s: a few corners, the fit in seconds


def _fit_lines(capsys, data, *extra) -> list:
    assert cli.main(["fit", NAME, "--data", str(data), "--samples", SAMPLES, "--folds", "0", *extra]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.mark.slow       # three fits of 3000 samples with the EKF grid and a judged run: about 30 s
def test_the_fit_on_mdf4_and_parquet_prints_the_csv_fit(tmp_path, capsys):
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    table = pcsv.read_csv(stanford.STANFORD_PATH)
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    pq.write_table(table, tmp_path / "half.parquet", row_group_size=5000)
    mdf = asammdf.MDF(version="4.10")
    # units as a logger writes them: speed in km/h, angles in degrees, accelerations in g (converted back)
    into = {"vx": ("km/h", 3.6), "vy": ("km/h", 3.6), "delta": ("deg", 180 / np.pi), "ay": ("g", 1 / 9.80665)}
    mdf.append([asammdf.Signal(cols[c] * into.get(c, (None, 1.0))[1], cols["t"], name=c,
                               unit=into.get(c, (stanford.UNITS[c], 1.0))[0]) for c in stanford.COLUMNS if c != "t"])
    mdf.save(tmp_path / "half.mf4", overwrite=True)
    mdf.close()
    csv = _fit_lines(capsys, "stanford")
    for log in (tmp_path / "half.parquet", tmp_path / "half.mf4"):
        lines = _fit_lines(capsys, log)
        assert lines[0] == csv[0].replace("on stanford,", f"on {log},")
        assert lines[1:] == csv[1:], (log, lines, csv)
    # a judged run read from MDF4 (the rest of the half): the same figures as its CSV
    rest = {c: a[13750:] for c, a in cols.items()}
    pcsv.write_csv(table.slice(13750), tmp_path / "rest.csv")
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(rest[c], rest["t"], name=c, unit=stanford.UNITS[c]) for c in stanford.COLUMNS
                if c != "t"])
    mdf.save(tmp_path / "rest.mf4", overwrite=True)
    mdf.close()
    judged = [_fit_lines(capsys, "stanford", "--judge", str(tmp_path / f"rest.{s}"))[-4:] for s in ("csv", "mf4")]
    assert [x.replace("rest.mf4", "rest.csv") for x in judged[1]] == judged[0]


def test_a_channel_of_another_kind_of_unit_is_one_typed_line(tmp_path, capsys):
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    table = pcsv.read_csv(stanford.STANFORD_PATH).slice(0, 1000)
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(cols[c], cols["t"], name=c, unit="s" if c == "yaw_rate" else stanford.UNITS[c])
                for c in stanford.COLUMNS if c != "t"])
    log = tmp_path / "wrong.mf4"
    mdf.save(log, overwrite=True)
    mdf.close()
    assert cli.main(["fit", NAME, "--data", str(log), "--samples", "0:1000", "--folds", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("uiogen: error: DatasetError: ") and str(log) in err and "channel 'yaw_rate'" in err, err
    assert "a unit of time" in err and "a unit of angular rate" in err, err


# --- logs read through the observer file's [data] map (ROS 2 bag, CAN log) -----------------------------------

ROWS = 3000
MAPPED = {"delta": ("delta", "rad"), "a_x": ("ax", "m/s^2"), "y_a_y": ("ay", "m/s^2"), "y_r": ("yaw_rate", "rad/s"),
          "v_x": ("vx", "m/s"), "v_y": ("vy", "m/s")}
"""The observer's inputs and its lateral speed reference ([data.truth] v_y): the shared column of each, its unit."""
BAG = {"delta": "/steer.data", "a_x": "/imu.linear_acceleration.x", "y_a_y": "/imu.linear_acceleration.y",
       "y_r": "/imu.angular_velocity.z", "v_x": "/vel.twist.linear.x", "v_y": "/vel.twist.linear.y"}


def _mapped_observer(folder: Path, columns: dict, units: bool = True, dbc: str | None = None) -> Path:
    """The built-in observer file with a [data] map of ``columns`` ({key: the log's channel})."""
    from model_defs import PARAMS_DIR
    text = (PARAMS_DIR.parent / "observers" / f"{NAME}.toml").read_text()
    text = re.sub(r'(?m)^parameters = "([^"]+)"', lambda m: f'parameters = "{PARAMS_DIR / m.group(1)}"', text)

    def entry(k):
        return f'{k} = {{ column = "{columns[k]}"' + (f', unit = "{MAPPED[k][1]}"' if units else "") + " }\n"
    text += '\n[data]\ntime = "t"\n' + (f'dbc = "{dbc}"\n' if dbc else "") + "\n[data.inputs]\n"
    text += "".join(entry(k) for k in MAPPED if k != "v_y") + "\n[data.truth]\n" + entry("v_y")
    path = folder / f"{NAME}.toml"
    path.write_text(text)
    return path


def _bag(path: Path, cols: dict) -> Path:
    """The rows as a ROS 2 bag in MCAP: sensor_msgs/Imu (yaw rate, a_x, a_y) and geometry_msgs/TwistStamped
    (v_x, v_y) with header stamps, std_msgs/Float64 steering timed by the recording; every topic at 100 Hz."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.LATEST)
    T = store.types
    imu, twist, f64 = "sensor_msgs/msg/Imu", "geometry_msgs/msg/TwistStamped", "std_msgs/msg/Float64"
    vec, zeros = T["geometry_msgs/msg/Vector3"], np.zeros(9)
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = {topic: w.add_connection(topic, kind, typestore=store)
                for topic, kind in (("/imu", imu), ("/vel", twist), ("/steer", f64))}
        for k, t in enumerate(cols["t"]):
            ns = int(round(t * 1e9))
            head = T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](ns // 10 ** 9, ns % 10 ** 9), "base_link")
            msg = T[imu](head, T["geometry_msgs/msg/Quaternion"](0, 0, 0, 1), zeros, vec(0.0, 0.0, cols["yaw_rate"][k]),
                         zeros, vec(cols["ax"][k], cols["ay"][k], 0.0), zeros)
            w.write(conn["/imu"], ns, store.serialize_cdr(msg, imu))
            vel = T[twist](head, T["geometry_msgs/msg/Twist"](vec(cols["vx"][k], cols["vy"][k], 0.0), vec(0.0, 0.0, 0.0)))
            w.write(conn["/vel"], ns, store.serialize_cdr(vel, twist))
            w.write(conn["/steer"], ns, store.serialize_cdr(T[f64](float(cols["delta"][k])), f64))
    return path


def _blf(folder: Path, cols: dict) -> tuple:
    """The rows as a BLF of a DBC (cantools) with one IEEE double signal per message, written by python-can at
    the rows' times: (the log, {key: MESSAGE.SIGNAL})."""
    can = pytest.importorskip("can")
    cantools = pytest.importorskip("cantools")
    from cantools.database.can import Message, Signal
    from cantools.database.conversion import LinearConversion
    names = {k: (f"M_{c.upper()}", c.capitalize()) for k, (c, _) in MAPPED.items()}
    db = cantools.database.Database(messages=[
        Message(frame_id=0x100 + j, name=m, length=8, signals=[
            Signal(sig, start=0, length=64, is_signed=True, conversion=LinearConversion(1.0, 0.0, True),
                   unit=MAPPED[k][1])]) for j, (k, (m, sig)) in enumerate(names.items())])
    (folder / "vehicle.dbc").write_text(db.as_dbc_string())
    db = cantools.database.load_file(str(folder / "vehicle.dbc"))
    log = folder / "log.blf"
    with can.BLFWriter(str(log)) as writer:
        for k, t in enumerate(cols["t"]):
            for key, (m, sig) in names.items():
                msg = db.get_message_by_name(m)
                writer.on_message_received(can.Message(timestamp=1392999600.0 + float(t - cols["t"][0]),
                                                       arbitration_id=msg.frame_id, is_extended_id=False,
                                                       data=msg.encode({sig: float(cols[MAPPED[key][0]][k])})))
    return log, {k: f"{m}.{sig}" for k, (m, sig) in names.items()}


def _fitted(capsys, observer, data, *extra) -> list:
    """The fit's printed lines less the files' (the observer files differ), the log's name as LOG, the judged
    runs' rows without their (path-truncated) labels."""
    assert cli.main(["fit", str(observer), "--data", str(data), "--samples", f"0:{ROWS}", "--folds", "0", *extra]) == 0
    out = capsys.readouterr().out.replace(str(data), "LOG")
    lines = [x for x in out.splitlines() if not x.endswith(("equals the fit", "(--write puts it there)"))]
    judged = next((k for k, x in enumerate(lines) if x.startswith("  the fitted numbers on the fit run")), len(lines))
    return lines[:judged + 2] + [x[4 + 44:] for x in lines[judged + 2:]]


@pytest.mark.slow       # three fits of 3000 samples with the EKF grid, two judged runs: about 45 s
def test_the_fit_on_a_ros2_bag_and_a_blf_prints_the_csv_fit(tmp_path, capsys):
    pytest.importorskip("rosbags")
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    table = pcsv.read_csv(stanford.STANFORD_PATH).slice(0, ROWS)
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    csv = tmp_path / "no_yaw_acc.csv"               # the shared format without a recorded yaw acceleration
    pcsv.write_csv(table.drop_columns(["yaw_acc"]), csv)
    ref = _fitted(capsys, NAME, csv, "--judge", str(csv))         # --judge: the same rows, judged
    assert ref[1] == f"  {fit.DERIVED_YAW_ACC}", ref
    assert ref[-4].startswith("  the fitted numbers on the fit run"), ref            # two rows: the fit, the judged
    bag_dir, can_dir = tmp_path / "bag_obs", tmp_path / "can_obs"
    bag_dir.mkdir(), can_dir.mkdir()
    bag = _bag(tmp_path / "bag", cols)
    assert _fitted(capsys, _mapped_observer(bag_dir, BAG), bag, "--judge", str(bag)) == ref
    blf, signals = _blf(can_dir, cols)
    assert _fitted(capsys, _mapped_observer(can_dir, signals, units=False, dbc="vehicle.dbc"), blf) == ref[:-4]


def test_the_yaw_acceleration_is_derived_on_the_range_alone(tmp_path):
    """numpy.gradient of the yaw rate over samples A..B-1 only (no sample outside the range is read); a log's
    recorded yaw_acc as it is."""
    t = np.arange(10) * 0.01
    r = np.sin(t * 7.0)
    run = stanford.StanfordRun(t=t, vx=t, vy=t, beta_true=t, ax=t, ay=t, yaw_rate=r, yaw_acc=None, delta=t,
                               delta_fl=t, delta_fr=t, source="x")
    assert np.array_equal(fit.yaw_acceleration(run, 2, 7), np.gradient(r[2:7], t[2:7]))
    recorded = stanford.StanfordRun(**{**run.__dict__, "yaw_acc": r * 2})
    assert np.array_equal(fit.yaw_acceleration(recorded, 2, 7), 2 * r[2:7])


def test_a_bag_without_the_mapped_topic_is_one_typed_line(tmp_path, capsys):
    pytest.importorskip("rosbags")
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    table = pcsv.read_csv(stanford.STANFORD_PATH).slice(0, 200)
    bag = _bag(tmp_path / "bag", {c: table.column(c).to_numpy() for c in table.column_names})
    observer = _mapped_observer(tmp_path, {**BAG, "v_x": "/vell.twist.linear.x"})
    assert cli.main(["fit", str(observer), "--data", str(bag), "--samples", "0:200", "--folds", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("uiogen: error: DatasetError: ") and str(bag) in err, err
    assert "missing topic(s) ['/vell'] ('/vell': closest in the file '/vel'" in err, err
    assert "in the observer file's [data] table" in err, err


def test_a_mapped_log_needs_the_lateral_speed_reference(tmp_path, capsys):
    """The fit judges the sideslip against the log's: a map without [data.truth] v_y names the key and the fix."""
    observer = _mapped_observer(tmp_path, {k: c for k, (c, _) in MAPPED.items()})
    observer.write_text(observer.read_text().replace("\n[data.truth]\n", "\n").replace('v_y = { column = "vy"', '# '))
    assert cli.main(["fit", str(observer), "--data", "stanford", "--samples", "0:1000", "--folds", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("uiogen: error: ConfigurationError: "), err
    assert str(observer) in err and "[data.truth] v_y is missing" in err and "in [data.truth]" in err, err


@pytest.mark.slow       # two fits of 3000 samples with the EKF grid: about 15 s
def test_a_recorded_yaw_acceleration_is_mapped_by_data_fit(tmp_path, capsys):
    """[data.fit] yaw_acceleration names the log's recorded yaw acceleration (in its unit): the mapped Parquet
    half fits as the shared CSV with its yaw_acc column does, and says nothing of a derivative."""
    require_shared(stanford.STANFORD_PATH, "shared Stanford log")
    table = pcsv.read_csv(stanford.STANFORD_PATH).slice(0, ROWS)
    csv = tmp_path / "half.csv"
    pcsv.write_csv(table, csv)
    ref = _fitted(capsys, NAME, csv)
    assert f"  {fit.DERIVED_YAW_ACC}" not in ref
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    import pyarrow as pa
    log = tmp_path / "half.parquet"                 # the yaw acceleration logged in deg/s^2
    pq.write_table(pa.table({**cols, "yaw_acc": cols["yaw_acc"] * 180 / np.pi}), log)
    obs = _mapped_observer(tmp_path, {k: c for k, (c, _) in MAPPED.items()})
    obs.write_text(obs.read_text() + '\n[data.fit]\nyaw_acceleration = { column = "yaw_acc", unit = "deg/s^2" }\n')
    mapped = _fitted(capsys, obs, log)
    assert mapped[0] == ref[0] and len(mapped) == len(ref)
    # the same numbers but for the last digits the unit's round trip leaves
    num = re.compile(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?")
    for a, b in zip(mapped[1:], ref[1:]):
        assert num.sub("#", a) == num.sub("#", b), (a, b)
        for x, y in zip(num.findall(a), num.findall(b)):
            assert float(x) == pytest.approx(float(y), rel=2e-3, abs=1e-9), (a, b)
    # a key that is not a fit signal, a unit of another kind: one typed line naming the table and the key
    for bad, said in (('yaw_accel = "yaw_acc"', "[data.fit] yaw_accel"),
                      ('yaw_acceleration = { column = "yaw_acc", unit = "m/s^2" }', "a unit of angular acceleration")):
        obs.write_text(obs.read_text().rsplit("[data.fit]\n", 1)[0] + f"[data.fit]\n{bad}\n")
        assert cli.main(["fit", str(obs), "--data", str(log), "--samples", "0:500", "--folds", "0"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("uiogen: error: ConfigurationError: "), err
        assert str(obs) in err and said in err, err
