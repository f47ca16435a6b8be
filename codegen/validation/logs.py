"""``uiogen validate --data``: logged runs, one path for every log. A log is read chunk by chunk by its reader
(:class:`MappedLog`, a user's own CSV, Parquet, MDF4, ROS 2 bag or CAN log (BLF, ASC with a DBC) mapped by the
observer file's ``[data]`` table; :class:`SharedLog`, the shared logs' format), the compiled step runs over the
chunks in one loop (:func:`run`), one statistics step takes each chunk (:class:`SignalStats`,
:class:`SideslipStats` with the peers of :mod:`codegen.validation.peers`), and one renderer prints the result
(:func:`format_table`).

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

from ..errors import ConfigurationError, DatasetError, ModelDefinitionError, SampleError
from ..project.columns import FIT_SIGNALS, UNITS, Column, factor, model_unit
from ..settings import config_error, suggest
from . import csvlog, log_checks, logfiles, streaming
from .common import SETTLE_TIME, format_stats, signal_stats


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


DATA_COLUMNS = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx", "y_delta": "delta",
                "y_v_x": "vx", "a_x": "ax"}
"""The shared format's column map: {observer input: column of :mod:`codegen.validation.stanford`}, the map an
observer file without a ``[data]`` table reads a log through."""

# the input sequence of an observer of the shared log, for tools that need one (codegen.tools.qemu,
# codegen.targets.float32): its validation is the logged run, not a simulated scenario
SHARED_LOG = "stanford log"
SHARED_LOGS = {SHARED_LOG: "stanford", "niki log": "niki"}
"""The shared logs as validation runs: {scenario name: the ``--data`` shorthand}. A parameter file's
``[meta] shared_log`` names its car's (``niki``): the float build is held to it too."""


def reads_the_log(input_names) -> bool:
    """Whether every input of the observer is a column of the shared log (DATA_COLUMNS)."""
    return all(c in DATA_COLUMNS for c in input_names)


def shared_log_inputs(input_names, log: str = "stanford") -> np.ndarray | None:
    """A shared log (``log``: a shorthand of :data:`SHARED_LOGS`) as the observer's input matrix, or
    None when the observer takes other signals than the log's (DatasetError, typed, where ../shared is
    absent)."""
    if not reads_the_log(input_names):
        return None
    from . import stanford
    run = stanford.load(log)
    return np.ascontiguousarray(np.column_stack([getattr(run, DATA_COLUMNS[c]) for c in input_names]),
                                dtype=np.float64)


class SharedLog:
    """A log in the shared format (:mod:`codegen.validation.stanford`: the columns, their SI units, the
    format's ranges and physics), read for an observer through :data:`DATA_COLUMNS`, chunk by chunk, and
    checked against the physics of the observer's ``model`` (:mod:`log_checks`; None: by the format alone) as
    :class:`MappedLog` reads a user's log. :meth:`chunks` yields ``(t, {input: values}, {}, {column: values})``: no output has a
    reference column of its own; the sideslip reference and the rest are among the columns."""

    def __init__(self, config, model, path, input_names, sample_time: float, block_bytes: int = csvlog.BLOCK_BYTES):
        from ..model import load_parameters
        from ..project.precision import input_noise
        from . import stanford
        missing = [c for c in input_names if c not in DATA_COLUMNS]
        if missing:
            raise SampleError(f"observer {config.name!r} needs {', '.join(missing)}, which the log does not record "
                              f"(it has delta, r, a_y, v_x); use an observer designed for this data, e.g. "
                              f"stanford_sideslip")
        self.path, self.input_names = stanford._resolve(path), list(input_names)
        self.sample_time, self.block_bytes = sample_time, block_bytes
        self.checks = None if model is None else log_checks.LogChecks(
            self.path, model, load_parameters(config.parameter_path), input_names,
            {n: log_checks.Column(DATA_COLUMNS[n], stanford.UNITS[DATA_COLUMNS[n]], model_unit(model, n),
                                  declared_by="format") for n in input_names}, sample_time,
            noise=input_noise(config, input_names))

    warnings, resampling = (), {}

    def chunks(self):
        from . import stanford
        for cols in stanford.chunks(self.path, sample_time=self.sample_time, block_bytes=self.block_bytes):
            inputs = {n: cols[DATA_COLUMNS[n]] for n in self.input_names}
            if self.checks is not None:
                self.checks.feed(cols["t"], inputs)
            yield cols["t"], inputs, {}, cols

    def finish(self) -> dict:
        return self.checks.finish() if self.checks is not None else {"checks": [], "warnings": []}


