"""Raw CAN logs (issue 41): ``uiogen validate OBSERVER --data LOG.blf|.asc`` decodes the frames with the DBC
the observer file's ``[data] dbc`` names, each mapped ``MESSAGE.SIGNAL`` a channel at its message's rate, in
the DBC signal's unit, and gives the figures of the same data as a CSV up to what the DBC's scale explains.

The Stanford slice, observer file and CSV result are test_log_formats' (its ``data`` fixture); the DBC is
written by cantools, the frames encoded with it and written as BLF and ASC by python-can (the real libraries,
as a logger would), at the log's own times from a Unix start time (a BLF's absolute times).
"""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from codegen.errors import ConfigurationError, DatasetError, UnsupportedError
from codegen.project import observer_file as observers
from codegen.validation import logfiles
from codegen.validation.common import SETTLE_TIME

from test_log_formats import ROOT, ROWS, _observer, _run, data  # noqa: F401 -- data: the shared module fixture

can = pytest.importorskip("can")                    # the validation extra (make venv installs it)
cantools = pytest.importorskip("cantools")
from cantools.database.can import Message, Signal                     # noqa: E402
from cantools.database.conversion import LinearConversion             # noqa: E402

pytestmark = pytest.mark.slow                       # runs a compiled extension (the fast lane has no build)

START = 1392999600.0
"""The logger's clock at the first frame (2014-02-21, the run's day): a BLF holds absolute times, and
python-can's float64 sum of start and offset is what the reader must round (logfiles.TICKS)."""

# map key -> (Stanford column, message, frame id, signal, DBC unit, scale, offset, signed); the unit
# converts to the model's (deg -> rad, km/h -> m/s), the offset puts a_y's zero mid-range of an unsigned raw
QUANTIZED = {"delta": ("delta", "STEER", 0x0C8, "RoadWheelAngle", "deg", 0.01, 0.0, True),
             "y_r": ("yaw_rate", "IMU", 0x120, "YawRate", "deg/s", 0.01, 0.0, True),
             "y_a_y": ("ay", "IMU", 0x120, "AccY", "m/s^2", 0.001, -32.768, False),
             "v_x": ("vx", "VEH", 0x3A0, "VehSpeed", "km/h", 0.01, 0.0, False),
             "beta": ("beta_true", "REF", 0x500, "Sideslip", "deg", 0.001, 0.0, True)}
TO_DBC = {"rad": 1.0, "deg": 180 / np.pi, "deg/s": 180 / np.pi, "m/s^2": 1.0, "km/h": 3.6}
"""The Stanford columns (rad, rad/s, m/s^2, m/s) into the DBC's units."""


EXTENDED = 0x18DA0000
"""Added to every frame id of a DBC of 29-bit (extended) ids (J1939-like: above the 11-bit range)."""


def _dbc(path: Path, signals: dict, floats: bool = False, extended: bool = False) -> Path:
    """A DBC of ``signals`` (QUANTIZED's layout): 16-bit integers with their scale and offset, two to a
    message; ``floats``: one IEEE double per message instead (no quantization), in the Stanford units;
    ``extended``: 29-bit frame ids (:data:`EXTENDED` added)."""
    messages = {}
    for key, (_, msg, fid, sig, unit, scale, offset, signed) in signals.items():
        if floats:
            name, unit = f"{msg}_{sig}", {"deg": "rad", "deg/s": "rad/s", "km/h": "m/s"}.get(unit, unit)
            messages[name] = (fid + len(messages), [                  # a frame id of its own
                Signal(sig, start=0, length=64, is_signed=True, conversion=LinearConversion(1.0, 0.0, True),
                       unit=unit)])
            continue
        fid_, sigs = messages.setdefault(msg, (fid, []))
        sigs.append(Signal(sig, start=16 * len(sigs), length=16, is_signed=signed,
                           conversion=LinearConversion(scale, offset, False), unit=unit))
    db = cantools.database.Database(messages=[Message(frame_id=fid + (EXTENDED if extended else 0), name=name, length=8,
                                                      signals=sigs, is_extended_frame=extended)
                                              for name, (fid, sigs) in messages.items()])
    path.write_text(db.as_dbc_string())
    return path


def _raw(x: np.ndarray, scale: float, offset: float) -> np.ndarray:
    """The raw integers a logger sends for physical values ``x`` (round to nearest, as cantools encodes)."""
    return np.round((x - offset) / scale)


