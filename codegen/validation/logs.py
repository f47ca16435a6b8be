"""Logged runs in the user's own CSV, mapped by the observer file's ``[data]`` table.

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

A column's value in the model's unit is ``value * unit factor * scale`` (:mod:`codegen.project.columns`
parses the map with the observer file). The log is read by
:mod:`codegen.validation.csvlog` (separator, decimal mark, finite values, the sample time of the
observer, no gaps). Estimates with a reference get the error statistics of every validation
(``observer.SIGNAL.rms``, ``unit``, ``truth_rms``, ``rms_percent`` ...:
:func:`codegen.validation.metrics.signal_report`); the others a summary in the same unit
(``estimates.SIGNAL.mean``, ``unit`` ...).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..project.columns import UNITS, ColumnMap, factor, model_unit, normalize_unit
from ..errors import ConfigurationError, DatasetError
from ..project.settings import config_error, suggest
from . import csvlog
from . import metrics
from .common import format_stats, signal_stats

def _read(path, cmap: ColumnMap, names: dict, sample_time: float) -> tuple:
    p = Path(path)
    needed = [cmap.time.column, *(c.column for c in names.values())]
    header, table = csvlog.read_table(p, list(dict.fromkeys(needed)))
    t = csvlog.finite_column(p, table, header, cmap.time.column, cmap.time.unit or "s")
    t = t * (UNITS[cmap.time.unit][1] if cmap.time.unit else 1.0) * cmap.time.scale
    csvlog.check_time(p, t, sample_time, column=cmap.time.column)
    return t, {k: csvlog.finite_column(p, table, header, c.column, c.unit or "model units") for k, c in names.items()}


def run(config, path) -> dict:
    """The compiled step over a logged run mapped by the observer file's ``[data]`` table.

    Raises
    ------
    ConfigurationError
        the map misses an observer input, names an input or output the observer does not have,
        or a unit that does not convert.
    DatasetError
        the log (see :mod:`codegen.validation.csvlog`).
    """
    from ..extension.build import load
    cmap = config.column_map
    if cmap is None:
        raise ConfigurationError(f"{config.source}: logged runs of this observer need a [data] table mapping the log's "
                                 f"columns to its inputs (docs/validation.md, 'Your own logs')", source=config.source)
    obs = load(config)
    model = config.load_model()
    missing = [n for n in obs.input_names if n not in cmap.inputs]
    if missing:
        raise config_error(cmap.source, "data.inputs", missing[0], None,
                           f"a column for every observer input ({', '.join(obs.input_names)}); missing: "
                           f"{', '.join(missing)}")
    for section, mapped, allowed in (("data.inputs", cmap.inputs, obs.input_names),
                                     ("data.truth", cmap.truth, obs.output_names)):
        for k in mapped:
            if k not in allowed:
                raise config_error(cmap.source, section, k, None, f"one of {', '.join(allowed)}", suggest(k, allowed))
    scale = {k: factor(c, model_unit(model, k), cmap.source, "data.inputs", k) for k, c in cmap.inputs.items()}
    scale.update({f"truth:{k}": factor(c, model_unit(model, k), cmap.source, "data.truth", k)
                  for k, c in cmap.truth.items()})
    names = {**cmap.inputs, **{f"truth:{k}": c for k, c in cmap.truth.items()}}
    t, cols = _read(path, cmap, names, obs.sample_time)
    inputs = np.column_stack([cols[n] * scale[n] for n in obs.input_names])
    out, status, _ = obs.run(inputs)
    t = t - t[0]
    units = {n: model_unit(model, n) for n in obs.output_names}
    compared, summary, signals = {}, {}, {"t": t}
    for j, name in enumerate(obs.output_names):
        est = out[:, j]
        signals[name] = est
        if name in cmap.truth:
            ref = cols[f"truth:{name}"] * scale[f"truth:{name}"]
            signals[f"{name}_truth"] = ref
            compared[name] = signal_stats(ref, est, t, unit=units[name])
        else:
            unit, to_shown, converted = metrics.reported_unit(units[name])
            shown = est * to_shown
            summary[name] = {"unit": unit, "mean": float(shown.mean()), "std": float(shown.std()),
                             "min": float(shown.min()), "max": float(shown.max())}
            if converted is not None:
                summary[name]["converted_from"] = converted
    if not len(t):
        raise DatasetError(f"{path}: no samples")
    return {"kind": "column_map", "observer": compared, "estimates": summary, "baselines": {},
            "status_flags": int(np.count_nonzero(status)), "samples": int(len(status)), "data": str(path),
            "signals": signals}


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
    return "\n".join(lines)