def _model_or_none(config):
    """The observer's model definition, or None for a family whose model is not one
    ModelDefinition (its log is then checked by the format alone)."""
    try:
        return config.load_model()
    except ModelDefinitionError:
        return None


class SignalStats:
    """The statistics of a mapped log: each output with a reference column (``[data.truth]``) against it, in the
    unit its model declares, the others summarised, and the signals kept for plots."""

    def __init__(self, cmap, output_names, units: dict):
        self.names = list(output_names)
        self.compared = {n: streaming.ErrorStats(units[n], settle=SETTLE_TIME) for n in cmap.truth}
        self.summary = {n: streaming.Summary(units[n]) for n in output_names if n not in cmap.truth}
        self.kept = streaming.Decimated()

    def add(self, t, est, status, refs, columns) -> None:
        sig = {"t": t}
        for j, name in enumerate(self.names):
            sig[name] = est[:, j]
            if name in self.compared:
                sig[f"{name}_truth"] = refs[name]
                self.compared[name].add(refs[name], est[:, j], t)
            else:
                self.summary[name].add(est[:, j])
        self.kept.add(sig)

    def result(self, config, log, report) -> dict:
        for n, stats in self.compared.items():           # a reference in another unit than declared (rad as deg)
            said = log.checks.reference_scale(n, stats.scale_ratio(), SETTLE_TIME)
            column = f"column {config.column_map.truth[n].column!r} (reference of {n},"
            if said is not None and not any(w.startswith(column) for w in report["warnings"]):   # said once
                report["warnings"].append(said)
        return {"observer": {n: s.result() for n, s in self.compared.items()},
                "estimates": {n: s.result() for n, s in self.summary.items()}, "baselines": {},
                "samples": log.reader.rows, "data": str(log.path), "signals": self.kept.signals(),
                "signals_stride": self.kept.stride, "unchecked_columns": report["unchecked_columns"],
                "format": log.fmt, "resampling": log.resampling, "noise": report["noise"],
                **({"log_checks_overridden": report["overridden"]} if "overridden" in report else {})}