def _log(path: Path, dbc: Path, cols: dict, rows=slice(None), skip=(), floats: bool = False, channel: int = 0,
         also=None) -> Path:
    """The Stanford slice as frames of the DBC, written by python-can's BLF or ASC writer (by suffix):
    every message once per row at the row's time (from START); ``skip``: messages left out; ``channel``:
    python-can's bus number (0: the file's CAN 1); ``also``: (channel, message, {signal: factor}) a second
    copy of one message on another bus, its raw values scaled (another sensor)."""
    db = cantools.database.load_file(str(dbc))
    t = cols["t"][rows] - cols["t"][0] + START
    payload = {}                                     # message -> {signal: per-row raw (or float) values}
    for key, (col, msg, _, sig, unit, scale, offset, _) in QUANTIZED.items():
        x = cols[col][rows]
        if floats:
            payload.setdefault(f"{msg}_{sig}", {})[sig] = x
        else:
            payload.setdefault(msg, {})[sig] = _raw(x * TO_DBC[unit], scale, offset)
    writer = can.BLFWriter(str(path)) if path.suffix == ".blf" else can.ASCWriter(str(path))
    with writer:
        for k, tk in enumerate(t):
            for name, sigs in payload.items():
                if name in skip:
                    continue
                m = db.get_message_by_name(name)
                data = m.encode({s: (float(v[k]) if floats else int(v[k])) for s, v in sigs.items()}, scaling=floats)
                writer.on_message_received(can.Message(timestamp=float(tk), arbitration_id=m.frame_id, data=data,
                                                       is_extended_id=m.is_extended_frame, channel=channel))
                if also is not None and also[1] == name:
                    other = m.encode({s: int(v[k] * also[2].get(s, 1.0)) for s, v in sigs.items()}, scaling=False)
                    writer.on_message_received(can.Message(timestamp=float(tk) + 1e-4, arbitration_id=m.frame_id,
                                                           data=other, is_extended_id=m.is_extended_frame,
                                                           channel=also[0]))
    return path


def _can_observer(folder: Path, dbc: str | None = "vehicle.dbc", floats: bool = False, **changes) -> Path:
    """test_log_formats' observer file mapping MESSAGE.SIGNAL channels (no units: the DBC's), with
    ``[data] dbc``; ``changes``: SIGNAL = "inline table"."""
    entries = {k: f'{{ column = "{f"{m}_{s}" if floats else m}.{s}" }}' for k, (_, m, _, s, *_) in QUANTIZED.items()}
    entries.update(changes)
    path = _observer(folder, **entries)
    if dbc is not None:
        path.write_text(path.read_text().replace('\n[data]\ntime = "t"\n', f'\n[data]\ntime = "t"\ndbc = "{dbc}"\n'))
    return path


def _cli_error(observer: Path, log: Path, kind: str = "DatasetError") -> str:
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", str(observer), "--data", str(log),
                           "--project", str(ROOT)], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"uiogen: error: {kind}: "), err
    return err


@pytest.fixture(scope="module")
def quantized(data, tmp_path_factory):
    """The quantized DBC, its BLF and ASC logs and the observer file mapping them."""
    folder = tmp_path_factory.mktemp("can")
    dbc = _dbc(folder / "vehicle.dbc", QUANTIZED)
    return {"folder": folder, "dbc": dbc, "observer": _can_observer(folder),
            "blf": _log(folder / "log.blf", dbc, data["cols"]), "asc": _log(folder / "log.asc", dbc, data["cols"])}


