"""Reading logged runs: CSV (plain or gzip), in chunks, checked before any number is used.

Shared by the Stanford loader (:mod:`codegen.validation.stanford`) and the column maps of user
logs (:mod:`codegen.validation.logs`). A log of any size is read in chunks of about
:data:`BLOCK_BYTES` of text (pyarrow's streaming CSV reader; only the columns used are
converted, so an extra text column is ignored), and every check below is streaming too: a 1 GB
log needs the memory of one chunk, not of the file.

Checked: a regular file (a directory, a FIFO or a device is refused as such), decoding (UTF-8,
a byte-order mark dropped, UTF-16 refused), the separator (comma, semicolon or tab, from the
header), line endings (LF, CRLF or CR alone), numbers with a '.' decimal mark, rows of the
header's length, finite values, and a time column sampled at the observer's period without gaps
(:class:`TimeCheck`). Every failure is a :class:`~codegen.errors.DatasetError` naming the file,
the column and the row.
"""
from __future__ import annotations

import csv
import gzip
import io
import os
import re
import stat
from pathlib import Path

import numpy as np

from ..errors import DatasetError
from ..settings import suggest

PERIOD_RTOL = 0.01
"""Relative tolerance of ``load(..., sample_time=Ts)``: the log's median period must be Ts (1 ± 0.01)."""
GAP_FACTOR = 1.5
"""A time step longer than GAP_FACTOR x the median period is a gap (samples missing)."""
SHORT_FACTOR = 0.5
"""A time step shorter than SHORT_FACTOR x the median period is irregular sampling."""
MAX_PERIOD = 1.0
"""[s] A vehicle-dynamics log sampled slower than 1 Hz is implausible: t is likely in milliseconds."""
MEDIAN_STEPS = 10_000
"""The sample period is the median of the log's first MEDIAN_STEPS time steps (all of them in a
shorter log): the gaps of the rest are judged against it without holding the time column."""
BLOCK_BYTES = 1 << 22
"""Text per chunk (4 MiB, about 26,000 rows of 11 columns; pyarrow reads a few ahead)."""

_SEPARATORS = {",": "comma ','", ";": "semicolon ';'", "\t": "tab"}
_BINARY_FORMATS = {b"PAR1": "Parquet", b"\x89HDF\r\n\x1a\n": "HDF5", b"MDF     ": "MDF (ASAM measurement data)",
                   b"PK\x03\x04": "zip (or xlsx)", b"ARROW1": "Arrow IPC (Feather)", b"\xd0\xcf\x11\xe0": "legacy Excel (xls)"}
_HEAD_BYTES = 1 << 20           # a header line longer than 1 MiB is not a CSV header
_SLOW_ROWS = 50_000             # rows per chunk of the csv-module reader


def _file_kind(mode: int) -> str:
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return "not a regular file"


def regular_file(p: Path) -> None:
    """Refuse a path that is missing or is not a regular file (``/dev/zero``, a FIFO, a directory):
    reading one would block, never end or fail with an unrelated message."""
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise DatasetError(f"data file not found: {p}") from None
    except OSError as exc:
        raise DatasetError(f"cannot read {p}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise DatasetError(f"{p} is {_file_kind(st.st_mode)}, not a data file; allowed: a regular CSV file "
                           f"(plain or gzip)")


def _is_gzip(p: Path) -> bool:
    with open(p, "rb") as fh:
        return fh.read(2) == b"\x1f\x8b"


def _binary(p: Path, gz: bool):
    return gzip.open(p, "rb") if gz else open(p, "rb")


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


_EXCEL_SEP = re.compile(r'^"?sep=(.)"?\s*$')
"""Excel's first line naming the separator (``sep=;``), before the header."""

_DECIMAL_COMMA = re.compile(r"^\s*[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?\s*$")


def _bad_value(p: Path, column: str, row: int, v: str, sep: str) -> DatasetError:
    where = f"{p}: column {column!r}, data row {row}"
    if _DECIMAL_COMMA.match(v):
        return DatasetError(
            f"{where}: value {v!r} uses a decimal comma (file read with {_SEPARATORS[sep]} "
            f"separators); allowed: '.' as the decimal mark (e.g. 1.5). Re-export the log with "
            f"'.' decimals, e.g. pandas.read_csv(path, sep={sep!r}, decimal=',')"
            f".to_csv(out, index=False)")
    if not v.strip():               # an empty cell: a missing sample, not a value to quote ('')
        return DatasetError(f"{where}: an empty cell (a missing sample); allowed: a decimal number such as 1.5 "
                            f"or -2.5e-3 in every row of a mapped column (fill or drop the row)")
    return DatasetError(f"{where}: non-numeric value {v!r}; allowed: a decimal number "
                        f"such as 1.5 or -2.5e-3")


