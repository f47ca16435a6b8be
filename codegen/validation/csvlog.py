"""Reading logged runs: CSV (plain or gzip), checked before any number is used.

Shared by the Stanford loader (:mod:`codegen.validation.stanford`) and the column maps of user
logs (:mod:`codegen.validation.logs`): decoding (UTF-8, a byte-order mark dropped, UTF-16
refused), the separator (comma, semicolon or tab, from the header), numbers with a '.' decimal
mark, finite values, and a time column sampled at the observer's period without gaps. Every
failure is a :class:`~codegen.errors.DatasetError` naming the file, the column and the row.
"""
from __future__ import annotations

import csv
import gzip
import io
import re
from pathlib import Path

import numpy as np

from ..errors import DatasetError

PERIOD_RTOL = 0.01
"""Relative tolerance of ``load(..., sample_time=Ts)``: the log's median period must be Ts (1 ± 0.01)."""
GAP_FACTOR = 1.5
"""A time step longer than GAP_FACTOR x the median period is a gap (samples missing)."""
SHORT_FACTOR = 0.5
"""A time step shorter than SHORT_FACTOR x the median period is irregular sampling."""
MAX_PERIOD = 1.0
"""[s] A vehicle-dynamics log sampled slower than 1 Hz is implausible: t is likely in milliseconds."""

_SEPARATORS = {",": "comma ','", ";": "semicolon ';'", "\t": "tab"}


def _decode(p: Path, raw: bytes) -> str:
    """Bytes of a (possibly gzip) file -> text; a UTF-8 byte-order mark is dropped."""
    try:
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise DatasetError(f"cannot read {p}: {exc}") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise DatasetError(f"cannot read {p}: the file is UTF-16 encoded (byte-order mark {raw[:2]!r}); "
                           f"allowed: UTF-8 or ASCII text; save it as UTF-8")
    try:
        return raw.decode("utf-8-sig")          # utf-8-sig strips a leading BOM, if any
    except UnicodeDecodeError as exc:
        raise DatasetError(f"cannot read {p}: not UTF-8 text ({exc}); allowed: UTF-8 or ASCII text") from None


def _split_header(line: str, sep: str) -> list:
    return [h.strip() for h in next(csv.reader([line], delimiter=sep), [])]


def _separator(p: Path, first_line: str, columns) -> str:
    """The field separator: the one of ',', ';', tab whose header split holds every column."""
    fits = [s for s in _SEPARATORS if set(columns) <= set(_split_header(first_line, s))]
    if len(fits) == 1:
        return fits[0]
    if len(fits) > 1:           # e.g. column names containing the other separator
        raise DatasetError(f"{p}: ambiguous separator: the header splits into all columns with "
                           f"{' and with '.join(_SEPARATORS[s] for s in fits)}; allowed: exactly one of "
                           f"comma, semicolon or tab")
    # no separator gives every column: let the missing-column message show the widest split
    return max(_SEPARATORS, key=lambda s: (len(_split_header(first_line, s)), s == ","))


_DECIMAL_COMMA = re.compile(r"^\s*[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?\s*$")


def _to_float(p: Path, rows: list, header: list, sep: str) -> np.ndarray:
    try:
        return np.array(rows, dtype=float)
    except ValueError:
        pass
    for i, r in enumerate(rows):           # locate the first bad cell for the message
        for j, v in enumerate(r):
            try:
                float(v)
            except ValueError:
                where = f"{p}: column {header[j]!r}, data row {i + 1}"
                if _DECIMAL_COMMA.match(v):
                    raise DatasetError(
                        f"{where}: value {v!r} uses a decimal comma (file read with {_SEPARATORS[sep]} "
                        f"separators); allowed: '.' as the decimal mark (e.g. 1.5). Re-export the log with "
                        f"'.' decimals, e.g. pandas.read_csv(path, sep={sep!r}, decimal=',')"
                        f".to_csv(out, index=False)") from None
                raise DatasetError(f"{where}: non-numeric value {v!r}; allowed: a decimal number "
                                   f"such as 1.5 or -2.5e-3") from None
    raise DatasetError(f"{p}: non-numeric value")   # pragma: no cover (np.array and float agree)