class SideslipStats:
    """The statistics of a log in the shared format: the sideslip error (beta of an observer of v_y is atan2(v_y,
    v_x) with the log's v_x) and the v_y error of the observer and of its peers (:mod:`codegen.validation.peers`,
    run on the whole log once it has been read), the measured steering angle against an observer that estimates
    it, the error on each side of the identification split, and around the log's large-sideslip peaks."""

    def __init__(self, config, input_names, output_names, path):
        from . import stanford
        self.outputs, self.path = list(output_names), path
        self.delta_unknown = "delta" in self.outputs and not {"y_delta", "delta"} & set(input_names)
        self.table = {"beta": streaming.ErrorStats("rad"), "vy": streaming.ErrorStats("m/s")}
        self.delta_stats, self.prev_delta = streaming.ErrorStats("rad"), None
        self.split = _identification_split(config, path)
        self.parts = {"identification": _Rms(), "evaluation": _Rms()}
        self.peaks = {tp: _Peak() for tp in stanford.peak_times(path)}
        self.kept, self.whole = streaming.Decimated(), {c: [] for c in stanford.COLUMNS}
        self.n, self.t_end = 0, None

    def add(self, t, est, status, refs, cols) -> None:
        outputs = self.outputs
        self.n += t.size
        self.t_end = float(t[-1])
        vx, truth = cols["vx"], cols["beta_true"]
        if "beta" in outputs:
            beta = est[:, outputs.index("beta")]
        else:   # observers of v_y (Nguyen et al. 2021): beta = atan(v_y / v_x) with the log's v_x
            beta = np.arctan2(est[:, outputs.index("v_y")], vx)
        self.table["beta"].add(truth, beta)
        self.table["vy"].add(vx * np.tan(truth), vx * np.tan(beta))
        if self.delta_unknown:
            # delta is an unknown input of the observer (one sample late): the log's measured delta checks it
            d = est[:, outputs.index("delta")]
            first = self.prev_delta is None
            meas = cols["delta"] if first else np.concatenate([[self.prev_delta], cols["delta"]])
            self.delta_stats.add(meas[:d.size - first], d[first:])
            self.prev_delta = float(cols["delta"][-1])
        if self.split is not None:
            self.parts["identification"].add(beta, truth, t < self.split)
            self.parts["evaluation"].add(beta, truth, t >= self.split)
        for tp, pk in self.peaks.items():
            pk.add(t, truth, beta, tp)
        self.kept.add({"t": t, "beta_true": truth, "beta": beta, "status": status})
        if self.whole is not None:
            for c in cols:                        # a column of stanford.OPTIONAL the log lacks stays empty
                self.whole[c].append(cols[c])
            if self.n > BASELINE_MAX_SAMPLES:
                self.whole = None                 # too long for the baselines: stop holding the run

    def result(self, config, log, report) -> dict:
        from . import stanford
        extra = {"delta": self.delta_stats.result()} if self.delta_unknown else {}
        result = {"observer": {k: v.result() for k, v in self.table.items()} | extra, "baselines": {},
                  "samples": self.n, "data": str(self.path)}
        signals = self.kept.signals()
        estimates = {}
        if self.whole is not None:
            run = stanford.StanfordRun(source=result["data"], **{c: np.concatenate(v) if v else None
                                                                  for c, v in self.whole.items()})
            estimates = _baselines(config, run)
            result["baselines"] = {k: _table(run, b) for k, b in estimates.items()}
            signals.update(estimates)
        else:
            result["baselines_skipped"] = (f"the log has {self.n} samples, more than {BASELINE_MAX_SAMPLES} (the "
                                           f"Kalman baselines hold the whole run and step at about 0.1 ms per "
                                           f"sample); the observer is reported alone")
        result["signals"], result["signals_stride"] = signals, self.kept.stride
        split = self.split
        if split is not None and self.t_end is not None and self.t_end > split:
            result["splits"] = {"t_split": split, "unit": "deg"}
            for part, m in (("identification", signals["t"] < split), ("evaluation", signals["t"] >= split)):
                row = {"samples": self.parts[part].n, "observer": self.parts[part].rms()}
                for k, b in estimates.items():
                    row[k] = float(np.degrees(np.sqrt(np.mean((b - signals["beta_true"])[m] ** 2))))
                result["splits"][part] = row
        rows = []
        for tp, pk in self.peaks.items():
            if pk.n:
                row = {"t": tp, "truth_peak_deg": float(np.degrees(pk.truth_peak)),
                       "observer": float(np.degrees(pk.err))}
                if estimates:
                    m = np.abs(signals["t"] - tp) <= PEAK_HALF_WIDTH
                    row.update({k: float(np.degrees(np.abs(b[m] - signals["beta_true"][m]).max()))
                                for k, b in estimates.items()})
                rows.append(row)
        result["peaks"] = rows
        return result


