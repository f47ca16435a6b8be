"""Logs in Parquet, MDF4 and ROS 2 bags for ``uiogen validate --data``, beside the CSV of
:mod:`codegen.validation.csvlog`.

The format is told by the file's first bytes, never by its name (a log renamed ``.csv`` is still
read as what it is): ``PAR1`` is Parquet, ``MDF     `` (``MDF`` and five spaces) is an ASAM MDF
file, ``LOGG`` a Vector BLF, text with an ASC header (a ``base hex`` or ``base dec`` line) a Vector ASC
CAN log; anything else is read as CSV (plain or gzip). Every reader delivers what
:class:`codegen.validation.csvlog.LogReader` delivers -- ``chunks()`` yielding ``(first, {column:
float64 array})`` and ``rows`` -- so the run, the time check, the unit and physics checks of
:mod:`codegen.validation.logs` are the same code for every format; and ``file_units``, the unit
each column or channel states in the file (:func:`resolve_unit` checks it against the map and
the model).

Parquet (:class:`ParquetLog`) is one table with one time column, like a CSV: read by row groups
in batches of :data:`BATCH_ROWS` rows (``pyarrow.parquet.ParquetFile.iter_batches``), only the
mapped columns; a column's unit is its field metadata ``unit``.

MDF (:class:`MdfLog`, asammdf) keeps every channel group at its own rate, each channel with its
group's master (time) channel. Only the mapped channels are read (``MDF.iter_get``, fragment by
fragment of their group's records; the file's other channels are never converted), twice: once to
judge each one's sampling (:class:`Sampling`), once to put them on one time base, the observer's
sample time, chunk by chunk (:class:`OnGrid`: :func:`on_grid`, :func:`resample` on the samples around
each chunk) -- memory grows neither with the file nor with the channels' length:

- the grid: the span where every mapped channel has data; the recorded times of the first mapped
  channel that is sampled at the observer's period without gaps, else ``start + k Ts``;
- a channel whose samples fall on the grid times is taken as recorded (no resampling, either
  method: the figures of the same log as a CSV, to the last bit);
- any other by its map entry's ``resample``: ``hold`` (default) the last sample at or before the
  grid time; ``linear`` the channel delayed by its largest sampling step D, interpolated: the
  value at grid time t is the straight line between the two samples around t - D, which are both
  at or before t (causal: never a sample from the future), with latency D reported;
- a step longer than :data:`~codegen.validation.csvlog.GAP_FACTOR` x a channel's median period is
  a gap (a DatasetError: no method should bridge missing samples silently); a channel whose
  period changes along the log, or that is slower than the observer, is a warning of the result.

A ROS 2 bag (:class:`BagLog`, rosbags; a folder with ``metadata.yaml``, sqlite3 or mcap storage) is
put on the grid the same way: each mapped ``TOPIC.FIELD`` (``/imu.angular_velocity.z``) is a
channel at its topic's rate, timed by its message's ``header.stamp`` (the bag's recording time for
a message without a header).

A CAN log (:class:`CanLog`: BLF or ASC, python-can, decoded with the DBC the map names, cantools) is
put on the grid the same way: each mapped ``MESSAGE.SIGNAL`` is a channel at its message's rate, timed
by the frames' timestamps relative to the log's first frame, in the DBC signal's unit.
"""
from __future__ import annotations

import difflib
import gc
import logging
import re
import struct
import sys
import zlib
from pathlib import Path

import numpy as np

from ..errors import DatasetError, UnsupportedError, install_hint
from ..project.columns import UNITS, normalize_unit
from ..settings import suggest
from .csvlog import GAP_FACTOR, MEDIAN_STEPS, PERIOD_RTOL, SHORT_FACTOR, LogReader, regular_file

PARQUET_MAGIC = b"PAR1"
BLF_MAGIC = b"LOGG"
ASC_HEAD_BYTES = 4096
"""Bytes of a text log searched for the ASC header line (``base hex|dec``): a header of comments, a date line and
the base line fits well within it."""
ASC_BASE = re.compile(r"^\s*base\s+(hex|dec)\b", re.IGNORECASE | re.MULTILINE)
MDF_MAGIC = b"MDF     "
BAG_FILES = (b"\x89MCAP0\r\n", b"SQLite format 3\x00")
BATCH_ROWS = 65_536
"""Rows per Parquet batch (and per chunk of a resampled MDF log): about 0.5 MiB per float64 column."""
DEFAULT_METHOD = "hold"
"""``hold`` by default: it never invents a value between samples and adds no delay at the grid times
where a sample lies; ``linear`` trades a delay of one sampling step for a smoother signal."""
RATE_BLOCK = 1000
"""A channel's period is compared block by block (medians of RATE_BLOCK steps) to find a rate change."""
GRID_RTOL = 1e-6
"""A sample within GRID_RTOL x the sample time of a grid time lies on it (times written as decimals, 10.01 s,
are not multiples of 0.01 to the last bit)."""


