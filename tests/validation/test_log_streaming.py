"""Logs read in chunks (issue 25, probes 5 and 6): a log of any size in bounded memory, the same
numbers, checks and messages whatever the chunking, and the file problems that were tracebacks
or wrong messages (CR-only line endings, an unused text column, /dev/zero, a FIFO, a directory).

Before the change a log was read whole (``Path.read_bytes`` then the csv module): a 1 GB log
needed 12.3 GB and 5 min; CR-only line endings raised ``_csv.Error``; an extra text column
refused the log; ``/dev/zero``, a FIFO or a directory was "not found".
"""
import gzip
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen.errors import DatasetError
from codegen.validation import csvlog
from codegen.validation import logs
from codegen.validation import stanford as S
from codegen.validation import streaming

from conftest import HANG_GUARD, require_shared
from test_log_checks import _synthetic, _write

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
SMALL = 2048                  # bytes of text per chunk: about a dozen rows of the Stanford format


def _log(tmp_path, n=3000, **kw) -> Path:
    return _write(tmp_path / "log.csv", _synthetic(n=n, **kw))


def test_the_reader_delivers_small_chunks(tmp_path):
    p = _log(tmp_path)
    reader = csvlog.LogReader(p, S.UNITS, block_bytes=SMALL)
    sizes = [cols["t"].size for _, cols in reader.chunks()]
    assert sum(sizes) == 3000 and len(sizes) > 100 and max(sizes) <= SMALL // 100


def test_loading_does_not_depend_on_the_chunking(tmp_path):
    p = _log(tmp_path)
    whole, parts = S.load(p, sample_time=0.01), S.load(p, sample_time=0.01, block_bytes=SMALL)
    assert all(np.array_equal(getattr(whole, c), getattr(parts, c)) for c in S.COLUMNS)


def test_the_real_log_in_small_chunks():
    require_shared(S.STANFORD_PATH, "shared Stanford log")
    whole, parts = S.load("stanford"), S.load("stanford", block_bytes=1 << 16)
    assert all(np.array_equal(getattr(whole, c), getattr(parts, c)) for c in S.COLUMNS)


@pytest.mark.parametrize("block", [SMALL, 1 << 22])
def test_errors_name_the_same_row_whatever_the_chunking(tmp_path, block):
    cols = _synthetic(n=3000)
    keep = np.r_[0:1700, 1750:3000]                       # 0.5 s missing after data row 1700
    gap = _write(tmp_path / "gap.csv", {c: a[keep] for c, a in cols.items()})
    with pytest.raises(DatasetError, match=r"gap of 0\.51 s before data row 1701 .*50 sample\(s\) missing.*; 1 gap"):
        S.load(gap, block_bytes=block)
    bad = tmp_path / "bad.csv"
    lines = _log(tmp_path).read_text().splitlines()
    fields = lines[2501].split(",")
    fields[6] = "n/a"
    lines[2501] = ",".join(fields)
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"column 'yaw_rate', data row 2501: non-numeric value 'n/a'"):
        S.load(bad, block_bytes=block)
    fields[6] = "nan"
    lines[2501] = ",".join(fields)
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"column 'yaw_rate' has 1 non-finite value\(s\), first at data row 2501"):
        S.load(bad, block_bytes=block)


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_validation_does_not_depend_on_the_chunking(tmp_path):
    p = _log(tmp_path)
    whole = logs.run("stanford_sideslip", str(p))
    parts = logs.run("stanford_sideslip", str(p), block_bytes=SMALL)
    for k in ("beta", "vy"):
        for stat, v in whole["observer"][k].items():
            got = parts["observer"][k][stat]
            assert got == (v if isinstance(v, str) or v is None else pytest.approx(v, rel=1e-9, abs=1e-12)), (k, stat)
    assert parts["status_flags"] == whole["status_flags"] and parts["samples"] == whole["samples"] == 3000
    assert np.array_equal(parts["signals"]["beta"], whole["signals"]["beta"])      # the state carried over
    assert [c["verdict"] for c in parts["log_checks"]] == [c["verdict"] for c in whole["log_checks"]]


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
def test_a_long_log_runs_without_the_baselines_and_keeps_every_kth_sample(tmp_path, monkeypatch):
    p = _log(tmp_path)
    whole = logs.run("stanford_sideslip", str(p))
    monkeypatch.setattr(logs, "BASELINE_MAX_SAMPLES", 1000)
    monkeypatch.setattr(streaming, "KEEP_SAMPLES", 700)
    long = logs.run("stanford_sideslip", str(p), block_bytes=SMALL)
    assert long["baselines"] == {} and "3000 samples, more than 1000" in long["baselines_skipped"]
    assert "baselines not run" in logs.format_table(long)
    assert long["observer"]["beta"]["rms"] == pytest.approx(whole["observer"]["beta"]["rms"], rel=1e-9)
    stride = long["signals_stride"]
    assert stride == 8 and np.array_equal(long["signals"]["beta"], whole["signals"]["beta"][::stride])


