"""Stanford sideslip data set: the shared logs' format, its loader and its checks.

Data
----
``../shared/data/stanford_sideslip/run_20140222_part1.csv.gz`` (beside the checkout) (see that folder's README):
100 Hz, 27,500 samples of run 20140222_01_01_03_250lm (Stanford's Ferrari 250 LM, 982 kg) with a
sideslip reference ``beta_true`` = atan2(vy, vx) of the log's own velocities (to 4e-9; not a separate sensor),
from MBDS/sideslip-angle-vehicle-estimation (MIT, (c) 2021 J. L. Blanco-Claraco), used in Leanza,
Reina, Blanco-Claraco, Sensors 21(16) 5409, 2021. :func:`load` accepts that path, any plain or
gzip CSV with the same columns, or the shorthand ``"stanford"``.

The estimators run beside the observers on these logs (the source repository's linear KF, an EKF,
the nonlinear-tyre model's EKF and UKF) are in :mod:`codegen.validation.peers`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DatasetError
from . import csvlog, log_checks
from .csvlog import GAP_FACTOR, MAX_PERIOD, PERIOD_RTOL, SHORT_FACTOR  # noqa: F401 (documented here too)

__all__ = ["STANFORD_PATH", "COLUMNS", "UNITS", "DatasetError", "StanfordRun", "load"]

STANFORD_PATH = (Path(__file__).resolve().parents[3] / "shared" / "data" / "stanford_sideslip"
                 / "run_20140222_part1.csv.gz")
"""Location of the converted first half of run 20140222_01_01_03_250lm."""

NIKI_PATH = STANFORD_PATH.parents[1] / "second_car" / "niki_high_speed.csv.gz"
"""Location of the shared run of the second car, Stanford's VW GTI "Niki" (200 Hz, OxTS truth)."""

SHORTHANDS = ("stanford", "niki")
"""Names of the shared logs beside a source checkout, for ``--data`` (:data:`STANFORD_PATH`, :data:`NIKI_PATH`)."""

EVALUATION_T_START = 137.5
"""[s from the log's start] The shared half's evaluation part starts here (sample 13750 of 27500): the
identification part (samples 0-13749) is the only one any number of an estimator of this log may be
chosen on; the evaluation part is reported, never fitted (``uiogen validate --data`` splits every
estimator's error there)."""

PEAK_TIMES = (110.0, 170.0, 207.0)
"""[s from the log's start] The three large-sideslip peaks of the shared half (its reference reaches
about -5 deg there): ``uiogen validate --data stanford`` reports each estimator's largest error
around them. A property of this log (:func:`peak_times`), not of any observer."""


def peak_times(path) -> tuple:
    """The sideslip peaks [s from the start] of a log in the shared format: :data:`PEAK_TIMES` for the
    shared log, none known for any other."""
    return PEAK_TIMES if str(_resolve(path)) == str(STANFORD_PATH) else ()


COLUMNS = ("t", "vx", "vy", "beta_true", "ax", "ay", "yaw_rate", "yaw_acc",
           "delta", "delta_fl", "delta_fr")
"""The format's columns, SI units (s, m/s, rad, m/s², rad/s, rad/s²); see :data:`UNITS`. Every one is
required but :data:`OPTIONAL`."""

OPTIONAL = ("yaw_acc",)
"""Columns a log may lack: most logs record no yaw acceleration (the run's ``yaw_acc`` is then None;
``uiogen fit`` derives it from the yaw rate and says so)."""

UNITS = {"t": "s", "vx": "m/s", "vy": "m/s", "beta_true": "rad", "ax": "m/s^2", "ay": "m/s^2",
         "yaw_rate": "rad/s", "yaw_acc": "rad/s^2", "delta": "rad", "delta_fl": "rad",
         "delta_fr": "rad"}
"""Declared unit of every column (data README: ``t`` [s], ``vx``, ``vy`` [m/s] at the CoG,
``beta_true`` [rad], ``ax``, ``ay`` [m/s²] at the CoG, ``yaw_rate`` [rad/s], ``yaw_acc`` [rad/s²],
``delta``, ``delta_fl``, ``delta_fr`` [rad] road-wheel angles)."""