def run(config, path="stanford", block_bytes: int | None = None, batch_rows: int | None = None, out=None) -> dict:
    """``uiogen validate --data``: the compiled step over a logged run, beside the peers.

    An observer file with a ``[data]`` table maps the log's own columns (:class:`MappedLog`); otherwise the
    log is in the shared format (:class:`SharedLog`). Either way the log is read in chunks (``block_bytes``
    of text each, or ``batch_rows`` rows of a Parquet or resampled MDF log: :mod:`codegen.validation.logfiles`;
    any size in bounded memory), the step runs chunk by chunk with its state carried over, one statistics
    step takes each chunk (:class:`SignalStats` of a mapped log, :class:`SideslipStats` of the shared format),
    and every check of :mod:`codegen.validation.log_checks` (units, the model's physics) must pass before
    anything is returned. ``config``: an observer's name or its :class:`~codegen.project.observer_file.ObserverConfig`.
    ``out``: a file (``.mf4`` or ``.parquet``) the observer's outputs and status are written to, on the log's
    time base (:mod:`codegen.validation.logout`), put in place once every check has passed.

    Returns the statistics' rows in the one definition of :func:`codegen.validation.metrics.signal_report`
    (a mapped log: ``observer.SIGNAL`` of the outputs with a reference, ``estimates.SIGNAL`` of the others; the
    shared format: ``beta`` [deg] and ``vy`` [m/s] of the observer and of each of ``baselines``, ``splits``
    (sideslip RMS per part of the log) where the log has an evaluation part, ``peaks``), the signals for plots,
    ``status_flags``, ``samples``, ``log_checks`` (every check and its verdict) and ``warnings``.

    Raises
    ------
    ConfigurationError
        the map misses an observer input, names an input or output the observer does not have,
        or a unit that does not convert.
    DatasetError
        the log (see :mod:`codegen.validation.csvlog`), or a column that fails its unit or the
        model's physics (:mod:`codegen.validation.log_checks`).
    """
    from ..extension.build import load, require_current
    from ..project.observer_file import get
    config = get(config) if isinstance(config, str) else config
    require_current(config)                 # never the compiled step of an older design
    obs = load(config)
    block_bytes = csvlog.BLOCK_BYTES if block_bytes is None else block_bytes
    model = _model_or_none(config)
    units = {n: model_unit(model, n) if model is not None else None for n in obs.output_names}
    if config.column_map is not None:
        log = MappedLog(config, path, obs.input_names, obs.output_names, config.sample_time, block_bytes, batch_rows)
        stats = SignalStats(config.column_map, obs.output_names, units)
    else:
        log = SharedLog(config, model, path, obs.input_names, obs.sample_time, block_bytes)
        stats = SideslipStats(config, obs.input_names, obs.output_names, log.path)
    written = None
    if out is not None:
        from . import logout
        written = logout.OutputLog(out, units, f"uiogen validate {config.name} --data {log.path}")
    state, flags, t0 = obs.initial_state(), 0, None
    try:
        for t, ins, refs, columns in log.chunks():
            est, status, state = obs.run(np.column_stack([ins[n] for n in obs.input_names]), state)
            flags += int(np.count_nonzero(status))
            if written is not None:
                written.add(t, est, status)            # the log's own times, not the run's from 0
            t0 = t[0] if t0 is None else t0
            stats.add(t - t0, est, status, refs, columns)
        report = log.finish()
        if written is not None:         # in place only when every check has passed
            written.finish()
    except BaseException:
        if written is not None:
            written.abort()
        raise
    report["warnings"][:0] = log.warnings      # the resampling's, first
    return {**stats.result(config, log, report), "status_flags": flags, "log_checks": report["checks"],
            "warnings": report["warnings"], **({"out": str(out)} if out is not None else {})}


PEAK_HALF_WIDTH = 5.0

BASELINE_MAX_SAMPLES = 300_000
"""The Kalman baselines run on logs of at most this many samples (50 min at 100 Hz): they hold the
whole run in memory and step at about 0.1 ms per sample, so on a longer log the observer is
reported alone and the result says why (``baselines_skipped``)."""


def _baselines(config, run) -> dict:
    """beta of every baseline of the shared log: the source repository's linear KF, the EKF, and the
    same-model peers of an observer of the nonlinear-tyre model (:class:`~codegen.contract.capabilities.LogPeers`),
    the two groups on two processes (:class:`~.workers.Workers`: independent runs, the same estimates)."""
    import os

    from ..contract.capabilities import LogPeers
    from .workers import Workers
    family = config.observer_family
    calls = [(_source_baselines, (run,))]
    if isinstance(family, LogPeers):        # the family's peers of the observer's own model and parameter file
        calls.append((family.log_peers, (config, run)))
    with Workers(min(len(calls), os.cpu_count() or 1)) as workers:
        estimates = {}
        for part in workers.map(calls):
            estimates.update(part)
    return estimates


def _source_baselines(run) -> dict:
    """beta of the source repository's linear KF and of its EKF on the shared log."""
    from . import peers
    return {"linear_kf": peers.linear_kf(run).beta, "ekf": peers.ekf(run).beta}