# --- the figures --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_float_signals_at_the_observer_rate_give_the_csv_figures(data, tmp_path, suffix):
    """IEEE double signals carry the CSV's numbers to the last bit, the frames at the CSV's times:
    the figures are the CSV's (the times relative to the first frame, rounded to 1 us)."""
    dbc = _dbc(tmp_path / "vehicle.dbc", QUANTIZED, floats=True)
    log = _log(tmp_path / f"log{suffix}", dbc, data["cols"], floats=True)
    res = _run(_can_observer(tmp_path, floats=True), log)
    csv = data["csv"]
    assert res["format"] == suffix[1:] and res["samples"] == ROWS
    assert abs(res["observer"]["beta"]["rms"] - csv["observer"]["beta"]["rms"]) <= 1e-9
    assert np.allclose(res["signals"]["beta"], csv["signals"]["beta"], rtol=0, atol=1e-12)
    assert {r["method"] for r in res["resampling"].values()} == {"as recorded"}
    assert res["resampling"]["IMU_YawRate.YawRate"]["rate_hz"] == pytest.approx(100)
    # the frames' times to the microsecond, not python-can's float64 sums with the 1.4e9 s start (~0.2 us off)
    t = data["cols"]["t"]
    assert np.array_equal(res["signals"]["t"], np.round((t - t[0]) * 1e6) / 1e6)


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_quantized_signals_give_the_figures_their_scale_explains(data, quantized, tmp_path, suffix):
    """16-bit signals with the DBC's scale and offset, in deg, deg/s and km/h: decoded, converted to the
    model's units and run, the figures are those of the quantized values (raw x scale + offset, computed
    here) written as a Parquet log, to 1e-12: the reader adds nothing to the DBC's quantization. Against the
    unquantized CSV, the sideslip RMS moves by what that quantization explains: at most the RMS of the
    estimates' difference plus half the reference's scale (Minkowski: | ||e1|| - ||e2|| | <= ||e1 - e2||,
    the reference rounded by at most half its 0.001 deg step), and by far less than the RMS itself."""
    res = _run(quantized["observer"], quantized[suffix[1:]])
    cols = data["cols"]
    t = np.round((cols["t"] - cols["t"][0]) * 1e6) / 1e6           # the reader's times (relative, 1 us)
    table = {"t": t}
    for key, (col, msg, _, sig, unit, scale, offset, _) in QUANTIZED.items():
        table[f"{msg}.{sig}"] = _raw(cols[col] * TO_DBC[unit], scale, offset) * scale + offset
    fields = [pa.field(c, pa.float64(), metadata={"unit": QUANTIZED_UNIT.get(c, "s")}) for c in table]
    pq.write_table(pa.Table.from_arrays([pa.array(v) for v in table.values()], schema=pa.schema(fields)),
                   tmp_path / "quantized.parquet")
    ref = _run(_can_observer(tmp_path, dbc=None), tmp_path / "quantized.parquet")
    rms, rms_q, rms_csv = (r["observer"]["beta"]["rms"] for r in (res, ref, data["csv"]))
    assert abs(rms - rms_q) <= 1e-12, (rms, rms_q)
    assert res["samples"] == ROWS and res["warnings"] == ref["warnings"]
    # what the quantization explains, against the unquantized CSV (the run's signals are kept whole here)
    assert res["signals_stride"] == 1 and data["csv"]["signals_stride"] == 1
    after = res["signals"]["t"] >= SETTLE_TIME
    d_est = np.degrees(res["signals"]["beta"] - data["csv"]["signals"]["beta"])[after]
    tol = np.sqrt(np.mean(d_est ** 2)) + 0.001 / 2                      # + half the reference's step, deg
    assert 0 < abs(rms - rms_csv) <= tol, (rms, rms_csv, tol)
    assert tol < 0.01 * rms_csv, (tol, rms_csv)


QUANTIZED_UNIT = {f"{m}.{s}": u for (_, m, _, s, u, *_) in QUANTIZED.values()}


def test_29_bit_frame_ids_give_the_11_bit_figures(data, quantized, tmp_path):
    """The same frames with extended (29-bit) ids, the DBC's messages extended too: the same figures to
    the last bit; a DBC of 11-bit ids does not decode the 29-bit frames (an id is its number and its
    kind), and the message says so."""
    dbc = _dbc(tmp_path / "vehicle.dbc", QUANTIZED, extended=True)
    log = _log(tmp_path / "log.blf", dbc, data["cols"])
    res = _run(_can_observer(tmp_path), log)
    ref = _run(quantized["observer"], quantized["blf"])
    assert res["observer"]["beta"]["rms"] == ref["observer"]["beta"]["rms"]
    assert np.array_equal(res["signals"]["beta"], ref["signals"]["beta"])
    (tmp_path / "vehicle.dbc").write_text(quantized["dbc"].read_text())         # 11-bit ids against the 29-bit log
    err = _cli_error(_can_observer(tmp_path), log)
    assert "never appear in the log" in err and f"0x{EXTENDED + 0x120:X} (extended)" in err, err