def check_time(p: Path, t: np.ndarray, sample_time, column: str = "t") -> None:
    """Strictly increasing, plausible period (not milliseconds), = sample_time, no gaps."""
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.flatnonzero(d <= 0)[0])
        raise DatasetError(f"{p}: time column {column!r} is not strictly increasing: data row {i + 2} has "
                           f"t = {t[i + 1]!r} after t = {t[i]!r}; allowed: strictly increasing times in s")
    per = float(np.median(d))
    ratio = per / sample_time if sample_time is not None else None
    if per > MAX_PERIOD or (ratio is not None and 300.0 <= ratio <= 3000.0):
        expect = f"the sample time {sample_time:g} s" if sample_time is not None else \
            f"a period of at most {MAX_PERIOD:g} s for a vehicle log"
        raise DatasetError(
            f"{p}: column {column!r} (declared unit s): median step of t {per:.6g} (in the file's unit), "
            f"expected {expect}; t looks like milliseconds (t / 1000 gives a period of {per / 1000:.6g} s, "
            f"{1000 / per:.4g} Hz); convert the column to seconds")
    if ratio is not None and abs(ratio - 1.0) > PERIOD_RTOL:
        raise DatasetError(
            f"{p}: column {column!r}: median sample period {per:.6g} s ({1 / per:.4g} Hz), but the expected "
            f"sample time is {sample_time:.6g} s ({1 / sample_time:.4g} Hz), allowed within "
            f"{PERIOD_RTOL:.0%}; resample the log to {1 / sample_time:.4g} Hz (e.g. "
            f"scipy.signal.resample_poly on a uniform grid) or use an observer designed for "
            f"{per:.6g} s")
    long, short = d > GAP_FACTOR * per, d < SHORT_FACTOR * per
    if long.any() or short.any():
        i = int(np.flatnonzero(long | short)[0])           # the first irregular step of the log
        bad, what, allowed = ((long, "gap", f"at most {GAP_FACTOR:g}") if long[i] else
                              (short, "short step", f"at least {SHORT_FACTOR:g}"))
        missing = f", about {d[i] / per - 1:.0f} sample(s) missing" if long[i] else ""
        raise DatasetError(
            f"{p}: column {column!r}: {what} of {d[i]:.6g} s before data row {i + 2} (t = {t[i]:.6g} -> "
            f"{t[i + 1]:.6g} s{missing}), {d[i] / per:.3g} x the median period {per:.6g} s; "
            f"{int(bad.sum())} {what}(s) in the log ({int((long | short).sum())} irregular step(s) in "
            f"all); allowed: steps {allowed} x the median period (no interpolation is done: split the "
            f"log at the {what} or resample it)")


def read_table(p: Path, columns) -> tuple:
    """(header, float table) of a CSV file holding at least ``columns``.

    Raises
    ------
    DatasetError
        missing or unreadable file, duplicated or missing columns, rows of the wrong length,
        non-numeric values, fewer than 2 rows.
    """
    p = Path(p)
    if not p.is_file():
        raise DatasetError(f"data file not found: {p}")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise DatasetError(f"cannot read {p}: {exc}") from None
    text = _decode(p, raw)
    first = next(iter(io.StringIO(text)), "")
    sep = _separator(p, first, columns)
    reader = csv.reader(io.StringIO(text), delimiter=sep)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise DatasetError(f"{p} is empty") from None
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DatasetError(f"{p}: duplicated column(s) {dup}")
    missing = [c for c in columns if c not in header]
    if missing:
        raise DatasetError(f"{p}: missing column(s) {missing}; found {header} (fields separated by "
                           f"{_SEPARATORS[sep]}; allowed separators: comma, semicolon or tab)")
    rows = [r for r in reader if r and any(f.strip() for f in r)]
    if len(rows) < 2:
        raise DatasetError(f"{p}: needs at least 2 data rows, found {len(rows)}")
    bad_len = next((i for i, r in enumerate(rows) if len(r) != len(header)), None)
    if bad_len is not None:
        raise DatasetError(f"{p}: data row {bad_len + 1} has {len(rows[bad_len])} fields, "
                           f"header has {len(header)} (separator {_SEPARATORS[sep]})")
    return header, _to_float(p, rows, header, sep)


def finite_column(p: Path, table: np.ndarray, header: list, column: str, unit: str) -> np.ndarray:
    """One column, refused when any value is not finite."""
    a = table[:, header.index(column)].copy()
    nonfinite = ~np.isfinite(a)
    if nonfinite.any():
        raise DatasetError(f"{p}: column {column!r} has {int(nonfinite.sum())} non-finite value(s), "
                           f"first at data row {int(np.flatnonzero(nonfinite)[0]) + 1}; allowed: "
                           f"finite numbers in {unit}")
    return a
