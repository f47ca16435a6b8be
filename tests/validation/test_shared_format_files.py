"""The shared log format (``codegen.validation.stanford.load``: ``uiogen fit --data``, ``--judge``, and
``uiogen validate --data`` of an observer file without a ``[data]`` map) in every file format the
reader of ``validate --data`` reads by name (issue 41): a CSV, Parquet, MDF4 through
:func:`codegen.validation.logfiles.open_log`, the units a file states converted to the format's.

Every file is written by the real library of its format (pyarrow, asammdf, rosbags) from the shared
Ferrari half and read back through the loader; the CSV's arrays are the reference.
"""
import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from codegen.validation import stanford as S

from conftest import require_shared

asammdf = pytest.importorskip("asammdf")            # the validation extra (make venv installs it)

ROWS = 3000                                          # 30 s: every physics check of the format is excited
TS = 0.01


@pytest.fixture(scope="module")
def half(tmp_path_factory):
    """The first ROWS rows of the shared half as a table, its CSV and its columns."""
    require_shared(S.STANFORD_PATH, "shared Stanford log")
    folder = tmp_path_factory.mktemp("shared_format")
    table = pcsv.read_csv(S.STANFORD_PATH).slice(0, ROWS)
    pcsv.write_csv(table, folder / "log.csv")
    cols = {c: table.column(c).to_numpy() for c in table.column_names}
    return {"table": table, "cols": cols, "csv": S.load(folder / "log.csv", sample_time=TS)}


def _mdf(path, cols, units=None, skip=()):
    """The columns as one MDF4 channel group at the log's rate, each channel with its unit (``units``:
    {column: (unit, factor the value is multiplied by)})."""
    units = units or {}
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(cols[c] * units.get(c, (None, 1.0))[1], cols["t"], name=c,
                               unit=units.get(c, (S.UNITS[c], 1.0))[0])
                for c in S.COLUMNS if c != "t" and c not in skip])
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


def _same(run, ref) -> bool:
    return all(np.array_equal(getattr(run, c), getattr(ref, c)) for c in S.COLUMNS)


def test_parquet_and_mdf4_load_as_the_csv_to_the_last_bit(half, tmp_path):
    pq.write_table(half["table"], tmp_path / "log.parquet", row_group_size=700)
    assert _same(S.load(tmp_path / "log.parquet", sample_time=TS), half["csv"])
    assert _same(S.load(_mdf(tmp_path / "log.mf4", half["cols"]), sample_time=TS), half["csv"])


def test_the_units_a_file_states_are_converted(half, tmp_path):
    """km/h, deg, deg/s and g in the channels' metadata: converted to the format's SI units (to rounding)."""
    into = {"vx": ("km/h", 3.6), "delta": ("deg", 180 / np.pi), "yaw_rate": ("deg/s", 180 / np.pi),
            "ay": ("g", 1 / 9.80665)}
    run = S.load(_mdf(tmp_path / "units.mf4", half["cols"], into), sample_time=TS)
    for c in S.COLUMNS:
        assert np.allclose(getattr(run, c), getattr(half["csv"], c), rtol=1e-12, atol=0), c


def test_a_channel_of_another_kind_of_unit_is_one_typed_line(half, tmp_path):
    log = _mdf(tmp_path / "wrong.mf4", half["cols"], {"vx": ("rad", 1.0)})
    with pytest.raises(S.DatasetError) as e:
        S.load(log, sample_time=TS)
    msg = str(e.value)
    assert str(log) in msg and "channel 'vx'" in msg and "'rad'" in msg and "a unit of speed" in msg, msg
    assert len(msg.splitlines()) == 1


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".mf4"])
def test_a_log_without_yaw_acc_loads_without_it(half, tmp_path, suffix):
    """Most logs record no yaw acceleration: in every format the log loads, its ``yaw_acc`` None (``uiogen
    fit`` derives it and says so) and every other column the CSV's; its physics check is the one left out."""
    cols = {c: a for c, a in half["cols"].items() if c != "yaw_acc"}
    log = tmp_path / f"no_yaw_acc{suffix}"
    if suffix == ".mf4":
        _mdf(log, half["cols"], skip=("yaw_acc",))
    else:
        table = pa.table(cols)
        pcsv.write_csv(table, log) if suffix == ".csv" else pq.write_table(table, log)
    run = S.load(log, sample_time=TS)
    assert run.yaw_acc is None
    assert all(np.array_equal(getattr(run, c), getattr(half["csv"], c)) for c in S.COLUMNS if c != "yaw_acc")
    # another column missing still is a typed line naming it (and that yaw_acc may be left out)
    table = pa.table({c: a for c, a in cols.items() if c != "vy"})
    pcsv.write_csv(table, tmp_path / "no_vy.csv")
    with pytest.raises(S.DatasetError) as e:
        S.load(tmp_path / "no_vy.csv", sample_time=TS)
    msg = str(e.value)
    assert "['vy']" in msg and "yaw_acc may be left out" in msg and len(msg.splitlines()) == 1, msg


def test_a_ros2_bag_is_one_typed_line_naming_its_channels(half, tmp_path):
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.LATEST)
    f64 = "std_msgs/msg/Float64"
    with Writer(tmp_path / "bag", version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/vx", f64, typestore=store)
        for t, v in zip(half["cols"]["t"][:100], half["cols"]["vx"][:100]):
            w.write(conn, int(round(t * 1e9)), store.serialize_cdr(store.types[f64](float(v)), f64))
    with pytest.raises(S.DatasetError) as e:
        S.load(tmp_path / "bag", sample_time=TS)
    msg = str(e.value)
    assert msg.startswith(f"{tmp_path / 'bag'} is a ROS 2 bag") and "TOPIC.FIELD" in msg, msg
    assert len(msg.splitlines()) == 1