class LogReader:
    """A CSV log opened for chunked reading of some of its columns.

    Parameters
    ----------
    path : str or os.PathLike
    columns : mapping of str to str
        The columns to read, each with the unit its message names (``{"t": "s", ...}``).
    block_bytes : int, optional
        Text per chunk (tests force it small to prove the checks do not depend on it).

    Raises
    ------
    DatasetError
        missing or not a regular file, unreadable, UTF-16, empty, duplicated or missing columns.
    """

    def __init__(self, path, columns, block_bytes: int = BLOCK_BYTES):
        p = Path(path)
        self.path, self.units, self.block_bytes = p, dict(columns), int(block_bytes)
        regular_file(p)
        try:
            self.gz = _is_gzip(p)
            with _binary(p, self.gz) as fh:
                head = fh.read(_HEAD_BYTES)
        except (OSError, EOFError) as exc:
            raise DatasetError(f"cannot read {p}: {exc}") from None
        kind = next((name for magic, name in _BINARY_FORMATS.items() if head.startswith(magic)), None)
        if kind:
            # named here: decoding it as text would only say "not UTF-8" at some byte
            how = (", e.g. pyarrow.csv.write_csv(pyarrow.parquet.read_table(path), out)" if kind == "Parquet" else "")
            mapped = ("; or map its columns in the observer file's [data] table, which reads Parquet and MDF4 "
                      "(docs/validation.md, 'Log formats')" if kind in ("Parquet", "MDF (ASAM measurement data)") else "")
            raise DatasetError(f"cannot read {p}: it is a {kind} file; allowed: a CSV log (plain or gzip); export "
                               f"it as CSV{how}{mapped}")
        if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
            raise DatasetError(f"cannot read {p}: the file is UTF-16 encoded (byte-order mark {head[:2]!r}); "
                               f"allowed: UTF-8 or ASCII text; save it as UTF-8")
        lines = re.split(rb"\r\n|\r|\n", head, maxsplit=2)
        try:
            first = lines[0].decode("utf-8-sig")        # utf-8-sig strips a leading BOM, if any
        except UnicodeDecodeError as exc:
            raise DatasetError(f"cannot read {p}: not UTF-8 text ({exc}); allowed: UTF-8 or ASCII text") from None
        # Excel's separator line ("sep=;" before the header, written so that Excel opens the file)
        hint = _EXCEL_SEP.match(first)
        self.skip = 1 + bool(hint)         # lines before the first data row
        if hint:
            first = lines[1].decode("utf-8", errors="replace") if len(lines) > 1 else ""
        if not first.strip():
            raise DatasetError(f"{p} is empty" if not head.strip() else f"{p}: the first line (the header) is empty")
        if hint and hint.group(1) not in _SEPARATORS:
            raise DatasetError(f"{p}: the first line {lines[0].decode('utf-8-sig')!r} names the separator "
                               f"{hint.group(1)!r}; allowed: comma, semicolon or tab")
        self.sep = hint.group(1) if hint else _separator(p, first, list(self.units))
        self.header = _split_header(first, self.sep)
        # a duplicated name matters only where it is read: which of the two would be meant is unknown
        dup = sorted({h for h in self.header if self.header.count(h) > 1 and h in self.units})
        if dup:
            raise DatasetError(f"{p}: duplicated column(s) {dup}: the map reads a name two columns have; allowed: "
                               f"one column of each mapped name (rename or drop the other)")
        missing = [c for c in self.units if c not in self.header]
        if missing:
            spare = [h for h in self.header if h not in self.units]
            hints = [f"{m!r}: did you mean {s!r}?" for m in missing for s in [suggest(m, spare)] if s]
            exc = DatasetError(f"{p}: missing column(s) {missing}; found {self.header}"
                               + (f" ({'; '.join(hints)})" if hints else "") + " (fields separated by "
                               f"{_SEPARATORS[self.sep]}; allowed separators: comma, semicolon or tab)")
            exc.missing, exc.head = missing, str(exc)      # a caller with a format of its own adds its advice
            raise exc
        self.rows = 0                # data rows delivered so far

    # --- the chunks ------------------------------------------------------------------------------

    def chunks(self):
        """Yield ``(first, {column: float64 array})`` per chunk, ``first`` the 0-based index of the
        chunk's first data row. Format errors are raised where they occur; non-finite values and
        a log of fewer than 2 rows when the last chunk has been read (the message counts them all).

        Raises
        ------
        DatasetError
        """
        self.rows = 0
        self._nonfinite = {c: [0, None] for c in self.units}
        yield from self._read()
        for c, (count, first) in self._nonfinite.items():
            if count:
                raise DatasetError(f"{self.path}: column {c!r} has {count} non-finite value(s), first at data "
                                   f"row {first + 1}; allowed: finite numbers in {self.units[c]}")
        if self.rows < 2:
            raise DatasetError(f"{self.path}: needs at least 2 data rows, found {self.rows}")

    def _read(self):
        """The chunks of the file (a reader of another format overrides it)."""
        try:
            yield from self._arrow()
        except _SlowPath:
            yield from self._slow(self.rows)

    def _deliver(self, cols: dict):
        n = len(next(iter(cols.values())))
        for c, a in cols.items():
            bad = ~np.isfinite(a)
            if bad.any():
                rec = self._nonfinite[c]
                if rec[1] is None:
                    rec[1] = self.rows + int(np.flatnonzero(bad)[0])
                rec[0] += int(bad.sum())
        first, self.rows = self.rows, self.rows + n
        return first, cols

    def _arrow(self):
        import pyarrow as pa
        from pyarrow import csv as pcsv
        names = list(self.units)
        try:
            source = pa.CompressedInputStream(pa.OSFile(str(self.path)), "gzip") if self.gz else str(self.path)
            reader = pcsv.open_csv(
                source,
                read_options=pcsv.ReadOptions(block_size=self.block_bytes, skip_rows=self.skip,
                                              column_names=[f"{i}:{h}" for i, h in enumerate(self.header)]),
                parse_options=pcsv.ParseOptions(delimiter=self.sep, newlines_in_values=False),
                convert_options=pcsv.ConvertOptions(
                    include_columns=[f"{self.header.index(c)}:{c}" for c in names],
                    column_types={f"{self.header.index(c)}:{c}": pa.float64() for c in names},
                    null_values=[], strings_can_be_null=False, quoted_strings_can_be_null=False))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, UnicodeDecodeError):
            raise _SlowPath() from None
        except OSError as exc:
            raise DatasetError(f"cannot read {self.path}: {exc}") from None
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                return
            except (pa.ArrowInvalid, pa.ArrowNotImplementedError, UnicodeDecodeError):
                raise _SlowPath() from None     # the csv module locates the row and says what is wrong
            except OSError as exc:
                raise DatasetError(f"cannot read {self.path}: {exc}") from None
            if batch.num_rows:
                yield self._deliver({c: batch.column(i).to_numpy(zero_copy_only=False)
                                     for i, c in enumerate(names)})

    def _text(self):
        raw = _binary(self.path, self.gz)
        return io.TextIOWrapper(raw, encoding="utf-8-sig", newline="")

    def _slow(self, done: int):
        """The csv module from the first row: the exact row and message of what pyarrow refused
        (rows before ``done`` were delivered already), or the rest of a log it cannot parse."""
        p, sep = self.path, self.sep
        idx = [self.header.index(c) for c in self.units]
        names = list(self.units)
        rows, i = [], 0

        def flush():
            out = {c: np.empty(len(rows)) for c in names}
            for k, r in enumerate(rows):
                for c, j in zip(names, idx):
                    try:
                        out[c][k] = float(r[j])
                    except ValueError:
                        raise _bad_value(p, c, self.rows + k + 1, r[j], sep) from None
            return self._deliver(out)

        try:
            with self._text() as fh:
                reader = csv.reader(fh, delimiter=sep)
                for _ in range(self.skip):               # the header (after Excel's separator line)
                    next(reader, None)
                for r in reader:
                    if not r or not any(f.strip() for f in r):
                        continue
                    i += 1
                    if len(r) != len(self.header):
                        raise DatasetError(f"{p}: data row {i} has {len(r)} fields, header has {len(self.header)} "
                                           f"(separator {_SEPARATORS[sep]})")
                    if i <= done:
                        continue
                    rows.append(r)
                    if len(rows) == _SLOW_ROWS:
                        yield flush()
                        rows = []
        except UnicodeDecodeError as exc:
            raise DatasetError(f"cannot read {p}: not UTF-8 text ({exc}); allowed: UTF-8 or ASCII text") from None
        except csv.Error as exc:
            raise DatasetError(f"{p}: data row {i + 1}: not a CSV row ({exc})") from None
        except (OSError, EOFError) as exc:
            raise DatasetError(f"cannot read {p}: {exc}") from None
        if rows:
            yield flush()