# Plausibility limits used to catch unit mistakes (degrees instead of radians, km/h, g units).
# ``t`` has none: its unit is checked through the sample period (see ``_check_time``).
_LIMITS = {
    "vx": (-5.0, 100.0),          # m/s
    "vy": (-20.0, 20.0),          # m/s
    "beta_true": (-0.7, 0.7),     # rad (40 deg: anything larger is degrees)
    "ax": (-30.0, 30.0),          # m/s^2
    "ay": (-30.0, 30.0),          # m/s^2
    "yaw_rate": (-3.0, 3.0),      # rad/s
    "yaw_acc": (-30.0, 30.0),     # rad/s^2
    "delta": (-0.8, 0.8),         # rad, road-wheel angle
    "delta_fl": (-0.8, 0.8),
    "delta_fr": (-0.8, 0.8),
}

_DEG = math.pi / 180.0
_G = 9.81
_KMH = 1.0 / 3.6
_MPH = 0.44704

# Larger-valued units a range violation may come from: (name, factor to the declared unit).
_ALT_UNITS = {"rad": (("degrees", _DEG),), "rad/s": (("deg/s", _DEG),), "rad/s^2": (("deg/s^2", _DEG),),
              "m/s": (("km/h", _KMH), ("mph", _MPH)), "m/s^2": (("ft/s^2", 0.3048),)}

# Physics consistency checks (see ``_check_physics``): minimum |correlation| and number of samples
# for a relation to be conclusive, and the band around the expected ratio 1 that is accepted.
_MIN_CORR = 0.5
_MIN_SAMPLES = 50
_RATIO_BAND = (1 / 1.6, 1.6)
_SMOOTH_S = 0.05            # [s] half-width of the boxcar / central difference used for derivatives


