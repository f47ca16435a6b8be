"""What every family's validation shares: the settle time, the error statistics (one definition
for every family), scenarios at an observer's rate, the model module's truth plant and the
CommonRoad vehicle an observer was designed for, and the sensor noise of the simulated measurements."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import ModelDefinitionError, SampleError
from ..project.sensor_noise import SENSOR_NOISE
from . import metrics, scenarios

SETTLE_TIME = 2.0


def signal_stats(truth, est, t=None, *, unit: str | None) -> dict:
    """The error statistics of one signal, every family's one definition
    (:func:`codegen.validation.metrics.signal_report`: figures in the declared ``unit``, a plane
    angle in rad given in degrees and marked so, the truth's RMS and the error as a percentage of
    it, NMSE % of Sentouh et al. 2023 eq. (32)), after SETTLE_TIME when sample times ``t`` are given
    (``after_s``). The papers' own table formats are built from these rows (or beside them)."""
    mask = slice(None) if t is None else np.asarray(t) >= SETTLE_TIME
    row = metrics.signal_report(np.asarray(truth)[mask], np.asarray(est)[mask], unit=unit)
    row["after_s"] = None if t is None else SETTLE_TIME
    return row


def _cell(v, width: int) -> str:
    return f"{'–':>{width}s}" if v is None else f"{v:{width}.4g}"


def format_stats(rows: dict, label: str = "signal") -> str:
    """:func:`signal_stats` rows as text, one definition for every table: the unit each row's figures
    are in (``deg*`` where converted from the declared rad), RMS, the truth's RMS and the error in %
    of it, max and mean absolute error, NMSE %; every figure to 4 significant digits, so a huge one
    (an estimate far off its reference) stays one readable cell."""
    lines = [f"{label:16s} {'unit':>7s} {'RMS':>10s} {'truth RMS':>10s} {'RMS %':>10s} {'max':>10s} {'MAE':>10s} "
             f"{'NMSE %':>10s}"]
    for sig, r in rows.items():
        unit = (r.get("unit") or "–") + ("*" if r.get("converted_from") else "")
        pct = "–" if r.get("rms_percent") is None else f"{r['rms_percent']:.4g}"
        nmse = "–" if r.get("nmse_percent") is None else f"{r['nmse_percent']:.4g}"
        lines.append(f"{sig:16s} {unit:>7s} {_cell(r.get('rms'), 10)} {_cell(r.get('truth_rms'), 10)} {pct:>10s} "
                     f"{_cell(r.get('max'), 10)} {_cell(r.get('mae'), 10)} {nmse:>10s}")
    after = {r.get("after_s") for r in rows.values()}
    notes = []
    if any(r.get("converted_from") for r in rows.values()):
        notes.append("* converted from the declared rad")
    if len(after) == 1 and None not in after:
        notes.append(f"after the first {after.pop():g} s")
    if notes:
        lines.append("(" + "; ".join(notes) + "; RMS % = 100 RMS / truth RMS)")
    return "\n".join(lines)


def truncate(scn, duration: float | None):
    """The first ``duration`` seconds of a scenario (every time series cut; None: all of it)."""
    if duration is None or duration >= scn.duration:
        return scn
    n = int(round(duration * scn.sample_rate)) + 1
    cut = {k: getattr(scn, k)[:n] for k in ("t", "v_ref", "a_ref", "T_a", "T_d_open")}
    for k in ("kappa_ref", "bank"):            # optional series
        if getattr(scn, k, None) is not None:
            cut[k] = getattr(scn, k)[:n]
    return replace(scn, **cut)


def commonroad_vehicle(config) -> int:
    """The CommonRoad parameter set an observer was designed for ([meta] commonroad_vehicle)."""
    from ..model import load_parameters
    vehicle = load_parameters(config.parameter_path).meta.get("commonroad_vehicle")
    if vehicle not in ("1", "2", "3"):
        raise ModelDefinitionError(
            f"observer {config.name!r} was designed for {config.parameters}, not for a CommonRoad car; "
            f"validate on the CommonRoad plant with an observer designed for its parameters, e.g. "
            f"lpv_linf_driver_torque_bmw320i or ts_fuzzy_uio_bmw320i")
    return int(vehicle)


def truth_plant(config, params):
    """The model module's truth plant (``PLANT``: e.g. Pacejka tyres) when the parameter set has the
    ``[plant]`` values it needs (``mu`` may follow the scenario), else None (the observer's own
    exact model is integrated)."""
    plant = getattr(config.load_model_module(), "PLANT", None)
    if plant is None:
        return None
    values = {**params.values, **params.plant}
    return plant if all(str(p) in values or str(p) == "mu" for p in plant.parameters) else None


def scenario_for(config, scenario, duration: float | None = None):
    """A library scenario (by name) at the observer's sample rate, or a built
    :class:`~codegen.validation.scenarios.Scenario` (e.g. a variant made with ``dataclasses.replace``)
    whose rate must be the observer's; optionally truncated."""
    if isinstance(scenario, scenarios.Scenario):
        if abs(scenario.sample_rate * config.sample_time - 1.0) > 1e-9:
            raise SampleError(f"scenario {scenario.name!r} is sampled at {scenario.sample_rate} Hz; observer "
                              f"{config.name!r} runs at {1.0 / config.sample_time} Hz")
        return truncate(scenario, duration)
    return truncate(scenarios.make(scenario, sample_rate=1.0 / config.sample_time), duration)