class _SlowPath(Exception):
    """pyarrow refused a chunk: the csv module reads on from there."""


def read_columns(path, columns, block_bytes: int = BLOCK_BYTES) -> dict:
    """Every chunk of :class:`LogReader` concatenated: ``{column: float64 array}`` (a log held in memory)."""
    reader = LogReader(path, columns, block_bytes)
    parts = {c: [] for c in reader.units}
    for _, cols in reader.chunks():
        for c, a in cols.items():
            parts[c].append(a)
    return {c: np.concatenate(a) for c, a in parts.items()}


class TimeCheck:
    """The time column, chunk by chunk: strictly increasing, a plausible period (not
    milliseconds), equal to the observer's sample time, without gaps or short steps.

    The period is the median of the first :data:`MEDIAN_STEPS` steps; :meth:`finish` raises
    what :func:`check_time` raises on the whole column (the first fault, the counts of all).
    """

    def __init__(self, p, sample_time=None, column: str = "t"):
        self.p, self.sample_time, self.column = Path(p), sample_time, column
        self.n = 0
        self.last = None             # last time of the previous chunk
        self.pending = []            # steps held until the period is known
        self.period = None
        self.back = None             # first non-increasing step (row, t_before, t_after)
        self.first_irregular = None  # (kind, row, step, t_before, t_after)
        self.long = self.short = 0

    def feed(self, t: np.ndarray) -> None:
        t = np.asarray(t, dtype=float)
        if not t.size:
            return
        # both[k] is the data row of index start + k; step k goes from it to the next one
        both, start = (t, 0) if self.last is None else (np.concatenate([[self.last], t]), self.n - 1)
        d = np.diff(both)
        self.last = float(t[-1])
        self.n += t.size
        if self.back is None:
            bad = np.flatnonzero(d <= 0)
            if bad.size:
                i = int(bad[0])
                self.back = (start + i, float(both[i]), float(both[i + 1]))
        if self.period is None:
            self.pending.append((start, both, d))
            if sum(x[2].size for x in self.pending) >= MEDIAN_STEPS:
                self._settle()
        else:
            self._irregular(start, both, d)

    def _settle(self) -> None:
        steps = np.concatenate([x[2] for x in self.pending])[:MEDIAN_STEPS]
        self.period = float(np.median(steps)) if steps.size else None
        pending, self.pending = self.pending, []
        if self.period is not None:
            for start, both, d in pending:
                self._irregular(start, both, d)

    def _irregular(self, start: int, both: np.ndarray, d: np.ndarray) -> None:
        per = self.period
        long, short = d > GAP_FACTOR * per, d < SHORT_FACTOR * per
        self.long += int(long.sum())
        self.short += int(short.sum())
        if self.first_irregular is None and (long.any() or short.any()):
            i = int(np.flatnonzero(long | short)[0])
            self.first_irregular = ("gap" if long[i] else "short step", start + i, float(d[i]),
                                    float(both[i]), float(both[i + 1]))

    def finish(self) -> float:
        """Raise the first fault; return the sample period (median step) [s]."""
        if self.period is None:
            self._settle()
        p, column, sample_time = self.p, self.column, self.sample_time
        if self.back is not None:
            i, before, after = self.back
            raise DatasetError(f"{p}: time column {column!r} is not strictly increasing: data row {i + 2} has "
                               f"t = {after!r} after t = {before!r}; allowed: strictly increasing times in s")
        per = self.period
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
        if self.first_irregular is not None:
            what, i, step, before, after = self.first_irregular
            is_gap = what == "gap"
            allowed = f"at most {GAP_FACTOR:g}" if is_gap else f"at least {SHORT_FACTOR:g}"
            missing = f", about {step / per - 1:.0f} sample(s) missing" if is_gap else ""
            raise DatasetError(
                f"{p}: column {column!r}: {what} of {step:.6g} s before data row {i + 2} (t = {before:.6g} -> "
                f"{after:.6g} s{missing}), {step / per:.3g} x the median period {per:.6g} s; "
                f"{self.long if is_gap else self.short} {what}(s) in the log ({self.long + self.short} irregular "
                f"step(s) in all); allowed: steps {allowed} x the median period (no interpolation is done: split "
                f"the log at the {what} or resample it)")
        return per


def check_time(p: Path, t: np.ndarray, sample_time, column: str = "t") -> float:
    """Strictly increasing, plausible period (not milliseconds), = sample_time, no gaps
    (:class:`TimeCheck` on a whole column); returns the median period [s]."""
    check = TimeCheck(p, sample_time, column)
    check.feed(t)
    return check.finish()