@dataclass(frozen=True, eq=False)
class StanfordRun:
    """One run of the Stanford data set, as read-only float arrays (SI units).

    Attributes
    ----------
    t : ndarray
        Time [s], strictly increasing.
    vx, vy : ndarray
        Longitudinal and lateral speed at the CoG [m/s].
    beta_true : ndarray
        Sideslip reference [rad]: atan2(vy, vx) of the log's own velocities (to 4e-9), not a separate sensor.
    ax, ay : ndarray
        Longitudinal and lateral acceleration at the CoG [m/s²].
    yaw_rate : ndarray
        [rad/s].
    yaw_acc : ndarray or None
        [rad/s²]; None when the log records none (:data:`OPTIONAL`).
    delta, delta_fl, delta_fr : ndarray
        Road-wheel steering angles (mean, front left, front right) [rad].
    source : str
        Path of the file read.
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    beta_true: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    yaw_rate: np.ndarray
    yaw_acc: np.ndarray | None
    delta: np.ndarray
    delta_fl: np.ndarray
    delta_fr: np.ndarray
    source: str

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def dt(self) -> float:
        """Median sample period [s]."""
        return float(np.median(np.diff(self.t)))


def _resolve(path) -> Path:
    name = path.strip().lower() if isinstance(path, str) else None
    if name in SHORTHANDS:
        shared = STANFORD_PATH if name == "stanford" else NIKI_PATH
        if not shared.is_file():     # an installed uiogen: the shorthand names a checkout's neighbour
            raise DatasetError(f"{name!r} is the shared log beside a source checkout ({shared}), which is "
                               f"not there: pass the log's own path (a CSV, plain or .gz)")
        return shared
    return Path(path)


def _range_error(p: Path, c: str, lo_found: float, hi_found: float, lo: float, hi: float) -> DatasetError:
    unit = UNITS[c]
    hint = ""
    for name, f in _ALT_UNITS.get(unit, ()):
        if lo <= lo_found * f and hi_found * f <= hi:
            hint = f"; it looks like {name} (x {f:.4g} gives [{lo_found * f:.4g}, {hi_found * f:.4g}] {unit})"
            break
    return DatasetError(
        f"{p}: column {c!r} spans [{lo_found:.4g}, {hi_found:.4g}], outside the plausible range "
        f"[{lo}, {hi}] of its declared unit {unit} (wrong unit?){hint}")


@dataclass(eq=False)
class _Rule:
    """One physical relation of the format: ``y ~ k x`` with k in ``band`` (see :func:`_judge`)."""

    col: str
    sides: object                   # (columns, t, h) -> (y, x); on the raw chunk when not windowed
    windowed: bool
    what: str
    unit: str
    band: tuple
    min_std: float
    guesses: tuple
    moments: log_checks.Moments = None

    def __post_init__(self):
        self.moments = log_checks.Moments()


def _rules() -> list:
    """The relations of :func:`_check_physics`, in the order they are judged."""
    box, ddt = log_checks.box, log_checks.ddt
    rules = [
        _Rule("beta_true", lambda c, t, h: (c["beta_true"], np.arctan2(c["vy"], c["vx"])), False,
              "beta_true = atan(vy / vx)", "", _RATIO_BAND, 1e-3, (
                  (1 / _DEG, "beta_true in degrees", "convert it with numpy.radians"),
                  (-1.0, "opposite sign conventions of beta_true and vy", "flip the sign of one of them"),
                  (1 / _KMH, "vx in km/h (vy in m/s)", "divide vx by 3.6"),
                  (_KMH, "vy in km/h (vx in m/s)", "divide vy by 3.6"))),
        _Rule("ax", lambda c, t, h: (box(c["ax"], h), ddt(c["vx"], t, h) - box(c["vy"] * c["yaw_rate"], h)), True,
              "ax = dvx/dt - vy yaw_rate", "", _RATIO_BAND, 0.2, (
                  (1 / _G, "ax in g", "multiply it by 9.81"),
                  (_KMH, "vx in km/h", "divide vx by 3.6"),
                  (_MPH, "vx in mph", "multiply vx by 0.44704"),
                  (-1.0, "ax of the opposite sign (braking positive)", "flip its sign"))),
        _Rule("ay", lambda c, t, h: (box(c["ay"], h), box(c["vx"] * c["yaw_rate"], h)), True,
              "ay = dvy/dt + vx yaw_rate (ay ~ vx yaw_rate while cornering)", "", _RATIO_BAND, 0.2, (
                  (1 / _G, "ay in g", "multiply it by 9.81"),
                  (_DEG, "yaw_rate in deg/s", "convert yaw_rate with numpy.radians"),
                  (_KMH, "vx in km/h", "divide vx by 3.6"),
                  (_MPH, "vx in mph", "multiply vx by 0.44704"),
                  (-1.0, "opposite sign conventions of ay and yaw_rate", "flip the sign of one of them"))),
        _Rule("yaw_acc", lambda c, t, h: (box(c["yaw_acc"], h), ddt(c["yaw_rate"], t, h)), True,
              "yaw_acc = d(yaw_rate)/dt", "", _RATIO_BAND, 0.05, (
                  (1 / _DEG, "yaw_acc in deg/s^2", "convert it with numpy.radians"),
                  (_DEG, "yaw_rate in deg/s (yaw_acc in rad/s^2)", "convert yaw_rate with numpy.radians"),
                  (-1.0, "yaw_acc of the opposite sign", "flip its sign"))),
        _Rule("delta", lambda c, t, h: (box(c["yaw_rate"], h), box(c["vx"] * c["delta"], h)), True,
              "yaw_rate / (vx delta) = 1 / (wheelbase + K_us vx^2)", " 1/m", (0.02, 2.0), 0.05, (
                  (_DEG, "delta in degrees, or a steering-wheel angle instead of the road-wheel angle",
                   "convert it with numpy.radians, or divide a steering-wheel angle by the steering ratio"),
                  (-1.0, "opposite sign conventions of delta and yaw_rate", "flip the sign of one of them")))]
    for side in ("delta_fl", "delta_fr"):
        rules.append(_Rule(side, lambda c, t, h, side=side: (c[side], c["delta"]), False,
                           "delta (the mean road-wheel angle)", "", _RATIO_BAND, 1e-3, (
                               (1 / _DEG, f"{side} in degrees (delta in rad)", "convert it with numpy.radians"),
                               (_DEG, f"delta in degrees ({side} in rad)", "convert delta with numpy.radians"),
                               (-1.0, f"{side} of the opposite sign", "flip its sign"))))
    return rules


def _judge(p, rule: _Rule) -> None:
    """Check that y ~ k x with k in the rule's band.

    The ratio k is bracketed by the direct and the reverse least-squares slopes, cov/var(x) and
    var(y)/cov (with errors in both variables the true slope lies between the two): the relation
    fails only when the whole bracket misses the band. It is inconclusive (skipped) when x barely
    moves (std < min_std), |correlation| < _MIN_CORR or fewer than _MIN_SAMPLES samples.
    ``guesses``: (factor, "looks like ...", fix): the ratio a known unit mistake would give.
    """
    m, col, band = rule.moments, rule.col, rule.band
    if m.n < _MIN_SAMPLES:
        return
    if not (m.std_x >= rule.min_std and m.cyy > 0 and m.cxy != 0):
        return
    corr = m.corr
    if abs(corr) < _MIN_CORR:
        return
    k1, lo, hi = m.bracket()
    if log_checks.meets(lo, hi, band):
        return
    found = f"ratio {k1:.4g} (bracket [{lo:.4g}, {hi:.4g}], correlation {corr:.2f}, {m.n} samples)"
    allowed = f"{band[0]:.3g} to {band[1]:.3g}{rule.unit} in the declared units"
    fits = [(f, looks, fix) for f, looks, fix in rule.guesses if log_checks.meets(lo, hi, (band[0] * f, band[1] * f))]
    if fits:
        raise DatasetError(f"{p}: column {col!r} is inconsistent with {rule.what}: {found}; allowed: "
                           f"{allowed}. It looks like "
                           + "; or ".join(f"{looks} (ratio ~ {f:.4g}): {fix}" for f, looks, fix in fits))
    raise DatasetError(f"{p}: column {col!r} is inconsistent with {rule.what}: {found}; allowed: {allowed}; "
                       f"no single known unit mistake explains it: check the units and sign conventions "
                       f"of the columns involved ({', '.join(f'{c} [{UNITS[c]}]' for c in _INVOLVED[col])})")


_INVOLVED = {"beta_true": ("beta_true", "vy", "vx"), "ax": ("ax", "vx", "vy", "yaw_rate"),
             "ay": ("ay", "vx", "yaw_rate"), "yaw_acc": ("yaw_acc", "yaw_rate"),
             "delta": ("delta", "yaw_rate", "vx"), "delta_fl": ("delta_fl", "delta"),
             "delta_fr": ("delta_fr", "delta")}


class _Checks:
    """Every check of the format, chunk by chunk: ranges, the time column and
    :func:`_check_physics`; :meth:`finish` raises the first failure, in that order."""

    def __init__(self, p: Path, sample_time, columns=COLUMNS):
        self.p = p
        self.time = csvlog.TimeCheck(p, sample_time)
        self.ranges = {c: [math.inf, -math.inf] for c in _LIMITS if c in columns}
        self.rules = [r for r in _rules() if set(_INVOLVED[r.col]) <= set(columns)]   # a column the log lacks
        self.window = None
        self.pending = []            # chunks held until the period (the averaging window) is known
        self.n = 0

    def feed(self, cols: dict) -> None:
        self.n += cols["t"].size
        for c, r in self.ranges.items():
            r[0], r[1] = min(r[0], float(cols[c].min())), max(r[1], float(cols[c].max()))
        self.time.feed(cols["t"])
        if self.time.period is None:
            self.pending.append(cols)
            return
        self._physics(cols)

    def _flush(self) -> None:
        """The period is known: the averaging window, and the chunks held until then."""
        self.window = log_checks.Window(max(1, int(round(_SMOOTH_S / self.time.period))))
        pending, self.pending = self.pending, []
        for chunk in pending:
            self._physics(chunk)

    def _physics(self, cols: dict) -> None:
        if self.window is None:
            self._flush()
        h = self.window.h
        for rule in self.rules:
            if not rule.windowed:
                y, x = rule.sides(cols, cols["t"], h)
                rule.moments.add(x, y)
        w = self.window.join(cols)
        if w is not None:
            for rule in self.rules:
                if rule.windowed:
                    y, x = rule.sides(w, w["t"], h)
                    rule.moments.add(x, y)

    def finish(self) -> None:
        for c, (lo_found, hi_found) in self.ranges.items():
            lo, hi = _LIMITS[c]
            if lo_found < lo or hi_found > hi:
                raise _range_error(self.p, c, lo_found, hi_found, lo, hi)
        per = self.time.finish()
        if self.window is None:
            self._flush()
        _check_physics(self.p, self, per)


def _check_physics(p: Path, checks: _Checks, per: float) -> None:
    """Unit consistency of the columns with one another (rules that a range check cannot give).

    * beta_true = atan(vy / vx) (definition of the sideslip angle);
    * ax = dvx/dt - vy r and ay = dvy/dt + vx r (CoG accelerations of a planar rigid body; for ay
      the term vx r dominates while cornering, so ay / (vx r) ~ 1, and ~ 1/9.81 when ay is in g);
    * yaw_acc = d(yaw_rate)/dt;
    * yaw_rate / (vx delta) = 1 / (wheelbase + K_us vx²) (steady-state single track), 0.02 to
      2 1/m for road-wheel angles in rad (wheelbases 1.5-5 m, strong understeer at speed), 57x
      smaller in degrees and ~15x smaller for a steering-wheel angle;
    * delta_fl, delta_fr ~ delta (delta is their mean).

    Derivatives are central differences over +-_SMOOTH_S, compared with the other side averaged
    over the same window (the chunks of a long log joined by :class:`log_checks.Window`, so the
    sums are those of the whole log). A relation is skipped when the log does not excite it
    (see :func:`_judge`), and all of them when the log is shorter than _MIN_SAMPLES + 2 windows.
    """
    h = max(1, int(round(_SMOOTH_S / per)))
    if checks.n < _MIN_SAMPLES + 2 * h:          # too short to judge any relation
        return
    for rule in checks.rules:
        _judge(p, rule)


def _sample_time(sample_time):
    if sample_time is None:
        return None
    try:
        sample_time = float(sample_time)
    except (TypeError, ValueError):
        raise DatasetError(f"sample_time must be a number of seconds, got {sample_time!r}") from None
    if not (math.isfinite(sample_time) and sample_time > 0):
        raise DatasetError(f"sample_time must be finite and > 0 s, got {sample_time!r}")
    return sample_time


def chunks(path="stanford", sample_time=None, block_bytes: int = csvlog.BLOCK_BYTES):
    """Yield the columns of a Stanford-format log chunk by chunk (``{column: array}``), checked
    as :func:`load` checks them: the format where it fails, the ranges, the time column and the
    physics once the last chunk has been read (the generator raises then).

    Raises
    ------
    DatasetError
        see :func:`load`.
    """
    p = _resolve(path)
    sample_time = _sample_time(sample_time)
    reader, factors = open_log(p, sample_time, block_bytes)
    checks = _Checks(p, sample_time, tuple(factors))
    for _, cols in reader.chunks():
        cols = {c: cols[c] * factors[c] if factors[c] != 1.0 else cols[c] for c in factors}
        checks.feed(cols)
        yield cols
    checks.finish()


_UNITS_TEXT = ", ".join(f"{c} [{u}]" for c, u in UNITS.items())
CHANNEL_FORMATS = {"rosbag2": ("a ROS 2 bag", "TOPIC.FIELD"), "blf": ("a CAN log (BLF)", "MESSAGE.SIGNAL"),
                   "asc": ("a CAN log (ASC)", "MESSAGE.SIGNAL")}
"""The formats whose channels are named by their place in the file, which no column of the format can be."""


def _allowed(missing) -> str:
    """What a log missing the shared format's columns ``missing`` must hold."""
    return (f"allowed: the shared format's columns {', '.join(COLUMNS)} (SI units: {_UNITS_TEXT}; "
            f"{', '.join(OPTIONAL)} may be left out) as the file's column or channel names")


