"""`uiogen fit --data` and `--judge` read the shared format in the files `uiogen validate --data` reads by
name (issue 41): the shared Ferrari half written as MDF4 (asammdf: channels with their units, every one at
100 Hz) and as Parquet (pyarrow) gives the CSV's fit to the last printed digit, through the reader of
validate (codegen.validation.stanford.open_log). The yaw acceleration is the log's recorded `yaw_acc`.
"""
import numpy as np
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from codegen import cli
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