def kind(path) -> str:
    """``"parquet"``, ``"mdf"``, ``"blf"``, ``"asc"``, ``"rosbag2"`` (a folder with ``metadata.yaml``) or
    ``"csv"``: the format of a log, from its first bytes (an ASC log: a ``base hex|dec`` line in its first
    :data:`ASC_HEAD_BYTES` bytes).

    Raises
    ------
    DatasetError
        missing, not a regular file, or unreadable.
    """
    p = Path(path)
    if p.is_dir() and (p / "metadata.yaml").is_file():
        return "rosbag2"
    regular_file(p)
    try:
        with open(p, "rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise DatasetError(f"cannot read {p}: {exc.strerror or exc}") from None
    if head.startswith(PARQUET_MAGIC):
        return "parquet"
    if head.startswith(MDF_MAGIC):
        return "mdf"
    if head.startswith(BLF_MAGIC):
        return "blf"
    if _asc_header(p):
        return "asc"
    if head.startswith(BAG_FILES) and (p.parent / "metadata.yaml").is_file():
        # the storage file of a bag: the bag is its folder (its metadata names the storage and the topics)
        raise DatasetError(f"{p} is the storage file of a ROS 2 bag; allowed: the bag's folder, {p.parent}")
    return "csv"


def _asc_header(p: Path) -> bool:
    """A Vector ASC log: text whose header has a line ``base hex`` or ``base dec`` (every ASC writer, Vector's
    and python-can's, writes it after the ``date`` line; a CSV's header row never starts with ``base hex``)."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(ASC_HEAD_BYTES)
    except OSError as exc:
        raise DatasetError(f"cannot read {p}: {exc.strerror or exc}") from None
    if head.startswith(b"\x1f\x8b"):        # a gzip CSV: its text is not the ASC header
        return False
    return ASC_BASE.search(head.decode("latin-1")) is not None


def closest(name: str, names, n: int = 3) -> list:
    """Up to ``n`` names of the file closest to a missing one (a case-insensitive match first)."""
    names = [str(x) for x in names]
    first = suggest(name, names)
    close = difflib.get_close_matches(name, names, n=n, cutoff=0.5)
    return list(dict.fromkeys(([first] if first else []) + close))[:n]


def _missing(p: Path, what: str, missing: list, names: list) -> DatasetError:
    near = {m: closest(m, names) for m in missing}
    hints = "; ".join(f"{m!r}: closest in the file {', '.join(repr(x) for x in near[m])}" if near[m]
                      else f"{m!r}: nothing close in the file" for m in missing)
    shown = names if len(names) <= 20 else names[:20] + [f"... ({len(names)} in all)"]
    head = f"{p}: missing {what}(s) {missing} ({hints}); the file has {shown}"
    exc = DatasetError(f"{head}; allowed: the names of the file's {what}s in the observer file's [data] table")
    exc.missing, exc.head = list(missing), head     # the shared format's loader says its own allowed names
    return exc


# --- units ----------------------------------------------------------------------------------------

def _dim_units(dim: str) -> str:
    return ", ".join(u for u, (d, _) in UNITS.items() if d == dim)


def resolve_unit(p: Path, what: str, file_unit, map_unit, model_unit):
    """The unit a column is converted from: the file's (a channel's unit, a Parquet field's metadata)
    checked against the map's and the model's; None where neither the file nor the map gives one.

    ``what``: ``channel 'ay' (y_a_y)`` for the messages. The map's unit is already checked (one of
    :data:`~codegen.project.columns.UNITS`). Strict: a file unit uiogen cannot read is refused unless the
    map states the unit (then the map's is used: the user has said what the numbers are); a file unit
    and a map unit that differ are refused (one of them is wrong, and uiogen cannot tell which).

    Returns
    -------
    (unit, source)
        ``source``: ``"file"``, ``"map"`` or None (no unit anywhere: the numbers are in the model's units).

    Raises
    ------
    DatasetError
        naming the file, the column and both units.
    """
    stated = str(file_unit).strip() if file_unit is not None else ""
    if not stated:
        return map_unit, ("map" if map_unit is not None else None)
    unit = normalize_unit(stated)
    if unit not in UNITS:
        if map_unit is not None:
            return map_unit, "map"
        raise DatasetError(f"{p}: {what} has unit {stated!r} in the file, which uiogen does not know; allowed: "
                           f"{', '.join(UNITS)} (or state the column's unit in the observer file's [data] entry, "
                           f"unit = \"...\", which is then used)")
    if map_unit is not None and UNITS[map_unit] != UNITS[unit]:
        raise DatasetError(f"{p}: {what} has unit {stated!r} in the file but {map_unit!r} in the observer file's "
                           f"[data] map; allowed: the same unit in both (drop unit from the map entry to use the "
                           f"file's, or correct the one that is wrong)")
    target = normalize_unit(model_unit) if model_unit else None
    if target not in UNITS:
        if target == unit:
            return unit, "file"
        raise DatasetError(f"{p}: {what} has unit {stated!r} in the file, but the model declares "
                           + (f"the unit {model_unit!r}, which uiogen cannot convert to" if model_unit else "no unit")
                           + "; allowed: the model's unit in the file, or a model that declares one of "
                           f"{', '.join(UNITS)}")
    dim, dim_model = UNITS[unit][0], UNITS[target][0]
    if dim != dim_model:
        raise DatasetError(f"{p}: {what} has unit {stated!r} in the file, a unit of {dim}, but the model's unit is "
                           f"{model_unit!r}, a unit of {dim_model}; allowed: a unit of {dim_model} "
                           f"({_dim_units(dim_model)})")
    return unit, "file"


# --- Parquet --------------------------------------------------------------------------------------

class ParquetLog(LogReader):
    """A Parquet log opened for reading some of its columns in batches.

    Parameters
    ----------
    path : str or os.PathLike
    columns : mapping of str to str
        The columns to read, each with the unit its message names.
    batch_rows : int, optional
        Rows per batch (tests force it small to prove the checks do not depend on it).

    Raises
    ------
    DatasetError
        not a readable Parquet file, duplicated or missing columns, a column that is not numeric,
        a unit metadata that is not UTF-8.
    """

    def __init__(self, path, columns, batch_rows: int = BATCH_ROWS):
        import pyarrow as pa
        import pyarrow.parquet as pq
        p = Path(path)
        self.path, self.units, self.batch_rows = p, dict(columns), int(batch_rows)
        regular_file(p)
        try:
            self._file = pq.ParquetFile(str(p))
            schema = self._file.schema_arrow
        except (pa.ArrowException, OSError) as exc:
            raise DatasetError(f"cannot read {p}: not a readable Parquet file ({exc})") from None
        self.header = list(schema.names)
        dup = sorted({h for h in self.header if self.header.count(h) > 1})
        if dup:
            raise DatasetError(f"{p}: duplicated column(s) {dup}")
        missing = [c for c in self.units if c not in self.header]
        if missing:
            raise _missing(p, "column", missing, self.header)
        self.file_units = {}
        for c in self.units:
            f = schema.field(c)
            if not (pa.types.is_integer(f.type) or pa.types.is_floating(f.type)):
                raise DatasetError(f"{p}: column {c!r} is of type {f.type}; allowed: integer or floating-point "
                                   f"numbers")
            raw = (f.metadata or {}).get(b"unit")
            try:
                self.file_units[c] = raw.decode("utf-8") if raw is not None else None
            except UnicodeDecodeError:
                raise DatasetError(f"{p}: column {c!r}: the field metadata 'unit' is not UTF-8 text ({raw!r})") \
                    from None
        self.rows = 0

    def _read(self):
        import pyarrow as pa
        names = list(self.units)
        batches = self._file.iter_batches(batch_size=self.batch_rows, columns=names)
        while True:
            try:
                batch = next(batches)
            except StopIteration:
                return
            except (pa.ArrowException, OSError) as exc:
                raise DatasetError(f"cannot read {self.path}: {exc}") from None
            if not batch.num_rows:
                continue
            cols = {}
            for c in names:
                a = batch.column(batch.schema.get_field_index(c))
                if a.null_count:
                    row = self.rows + int(np.flatnonzero(a.is_null().to_numpy(zero_copy_only=False))[0]) + 1
                    raise DatasetError(f"{self.path}: column {c!r}, row {row}: a null (a missing sample); allowed: "
                                       f"a number in every row of a mapped column (fill or drop the row)")
                cols[c] = a.cast(pa.float64()).to_numpy(zero_copy_only=False)
            yield self._deliver(cols)


# --- MDF: channels at their own rates onto the observer's grid ------------------------------------

def _quiet(*names):
    """Silence the loggers ``names`` (asammdf; python-can and cantools): with no handler configured Python
    prints a library's warnings (a BLF object of an unknown type, a DBC attribute ignored) to stderr, below
    the one-line error of the command line; uiogen says what matters."""
    for name in names:
        log = logging.getLogger(name)
        if not any(isinstance(h, logging.NullHandler) for h in log.handlers):
            log.addHandler(logging.NullHandler())
        log.propagate = False


def _mdf():
    try:
        from asammdf import MDF
    except ImportError:
        raise UnsupportedError("MDF logs need asammdf, which is not installed: " + install_hint("validation")) \
            from None
    _quiet("asammdf")
    return MDF


def _open(MDF, p: Path):
    """``(MDF of the file, the open file)``, or a DatasetError: asammdf raises many types on a damaged
    file, and the half-built object's ``__del__`` then fails too, which Python would print as 'Exception
    ignored' below the one-line error; it is collected here with that report swallowed.

    asammdf is given the open file, not its path: with a path it maps the whole file into memory
    (``mmap``), and every page a read touches then counts in the process's resident memory -- a 726 MB
    file read channel by channel peaked at 0.98 GB, from the open file at 0.21 GB."""
    hook, failure = sys.unraisablehook, None
    sys.unraisablehook = lambda unraisable: None
    try:
        try:
            fh = open(p, "rb")
        except OSError as exc:
            raise DatasetError(f"cannot read {p}: {exc.strerror or exc}") from None
        try:
            return MDF(fh), fh
        except Exception as exc:     # noqa: BLE001 -- any failure of the parser says the same to the user
            failure = f"{type(exc).__name__}: {exc}"
        fh.close()
        gc.collect()                 # the exception (and the half-built object it holds) is gone: collect it now
    finally:
        sys.unraisablehook = hook
    raise DatasetError(f"cannot read {p}: not a readable MDF file ({failure})")


class Sampling:
    """The facts of one mapped channel's sampling, its samples fed once, in order, chunk by chunk
    (:meth:`feed`, then :meth:`finish`): its number of samples, first and last time, median period (of
    its first :data:`~codegen.validation.csvlog.MEDIAN_STEPS` steps, as the CSV's time check takes
    it), largest step, gaps, short steps and the first block whose period departs from it. Memory: the
    first MEDIAN_STEPS steps and one :data:`RATE_BLOCK`, whatever the channel's length.

    :meth:`finish` raises what the channel cannot be read with, in this order: fewer than 2 samples,
    non-finite values, times that do not increase, a gap."""

    def __init__(self, p: Path, name: str, unit, method: str):
        self.p, self.name, self.unit, self.method = p, name, unit, method
        self.n, self.first_t, self.last_t = 0, None, None
        self.bad, self.bad_t, self.back = 0, None, None
        self.period, self.head = None, []              # the first steps, (t before, step), until the period is known
        self.max_step, self.short, self.gaps, self.gap = 0.0, 0, 0, None
        self.block, self.block_t0, self.rate_change = [], None, None

    def feed(self, t: np.ndarray, x: np.ndarray) -> None:
        if not t.size:
            return
        bad = ~np.isfinite(x)
        if bad.any():
            self.bad += int(bad.sum())
            if self.bad_t is None:
                self.bad_t = float(t[int(np.flatnonzero(bad)[0])])
        joined = t if self.last_t is None else np.concatenate([[self.last_t], t])   # the steps across chunks too
        before, d = joined[:-1], np.diff(joined)
        if self.back is None:
            back = np.flatnonzero(~(d > 0))
            if back.size:
                i = int(back[0])
                # (time before, time after, the later sample's number from 1)
                self.back = (float(before[i]), float(joined[i + 1]), self.n + i + (2 if self.last_t is None else 1))
        self.first_t = float(t[0]) if self.first_t is None else self.first_t
        self.last_t = float(t[-1])
        self.n += t.size
        if self.period is None:
            self.head.append((before, d))
            if sum(s.size for _, s in self.head) >= MEDIAN_STEPS:
                self._settle()
        else:
            self._steps(before, d)

    def _settle(self) -> None:
        """The period from the first steps, and those steps judged by it."""
        before = np.concatenate([b for b, _ in self.head]) if self.head else np.empty(0)
        d = np.concatenate([s for _, s in self.head]) if self.head else np.empty(0)
        self.head = None
        self.period = float(np.median(d[:MEDIAN_STEPS])) if d.size else float("nan")
        self._steps(before, d)

    def _steps(self, before: np.ndarray, d: np.ndarray) -> None:
        if not d.size:
            return
        self.max_step = max(self.max_step, float(d.max()))
        long = np.flatnonzero(d > GAP_FACTOR * self.period)
        if long.size:
            self.gaps += int(long.size)
            if self.gap is None:
                self.gap = (float(d[long[0]]), float(before[long[0]]))
        self.short += int(np.count_nonzero(d < SHORT_FACTOR * self.period))
        k = 0
        while k < d.size:                       # blocks of RATE_BLOCK steps from the channel's first
            if not self.block:
                self.block_t0 = float(before[k])
            take = min(RATE_BLOCK - sum(b.size for b in self.block), d.size - k)
            self.block.append(d[k:k + take])
            k += take
            if sum(b.size for b in self.block) == RATE_BLOCK:
                self._judge_block()

    def _judge_block(self) -> None:
        block = np.concatenate(self.block)
        self.block = []
        if self.rate_change is None and block.size >= RATE_BLOCK // 2 \
                and abs(np.median(block) / self.period - 1.0) > PERIOD_RTOL:
            self.rate_change = (self.block_t0, self.block_t0 + float(block.sum()), float(np.median(block)))

    def finish(self) -> None:
        p, name = self.p, self.name
        if self.n < 2:
            raise DatasetError(f"{p}: channel {name!r} has {self.n} sample(s); needs at least 2")
        if self.bad:
            raise DatasetError(f"{p}: channel {name!r} has {self.bad} non-finite value(s), first at "
                               f"t = {self.bad_t:.6g} s; allowed: finite numbers")
        if self.back is not None:
            t0, t1, k = self.back
            raise DatasetError(f"{p}: channel {name!r}: time is not strictly increasing: t = {t1!r} s after "
                               f"t = {t0!r} s (sample {k}); allowed: strictly increasing times")
        if self.period is None:
            self._settle()
        if self.block:
            self._judge_block()
        if self.gap is not None:
            step, t = self.gap
            raise DatasetError(
                f"{p}: channel {name!r}: gap of {step:.6g} s after t = {t:.6g} s ({step / self.period:.3g} x its "
                f"median period {self.period:.6g} s, {1 / self.period:.4g} Hz); {self.gaps} gap(s) in the channel; "
                f"allowed: steps of at most {GAP_FACTOR:g} x the median period (no method bridges missing samples: "
                f"split the log at the gap)")
        # linear needs the two samples around t - D: its first value is one step after the first sample
        self.start = self.first_t + (self.max_step if self.method == "linear" else 0.0)
        self.end = self.last_t

    def regular_at(self, ts: float) -> bool:
        """Sampled at the period ``ts`` without short steps (gaps are refused when read)."""
        return abs(self.period / ts - 1.0) <= PERIOD_RTOL and not self.short and self.rate_change is None


class Channel(Sampling):
    """One mapped channel held whole: its times [s] ``t``, values ``x``, unit, and the facts of its
    sampling (:class:`Sampling`); :meth:`parts` gives it as one part."""

    def __init__(self, p: Path, name: str, t: np.ndarray, x: np.ndarray, unit, method: str):
        super().__init__(p, name, unit, method)
        self.t, self.x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
        self.feed(self.t, self.x)
        self.finish()

    def parts(self):
        yield self.t, self.x


def time_base(channels: list, ts: float) -> np.ndarray:
    """The grid of channels held whole: the span where every channel has data, at the sample time ``ts``
    [s]; the recorded times of the first channel sampled at ``ts`` (the CSV's times when the log is on the
    grid), else start + k ts (:class:`OnGrid` builds the same grid chunk by chunk)."""
    start, end = max(c.start for c in channels), min(c.end for c in channels)
    tol = GRID_RTOL * ts
    for c in channels:
        if c.regular_at(ts):
            # a sample within tol of the span's ends belongs to it (the times are the other channels' too)
            return c.t[(c.t >= start - tol) & (c.t <= end + tol)]
    return start + ts * np.arange(int(np.floor((end - start) / ts + GRID_RTOL)) + 1)


def on_grid(c, grid: np.ndarray, ts: float) -> np.ndarray | None:
    """The channel's values as recorded when its samples over the grid's span are the grid times, else None
    (``c``: a :class:`Channel`, or the part of one held while it is put on the grid)."""
    tol = GRID_RTOL * ts
    i0, i1 = np.searchsorted(c.t, grid[0] - tol, side="left"), np.searchsorted(c.t, grid[-1] + tol, side="right")
    if i1 - i0 == grid.size and np.all(np.abs(c.t[i0:i1] - grid) <= tol):
        return c.x[i0:i1]
    return None


def resample(c, grid: np.ndarray, ts: float) -> tuple:
    """The channel's values at the grid times and the latency [s] its method adds.

    ``hold``: the last sample at or before each grid time (within :data:`GRID_RTOL` x ``ts``), latency 0
    (a value is up to one period old). ``linear``: the straight line between the samples around t - D,
    D the channel's largest step: both are at or before t; latency D.
    """
    if c.method == "linear":
        return np.interp(grid - c.max_step, c.t, c.x), c.max_step
    idx = np.searchsorted(c.t, grid + GRID_RTOL * ts, side="right") - 1
    return c.x[np.maximum(idx, 0)], 0.0


class _Held:
    """The samples of one channel held while it is put on the grid: from the last one a later grid time may
    need (hold: at or before it; linear: at or before it less the channel's largest step) to the first past
    the grid chunk, pulled from the channel's parts as the grid advances."""

    def __init__(self, c: Sampling, parts):
        self.method, self.max_step, self.parts = c.method, c.max_step, parts
        self.t, self.x, self.done = np.empty(0), np.empty(0), False

    def cover(self, until: float) -> None:
        """Hold samples up to the first past ``until`` (or every one left)."""
        ts, xs = [self.t], [self.x]
        last = self.t[-1] if self.t.size else -np.inf
        while not self.done and last <= until:
            try:
                t, x = next(self.parts)
            except StopIteration:
                self.done = True
                break
            if t.size:
                ts.append(t)
                xs.append(x)
                last = t[-1]
        if len(ts) > 1:
            self.t, self.x = np.concatenate(ts), np.concatenate(xs)

    def count_after(self, after: float, until: float) -> int:
        return int(np.count_nonzero((self.t > after) & (self.t <= until)))

    def release(self, before: float) -> None:
        """Drop the samples before the last one at or before ``before``."""
        i = max(0, int(np.searchsorted(self.t, before, side="right")) - 1)
        if i:
            self.t, self.x = self.t[i:], self.x[i:]


class OnGrid:
    """Channels at their own rates on one grid at the observer's sample time, delivered in chunks.

    A reader sets ``self.channels`` (each a :class:`Sampling`, every sample of it seen once) and calls
    :meth:`_put_on_grid`; :meth:`_parts` gives ``{channel name: iterator of (t, x) parts}`` for a second
    pass, in which :meth:`chunks` puts them on the grid chunk by chunk. Only a chunk of the grid and the
    samples around it are held: memory does not grow with the log (a reader holding its channels whole,
    :class:`Channel`, gives them as one part)."""

    def _parts(self):
        """A context manager giving ``{channel name: iterator of (t, x)}``: the channels held whole."""
        import contextlib
        return contextlib.nullcontext({c.name: c.parts() for c in self.channels})

    def _put_on_grid(self, ts: float) -> None:
        """The span, the grid's source, ``resampling`` and ``warnings`` of ``self.channels`` at the sample
        time ``ts`` [s] (the values: :meth:`chunks`)."""
        p = self.path
        start, end = max(c.start for c in self.channels), min(c.end for c in self.channels)
        if end - start < ts:
            spans = "; ".join(f"{c.name!r} {c.start:.6g}..{c.end:.6g} s" for c in self.channels)
            raise DatasetError(f"{p}: the mapped channels share no span of at least one sample time {ts:g} s "
                               f"({spans}); allowed: channels recorded over the same interval")
        self.ts, self.span = ts, (start, end)
        # the grid: the recorded times of the first channel sampled at ts, else start + k ts
        self.grid_source = next((c.name for c in self.channels if c.regular_at(ts)), None)
        self.resampling, self.warnings = {}, []
        for c in self.channels:
            latency = c.max_step if c.method == "linear" else 0.0
            self.resampling[c.name] = {"rate_hz": 1.0 / c.period, "method": c.method, "latency_s": latency}
            if c.period > ts * (1.0 + PERIOD_RTOL):
                self.warnings.append(
                    f"channel {c.name!r} is sampled at {1 / c.period:.4g} Hz, slower than the observer's "
                    f"{1 / ts:.4g} Hz: {c.method} gives it between samples"
                    + (f" (latency {latency:.6g} s)" if c.method == "linear" else " (each value held until the next)"))
            if c.rate_change is not None:
                t0, t1, per = c.rate_change
                self.warnings.append(f"channel {c.name!r} changes its rate: median period {per:.6g} s "
                                     f"({1 / per:.4g} Hz) from t = {t0:.6g} to {t1:.6g} s, {c.period:.6g} s "
                                     f"({1 / c.period:.4g} Hz) over the log")
            if c.short:
                self.warnings.append(f"channel {c.name!r} has {c.short} step(s) shorter than {SHORT_FACTOR:g} x its "
                                     f"median period {c.period:.6g} s (irregular sampling)")
        self.rows = 0

    def _grid_chunks(self, held: dict):
        """The grid, ``chunk_rows`` times at a time."""
        ts, rows = self.ts, self.chunk_rows
        start, end = self.span
        tol = GRID_RTOL * ts
        if self.grid_source is None:
            n = int(np.floor((end - start) / ts + GRID_RTOL)) + 1
            for first in range(0, n, rows):
                yield start + ts * np.arange(first, min(n, first + rows))
            return
        src, last = held[self.grid_source], -np.inf

        def ahead():
            return (src.t > last) & (src.t >= start - tol) & (src.t <= end + tol)
        while True:
            while not src.done and (not src.t.size or src.t[-1] <= end + tol) and np.count_nonzero(ahead()) < rows:
                src.cover((src.t[-1] if src.t.size else start) + rows * ts)
            t = src.t[ahead()][:rows]
            if not t.size:
                return
            last = float(t[-1])
            yield t

    def chunks(self):
        """Yield ``(first, {key: float64 array})`` of the grid, the time under ``time_key`` [s]."""
        self.rows = 0
        ts = self.ts
        tol = GRID_RTOL * ts
        recorded = {c.name: True for c in self.channels}
        with self._parts() as parts:
            held = {c.name: _Held(c, iter(parts[c.name])) for c in self.channels}
            first = 0
            for grid in self._grid_chunks(held):
                cols = {self.time_key: grid}
                for c in self.channels:
                    h = held[c.name]
                    h.cover(grid[-1] + tol)
                    x = on_grid(h, grid, ts)
                    if x is None:
                        recorded[c.name] = False
                        x, _ = resample(h, grid, ts)
                    cols[c.name] = np.array(x, dtype=float)
                    h.release(grid[-1] - h.max_step - tol if c.method == "linear" else grid[-1] - tol)
                if first == 0 and grid.size < min(2, self.chunk_rows):
                    raise DatasetError(f"{self.path}: the mapped channels share {grid.size} sample time(s); needs "
                                       f"at least 2")
                first += grid.size
                self.rows = first
                yield first - grid.size, cols
        for c in self.channels:
            if recorded[c.name]:
                self.resampling[c.name].update(method="as recorded", latency_s=0.0)


class TableOnGrid(OnGrid):
    """A CSV or Parquet log sampled at another rate than the observer's, on the observer's grid: its
    mapped columns streamed through ``table`` (the streaming reader, every check of its format), each
    a channel on the log's one time column (converted to s by ``time_factor``), put on the grid like an
    MDF log's channels (``methods``: ``hold`` or ``linear`` per column). The table is read twice, chunk
    by chunk (one pass judges each channel's sampling, a second puts them on the grid), so memory does
    not grow with the log. A log at the observer's rate is streamed as it is (:func:`period_of`)."""

    def __init__(self, table, time_key: str, time_factor: float, methods, sample_time: float,
                 chunk_rows: int = BATCH_ROWS):
        self.path, self.time_key, self.chunk_rows = table.path, time_key, int(chunk_rows)
        self._table, self._time_factor = table, time_factor
        self.file_units = dict(getattr(table, "file_units", {}))
        self.channels = [Sampling(self.path, c, self.file_units.get(c), (methods or {}).get(c, DEFAULT_METHOD))
                         for c in table.units if c != time_key]
        for part in self._batches():
            for c in self.channels:
                c.feed(*part[c.name])
        for c in self.channels:
            c.finish()
        self._put_on_grid(sample_time)

    def _batches(self):
        """``{channel: (t [s], x)}`` per chunk of the table, every channel at the table's times."""
        for _, cols in self._table.chunks():
            t = cols[self.time_key] * self._time_factor
            yield {c.name: (t, cols[c.name]) for c in self.channels}

    def _parts(self):
        import contextlib
        demux = _Demux(self._batches(), [c.name for c in self.channels])
        return contextlib.nullcontext({c.name: demux.parts(c.name) for c in self.channels})


def period_of(table, time_key: str, time_factor: float) -> float:
    """The median period [s] of the first :data:`~codegen.validation.csvlog.MEDIAN_STEPS` steps of a CSV or
    Parquet log's time column (what its time check judges the log by)."""
    from .csvlog import MEDIAN_STEPS
    times, held = [], 0
    for _, cols in table.chunks():
        times.append(cols[time_key])
        held += cols[time_key].size
        if held > MEDIAN_STEPS:
            break
    t = np.concatenate(times)[:MEDIAN_STEPS + 1] * time_factor
    return float(np.median(np.diff(t))) if t.size >= 2 else float("nan")


class MdfLog(OnGrid):
    """An MDF log: the mapped channels, each read alone with its own master, on the observer's grid.

    Parameters
    ----------
    path : str or os.PathLike
    channels : mapping of str to str
        The channels to read (the map's ``column`` names), each with the unit its message names.
    time_key : str
        The key the grid times [s] are delivered under (the map's ``time`` column, which an MDF file
        does not need: every channel has its group's master).
    methods : mapping of str to str
        ``hold`` or ``linear`` per channel (:data:`DEFAULT_METHOD` where absent).
    sample_time : float
        The observer's sample time [s].
    chunk_rows : int, optional
        Grid samples per chunk.

    Raises
    ------
    DatasetError
        not a readable MDF file, a channel missing (the closest names listed), ambiguous (in several
        groups), not numeric, non-finite, with a gap, or no span where every channel has data.
    UnsupportedError
        asammdf is not installed.
    """

    def __init__(self, path, channels, time_key: str, methods, sample_time: float, chunk_rows: int = BATCH_ROWS):
        MDF = _mdf()
        p = Path(path)
        self.path, self.units, self.time_key, self.chunk_rows = p, dict(channels), time_key, int(chunk_rows)
        regular_file(p)
        self._where = {}                    # channel -> (group, index, factor of its master's unit to s)
        self._unit = {}                     # channel -> its unit, as asammdf gives it with the samples
        with self._opened(MDF) as mdf:
            self.channels = [self._channel(mdf, p, name, methods.get(name, DEFAULT_METHOD)) for name in self.units]
        self.file_units = {c.name: c.unit for c in self.channels}
        self._put_on_grid(float(sample_time))

    def _opened(self, MDF=None):
        """The file opened by asammdf (a context manager), read in fragments of :data:`MDF_FRAGMENT` bytes."""
        import contextlib
        MDF = MDF or _mdf()

        @contextlib.contextmanager
        def opened():
            mdf, fh = _open(MDF, self.path)
            try:
                mdf.configure(read_fragment_size=MDF_FRAGMENT)
                yield mdf
            finally:
                mdf.close()
                fh.close()
        return opened()

    def _fragments(self, mdf, name: str):
        """The channel's (t [s], x) fragment by fragment (``MDF.iter_get``: one data fragment of its group
        at a time, never the whole channel)."""
        import contextlib
        group, index, factor = self._where[name]
        try:
            fragments = mdf.iter_get(name, group=group, index=index)
            while True:
                # asammdf 8.8 prints a throughput line to stdout when a read of its data runs past 10 s (a
                # channel read fragment by fragment beside the others): it would break --json
                with contextlib.redirect_stdout(_Sink()):
                    sig = next(fragments, None)
                if sig is None:
                    return
                x = np.asarray(sig.samples)
                if x.dtype.kind not in "iuf" or x.ndim != 1:
                    raise DatasetError(f"{self.path}: channel {name!r} holds {x.dtype} values of shape "
                                       f"{x.shape[1:] or 'scalar'}; allowed: one number per sample")
                self._unit[name] = sig.unit or None         # the channel's, or its conversion's
                yield np.asarray(sig.timestamps, dtype=float) * factor, x.astype(float)
        except DatasetError:
            raise
        except Exception as exc:     # noqa: BLE001 -- asammdf's own reading errors, of many types
            raise DatasetError(f"cannot read {self.path}: channel {name!r}: {type(exc).__name__}: {exc}") from None

    def _parts(self):
        import contextlib

        @contextlib.contextmanager
        def parts():
            with self._opened() as mdf:
                yield {c.name: self._fragments(mdf, c.name) for c in self.channels}
        return parts()

    def _channel(self, mdf, p: Path, name: str, method: str) -> Sampling:
        found = mdf.channels_db.get(name)
        if not found:
            raise _missing(p, "channel", [name], list(mdf.channels_db))
        if len(found) > 1:
            raise DatasetError(f"{p}: channel {name!r} is in {len(found)} channel groups ({[g for g, _ in found]}); "
                               f"allowed: a channel name that is unique in the file")
        group, index = found[0]
        master = mdf.masters_db.get(group)
        t_unit = mdf.groups[group].channels[master].unit.strip() if master is not None else ""
        t_unit = normalize_unit(t_unit) if t_unit else "s"
        if UNITS.get(t_unit, ("",))[0] != "time":
            raise DatasetError(f"{p}: channel {name!r}: its master channel has unit {t_unit!r}; allowed: a time "
                               f"master in s or ms")
        self._where[name] = (group, index, UNITS[t_unit][1])
        c = Sampling(p, name, None, method)
        for t, x in self._fragments(mdf, name):
            c.feed(t, x)
        c.unit = self._unit.get(name)
        c.finish()
        return c


class _Sink:
    """A text stream that keeps nothing."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


MDF_FRAGMENT = 8 << 20
"""Bytes of an MDF channel group's data read at a time (asammdf's ``read_fragment_size``): a fragment's
records, whatever the file's size."""


ROS2_STORE = "LATEST"
"""The rosbags typestore of the message types a bag names without their definitions (the newest ROS 2
distribution's standard messages; a bag that stores its definitions is read with its own)."""


def _rosbags():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UnsupportedError("ROS 2 bags need rosbags, which is not installed: " + install_hint("validation")) \
            from None
    return AnyReader, get_typestore(getattr(Stores, ROS2_STORE))


def _split(name: str):
    """``/imu/data.angular_velocity.z`` -> (``/imu/data``, [``angular_velocity``, ``z``]): a ROS 2 topic
    name holds no '.', so the first '.' ends it."""
    topic, _, path = name.partition(".")
    return topic, [f for f in path.split(".") if f]


def _fields(msg) -> list:
    """The fields of a deserialized message (not the type's own ``__msgtype__``)."""
    names = getattr(msg, "__dataclass_fields__", None) or getattr(msg, "__slots__", ())
    return [f for f in names if not f.startswith("__")]


def _field(p: Path, name: str, msg, path: list):
    value = msg
    for k, f in enumerate(path):
        if f.isdigit() and isinstance(value, (list, tuple, np.ndarray)):
            if int(f) >= len(value):
                raise DatasetError(f"{p}: channel {name!r}: index {f} of {'.'.join(path[:k])!r}, which holds "
                                   f"{len(value)} value(s); allowed: an index from 0 to {len(value) - 1}")
            value = value[int(f)]
            continue
        if not hasattr(value, f) or f not in _fields(value):
            have = _fields(value)
            near = closest(f, have)
            raise DatasetError(f"{p}: channel {name!r}: the message has no field {'.'.join(path[:k + 1])!r}"
                               + (f" (closest: {', '.join(repr(x) for x in near)})" if near else "")
                               + f"; allowed: one of {have} at that level (TOPIC.FIELD.SUBFIELD, e.g. "
                               f"/imu.angular_velocity.z)")
        value = getattr(value, f)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise DatasetError(f"{p}: channel {name!r} is {type(value).__name__}, not a number; allowed: a numeric "
                           f"field (fields: {_fields(value) or 'none'})")
    return float(value)


def _stamp(msg):
    """The message's header stamp [s], or None where it has none."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    return None if stamp is None else stamp.sec + 1e-9 * stamp.nanosec


class BagLog(OnGrid):
    """A ROS 2 bag (a folder with ``metadata.yaml``, sqlite3 or mcap storage; rosbags): every mapped
    ``TOPIC.FIELD`` a channel, at its topic's rate, on the observer's grid.

    A channel's time is its message's ``header.stamp`` where the message has a header, else the time
    the bag recorded it. Only the messages of the mapped topics are read, and only the mapped fields
    kept, :data:`BAG_BATCH` messages at a time: one pass judges each channel's sampling, a second puts
    them on the grid chunk by chunk (the bag's order interleaves the topics: :class:`_Demux`). ROS
    messages carry no units (REP 103: SI), so the map's units apply.

    Parameters
    ----------
    path, channels, time_key, methods, sample_time, chunk_rows
        As :class:`MdfLog`; ``channels``: ``TOPIC.FIELD`` names.

    Raises
    ------
    DatasetError
        not a readable bag, a topic or field missing (the closest listed), a field that is not a number,
        non-finite, with a gap.
    UnsupportedError
        rosbags is not installed.
    """

    def __init__(self, path, channels, time_key: str, methods, sample_time: float, chunk_rows: int = BATCH_ROWS):
        p = Path(path)
        self.path, self.units, self.time_key, self.chunk_rows = p, dict(channels), time_key, int(chunk_rows)
        wanted = {}
        for name in self.units:
            topic, fields = _split(name)
            if not fields:
                raise DatasetError(f"{p}: channel {name!r} names no field; allowed: TOPIC.FIELD (e.g. "
                                   f"/imu.angular_velocity.z, /speed.data)")
            wanted.setdefault(topic, []).append((name, fields))
        self._wanted = wanted
        self.channels = [Sampling(p, name, None, methods.get(name, DEFAULT_METHOD))
                         for names in wanted.values() for name, _ in names]
        by_name = {c.name: c for c in self.channels}
        with self._reading() as batches:
            for part in batches:
                for name, (t, x) in part.items():
                    by_name[name].feed(t, x)
        for c in self.channels:
            c.finish()
        self.file_units = {}
        self._put_on_grid(float(sample_time))

    def _reading(self):
        """A context manager giving the mapped channels' samples, ``{channel: (t, x)}`` of up to
        :data:`BAG_BATCH` messages at a time, in the bag's order (one pass over the mapped topics'
        messages; a reading error of rosbags a DatasetError)."""
        import contextlib
        AnyReader, store = _rosbags()
        p, wanted = self.path, self._wanted

        def batches(reader, conns):
            times = {t: [] for t in wanted}
            values = {n: [] for names in wanted.values() for n, _ in names}
            count = 0
            for conn, recorded, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = _stamp(msg)
                times[conn.topic].append(recorded * 1e-9 if stamp is None else stamp)
                for name, fields in wanted[conn.topic]:
                    values[name].append(_field(p, name, msg, fields))
                count += 1
                if count == BAG_BATCH:
                    yield _arrays(wanted, times, values)
                    times = {t: [] for t in wanted}
                    values = {n: [] for n in values}
                    count = 0
            if count:
                yield _arrays(wanted, times, values)

        @contextlib.contextmanager
        def reading():
            try:
                with AnyReader([p], default_typestore=store) as reader:
                    topics = {c.topic for c in reader.connections}
                    missing = [t for t in wanted if t not in topics]
                    if missing:
                        raise _missing(p, "topic", missing, sorted(topics))
                    yield batches(reader, [c for c in reader.connections if c.topic in wanted])
            except DatasetError:
                raise
            except Exception as exc:     # noqa: BLE001 -- rosbags raises its own types and sqlite's, apsw's, mcap's
                raise DatasetError(f"cannot read {p}: not a readable ROS 2 bag ({type(exc).__name__}: {exc})") \
                    from None
        return reading()

    def _parts(self):
        import contextlib

        @contextlib.contextmanager
        def parts():
            with self._reading() as batches:
                demux = _Demux(batches, [c.name for c in self.channels])
                yield {c.name: demux.parts(c.name) for c in self.channels}
        return parts()


BAG_BATCH = 8192
"""Messages of a bag read before their samples are handed on (per channel, as arrays)."""


def _arrays(wanted: dict, times: dict, values: dict) -> dict:
    """{channel: (t, x)} of a batch of messages (each channel at its topic's times)."""
    out = {}
    for topic, names in wanted.items():
        t = np.asarray(times[topic], dtype=float)
        for name, _ in names:
            out[name] = (t, np.asarray(values[name], dtype=float))
    return out


class _Demux:
    """One pass over a bag's batches, each channel's parts given to it in turn (a channel's parts wait in
    its queue until it asks: the grid pulls every channel up to the same time, so the queues stay short)."""

    def __init__(self, batches, names):
        from collections import deque
        self.batches, self.done = batches, False
        self.queues = {n: deque() for n in names}

    def parts(self, name: str):
        queue = self.queues[name]
        while True:
            if queue:
                yield queue.popleft()
                continue
            if self.done:
                return
            try:
                part = next(self.batches)
            except StopIteration:
                self.done = True
                continue
            for n, tx in part.items():
                self.queues[n].append(tx)


# --- CAN logs (BLF, ASC) decoded with a DBC ---------------------------------------------------------

CAN_FORMATS = ("blf", "asc")
CAN_BATCH = 8192
"""Decoded frames of a CAN log read before their samples are handed on (per channel, as arrays)."""
TICKS = 1_000_000
"""Frame times are rounded to 1 us (1 / TICKS s) from the log's first frame: python-can gives a BLF frame's time as the
file's start (Unix time, ~1.7e9 s) plus its offset in one float64, which holds it to ~0.2 us; 1 us is far
below a CAN frame's duration (at least ~50 us at 1 Mbit/s), so no two frames of a message merge."""


def _can():
    try:
        import can
        import cantools
    except ImportError:
        raise UnsupportedError("CAN logs (BLF, ASC) need python-can and cantools, which are not installed: "
                               + install_hint("validation")) from None
    _quiet("can", "cantools")
    return can, cantools


def frame_id(key) -> str:
    """``0x120``, ``0x18FEF100 (extended)``: a frame id as the messages write it."""
    fid, extended = key
    return f"0x{fid:X}" + (" (extended)" if extended else "")


def load_dbc(path):
    """The DBC database at ``path`` (cantools).

    Raises
    ------
    DatasetError
        missing, not a regular file, or not a DBC cantools can parse (naming the file).
    """
    _, cantools = _can()
    p = Path(path)
    if not p.exists():
        raise DatasetError(f"{p}: no such DBC file (the observer file's [data] dbc, relative to the observer file); "
                           f"allowed: the path of the DBC the CAN log is decoded with")
    regular_file(p)
    try:
        return cantools.database.load_file(str(p), database_format="dbc")
    except Exception as exc:     # noqa: BLE001 -- cantools' parse errors, a decoding error, an I/O error
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise DatasetError(f"cannot read the DBC {p}: not a DBC file cantools can parse ({type(exc).__name__}"
                           + (f": {first}" if first else "") + ")") from None


class CanLog(OnGrid):
    """A CAN log (Vector BLF or ASC, read by python-can) decoded with a DBC (cantools): every mapped
    ``MESSAGE.SIGNAL`` a channel at its message's rate, on the observer's grid.

    The file is streamed frame by frame, twice (as a bag: one pass judges each channel's sampling, a
    second puts the channels on the grid chunk by chunk): only the frames of the mapped messages are
    decoded (their ids looked up in a dict: the others cost a lookup), only the mapped signals kept, each
    with the times of the frames that carry it (a multiplexed signal: only the frames of its multiplexer
    value), :data:`CAN_BATCH` frames at a time, so memory does not grow with the log. A channel's times are its frames' timestamps
    relative to the log's first frame (any id), rounded to 1 us (:data:`TICKS`); its values are the DBC's
    physical values (cantools applies the scale and offset), its unit the DBC signal's.

    Parameters
    ----------
    path, channels, time_key, methods, sample_time, chunk_rows
        As :class:`MdfLog`; ``channels``: ``MESSAGE.SIGNAL`` names of the DBC.
    dbc : str or os.PathLike
        The DBC file.

    Raises
    ------
    DatasetError
        the DBC missing or unparsable; a message or signal the DBC lacks (the closest names listed);
        a mapped message that never appears in the log (its frame id and the ids the log has); a frame
        that does not decode; a damaged log; a channel with a gap (:class:`Channel`).
    UnsupportedError
        python-can or cantools is not installed.
    """

    def __init__(self, path, channels, time_key: str, methods, sample_time: float, dbc, chunk_rows: int = BATCH_ROWS,
                 bus: int | None = None):
        _can()
        p = Path(path)
        self.path, self.units, self.time_key, self.chunk_rows = p, dict(channels), time_key, int(chunk_rows)
        self.format, self._dbc, self._bus = kind(p), dbc, bus
        db = load_dbc(dbc)
        wanted, self.file_units = {}, {}        # (frame id, extended) -> (message, [(channel, signal)])
        for name in self.units:
            msg, sig = self._signal(db, Path(dbc), name)
            key = (msg.frame_id, bool(msg.is_extended_frame))
            wanted.setdefault(key, (msg, []))[1].append((name, sig.name))
            self.file_units[name] = sig.unit or None
        self._wanted = wanted
        self.channels = [Sampling(p, name, self.file_units[name], methods.get(name, DEFAULT_METHOD))
                         for name in self.units]
        by_name = {c.name: c for c in self.channels}
        seen = set()            # the (frame id, extended) of every frame on the bus read
        buses = {}              # mapped (frame id, extended) -> the buses (1 = CAN 1) its frames came on
        on_bus = set()          # the buses of every frame
        with self._reading(seen, buses, on_bus) as batches:
            for part in batches:
                for name, (t, x) in part.items():
                    by_name[name].feed(t, x)
        listed = ", ".join("CAN " + str(b) if b is not None else "a bus with no number" for b in sorted(
            on_bus, key=lambda b: (b is None, b or 0)))
        if bus is not None and bus not in on_bus:
            raise DatasetError(f"{p}: [data] can_channel = {bus}: the log has no frame on CAN {bus}; its frames are on "
                               f"{listed or 'no bus'}; allowed: one of those")
        mixed = {k: b for k, b in buses.items() if len(b) > 1}
        if mixed:
            k, b = next(iter(mixed.items()))
            raise DatasetError(f"{p}: message {wanted[k][0].name!r} (frame id {frame_id(k)}) comes on "
                               f"{len(b)} buses ({', '.join('CAN ' + str(x) for x in sorted(b, key=lambda x: x or 0))}): "
                               f"two sources of one signal would be mixed; allowed: [data] can_channel = N (N: the "
                               f"bus to read, as numbered in the log)")
        absent = [k for k in wanted if k not in seen]
        if absent:
            ids = sorted(seen)
            shown = [frame_id(k) for k in ids[:30]] + ([f"... ({len(ids)} in all)"] if len(ids) > 30 else [])
            names = ", ".join(f"{wanted[k][0].name!r} (frame id {frame_id(k)})" for k in absent)
            raise DatasetError(f"{p}: message(s) {names} of the DBC {dbc} never appear in the log"
                               + (f" on CAN {bus}" if bus is not None else "") + "; the log has "
                               + (f"frame ids {', '.join(shown)}" if ids else "no CAN frames")
                               + "; allowed: messages the log holds (is the DBC the log's bus's?)")
        for c in self.channels:
            c.finish()
        self._put_on_grid(float(sample_time))

    def _reading(self, seen: set, buses: dict, on_bus: set):
        """A context manager giving the mapped signals' samples, ``{channel: (t, x)}`` of up to :data:`CAN_BATCH`
        decoded frames at a time, in the log's order (one pass over the file, frame by frame). ``seen``,
        ``buses``, ``on_bus`` are filled with the frame ids of the bus read, the buses of each mapped message and
        of every frame. A channel's times are its frames' timestamps relative to the log's first frame (any id),
        rounded to 1 us (:data:`TICKS`). A reading error of python-can a DatasetError."""
        import contextlib
        can, _ = _can()
        p, wanted, bus, dbc = self.path, self._wanted, self._bus, self._dbc
        what = "BLF" if self.format == "blf" else "ASC"

        def arrays(times: dict, values: dict, first: float) -> dict:
            # whole microseconds divided by TICKS: the closest float64 to each time (10.01 s, not 10.010000000000002)
            return {n: (np.round((np.asarray(times[n], dtype=float) - first) * TICKS) / TICKS,
                        np.asarray(values[n], dtype=float)) for n in times}

        def batches(reader):
            times = {n: [] for n in self.units}
            values = {n: [] for n in self.units}
            first, count = None, 0
            for frame in reader:
                if frame.is_error_frame or frame.is_remote_frame:
                    continue
                first = frame.timestamp if first is None else first
                # python-can numbers the buses from 0 (the file's CAN 1 is channel 0)
                number = frame.channel + 1 if isinstance(frame.channel, int) else None
                on_bus.add(number)
                if bus is not None and number != bus:
                    continue
                key = (frame.arbitration_id, bool(frame.is_extended_id))
                seen.add(key)
                entry = wanted.get(key)
                if entry is None:
                    continue
                buses.setdefault(key, set()).add(number)
                msg, sigs = entry
                try:
                    decoded = msg.decode(bytes(frame.data), decode_choices=False, scaling=True)
                except Exception as exc:     # noqa: BLE001 -- cantools' DecodeError, bitstruct's errors
                    raise DatasetError(f"{p}: frame {frame_id(key)} at t = {frame.timestamp - first:.6f} s does not "
                                       f"decode as message {msg.name!r} of the DBC {dbc} ({type(exc).__name__}: "
                                       f"{exc}); allowed: frames of the DBC's length and layout") from None
                for name, sig in sigs:
                    if sig in decoded:      # a multiplexed signal is only in its multiplexer value's frames
                        times[name].append(frame.timestamp)
                        values[name].append(float(decoded[sig]))
                count += 1
                if count == CAN_BATCH:
                    yield arrays(times, values, first)
                    times = {n: [] for n in times}
                    values = {n: [] for n in values}
                    count = 0
            if count:
                yield arrays(times, values, first)

        @contextlib.contextmanager
        def reading():
            reader = None
            try:
                if self.format == "blf":
                    reader = can.BLFReader(str(p))
                    size = p.stat().st_size
                    if reader.file_size > size:     # python-can reads a file cut short as if it ended there
                        raise DatasetError(f"cannot read {p}: not a readable BLF file (cut short: {size} bytes of the "
                                           f"{reader.file_size} its header states)")
                else:
                    reader = can.ASCReader(str(p))
                yield batches(reader)
            except DatasetError:
                raise
            except (can.CanError, can.io.blf.BLFParseError, struct.error, zlib.error, ValueError, IndexError, OSError,
                    EOFError) as exc:
                raise DatasetError(f"cannot read {p}: not a readable {what} file ({type(exc).__name__}: {exc})") \
                    from None
            finally:
                if reader is not None:
                    reader.stop()
        return reading()

    def _parts(self):
        """The second pass: every channel's samples put on the grid as the file is read again (:class:`_Demux`)."""
        import contextlib

        @contextlib.contextmanager
        def parts():
            with self._reading(set(), {}, set()) as batches:
                demux = _Demux(batches, [c.name for c in self.channels])
                yield {c.name: demux.parts(c.name) for c in self.channels}
        return parts()

    @staticmethod
    def _signal(db, dbc: Path, name: str):
        """The DBC's message and signal of a ``MESSAGE.SIGNAL`` channel name."""
        message, _, signal = name.partition(".")
        if not signal:
            raise DatasetError(f"{dbc}: channel {name!r} names no signal; allowed: MESSAGE.SIGNAL, a message of the "
                               f"DBC and one of its signals (e.g. {_example(db)})")
        try:
            msg = db.get_message_by_name(message)
        except KeyError:
            names = [m.name for m in db.messages]
            near = closest(message, names)
            raise DatasetError(f"{dbc}: channel {name!r}: the DBC has no message {message!r}"
                               + (f" (closest: {', '.join(repr(x) for x in near)})" if near else "")
                               + f"; allowed: MESSAGE.SIGNAL with a message of the DBC ({len(names)}: "
                               + ", ".join(names[:20]) + (", ..." if len(names) > 20 else "") + ")") from None
        sigs = [s.name for s in msg.signals]
        if signal not in sigs:
            near = closest(signal, sigs)
            raise DatasetError(f"{dbc}: channel {name!r}: message {message!r} has no signal {signal!r}"
                               + (f" (closest: {', '.join(repr(x) for x in near)})" if near else "")
                               + f"; allowed: one of its signals {sigs}")
        return msg, msg.get_signal_by_name(signal)


def _example(db) -> str:
    for m in db.messages:
        if m.signals:
            return f"{m.name}.{m.signals[0].name}"
    return "IMU.YawRate"


def open_log(path, columns, time_key: str, sample_time: float, methods=None, block_bytes=None, batch_rows=None,
             dbc=None, bus=None):
    """The reader of a log by its content: :class:`ParquetLog`, :class:`MdfLog`, :class:`BagLog`,
    :class:`CanLog` (with ``dbc``, the DBC's path) or a CSV :class:`~codegen.validation.csvlog.LogReader`;
    ``columns`` includes ``time_key`` (the readers of channels with their own times do not read it)."""
    what = kind(path)
    if what == "parquet":
        return ParquetLog(path, columns, batch_rows or BATCH_ROWS)
    if what in CAN_FORMATS:
        channels = {c: u for c, u in columns.items() if c != time_key}
        return CanLog(path, channels, time_key, methods or {}, sample_time, dbc, batch_rows or BATCH_ROWS, bus)
    if what in ("mdf", "rosbag2"):
        channels = {c: u for c, u in columns.items() if c != time_key}
        return (MdfLog if what == "mdf" else BagLog)(path, channels, time_key, methods or {}, sample_time,
                                                     batch_rows or BATCH_ROWS)
    reader = LogReader(path, columns, *(() if block_bytes is None else (block_bytes,)))
    reader.file_units = {}
    return reader