def _table(run, b) -> dict:
    return {"beta": signal_stats(run.beta_true, b, unit="rad"),
            "vy": signal_stats(run.vx * np.tan(run.beta_true), run.vx * np.tan(b), unit="m/s")}


class _Rms:
    """RMS of the beta error [deg] over the samples of a mask, streamed."""

    def __init__(self):
        self.n, self.sq = 0, 0.0

    def add(self, beta, truth, mask) -> None:
        e = (beta - truth)[mask]
        self.n += int(e.size)
        self.sq += float(np.sum(e * e))

    def rms(self) -> float:
        return float(np.degrees(np.sqrt(self.sq / self.n))) if self.n else float("nan")


class _Peak:
    """The truth's largest |beta| and the observer's largest |error| within +-PEAK_HALF_WIDTH of a time."""

    def __init__(self):
        self.n, self.truth_peak, self.err = 0, 0.0, 0.0

    def add(self, t, truth, beta, tp) -> None:
        m = np.abs(t - tp) <= PEAK_HALF_WIDTH
        if not m.any():
            return
        tm = truth[m]
        i = int(np.argmax(np.abs(tm)))
        if not self.n or abs(tm[i]) > abs(self.truth_peak):
            self.truth_peak = float(tm[i])
        self.err = max(self.err, float(np.abs(beta[m] - tm).max()))
        self.n += int(m.sum())


def _identification_split(config, path=None):
    """Where the evaluation part of a log starts [s from its start]: the observer's parameter file's
    ``[meta] identification_t_end`` (its numbers were chosen before it), else, on the shared Stanford
    log, :data:`codegen.validation.stanford.EVALUATION_T_START` (the same protocol for every estimator
    of that log); None otherwise (and the result has no split when the log does not reach past it)."""
    from ..model import load_parameters
    from . import stanford
    raw = load_parameters(config.parameter_path).meta.get("identification_t_end")
    if raw is not None:
        return float(raw)
    if path is not None and str(path) == str(stanford.STANFORD_PATH):
        return stanford.EVALUATION_T_START
    return None


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