def test_streamed_statistics_equal_whole_arrays():
    from codegen.validation.common import signal_stats
    rng = np.random.default_rng(4)
    y, e, t = rng.standard_normal(5000), 0.1 * rng.standard_normal(5000), 0.01 * np.arange(5000)
    for unit in ("rad", "rad/s", "N"):          # an angle reported in deg (and marked so), the others as declared
        ref = signal_stats(y, y + e, t, unit=unit)
        acc = streaming.ErrorStats(unit, settle=2.0)
        for i in range(0, 5000, 333):
            acc.add(y[i:i + 333], (y + e)[i:i + 333], t[i:i + 333])
        assert set(acc.result()) == set(ref)
        for k, v in ref.items():
            got = acc.result()[k]
            assert got == (v if isinstance(v, str) or v is None else pytest.approx(v, rel=1e-10)), (unit, k)
    assert ref["unit"] == "N" and ref["truth_rms"] > 0 and ref["after_s"] == 2.0


# --- file problems ----------------------------------------------------------------------------------

def test_cr_only_line_endings_are_read(tmp_path):
    p = _log(tmp_path, n=500)
    cr = tmp_path / "cr.csv"
    cr.write_bytes(p.read_bytes().replace(b"\n", b"\r"))
    assert all(np.array_equal(getattr(S.load(cr), c), getattr(S.load(p), c)) for c in S.COLUMNS)


def test_an_unused_text_column_is_ignored(tmp_path):
    p = _log(tmp_path, n=500)
    lines = p.read_text().splitlines()
    text = tmp_path / "notes.csv"
    text.write_text("\n".join([lines[0] + ",driver"] + [f"{x},\"lap {i}, dry\"" for i, x in enumerate(lines[1:])]))
    assert all(np.array_equal(getattr(S.load(text), c), getattr(S.load(p), c)) for c in S.COLUMNS)


def test_a_gzip_log_in_small_chunks(tmp_path):
    p = _log(tmp_path, n=800)
    gz = tmp_path / "log.csv.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    assert all(np.array_equal(getattr(S.load(gz, block_bytes=SMALL), c), getattr(S.load(p), c)) for c in S.COLUMNS)


@pytest.mark.slow       # runs a compiled extension (the fast lane has no build)
@pytest.mark.parametrize("kind", ["dev-zero", "fifo", "directory"])
def test_non_regular_files_are_refused_as_such(tmp_path, kind):
    if kind == "dev-zero":
        path, what = Path("/dev/zero"), "a character device"
        if not path.exists():
            pytest.skip("no /dev/zero")
    elif kind == "fifo":
        path, what = tmp_path / "pipe.csv", "a FIFO (named pipe)"
        os.mkfifo(path)
    else:
        path, what = tmp_path, "a directory"
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "validate", "stanford_sideslip", "--data", str(path)],
                          capture_output=True, text=True, cwd=ROOT, timeout=HANG_GUARD)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and f"{path} is {what}, not a data file" in err, err
