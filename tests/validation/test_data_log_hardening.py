"""Hardening of the logged-run loader ``codegen.validation.stanford.load`` (``uiogen validate --data``).

Three families of silently accepted or unclearly refused logs, each now read correctly or refused
with a DatasetError naming the file, the column, what was found and what is allowed:

1. time: sample period against the observer's sample time, gaps, irregular steps, milliseconds;
2. units: per-column plausible ranges and physical consistency between columns (a_y against
   v_x r, beta against atan(v_y / v_x), delta against r / v_x, ...), which a range alone cannot
   give (a gentle drive in g stays in range);
3. format: UTF-8 byte-order mark, ';' and tab separators, decimal commas.

Logs are written in tmp_path from two sources: a synthetic run with consistent planar rigid-body
physics (always available) and the first rows of the shared real file, read with the csv module
(skipped when the file is absent, a failure under CI=true).
"""
import csv
import gzip
import io
import math
import os

import numpy as np
import pytest

from codegen.errors import SampleError
from codegen.validation import stanford as S

REAL_ROWS = 1000         # 10 s of the real log: enough cornering for every physical relation


def _need_real():
    if not S.STANFORD_PATH.is_file():
        msg = f"shared data file missing: {S.STANFORD_PATH}"
        if os.environ.get("CI") == "true":
            pytest.fail(msg)
        pytest.skip(msg)