def open_log(p: Path, sample_time, block_bytes: int = csvlog.BLOCK_BYTES) -> tuple:
    """``(reader, {column: factor to its declared unit})``: the shared format's columns of a log (those of
    :data:`OPTIONAL` the log lacks left out of both) in any
    format ``uiogen validate --data`` reads by name -- a CSV (streamed as before), Parquet, MDF4 --
    through its reader (:func:`codegen.validation.logfiles.open_log`: the format told by the content,
    one channel per column, an MDF log's channels on the grid of ``sample_time``). A unit the file
    states (an MDF channel's, a Parquet field's) is checked against the column's declared unit
    (:data:`UNITS`) and converted to it (:func:`codegen.validation.logfiles.resolve_unit`); a column
    without one is in its declared unit, as in the CSV.

    Raises
    ------
    DatasetError
        the reader's (a missing column or channel with the closest names, a gap, a unit of another kind);
        a ROS 2 bag or a CAN log, whose channels are TOPIC.FIELD or MESSAGE.SIGNAL (they are read through an
        observer file's ``[data]`` map); an MDF log without a sample time to put it on.
    """
    from ..project.columns import UNITS as KNOWN
    from . import logfiles
    fmt = logfiles.kind(p)
    if fmt in CHANNEL_FORMATS:
        what, names = CHANNEL_FORMATS[fmt]
        raise DatasetError(f"{p} is {what}, whose channels are named {names}, never the shared format's columns "
                           f"({', '.join(COLUMNS)}); allowed: a CSV, Parquet or MDF4 log with those columns or "
                           f"channels (uiogen validate --data and uiogen fit read a {names} log through an observer "
                           f"file's [data] map)")
    if fmt == "mdf" and sample_time is None:
        raise DatasetError(f"{p}: an MDF log's channels are put on the observer's sample time, and none is given; "
                           f"allowed: the log read for an observer (sample_time = its sample time)")
    columns = dict(UNITS)
    try:
        try:
            reader = logfiles.open_log(p, columns, "t", sample_time, block_bytes=block_bytes)
        except DatasetError as exc:
            lacks = set(getattr(exc, "missing", None) or ()) & set(OPTIONAL)
            if not lacks:
                raise
            # the log records none of them: without them (a required column missing is then said alone)
            columns = {c: u for c, u in UNITS.items() if c not in lacks}
            reader = logfiles.open_log(p, columns, "t", sample_time, block_bytes=block_bytes)
    except DatasetError as exc:
        if not getattr(exc, "missing", None):
            raise
        raise DatasetError(f"{exc.head}; {_allowed(exc.missing)}") from None
    factors = {}
    for c in columns:
        if c == "t" and isinstance(reader, logfiles.OnGrid):        # the grid's times are in s
            factors[c] = 1.0
            continue
        what = f"{'channel' if isinstance(reader, logfiles.OnGrid) else 'column'} {c!r}"
        unit, _ = logfiles.resolve_unit(p, what, reader.file_units.get(c), None, UNITS[c])
        factors[c] = 1.0 if unit is None else KNOWN[unit][1] / KNOWN[UNITS[c]][1]
    return reader, factors