def test_a_log_of_two_buses_needs_its_bus_named(data, quantized, tmp_path):
    """IMU frames on CAN 1 and, from another unit, on CAN 2 (its yaw rate 20 % off): mixed, the signal
    would jump between the two; refused naming both buses and the key. can_channel = 1 gives the
    single-bus figures to the last bit; a bus the log does not have lists those it has."""
    log = _log(tmp_path / "two.asc", quantized["dbc"], data["cols"], also=(1, "IMU", {"YawRate": 1.2}))
    observer = _can_observer(tmp_path)
    (tmp_path / "vehicle.dbc").write_text(quantized["dbc"].read_text())
    err = _cli_error(observer, log)
    assert "message 'IMU' (frame id 0x120) comes on 2 buses (CAN 1, CAN 2)" in err
    assert "[data] can_channel = N" in err
    text = observer.read_text().replace('dbc = "vehicle.dbc"\n', 'dbc = "vehicle.dbc"\ncan_channel = 1\n')
    observer.write_text(text)
    res = _run(observer, log)
    ref = _run(quantized["observer"], quantized["asc"])
    assert res["observer"]["beta"]["rms"] == ref["observer"]["beta"]["rms"]
    observer.write_text(text.replace("can_channel = 1", "can_channel = 3"))
    err = _cli_error(observer, log)
    assert "[data] can_channel = 3: the log has no frame on CAN 3; its frames are on CAN 1, CAN 2" in err
    observer.write_text(text.replace("can_channel = 1", "can_channel = 0"))
    err = _cli_error(observer, log, kind="ConfigurationError")
    assert "can_channel = 0" in err and ">= 1" in err


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_the_log_is_streamed_in_batches_with_the_same_figures(data, quantized, monkeypatch, suffix):
    """The log is read twice, :data:`~codegen.validation.logfiles.CAN_BATCH` decoded frames at a time (one
    pass judges the sampling, one puts the channels on the grid): batches of 7 frames give the figures of
    one batch number for number; grid chunks of 100 samples on top, the same estimates (the statistics
    merged chunk by chunk, to the last bits)."""
    log = quantized[suffix[1:]]
    monkeypatch.setattr(logfiles, "CAN_BATCH", 10 ** 9)
    whole = _run(quantized["observer"], log)
    monkeypatch.setattr(logfiles, "CAN_BATCH", 7)
    small = _run(quantized["observer"], log)
    assert small["samples"] == whole["samples"] == ROWS
    assert small["observer"] == whole["observer"] and small["resampling"] == whole["resampling"]
    for key in ("t", "beta"):
        assert np.array_equal(small["signals"][key], whole["signals"][key])
    chunked = _run(quantized["observer"], log, batch_rows=100)
    assert np.array_equal(chunked["signals"]["beta"], whole["signals"]["beta"])
    assert chunked["observer"]["beta"]["rms"] == pytest.approx(whole["observer"]["beta"]["rms"], rel=1e-13)


def test_staggered_frames_are_held(data, tmp_path):
    """Frames of one period spread over the bus (each message 0.3 ms after the one before): the grid is
    the first channel's times, the later messages' samples fall after its times and are held, one period
    old: the figures move, by less than 1 %, and the report says hold."""
    dbc = _dbc(tmp_path / "vehicle.dbc", QUANTIZED, floats=True)
    db = cantools.database.load_file(str(dbc))
    cols = data["cols"]
    log = tmp_path / "staggered.blf"
    with can.BLFWriter(str(log)) as writer:
        for k in range(ROWS):
            for j, (key, (col, msg, _, sig, *_)) in enumerate(QUANTIZED.items()):
                m = db.get_message_by_name(f"{msg}_{sig}")
                writer.on_message_received(can.Message(
                    timestamp=START + cols["t"][k] - cols["t"][0] + 3e-4 * j, arbitration_id=m.frame_id,
                    data=m.encode({sig: float(cols[col][k])}), is_extended_id=False))
    res = _run(_can_observer(tmp_path, floats=True), log)
    rms, ref = res["observer"]["beta"]["rms"], data["csv"]["observer"]["beta"]["rms"]
    assert 0 < abs(rms - ref) < 0.01 * ref, (rms, ref)
    assert res["resampling"]["STEER_RoadWheelAngle.RoadWheelAngle"]["method"] == "as recorded"
    assert res["resampling"]["VEH_VehSpeed.VehSpeed"]["method"] == "hold"


def test_the_format_is_told_by_content(quantized, tmp_path):
    for fmt in ("blf", "asc"):
        renamed = tmp_path / f"{fmt}_log.csv"
        renamed.write_bytes(quantized[fmt].read_bytes())
        assert logfiles.kind(renamed) == fmt
    text = tmp_path / "basement.csv"
    text.write_text("base,hex\n1,2\n")                                 # a CSV is not an ASC
    assert logfiles.kind(text) == "csv"


# --- typed errors: one line, naming the file ---------------------------------------------------------------

def test_a_dbc_unit_of_the_wrong_kind(data, tmp_path):
    signals = dict(QUANTIZED, y_a_y=QUANTIZED["y_a_y"][:4] + ("deg/s",) + QUANTIZED["y_a_y"][5:])
    dbc = _dbc(tmp_path / "vehicle.dbc", signals)
    log = _log(tmp_path / "log.blf", dbc, data["cols"], rows=slice(0, 300))
    err = _cli_error(_can_observer(tmp_path), log)
    assert "channel 'IMU.AccY' (y_a_y) has unit 'deg/s' in the file, a unit of angular rate" in err, err