def _real_head(n=REAL_ROWS) -> dict:
    _need_real()
    with gzip.open(S.STANFORD_PATH, "rt", newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = [next(reader) for _ in range(n)]
    return {c: np.array([float(r[header.index(c)]) for r in rows]) for c in S.COLUMNS}


def _synthetic(n=1500, dt=0.01, t0=10.0, vx0=25.0, dvx=3.0, r_amp=0.3, f_r=0.2, vy_amp=0.4,
               wheelbase=2.4, k_us=0.002, seed=0) -> dict:
    """Planar rigid-body kinematics at the CoG, SI units, with small sensor noise.

    ax = dvx/dt - vy r, ay = dvy/dt + vx r, beta = atan(vy/vx), yaw_acc = dr/dt,
    delta = r (wheelbase + k_us vx^2) / vx (steady-state single track).
    """
    rng = np.random.default_rng(seed)
    t = t0 + dt * np.arange(n)
    w1, w2 = 2 * math.pi * 0.1, 2 * math.pi * f_r
    vx = vx0 + dvx * np.sin(w1 * t)
    r = r_amp * np.sin(w2 * t)
    vy = vy_amp * np.sin(w2 * t + 0.6)
    delta = r * (wheelbase + k_us * vx ** 2) / vx
    noise = lambda s: s * rng.standard_normal(n)               # noqa: E731
    return {"t": t, "vx": vx, "vy": vy, "beta_true": np.arctan2(vy, vx),
            "ax": dvx * w1 * np.cos(w1 * t) - vy * r + noise(0.05),
            "ay": vy_amp * w2 * np.cos(w2 * t + 0.6) + vx * r + noise(0.05),
            "yaw_rate": r + noise(0.001), "yaw_acc": r_amp * w2 * np.cos(w2 * t) + noise(0.02),
            "delta": delta, "delta_fl": 1.04 * delta, "delta_fr": 0.96 * delta}


def _gentle() -> dict:
    """A gentle drive: every unit mistake below stays inside the plausible ranges."""
    return _synthetic(vx0=15.0, dvx=1.5, r_amp=0.045, f_r=0.35, vy_amp=0.15)


def _write(path, cols: dict, sep=",", bom=False, decimal=".", newline="\n", gz=False):
    buf = io.StringIO(newline="")
    w = csv.writer(buf, delimiter=sep, lineterminator=newline)
    w.writerow(S.COLUMNS)
    n = cols["t"].size
    for i in range(n):
        w.writerow([repr(float(cols[c][i])).replace(".", decimal) for c in S.COLUMNS])
    data = (("\ufeff" if bom else "") + buf.getvalue()).encode("utf-8")
    path.write_bytes(gzip.compress(data) if gz else data)
    return path


def _same(run, cols):
    return all(np.array_equal(getattr(run, c), cols[c]) for c in S.COLUMNS)


@pytest.fixture(params=["synthetic", "real"])
def base(request):
    return _synthetic() if request.param == "synthetic" else _real_head()


def _rows(cols, keep):
    return {c: a[keep] for c, a in cols.items()}


# --- consistent logs load unchanged -------------------------------------------------------------

@pytest.mark.slow       # 9 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
@pytest.mark.parametrize("source", ["synthetic", "gentle", "real"])
def test_consistent_logs_load_unchanged(tmp_path, source):
    cols = {"synthetic": _synthetic, "gentle": _gentle, "real": _real_head}[source]()
    run = S.load(_write(tmp_path / "log.csv", cols), sample_time=0.01)
    assert _same(run, cols)
    assert run.dt == pytest.approx(0.01)


def test_real_file_loads_exactly_as_before():
    _need_real()
    run = S.load(S.STANFORD_PATH, sample_time=0.01)
    with gzip.open(S.STANFORD_PATH, "rt", newline="") as f:
        rows = list(csv.reader(f))
    table = np.array(rows[1:], dtype=float)
    assert all(np.array_equal(getattr(run, c), table[:, rows[0].index(c)]) for c in S.COLUMNS)
    assert run.n == 27500 and run.dt == pytest.approx(0.01, rel=1e-9)       # 100 Hz
    with pytest.raises(S.DatasetError, match=r"column 't'.*0\.01 s.*0\.02 s.*resample"):
        S.load(S.STANFORD_PATH, sample_time=0.02)


def test_straight_drive_is_not_judged(tmp_path):
    """No cornering, no steering: the relations are inconclusive and the log is accepted."""
    n = 800
    rng = np.random.default_rng(3)
    t = 5.0 + 0.01 * np.arange(n)
    z = np.zeros(n)
    cols = {"t": t, "vx": np.full(n, 20.0), "vy": z, "beta_true": z, "ax": 0.02 * rng.standard_normal(n),
            "ay": 0.02 * rng.standard_normal(n), "yaw_rate": 1e-3 * rng.standard_normal(n), "yaw_acc": z,
            "delta": z, "delta_fl": z, "delta_fr": z}
    assert _same(S.load(_write(tmp_path / "s.csv", cols)), cols)


# --- 1. time column -----------------------------------------------------------------------------

def test_50hz_log_against_100hz_observer(tmp_path, base):
    cols = _rows(base, slice(None, None, 2))
    p = _write(tmp_path / "50hz.csv", cols)
    assert S.load(p).dt == pytest.approx(0.02)                  # fine on its own
    with pytest.raises(S.DatasetError) as e:
        S.load(p, sample_time=0.01)
    msg = str(e.value)
    assert str(p) in msg and "column 't'" in msg and "0.02 s" in msg and "0.01 s" in msg
    assert "50 Hz" in msg and "100 Hz" in msg and "resample" in msg


def test_gap_in_the_log(tmp_path, base):
    keep = np.r_[0:200, 700:base["t"].size]                     # 5 s missing
    p = _write(tmp_path / "gap.csv", _rows(base, keep))
    for ts in (None, 0.01):
        with pytest.raises(S.DatasetError, match=r"column 't': gap of 5\.01 s before data row 201") as e:
            S.load(p, sample_time=ts)
        assert "500 sample(s) missing" in str(e.value) and "no interpolation" in str(e.value)


def test_irregular_short_step(tmp_path, base):
    cols = {c: a.copy() for c, a in base.items()}
    cols["t"][100] = cols["t"][99] + 0.002
    with pytest.raises(S.DatasetError, match=r"column 't': short step of 0\.002 s before data row 101"):
        S.load(_write(tmp_path / "short.csv", cols))


@pytest.mark.parametrize("ts", [None, 0.01])
def test_time_in_milliseconds(tmp_path, base, ts):
    cols = {**base, "t": base["t"] * 1000.0}
    p = _write(tmp_path / "ms.csv", cols)
    with pytest.raises(S.DatasetError, match=r"column 't'.*looks like milliseconds") as e:
        S.load(p, sample_time=ts)
    assert str(p) in str(e.value)


@pytest.mark.parametrize("ts", [0.0, -0.01, float("nan"), "abc"])
def test_bad_sample_time_argument(tmp_path, ts):
    p = _write(tmp_path / "x.csv", _synthetic(n=100))
    with pytest.raises(S.DatasetError, match="sample_time"):
        S.load(p, sample_time=ts)


# --- 2. units: ranges and physical consistency --------------------------------------------------

DEG = 180.0 / math.pi

# (scaled columns and factor, column named, phrase of the message)
MISTAKES = {
    "ay_in_g": ({"ay": 1 / 9.81}, "ay", "ay in g"),
    "ax_in_g": ({"ax": 1 / 9.81}, "ax", "ax in g"),
    "yaw_rate_deg_s": ({"yaw_rate": DEG, "yaw_acc": DEG}, "ay", "yaw_rate in deg/s"),
    "yaw_acc_deg_s2": ({"yaw_acc": DEG}, "yaw_acc", "yaw_acc in deg/s^2"),
    "delta_deg": ({"delta": DEG, "delta_fl": DEG, "delta_fr": DEG}, "delta", "delta in degrees"),
    "delta_fl_deg": ({"delta_fl": DEG}, "delta_fl", "delta_fl in degrees"),
    "beta_deg": ({"beta_true": DEG}, "beta_true", "beta_true in degrees"),
    "speeds_kmh": ({"vx": 3.6, "vy": 3.6}, "ax", "vx in km/h"),
    "ay_sign": ({"ay": -1.0}, "ay", "opposite sign conventions of ay and yaw_rate"),
}


@pytest.mark.parametrize("name", list(MISTAKES))
def test_unit_mistake_inside_the_ranges_is_caught(tmp_path, name):
    """A gentle drive: every scaled column stays inside its plausible range; physics tells."""
    scale, col, phrase = MISTAKES[name]
    cols = _gentle()
    bad = {**cols, **{c: cols[c] * f for c, f in scale.items()}}
    for c in S.COLUMNS:                                           # the range check alone passes
        if c in S._LIMITS:
            lo, hi = S._LIMITS[c]
            assert lo <= bad[c].min() and bad[c].max() <= hi, c
    p = _write(tmp_path / f"{name}.csv", bad)
    with pytest.raises(S.DatasetError) as e:
        S.load(p)
    msg = str(e.value)
    assert str(p) in msg and f"column {col!r}" in msg and phrase in msg and "allowed" in msg, msg


@pytest.mark.parametrize("name,phrase", [("ay_in_g", "ay in g"), ("ax_in_g", "ax in g"),
                                         ("delta_deg", "degrees"), ("beta_deg", "degrees"),
                                         ("yaw_rate_deg_s", "deg/s")])
def test_unit_mistake_on_a_full_drive(tmp_path, base, name, phrase):
    """The same mistakes on the real log's head: caught by the range (with its unit guess) or physics."""
    scale, col, _ = MISTAKES[name]
    bad = {**base, **{c: base[c] * f for c, f in scale.items()}}
    with pytest.raises(S.DatasetError, match="looks like") as e:
        S.load(_write(tmp_path / "bad.csv", bad))
    assert phrase in str(e.value), str(e.value)


def test_range_message_names_the_declared_unit(tmp_path):
    cols = _synthetic()
    cols["vx"] = cols["vx"] * 3.6 + 60.0                          # 130-170 "m/s": km/h
    with pytest.raises(S.DatasetError, match=r"column 'vx'.*declared unit m/s.*looks like km/h"):
        S.load(_write(tmp_path / "kmh.csv", cols))
    assert set(S.UNITS) == set(S.COLUMNS)


# --- 3. file format -----------------------------------------------------------------------------

@pytest.mark.parametrize("kw", [dict(bom=True), dict(bom=True, gz=True), dict(sep=";"), dict(sep="\t"),
                                dict(sep=";", bom=True, newline="\r\n")],
                         ids=["bom", "bom-gzip", "semicolon", "tab", "semicolon-bom-crlf"])
def test_bom_and_separators_are_read(tmp_path, kw):
    cols = _synthetic(n=300)
    run = S.load(_write(tmp_path / "f.csv", cols, **kw))
    assert _same(run, cols)


@pytest.mark.parametrize("first", ["sep=;", '"sep=;"', "sep=\t"])
def test_excel_separator_line_is_read(tmp_path, first):
    """Excel writes ``sep=;`` before the header so that it opens the file: the line names the
    separator, the header follows (pyarrow's reader and the csv module's both skip it)."""
    cols = _synthetic(n=300)
    sep = first.strip('"')[-1]
    p = _write(tmp_path / "x.csv", cols, sep=sep)
    p.write_text(first + "\r\n" + p.read_text())
    assert _same(S.load(p), cols)
    lines = p.read_text().splitlines()
    lines[5] = lines[5].replace("0", "x", 1)           # a bad cell: the slow reader's row number is the data row
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(S.DatasetError, match="data row 4"):
        S.load(p)
    p.write_text("sep=|\n" + p.read_text().split("\n", 1)[1])
    with pytest.raises(S.DatasetError, match=r"names the separator '\|'; allowed: comma, semicolon or tab"):
        S.load(p)


def test_an_unused_duplicated_column_is_ignored(tmp_path):
    """Two columns of one name that the map does not read are no reason to refuse the log; a mapped
    name that two columns have is (which one is meant is unknown)."""
    cols = _synthetic(n=300)
    p = _write(tmp_path / "d.csv", cols)
    lines = p.read_text().splitlines()
    p.write_text("\n".join([lines[0] + ",note,note"] + [ln + ",1,2" for ln in lines[1:]]) + "\n")
    assert _same(S.load(p), cols)
    p.write_text("\n".join([lines[0] + ",vx"] + [ln + ",1" for ln in lines[1:]]) + "\n")
    with pytest.raises(S.DatasetError, match=r"duplicated column\(s\) \['vx'\].*rename or drop the other"):
        S.load(p)


@pytest.mark.parametrize("sep", [";", "\t"])
def test_decimal_comma_is_refused(tmp_path, sep):
    p = _write(tmp_path / "eu.csv", _synthetic(n=300), sep=sep, decimal=",")
    with pytest.raises(S.DatasetError) as e:
        S.load(p)
    msg = str(e.value)
    assert str(p) in msg and "column 't', data row 1" in msg and "decimal comma" in msg
    assert "'.' as the decimal mark" in msg


def test_non_numeric_names_column_and_row(tmp_path):
    cols = _synthetic(n=50)
    p = _write(tmp_path / "n.csv", cols)
    lines = p.read_text().splitlines()
    f = lines[3].split(",")
    f[S.COLUMNS.index("yaw_rate")] = "n/a"
    lines[3] = ",".join(f)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(S.DatasetError, match=r"column 'yaw_rate', data row 3: non-numeric value 'n/a'"):
        S.load(p)


@pytest.mark.parametrize("cell", ["", "  "])
def test_an_empty_cell_is_named_as_such(tmp_path, cell):
    """An empty cell was reported as "non-numeric value ''"; it is named as an empty cell, with its row
    and column."""
    p = _write(tmp_path / "n.csv", _synthetic(n=50))
    lines = p.read_text().splitlines()
    f = lines[5].split(",")
    f[S.COLUMNS.index("yaw_rate")] = cell
    lines[5] = ",".join(f)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(S.DatasetError, match=r"n.csv: column 'yaw_rate', data row 5: an empty cell \(a missing "
                                             r"sample\); allowed: a decimal number"):
        S.load(p)


def test_utf16_is_refused(tmp_path):
    p = tmp_path / "u16.csv"
    p.write_bytes(",".join(S.COLUMNS).encode("utf-16"))
    with pytest.raises(S.DatasetError, match="UTF-16"):
        S.load(p)


def test_errors_stay_sample_errors(tmp_path):
    p = _write(tmp_path / "ms.csv", {**_synthetic(n=100), "t": 1000.0 * _synthetic(n=100)["t"]})
    with pytest.raises(SampleError):
        S.load(p)


def test_a_parquet_log_is_read_and_another_binary_is_named_as_such(tmp_path):
    """A Parquet log was refused as "not UTF-8 text (... can't decode byte 0x90 in position 7)", then with
    advice to convert it; it is read now (issue 41: the reader of validate --data), as its CSV. A binary
    format no reader takes is still named (an HDF5 file)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    p = tmp_path / "log.parquet"
    cols = _synthetic(n=50)
    pq.write_table(pa.table(cols), p)
    assert _same(S.load(p), cols)
    h = tmp_path / "log.h5"
    h.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    with pytest.raises(S.DatasetError, match=r"log.h5: it is a HDF5 file; allowed: a CSV log \(plain or gzip\)"):
        S.load(h)
