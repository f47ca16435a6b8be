"""Logged runs in the user's own CSV, Parquet, MDF4, ROS 2 bag or CAN log (BLF, ASC with a DBC), mapped by the
observer file's ``[data]`` table.

``uiogen validate my_observer.toml --data my_log.csv`` runs the compiled step over a log whose
columns the observer file maps onto the observer's inputs, each with its unit (converted to the
unit the model declares for that signal) or an explicit scale::

    [data]
    time = { column = "time", unit = "ms" }               # or time = "t" (seconds)

    [data.inputs]                                         # every input of the observer
    delta = { column = "steer_wheel", unit = "deg", scale = 0.0625 }   # unit, then the steering ratio
    y_r = { column = "yaw_rate", unit = "deg/s" }
    y_a_y = { column = "ay", unit = "g" }
    v_x = { column = "speed", unit = "km/h" }

    [data.truth]                                          # optional: references of the estimates
    v_y = { column = "vy_ref", unit = "m/s" }

    [data.fit]                                            # optional: read by `uiogen fit` only
    yaw_acceleration = { column = "yaw_acc", unit = "deg/s^2" }

A column's value in the model's unit is ``value * unit factor * scale`` (:mod:`codegen.project.columns`
parses the map with the observer file). The log is read in chunks by
:mod:`codegen.validation.csvlog` (separator, decimal mark, finite values, the sample time of the
observer, no gaps) and every mapped column is checked against its unit's plausible range and the
physics of the observer's model (:mod:`codegen.validation.log_checks`) before any estimate is
reported. Estimates with a reference get the error statistics of every validation
(``observer.SIGNAL.rms``, ``unit``, ``truth_rms``, ``rms_percent`` ...:
:func:`codegen.validation.metrics.signal_report`); the others a summary in the same unit
(``estimates.SIGNAL.mean``, ``unit`` ...); ``warnings``
lists the checks that were ambiguous, ``log_checks`` every check and its verdict.

A Parquet, MDF4, ROS 2 or CAN log (:mod:`codegen.validation.logfiles`, told by its content; a
CAN log decoded with the DBC of ``[data] dbc``, its columns ``MESSAGE.SIGNAL``) is read through the
same map: the units its file states are checked against the map's and the model's, and channels at
their own rates are put on the observer's sample time (``resampling`` says how, per channel).
``out``: the outputs and status written as MDF4 or Parquet
(:mod:`codegen.validation.logout`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ConfigurationError, DatasetError
from ..project.columns import FIT_SIGNALS, UNITS, Column, factor, model_unit
from ..settings import config_error, suggest
from . import csvlog, log_checks, logfiles, streaming
from .common import SETTLE_TIME, format_stats


def _spec(col) -> dict:
    """A mapped column as the observer file writes it (for a message)."""
    spec = {"column": col.column}
    if col.unit is not None:
        spec["unit"] = col.unit
    if col.scale != 1.0:
        spec["scale"] = col.scale
    if col.resample is not None:
        spec["resample"] = col.resample
    return spec


def require_map(config) -> None:
    """A ConfigurationError when the observer file has no ``[data]`` table."""
    if config.column_map is None:
        raise ConfigurationError(f"{config.source}: logged runs of this observer need a [data] table mapping the log's "
                                 f"columns to its inputs (docs/validation.md, 'Your own logs')", source=config.source)


class MappedLog:
    """The log the observer file's ``[data]`` map reads, in every format (:func:`logfiles.open_log`), chunk by
    chunk on the observer's sample time: ``uiogen validate --data`` and ``uiogen fit --data`` read it here.

    Every observer input must be mapped, every key be an input (``[data.inputs]``) or an output
    (``[data.truth]``); the units the file states are checked against the map's and the model's; a CSV or
    Parquet table at another rate is put on the grid as a channel log is. :meth:`chunks` yields ``(t, {input:
    values in the model's unit}, {output: reference values in the model's unit})`` with the time and the
    model's physics checked (:mod:`log_checks`) as they go; :meth:`finish` raises the first failure and
    returns the checks' report. ``warnings`` and ``resampling``: the resampling's (a channel log's).

    Raises
    ------
    ConfigurationError
        no ``[data]`` table, a missing input, a key that is no input or output, a unit that does not convert,
        a CAN log without ``[data] dbc``.
    DatasetError
        the log's (see :mod:`codegen.validation.csvlog`, :mod:`codegen.validation.logfiles`).
    """

    def __init__(self, config, path, input_names, output_names, sample_time: float,
                 block_bytes: int = csvlog.BLOCK_BYTES, batch_rows: int | None = None, fit_signals=()):
        from ..model import load_parameters
        require_map(config)
        cmap = config.column_map
        model = config.load_model()
        missing = [n for n in input_names if n not in cmap.inputs]
        # a key that is no signal first: a misspelt input ('y_gyr') is named, with the input it meant,
        # rather than reported as the input it left missing
        for section, mapped, allowed, what in (("data.inputs", cmap.inputs, input_names, "input"),
                                               ("data.truth", cmap.truth, output_names, "output")):
            for k, col in mapped.items():
                if k not in allowed:
                    near = suggest(k, [n for n in missing if n in allowed] or allowed) if what == "input" else None
                    raise config_error(cmap.source, section, k, _spec(col),
                                       f"not an {what} of observer {config.name}: one of {', '.join(allowed)}"
                                       + (f"; missing: {', '.join(missing)}" if what == "input" and missing else ""),
                                       near or suggest(k, allowed))
        if missing:
            raise ConfigurationError(f"{cmap.source}: [data.inputs] {missing[0]} is missing: a column for every "
                                     f"observer input ({', '.join(input_names)}); missing: {', '.join(missing)}",
                                     source=cmap.source, section="data.inputs", key=missing[0],
                                     allowed="a column for every observer input")
        # what the caller reads of [data.fit] (uiogen fit: a recorded yaw acceleration), in its FIT_SIGNALS unit
        fit = {k: c for k, c in cmap.fit.items() if k in fit_signals}
        names = {**cmap.inputs, **{f"truth:{k}": c for k, c in cmap.truth.items()},
                 **{f"fit:{k}": c for k, c in fit.items()}}
        p = Path(path)
        units = {cmap.time.column: cmap.time.unit or "s"}
        for c in names.values():
            units.setdefault(c.column, c.unit or "model units")
        methods = {c.column: c.resample for c in names.values() if c.resample}
        fmt = logfiles.kind(p)
        if fmt in logfiles.CAN_FORMATS and cmap.dbc is None:
            raise ConfigurationError(f"{cmap.source}: [data] dbc is missing: {p} is a CAN log ({fmt.upper()}), "
                                     f"whose frames are decoded with a DBC; allowed: dbc = \"FILE.dbc\" in [data] "
                                     f"(relative to the observer file), the columns then MESSAGE.SIGNAL", source=cmap.source,
                                     section="data", key="dbc", allowed="the path of the log's DBC")
        reader = logfiles.open_log(p, units, cmap.time.column, sample_time, methods, block_bytes, batch_rows,
                                   dbc=cmap.dbc, bus=cmap.can_channel)
        mdf = isinstance(reader, logfiles.OnGrid)       # MDF4, ROS 2, CAN: channels with their own times
        word = "channel" if mdf else "column"
        # the units the file states (an MDF channel's, a Parquet field's) against the map's and the model's
        mapped, declared_by = {}, {}
        for n, c in names.items():
            signal = n.removeprefix("truth:").removeprefix("fit:")
            want = FIT_SIGNALS[signal] if n.startswith("fit:") else model_unit(model, signal)
            what = n.replace("truth:", "reference of ").replace("fit:", "[data.fit] ")
            unit, source = logfiles.resolve_unit(p, f"{word} {c.column!r} ({what})",
                                                 reader.file_units.get(c.column), c.unit, want)
            mapped[n] = Column(c.column, unit, c.scale, c.resample)
            declared_by[n] = "file" if source == "file" and c.unit is None else "map"
        in_cols = {n: mapped[n] for n in cmap.inputs}
        truth = {n: mapped[f"truth:{n}"] for n in cmap.truth}
        scale = {k: factor(c, model_unit(model, k), cmap.source, "data.inputs", k) for k, c in in_cols.items()}
        scale.update({f"truth:{k}": factor(c, model_unit(model, k), cmap.source, "data.truth", k)
                      for k, c in truth.items()})
        self.fit = {k: mapped[f"fit:{k}"] for k in fit}
        scale.update({f"fit:{k}": factor(c, FIT_SIGNALS[k], cmap.source, "data.fit", k) for k, c in self.fit.items()})
        time = csvlog.TimeCheck(p, sample_time, column=cmap.time.column)
        if mdf:                 # every channel's own times, in s: the map's time entry is not read
            t_factor = 1.0
        else:
            t_unit, _ = logfiles.resolve_unit(p, f"column {cmap.time.column!r} (time)",
                                              reader.file_units.get(cmap.time.column), cmap.time.unit, "s")
            t_factor = (UNITS[t_unit][1] if t_unit else 1.0) * cmap.time.scale
            period = logfiles.period_of(reader, cmap.time.column, t_factor)
            # another rate than the observer's: read whole and put on its grid, as an MDF log's channels (a
            # period past MAX_PERIOD, times in ms taken for s, or times that do not increase: the stream says so)
            if 0 < period <= csvlog.MAX_PERIOD and abs(period / sample_time - 1.0) > csvlog.PERIOD_RTOL:
                reader = logfiles.TableOnGrid(reader, cmap.time.column, t_factor, methods, sample_time,
                                              batch_rows or logfiles.BATCH_ROWS)
                t_factor = 1.0
        from ..project.precision import input_noise
        checks = log_checks.LogChecks(
            p, model, load_parameters(config.parameter_path), input_names,
            {n: log_checks.Column(c.column, c.unit, model_unit(model, n), c.scale, declared_by=declared_by[n])
             for n, c in in_cols.items()},
            sample_time,
            truth={n: log_checks.Column(c.column, c.unit, model_unit(model, n), c.scale, table="data.truth",
                                        declared_by=declared_by[f"truth:{n}"])
                   for n, c in truth.items()},
            noise=input_noise(config, input_names), physics_checks=cmap.physics_checks)
        self.path, self.fmt, self.reader, self.checks, self.time = p, fmt, reader, checks, time
        self.cmap, self.t_factor, self.scale, self.input_names = cmap, t_factor, scale, list(input_names)
        self.mapped = mdf

    warnings = property(lambda self: getattr(self.reader, "warnings", []))
    resampling = property(lambda self: getattr(self.reader, "resampling", {}))

    def chunks(self):
        cmap = self.cmap
        for _, cols in self.reader.chunks():
            t = cols[cmap.time.column] * self.t_factor
            self.time.feed(t)
            inputs = {n: cols[cmap.inputs[n].column] * self.scale[n] for n in self.input_names}
            self.checks.feed(t, inputs)
            truth = {n: cols[c.column] * self.scale[f"truth:{n}"] for n, c in cmap.truth.items()}
            self.checks.feed_truth(truth)
            fit = {n: cols[c.column] * self.scale[f"fit:{n}"] for n, c in self.fit.items()}
            for n, x in fit.items():
                if not np.all(np.isfinite(x)):
                    k = int(np.flatnonzero(~np.isfinite(x))[0])
                    raise DatasetError(f"{self.path}: [data.fit] {n}: {self.fit[n].column!r} is not a finite number "
                                       f"at t = {t[k]:g} s (every sample the fit reads must be)")
            yield t, inputs, truth, fit

    def finish(self) -> dict:
        self.time.finish()
        return self.checks.finish()


def run(config, path, block_bytes: int = csvlog.BLOCK_BYTES, batch_rows: int | None = None, out=None) -> dict:
    """The compiled step over a logged run mapped by the observer file's ``[data]`` table.

    The log is read in chunks (``block_bytes`` of text each): the step runs chunk by chunk with
    its state carried over, the statistics are merged, and every check of
    :mod:`codegen.validation.log_checks` (units, the model's physics) must pass before anything
    is returned. ``out``: a file (``.mf4`` or ``.parquet``) the observer's outputs and status are
    written to, on the log's time base (:mod:`codegen.validation.logout`), put in place once every
    check has passed.

    Raises
    ------
    ConfigurationError
        the map misses an observer input, names an input or output the observer does not have,
        or a unit that does not convert.
    DatasetError
        the log (see :mod:`codegen.validation.csvlog`), or a column that fails its unit or the
        model's physics (:mod:`codegen.validation.log_checks`).
    """
    from ..extension.build import load
    require_map(config)
    obs = load(config)
    model = config.load_model()
    log = MappedLog(config, path, obs.input_names, obs.output_names, config.sample_time, block_bytes, batch_rows)
    cmap, p, fmt, reader = config.column_map, log.path, log.fmt, log.reader
    declared = {n: model_unit(model, n) for n in obs.output_names}
    compared = {n: streaming.ErrorStats(declared[n], settle=SETTLE_TIME) for n in cmap.truth}
    summary = {n: streaming.Summary(declared[n]) for n in obs.output_names if n not in cmap.truth}
    kept = streaming.Decimated()
    state, flags, t0 = obs.initial_state(), 0, None
    written = None
    if out is not None:
        from . import logout
        written = logout.OutputLog(out, declared, f"uiogen validate {config.name} --data {p}")
    try:
        for t, ins, refs, _ in log.chunks():
            inputs = np.column_stack([ins[n] for n in obs.input_names])
            est, status, state = obs.run(inputs, state)
            flags += int(np.count_nonzero(status))
            if written is not None:
                written.add(t, est, status)            # the log's own times, not the run's from 0
            t0 = t[0] if t0 is None else t0
            t = t - t0
            sig = {"t": t}
            for j, name in enumerate(obs.output_names):
                sig[name] = est[:, j]
                if name in cmap.truth:
                    ref = refs[name]
                    sig[f"{name}_truth"] = ref
                    compared[name].add(ref, est[:, j], t)
                else:
                    summary[name].add(est[:, j])
            kept.add(sig)
        report = log.finish()
        if written is not None:         # in place only when every check has passed
            written.finish()
    except BaseException:
        if written is not None:
            written.abort()
        raise
    report["warnings"][:0] = getattr(reader, "warnings", [])      # the resampling's, first
    for n, stats in compared.items():           # a reference in another unit than declared (rad as deg)
        said = log.checks.reference_scale(n, stats.scale_ratio(), SETTLE_TIME)
        column = f"column {cmap.truth[n].column!r} (reference of {n},"
        if said is not None and not any(w.startswith(column) for w in report["warnings"]):   # said once
            report["warnings"].append(said)
    return {"kind": "column_map", "observer": {n: s.result() for n, s in compared.items()},
            "estimates": {n: s.result() for n, s in summary.items()}, "baselines": {},
            "status_flags": flags, "samples": reader.rows, "data": str(path), "signals": kept.signals(),
            "signals_stride": kept.stride, "log_checks": report["checks"], "warnings": report["warnings"],
            "unchecked_columns": report["unchecked_columns"], "format": fmt,
            "resampling": getattr(reader, "resampling", {}), "out": str(out) if out is not None else None,
            "noise": report["noise"], **({"log_checks_overridden": report["overridden"]} if "overridden" in report
                                         else {})}


def resampled_line(resampling) -> str | None:
    """The line naming the channels put on the observer's sample time other than as recorded (None: none was):
    what the figures rest on, channels the log did not hold at the observer's times."""
    moved = {c: r for c, r in (resampling or {}).items() if r["method"] != "as recorded"}
    if not moved:
        return None
    return "resampled onto the observer's sample time: " + "; ".join(
        f"{c!r} {r['rate_hz']:.4g} Hz, {r['method']}" + (f" (latency {r['latency_s']:.3g} s)" if r["latency_s"]
                                                         else "") for c, r in moved.items())


def unchecked_line(rows) -> str | None:
    """The line naming the mapped columns no physics check covered (None: every one was)."""
    if not rows:
        return None
    cols = "; ".join(f"{r['column']!r} ([{r['table']}] {r['signal']}, unit {r['unit'] or 'none'}: {r['why']}"
                     + ("" if r["range_checked"] else "; no range either") + ")" for r in rows)
    one = len(rows) == 1
    return (f"unchecked: {cols}. No physics check covered {'it' if one else 'them'} (a range check, where there is "
            f"one, misses a unit off by a factor under {log_checks.SMALL_FACTOR:g} inside the model's box): "
            f"double-check {'its' if one else 'their'} unit")


def format_table(result: dict) -> str:
    lines = []
    if result["observer"]:
        lines.append(format_stats(result["observer"]))
    if result["estimates"]:
        lines.append(f"{'estimate':12s} {'unit':>7s} {'mean':>10s} {'std':>10s} {'min':>10s} {'max':>10s}   "
                     f"(no reference column)")
        for name, s in result["estimates"].items():
            unit = (s.get("unit") or "–") + ("*" if s.get("converted_from") else "")
            lines.append(f"{name:12s} {unit:>7s} {s['mean']:10.4g} {s['std']:10.4g} {s['min']:10.4g} {s['max']:10.4g}")
    said = resampled_line(result.get("resampling"))
    if said:
        lines.append(said)
    lines += [f"warning: {w}" for w in result.get("warnings", ())]
    said = unchecked_line(result.get("unchecked_columns"))
    if said:
        lines.append(said)
    return "\n".join(lines)