def load(path="stanford", sample_time=None, block_bytes: int = csvlog.BLOCK_BYTES) -> StanfordRun:
    """Read a Stanford-format CSV (plain or gzip) and validate it.

    Parameters
    ----------
    path : str or os.PathLike, optional
        File to read; ``"stanford"`` (default) resolves to :data:`STANFORD_PATH`. Gzip is detected
        from the file's magic bytes, not its name. A UTF-8 byte-order mark is ignored; the field
        separator may be a comma, a semicolon or a tab (detected from the header); the decimal
        mark must be '.'; extra columns are ignored.
    sample_time : float, optional
        Expected sample time [s] (e.g. the observer's): the log's median period must equal it
        within :data:`PERIOD_RTOL` (relative). None: not compared.
    block_bytes : int, optional
        Text per chunk read (:mod:`codegen.validation.csvlog`); the result does not depend on it.

    Returns
    -------
    StanfordRun

    Raises
    ------
    DatasetError
        Missing, unreadable or not a regular file (UTF-16, not UTF-8), missing or duplicated
        columns, non-numeric values (a decimal comma included) or non-finite values, fewer than 2
        rows; a time column that is not strictly increasing, looks like milliseconds, has gaps (a
        step > :data:`GAP_FACTOR` x the median period) or short steps (< :data:`SHORT_FACTOR` x),
        or whose period differs from ``sample_time``; values outside physical ranges, or columns
        that contradict one another physically (a unit mistake: degrees for radians, g, km/h,
        deg/s; see :func:`_check_physics`). The message names the file, the column, what was
        found and what is allowed.
    """
    parts = {c: [] for c in COLUMNS}
    p = _resolve(path)
    for cols in chunks(p, sample_time, block_bytes):
        for c in cols:
            parts[c].append(cols[c])
    out = {c: None for c in OPTIONAL}              # a column the log lacks
    for c in COLUMNS:
        if not parts[c]:
            continue
        a = np.concatenate(parts[c])
        a.setflags(write=False)
        out[c] = a
    return StanfordRun(source=str(p), **out)
