"""The column map of a logged run: the ``[data]`` table of an observer file, and units.

Parsed with the observer file (every key and unit checked there, like the rest of the file);
used by :mod:`codegen.validation.logs`, which reads the log and runs the compiled step. A
column's value in the model's unit is ``value * unit factor * scale``; the unit converts to the
one the model declares for that signal (``ModelDefinition.units``, a scheduling signal's unit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..settings import Rule, config_error, parse_table, suggest

# unit -> (dimension, factor to the dimension's SI unit)
UNITS = {
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0), "mrad": ("angle", 1e-3),
    "rad/s": ("angular rate", 1.0), "deg/s": ("angular rate", math.pi / 180.0),
    "rad/s^2": ("angular acceleration", 1.0), "deg/s^2": ("angular acceleration", math.pi / 180.0),
    "m/s": ("speed", 1.0), "km/h": ("speed", 1.0 / 3.6), "mph": ("speed", 0.44704),
    "m/s^2": ("acceleration", 1.0), "g": ("acceleration", 9.80665),
    "N": ("force", 1.0), "kN": ("force", 1e3),
    "N m": ("torque", 1.0), "kN m": ("torque", 1e3),
    "s": ("time", 1.0), "ms": ("time", 1e-3),
    "m": ("length", 1.0), "mm": ("length", 1e-3), "km": ("length", 1e3),
    "A": ("current", 1.0), "mA": ("current", 1e-3), "V": ("voltage", 1.0), "mV": ("voltage", 1e-3),
    "1": ("dimensionless", 1.0),
}
_SPELLINGS = {"m/s²": "m/s^2", "rad/s²": "rad/s^2", "deg/s²": "deg/s^2", "Nm": "N m", "N*m": "N m", "N·m": "N m",
              "kNm": "kN m", "-": "1", "kph": "km/h", "°": "deg", "°/s": "deg/s"}

COLUMN_KEYS = {"column": Rule(str, required=True, doc="the log's column (CSV header, Parquet column) or MDF channel"),
               "unit": Rule(str, doc="the column's unit, converted to the model's"),
               "scale": Rule(float, doc="a factor applied after the unit (a steering ratio, a sign)"),
               "resample": Rule(str, doc='a channel at another rate than the observer\'s: "hold" (default: the last '
                                         'sample) or "linear" (causal, delayed by its sampling step)')}
RESAMPLE = ("hold", "linear")
FIT_SIGNALS = {"yaw_acceleration": "rad/s^2"}
"""The signals a ``[data.fit]`` table may map (``uiogen fit`` reads them; ``validate`` does not), and their unit."""
PHYSICS_CHECKS = ("refuse", "warn")
TIME_KEYS = {k: v for k, v in COLUMN_KEYS.items() if k != "resample"}   # the time base is not resampled
DATA_KEYS = {"time": Rule(None, required=True, doc='"COLUMN" (seconds) or { column = ..., unit = ... }'),
             "inputs": Rule(dict, required=True, doc="{ OBSERVER_INPUT = { column = ..., unit = ... } }"),
             "truth": Rule(dict, doc="{ OBSERVER_OUTPUT = { column = ..., unit = ... } }"),
             "fit": Rule(dict, doc="{ yaw_acceleration = { column = ..., unit = ... } }: what only `uiogen fit` "
                                   "reads beside the inputs and the references (absent: derived from the yaw rate)"),
             "dbc": Rule(str, doc='the DBC a CAN log (BLF, ASC) is decoded with, relative to the observer file; '
                                  'columns are then "MESSAGE.SIGNAL"'),
             "can_channel": Rule(int, ge=1, doc="the bus of a CAN log recorded on several, numbered as Vector's "
                                               "tools show it (1 for CAN 1): only its frames are decoded"),
             "physics_checks": Rule(str, choices=PHYSICS_CHECKS,
                                    doc='"refuse" (default): a log that fails a physics relation of the model is '
                                        'refused; "warn": it is run, the failure a warning in the report')}


def normalize_unit(unit: str) -> str:
    u = " ".join(str(unit).split())
    return _SPELLINGS.get(u, u)


@dataclass(frozen=True)
class Column:
    """One mapped column: its header, unit and scale (the value in model units is x * factor * scale)."""

    column: str
    unit: str | None = None
    scale: float = 1.0
    resample: str | None = None     # hold or linear for a log at another rate (None: the default, hold)


@dataclass(frozen=True)
class ColumnMap:
    """The ``[data]`` table of an observer file."""

    source: str
    time: Column
    inputs: dict = field(default_factory=dict)
    truth: dict = field(default_factory=dict)
    fit: dict = field(default_factory=dict)     # FIT_SIGNALS the log records ([data.fit])
    dbc: str | None = None          # the DBC of a CAN log, as a path (relative ones resolved against the source)
    physics_checks: str = "refuse"  # "warn": a failed physics relation of the log checks is a warning
    can_channel: int | None = None  # the bus of a multi-bus CAN log (1 = CAN 1); None: the log must not need one


def _column(value, source: str, section: str, key: str, units=tuple(UNITS), keys=COLUMN_KEYS) -> Column:
    """One column spec; ``units``: the units allowed for it (the time column: s, ms); ``keys``: its keys."""
    if isinstance(value, str):
        value = {"column": value}
    if not isinstance(value, dict):
        raise config_error(source, section, key, value, '"COLUMN" or an inline table { column = "...", unit = "..." }')
    parsed = parse_table(value, keys, source=source, section=f"{section}.{key}")
    if not parsed["column"].strip():
        # an empty header would otherwise surface later as a "missing column ['']" of the log
        raise config_error(source, f"{section}.{key}", "column", parsed["column"], "the (non-empty) header of a column "
                           "of the log")
    unit = parsed.get("unit")
    if unit is not None:
        unit = normalize_unit(unit)
        if unit not in units:
            raise config_error(source, f"{section}.{key}", "unit", value["unit"],
                               f"one of {', '.join(units)}", suggest(unit, list(units)))
    scale = float(parsed.get("scale", 1.0))
    if scale == 0.0:
        # a zero factor turns the column into zeros: the step would run on a signal the log does not hold
        raise config_error(source, f"{section}.{key}", "scale", value["scale"],
                           "a finite number other than 0 (a factor applied after the unit: a steering ratio, -1 for "
                           "the opposite sign)")
    resample = parsed.get("resample")
    if resample is not None and resample not in RESAMPLE:
        raise config_error(source, f"{section}.{key}", "resample", resample,
                           "hold (the last sample at or before each step) or linear (interpolated, delayed by one "
                           "sampling step of the channel: never a value from the future)",
                           suggest(resample, list(RESAMPLE)))
    return Column(parsed["column"], unit, scale, resample)


def parse(table, source: str) -> ColumnMap:
    """Check a ``[data]`` table (every key, every column spec); names are checked against the
    observer's inputs and outputs when a log is run (:func:`run`).

    Raises
    ------
    ConfigurationError
        naming the file, the key and what is allowed.
    """
    parsed = parse_table(table, DATA_KEYS, source=source, section="data")
    time = _column(table["time"], source, "data", "time", units=tuple(u for u, (dim, _) in UNITS.items()
                                                                    if dim == "time"), keys=TIME_KEYS)
    inputs = {k: _column(v, source, "data.inputs", k) for k, v in table["inputs"].items()}
    truth = {k: _column(v, source, "data.truth", k) for k, v in table.get("truth", {}).items()}
    for k, v in table.get("fit", {}).items():
        if k not in FIT_SIGNALS:
            raise config_error(source, "data.fit", k, v, f"one of {', '.join(FIT_SIGNALS)} (what uiogen fit reads "
                               f"beside the inputs and the references)", suggest(k, list(FIT_SIGNALS)))
    fit = {k: _column(v, source, "data.fit", k) for k, v in table.get("fit", {}).items()}
    for k, c in fit.items():
        factor(c, FIT_SIGNALS[k], source, "data.fit", k)           # its unit of the signal's kind, now
    dbc = parsed.get("dbc")
    if dbc is not None:
        if not dbc.strip():
            raise config_error(source, "data", "dbc", dbc, 'the path of a DBC file, relative to the observer file '
                               '(dbc = "vehicle.dbc")')
        # read when a CAN log is run (a missing DBC must not break the verbs that never read a log)
        dbc = str(Path(source).parent / dbc) if source else dbc
    can_channel = parsed.get("can_channel")
    if can_channel is not None and dbc is None:
        raise config_error(source, "data", "can_channel", can_channel, "a bus number beside dbc = \"FILE.dbc\" (it "
                           "chooses the frames of a CAN log, which only a DBC decodes)")
    return ColumnMap(source, time, inputs, truth, fit, dbc, parsed.get("physics_checks", "refuse"), can_channel)


def model_unit(model, signal: str) -> str | None:
    """The unit the model declares for an observer input/output (y_NAME: the output NAME)."""
    name = signal[2:] if signal.startswith("y_") and signal[2:] in [n for n, _ in model.outputs] else signal
    for sig in model.scheduling:
        if str(sig.symbol) == name and getattr(sig, "unit", None):
            return sig.unit
    return (model.units or {}).get(name)


def factor(col: Column, model_unit: str | None, source: str, section: str, key: str) -> float:
    """The factor from the column's numbers to the model's unit (unit conversion times scale).

    Raises
    ------
    ConfigurationError
        a unit that does not convert to the model's (another dimension, or a model unit the
        table does not know: give ``scale`` instead).
    """
    if col.unit is None:
        return col.scale
    target = normalize_unit(model_unit) if model_unit else None
    if target is None:
        raise config_error(source, f"{section}.{key}", "unit", col.unit,
                           f"a scale: the model declares no unit for {key} (add it to the model's units, or give "
                           f"scale = ... instead of unit)")
    if target not in UNITS:
        if col.unit == target:
            return col.scale
        raise config_error(source, f"{section}.{key}", "unit", col.unit,
                           f"the model's unit {model_unit!r}, which uiogen cannot convert to; give scale = ...")
    (dim, f_col), (dim_model, f_model) = UNITS[col.unit], UNITS[target]
    if dim != dim_model:
        raise config_error(source, f"{section}.{key}", "unit", col.unit,
                           f"a unit of {dim_model} like the model's {model_unit!r} (got a unit of {dim})")
    return f_col / f_model * col.scale