def plot(result: dict, path: str) -> None:
    """The run of :func:`run` as a figure at ``path``: a mapped log's every estimate with its reference, or the
    shared format's sideslip of the observer and its peers and their errors."""
    from ..project.outputs import pyplot
    plt = pyplot()
    sig = result["signals"]
    if "estimates" in result:       # a mapped log: every estimate, with its reference
        names = [k for k in sig if k != "t" and not k.endswith("_truth")]
        fig, ax = plt.subplots(len(names), 1, figsize=(10, 2.2 * len(names)), sharex=True, squeeze=False)
        for a, k in zip(ax[:, 0], names):
            if f"{k}_truth" in sig:
                a.plot(sig["t"], sig[f"{k}_truth"], "k", lw=0.8, label="reference")
            a.plot(sig["t"], sig[k], "r", lw=0.8, label="observer (C step)")
            a.set_ylabel(k)
            a.legend(loc="upper right", fontsize=8)
        ax[-1, 0].set_xlabel("t [s]")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    deg = 180 / np.pi
    ax[0].plot(sig["t"], sig["beta_true"] * deg, "k", lw=0.8, label="reference atan2(vy, vx) of the log")
    ax[0].plot(sig["t"], sig["beta"] * deg, "r", lw=0.8, label="observer (C step)")
    ax[0].plot(sig["t"], sig["linear_kf"] * deg, "b", lw=0.6, alpha=0.6, label="linear KF")
    ax[0].set_ylabel("beta [deg]")
    ax[0].legend(loc="upper right", fontsize=8)
    for key, color in (("beta", "r"), ("linear_kf", "b"), ("ekf", "g"), ("ekf_nonlinear_tyre", "m"),
                       ("ukf_nonlinear_tyre", "c")):
        if key in sig:
            ax[1].plot(sig["t"], (sig[key] - sig["beta_true"]) * deg, color, lw=0.6, label=key)
    for pk in result.get("peaks", ()):
        for a in ax:
            a.axvspan(pk["t"] - PEAK_HALF_WIDTH, pk["t"] + PEAK_HALF_WIDTH, color="0.85", zorder=0)
    if "splits" in result:
        for a in ax:
            a.axvline(result["splits"]["t_split"], color="k", ls=":", lw=0.8)
    ax[1].set_ylabel("error [deg]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_table(result: dict) -> str:
    """The table of a logged run (:func:`run`), section by section: the sideslip of the observer and its peers
    (the shared format: with an identification split, the evaluation part, on samples no choice was made on,
    is the headline column, the identification part and the whole log beside it), the outputs with a reference
    and the others summarised (a mapped log), then what the figures rest on (resampled channels, peers not run,
    warnings, unchecked columns)."""
    lines = _sideslip_lines(result) if "peaks" in result else []
    if result["observer"] and "estimates" in result:
        lines.append(format_stats(result["observer"]))
    if result.get("estimates"):
        lines.append(f"{'estimate':12s} {'unit':>7s} {'mean':>10s} {'std':>10s} {'min':>10s} {'max':>10s}   "
                     f"(no reference column)")
        for name, s in result["estimates"].items():
            unit = (s.get("unit") or "–") + ("*" if s.get("converted_from") else "")
            lines.append(f"{name:12s} {unit:>7s} {s['mean']:10.4g} {s['std']:10.4g} {s['min']:10.4g} {s['max']:10.4g}")
    said = resampled_line(result.get("resampling"))
    if said:
        lines.append(said)
    if result.get("baselines_skipped"):
        lines.append(f"baselines not run: {result['baselines_skipped']}")
    lines += [f"warning: {w}" for w in result.get("warnings", ())]
    said = unchecked_line(result.get("unchecked_columns"))
    if said:
        lines.append(said)
    return "\n".join(lines)


def _sideslip_lines(result: dict) -> list:
    rows = [("observer", result["observer"])] + list(result["baselines"].items())
    sp_ = result.get("splits")
    if sp_:
        ev, idn = sp_["evaluation"], sp_["identification"]
        lines = [f"beta RMSE [deg] on the evaluation part (t >= {sp_['t_split']:g} s, {ev['samples']} samples; the "
                 f"headline), the identification part (t < {sp_['t_split']:g} s, {idn['samples']} samples) and the "
                 f"whole log; max, MAE [deg] and vy RMSE [m/s] on the whole log",
                 f"{'estimator':18s} {'evaluation':>10s} {'identif.':>9s} {'whole':>9s} {'beta max':>9s} {'beta MAE':>9s} "
                 f"{'vy RMSE':>9s}"]
        for name, t in rows:
            lines.append(f"{name:18s} {ev[name]:10.4f} {idn[name]:9.4f} {t['beta']['rms']:9.4f} {t['beta']['max']:9.4f} "
                         f"{t['beta']['mae']:9.4f} {t['vy']['rms']:9.4f}")
    else:
        lines = [f"{'estimator':18s} {'beta RMSE':>10s} {'beta max':>9s} {'beta MAE':>9s} {'vy RMSE':>9s}   [deg, m/s]"]
        for name, t in rows:
            lines.append(f"{name:18s} {t['beta']['rms']:10.4f} {t['beta']['max']:9.4f} {t['beta']['mae']:9.4f} "
                         f"{t['vy']['rms']:9.4f}")
    truth = result["observer"]["beta"]
    if truth.get("truth_rms"):
        lines.append(f"beta truth RMS {truth['truth_rms']:.4f} deg on the whole log; its RMSE in % of it: "
                     + ", ".join(f"{name} {t['beta']['rms_percent']:.1f} %" for name, t in rows))
    for pk in result.get("peaks", ()):
        lines.append(f"peak t = {pk['t']:g} s (truth peak {pk['truth_peak_deg']:.2f} deg), max |beta error| within "
                     f"+-{PEAK_HALF_WIDTH:g} s: " + ", ".join(f"{k} {v:.2f}" for k, v in pk.items()
                                                           if k not in ("t", "truth_peak_deg")))
    if "delta" in result["observer"]:
        d = result["observer"]["delta"]
        lines.append(f"steering angle delta (an unknown input of this observer) vs the log's measured delta: "
                     f"RMSE {d['rms']:.4f} deg, max {d['max']:.4f} deg, MAE {d['mae']:.4f} deg")
    return lines