def test_a_missing_or_unparsable_dbc(quantized, tmp_path):
    observer = _can_observer(tmp_path, dbc="nowhere.dbc")
    err = _cli_error(observer, quantized["blf"])
    assert f"{tmp_path / 'nowhere.dbc'}: no such DBC file" in err, err
    (tmp_path / "broken.dbc").write_text('VERSION ""\nBO_ x288 IMU: 8 Vector__XXX\n')    # a frame id that is no number
    err = _cli_error(_can_observer(tmp_path, dbc="broken.dbc"), quantized["blf"])
    assert f"cannot read the DBC {tmp_path / 'broken.dbc'}: not a DBC file cantools can parse " \
           f"(UnsupportedDatabaseFormatError: DBC: \"Invalid syntax at line 2, column 5" in err, err


def test_a_message_or_signal_the_dbc_lacks(quantized, tmp_path):
    folder, dbc = tmp_path, str(quantized["dbc"])              # the fixture's observer file stays as it is
    with pytest.raises(DatasetError, match=r"channel 'IMU.YawRat': message 'IMU' has no signal 'YawRat' \(closest: "
                                           r"'YawRate'\); allowed: one of its signals \['YawRate', 'AccY'\]"):
        _run(_can_observer(folder, dbc, y_r='{ column = "IMU.YawRat" }'), quantized["blf"])
    with pytest.raises(DatasetError, match=r"channel 'IMUU.YawRate': the DBC has no message 'IMUU' \(closest: 'IMU'"):
        _run(_can_observer(folder, dbc, y_r='{ column = "IMUU.YawRate" }'), quantized["blf"])
    with pytest.raises(DatasetError, match=r"channel 'IMU' names no signal; allowed: MESSAGE.SIGNAL"):
        _run(_can_observer(folder, dbc, y_r='{ column = "IMU" }'), quantized["blf"])


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_a_message_the_log_never_has(data, quantized, tmp_path, suffix):
    log = _log(tmp_path / f"log{suffix}", quantized["dbc"], data["cols"], rows=slice(0, 300), skip=("VEH",))
    err = _cli_error(quantized["observer"], log)
    assert f"{log}: message(s) 'VEH' (frame id 0x3A0) of the DBC" in err, err
    assert "never appear in the log; the log has frame ids 0xC8, 0x120, 0x500" in err, err


def test_a_can_log_without_a_dbc_key(quantized, tmp_path):
    observer = _can_observer(tmp_path, dbc=None)
    with pytest.raises(ConfigurationError, match=r"\[data\] dbc is missing: .*log.blf is a CAN log \(BLF\)"):
        _run(observer, quantized["blf"])
    _cli_error(observer, quantized["asc"], kind="ConfigurationError")


def test_a_damaged_blf(quantized, tmp_path):
    whole = quantized["blf"].read_bytes()
    cut = tmp_path / "cut.blf"
    cut.write_bytes(whole[:len(whole) // 2])                          # a copy cut short
    err = _cli_error(quantized["observer"], cut)
    assert f"cannot read {cut}: not a readable BLF file (cut short: " in err, err
    garbled = tmp_path / "garbled.blf"
    garbled.write_bytes(whole[:144] + b"XXXX" + whole[148:])            # the first object's signature overwritten
    err = _cli_error(quantized["observer"], garbled)
    assert f"cannot read {garbled}: not a readable BLF file (" in err, err


@pytest.mark.parametrize("missing", ["can", "cantools"])
def test_without_the_libraries_the_install_hint(quantized, monkeypatch, missing):
    monkeypatch.setitem(sys.modules, missing, None)                  # import fails as if not installed
    with pytest.raises(UnsupportedError, match=r"CAN logs \(BLF, ASC\) need python-can and cantools, which are not "
                                               r"installed: pip install 'uiogen\[validation\]'"):
        logfiles.CanLog(quantized["blf"], {"IMU.YawRate": None}, "t", {}, 0.01, quantized["dbc"])


def test_an_empty_or_misspelt_dbc_key(tmp_path):
    with pytest.raises(ConfigurationError, match=r'\[data\] dbc = " ": the path of a DBC file, relative to the '
                                                 r'observer file'):
        observers.get(str(_can_observer(tmp_path, dbc=" ")), project=ROOT)
    path = _can_observer(tmp_path)
    path.write_text(path.read_text().replace('dbc = "vehicle.dbc"', 'dbcfile = "vehicle.dbc"'))
    with pytest.raises(ConfigurationError, match=r"dbcfile.*dbc"):
        observers.get(str(path), project=ROOT)
