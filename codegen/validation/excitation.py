"""``uiogen validate NAME --scenario excitation``: a validation scenario for any model.

No driver, no track, nothing of a particular paper: the model's own nonlinear equations (the
symbolic ``MODEL``, before any polytope or TS reduction) are integrated (RK4 at Ts/10, the
inputs evaluated continuously between the samples, as a real car's are) with

* every input scheduling signal swept inside its box: a sine of 0.9 of the half-range about the
  box's centre whose slope stays within the box's rate bounds (at its centre when it has none);
  an ``[inputs.NAME]`` table of the signal narrows the swept range (a car the open-loop scenario
  would spin at the top of its speed box);
* every known and unknown input a seeded, smooth random signal (a sum of sinusoids below its
  ``bandwidth``, 1 Hz by default) filling the range ``[inputs.NAME] min, max`` of the parameter
  file (or, without that table, the input's ``[state_bounds]`` entry: the set a design certifies);
* the state starting at the centre of its ``[state_bounds]`` box (or at 0).

The compiled step runs over the sampled outputs, known inputs and scheduling signals with the
sensor noise the parameter file declares (``[sensor_noise]``, :mod:`codegen.validation.noise`:
seeded white noise at those levels, the levels in ``result["noise"]``; none declared, or
``noise=False`` (``--noise-free``): noise free, and the result says which), and its estimates are
compared with the simulated states and unknown inputs after the settle time; the result has the
shape of every validation (``observer.SIGNAL.rms``, ``unit``, ``truth_rms``, ``truth_std``,
``no_information``, ``rms_percent``, ``nmse_percent``: :func:`codegen.validation.metrics.signal_report`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ModelDefinitionError
from ..settings import config_error, suggest
from ..model import load_parameters, parameter_substitution
from . import model_plant
from .common import SETTLE_TIME, signal_stats

DURATION = 30.0


def _smooth(t: np.ndarray, rng, lo: float, hi: float, bandwidth: float):
    """A seeded sum of sinusoids in [0.05, bandwidth] Hz, scaled to fill [lo, hi] (90 % of it on
    the sample times ``t``); returned as a function of time."""
    f = np.exp(rng.uniform(np.log(0.05), np.log(bandwidth), 12))
    ph = rng.uniform(0.0, 2 * np.pi, 12)

    def raw(tt):
        # one sinusoid at a time, added in order: the same doubles as the (12, n) matrix summed over its
        # rows, without it (12 copies of the times, twice over: a 30,000 s campaign run took 21 GB)
        tt = np.atleast_1d(tt)
        out = np.sin(2 * np.pi * f[0] * tt + ph[0]) / f[0]
        for fk, pk in zip(f[1:], ph[1:]):
            out += np.sin(2 * np.pi * fk * tt + pk) / fk
        return out
    x = raw(t)
    x_min, width = x.min(), max(x.max() - x.min(), 1e-300)
    return lambda tt: lo + (0.05 + 0.9 * (raw(tt) - x_min) / width) * (hi - lo)


STEP_S = 2.0
"""s a signal without rate bounds holds each level of its staircase (it may jump: a gear ratio)."""


def _sweep(box, lower: float, upper: float):
    mid, half = 0.5 * (lower + upper), 0.45 * (upper - lower)
    if half <= 0:
        return lambda tt: np.full(np.shape(np.atleast_1d(tt)), mid)
    if not box.rate_bounded:
        # five levels across 90 % of the box, up and down, each held STEP_S: every jump between neighbours
        levels = mid + half * np.array([-1.0, -0.5, 0.0, 0.5, 1.0, 0.5, 0.0, -0.5])
        return lambda tt: levels[(np.floor(np.atleast_1d(tt) / STEP_S).astype(int)) % len(levels)]
    rate = min(abs(box.rate_lower), abs(box.rate_upper))
    if rate <= 0:
        return lambda tt: np.full(np.shape(np.atleast_1d(tt)), mid)
    omega = 0.9 * rate / half                  # |d/dt half sin(omega t)| <= 0.9 rate
    return lambda tt: mid - half * np.cos(omega * np.atleast_1d(tt))


def input_range(params, name: str):
    """(min, max, bandwidth Hz) of input ``name`` in the excitation scenario: its ``[inputs.NAME]``
    table, else its ``[state_bounds]`` entry (the set a design certifies, at 1 Hz), else None."""
    spec = params.inputs.get(name)
    if spec is not None:
        return spec["min"], spec["max"], spec.get("bandwidth", 1.0)
    if name in params.state_bounds:
        return (*params.state_bounds[name], 1.0)
    return None


def signal_functions(config, duration: float = DURATION, seed: int = 0) -> tuple:
    """(sample times, {name: function of time}) of the scenario's raw scheduling signals and inputs.

    Raises
    ------
    ModelDefinitionError
        naming every scheduling box and input range the parameter file lacks, in one message.
    """
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    t = np.arange(0.0, duration + 0.5 * config.sample_time, config.sample_time)
    rng = np.random.default_rng(seed)
    signals = [str(s) for s in (*model.known_inputs, *model.unknown_inputs,
                                *(g.symbol for g in model.scheduling if g.derived is None))]
    for key in params.inputs:
        if key not in signals:
            raise config_error(params.source, "inputs", key, params.inputs[key], f"an input or input scheduling signal of model "
                               f"{model.name!r}: {', '.join(signals) or 'none'}", suggest(key, signals))
    out, missing = {}, []
    for sig in model.scheduling:
        if sig.derived is None:
            name = str(sig.symbol)
            box = params.scheduling.get(name)
            if box is None:
                missing.append(f"[scheduling.{name}] (min, max, rate_min, rate_max: the sweep of {name})")
                continue
            lower, upper = box.lower, box.upper
            if name in params.inputs:           # a narrower sweep (a car unstable at the top of the box)
                lower, upper = params.inputs[name]["min"], params.inputs[name]["max"]
                if not box.lower <= lower <= upper <= box.upper:
                    raise config_error(params.source, f"inputs.{name}", "min", lower,
                                       f"min and max inside [scheduling.{name}] = [{box.lower:g}, {box.upper:g}] "
                                       f"(the sweep of the excitation scenario narrows the box, never widens it)")
            out[name] = _sweep(box, lower, upper)
    for u in (*model.known_inputs, *model.unknown_inputs):
        spec = input_range(params, str(u))
        if spec is None:
            missing.append(f"[inputs.{u}] (min, max, optionally bandwidth in Hz: the range of "
                           f"{'known' if u in model.known_inputs else 'unknown'} input {u})")
        else:
            out[str(u)] = _smooth(t, rng, *spec)
    if missing:
        raise ModelDefinitionError(f"{params.source}: the excitation scenario needs {len(missing)} table(s) the file "
                                   f"lacks: {'; '.join(missing)}")
    return t, out


def signals(config, duration: float = DURATION, seed: int = 0) -> dict:
    """The scenario's inputs at the observer's sample times: {name: array}, with ``t``."""
    t, funcs = signal_functions(config, duration, seed)
    return {"t": t, **{name: f(t) for name, f in funcs.items()}}


@dataclass(frozen=True, eq=False)
class ExcitationRun:
    """One excitation run's inputs, ready for a plant: the sample times, every external signal
    at them, and the stage-input matrix of :class:`~codegen.validation.model_plant.ModelPlant`."""

    name: str
    seed: int
    t: np.ndarray
    signals: dict           # {external signal: values at t}
    stages: np.ndarray      # E of ModelPlant.simulate
    x0: np.ndarray          # the state at t = 0


def scenario(config, duration: float = DURATION, seed: int = 0, plant=None) -> ExcitationRun:
    """The excitation run of ``config`` (its model's plant, or ``plant``) as data."""
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    plant = plant or model_plant.plant(model, config.sample_time)
    t, funcs = signal_functions(config, duration, seed)
    return ExcitationRun("excitation", int(seed), t, {k: np.asarray(funcs[k](t), float) for k in plant.external},
                         plant.stage_inputs(t, funcs), model_plant.initial_state(model, params))


def simulate(config, duration: float = DURATION, seed: int = 0) -> dict:
    """Truth of the excitation scenario on the model's own equations (:mod:`codegen.validation.model_plant`,
    RK4 at Ts/10 with the inputs between the samples): states, inputs, outputs (as ``y_NAME`` and
    NAME), scheduling signals, at the observer's sample times."""
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    subs = parameter_substitution(model, params)
    plant = model_plant.plant(model, config.sample_time)
    run = scenario(config, duration, seed, plant)
    truth = {"t": run.t, **run.signals, **plant.simulate(run.x0, run.stages, [subs[p] for p in model.parameters])}
    bad = [k for k in plant.states if not np.all(np.isfinite(truth[k]))]
    if bad:
        k = int(np.argmin(np.isfinite(truth[bad[0]])))
        raise ModelDefinitionError(f"model {model.name!r}: the excitation run left the finite numbers at t = "
                                   f"{run.t[k]:.3g} s (state {bad[0]}); narrow the [inputs.*] ranges of "
                                   f"{params.source}")
    _refuse_divergence(model, params, run.t, truth, plant.states)
    for name, _ in model.outputs:
        truth.setdefault(name, truth[f"y_{name}"])
    return truth


DIVERGED_FACTOR = 10.0
"""A state beyond DIVERGED_FACTOR x the plausible range of its dimension
(:data:`codegen.validation.log_checks.PLAUSIBLE`) has left any plausible range."""
DIVERGED_BOX_FACTOR = 1e3
"""A state beyond DIVERGED_BOX_FACTOR x the largest |bound| of its ``[state_bounds]`` box has left
it for good (an open-loop position state may drift out of its box some 100-fold; a diverging one
grows without bound)."""
DIVERGED_ABSOLUTE = 1e9
"""|value| in the model's unit no state of a vehicle model reaches (whatever its unit or box)."""


def _refuse_divergence(model, params, t, truth, states) -> None:
    """Raise when the plant's trajectory diverged while staying finite (an unstable plant under the
    excitation: every figure, the truth's RMS included, would then be the divergence's, not the
    observer's). Each state is held against the first of: DIVERGED_FACTOR x the plausible range of
    its unit's dimension, DIVERGED_BOX_FACTOR x its ``[state_bounds]`` box, DIVERGED_ABSOLUTE."""
    from .log_checks import PLAUSIBLE, _dimension, _si
    first = None
    for k in states:
        x = np.abs(np.asarray(truth[k], float))
        unit = (model.units or {}).get(k)
        dim = _dimension(unit)
        limits = [(DIVERGED_ABSOLUTE, f"+-{DIVERGED_ABSOLUTE:g} {unit or '(model units)'}")]
        if dim in PLAUSIBLE:
            limits.append((DIVERGED_FACTOR * PLAUSIBLE[dim], f"{DIVERGED_FACTOR:g} x the plausible range of "
                           f"{'an' if dim[0] in 'aeiou' else 'a'} {dim} (+-{PLAUSIBLE[dim]:.4g} {_si(dim)})"))
        if k in params.state_bounds:
            lo, hi = params.state_bounds[k]
            limits.append((DIVERGED_BOX_FACTOR * max(abs(lo), abs(hi)), f"{DIVERGED_BOX_FACTOR:g} x its "
                           f"[state_bounds] box [{lo:g}, {hi:g}]"))
        limit, what = min(limits, key=lambda lw: lw[0])
        beyond = np.flatnonzero(x > limit)
        if beyond.size and (first is None or beyond[0] < first[1]):
            first = (k, int(beyond[0]), limit, what, unit, float(x.max()), int(np.argmax(x)))
    if first is None:
        return
    k, i, _, what, unit, peak, j = first
    raise ModelDefinitionError(
        f"model {model.name!r}: the plant diverged in the excitation run: state {k} left {what} at t = {t[i]:.4g} s "
        f"and reached |{k}| = {peak:.4g} {unit or '(model units)'} at t = {t[j]:.4g} s, so every figure of the run "
        f"(the truth's RMS, the errors, NMSE) would measure the divergence, not the observer; the model is unstable "
        f"under this excitation: check the signs of its equations, or narrow the [inputs.*] ranges (or the swept "
        f"[scheduling.*] range) of {params.source}")


def noise_record(input_names, model, params, noise: bool = True, source: str | None = None) -> dict:
    """What the run's measurements carry: ``levels`` {observer input: standard deviation, in the
    model's unit of the signal}, ``units``, ``noise_free`` (the inputs read without noise), ``source``
    (the parameter file as the observer file names it, ``source``: the same project in another folder
    gives the same record) and ``mode``: "declared" (``[sensor_noise]``), "none declared" (the file has
    no level for any input the observer reads), or "off" (``noise=False``, ``--noise-free``)."""
    from . import noise as sensor
    levels = sensor.observer_levels(input_names, model, params)       # checked even when turned off
    if not noise:
        mode, levels = "off", {}
    else:
        mode = "declared" if any(levels.values()) else "none declared"
    units = dict(model.units or {})
    signals = sensor.measured_signals(model)
    return {"mode": mode, "levels": levels, "source": source or params.source,
            "units": {c: units.get(sensor.column_signal(c, signals) or c) for c in levels},
            "noise_free": [c for c in input_names if not levels.get(c)]}


def run(config, duration: float | None = None, seed: int = 0, progress=None, observer=None,
        noise: bool = True) -> dict:
    """The compiled step (``observer``, default the observer's extension) over the excitation
    scenario, its inputs with the declared sensor noise (``noise=False``: without); tables in the
    shape of every validation."""
    from .. import pipeline
    from ..extension.build import load
    from . import noise as sensor
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    truth = simulate(config, duration or DURATION, seed)
    obs = observer if observer is not None else load(config)
    missing = [c for c in obs.input_names if c not in truth]
    if missing:
        raise ModelDefinitionError(f"observer {config.name!r}: its inputs {missing} are not signals of the model")
    record = noise_record(list(obs.input_names), model, params, noise, source=str(config.parameters))
    measured = np.column_stack([truth[c] for c in obs.input_names])
    if record["levels"]:
        measured = sensor.add(measured, list(obs.input_names), record["levels"], seed)
        record["seed"] = int(seed)
    out, status, _ = obs.run(measured)
    b = pipeline.build(config)
    lags = b.output_lags()
    from ..contract.capabilities import NoiseBound
    family = config.observer_family
    if record["mode"] == "declared" and isinstance(family, NoiseBound):
        # the certificate's noise-to-estimate bound, restated at the levels this run adds
        record["certified_bound"] = family.noise_bound(b, sensor.declared(model, params))
    units = dict(model.units)
    table, estimates = {}, {}
    for i, s in enumerate(obs.output_names):
        lag = lags.get(s, 0)
        est = np.concatenate([out[lag:, i], np.full(lag, np.nan)])
        estimates[s] = est
        if s in truth:
            keep = slice(0, len(est) - lag)
            table[s] = signal_stats(truth[s][keep], est[keep], truth["t"][keep], unit=units.get(s))
    # which bits: a SCHEDULING_CLAMPED sample is outside the certified set, a NUMERICAL_FAILURE one
    # reset the state (the estimate is not of the step's dynamics there)
    # (an observer that does not name its bits, a CasADi step run in its place, is counted as flagged only)
    counts = {k: int(np.count_nonzero(status & bit)) for k, bit in getattr(obs, "status_bits", {}).items() if bit}
    return {"observer": table, "baselines": {}, "status_flags": int(np.count_nonzero(status)),
            "status_counts": {k: v for k, v in counts.items() if v},
            "samples": int(len(status)), "max_abs_ay": max_abs_ay(truth),
            "plant": "model", "plant_model": f"{model.name} (its own equations, excitation)",
            "scenario": "excitation", "table_format": "generic", "units": units, "noise": record,
            "signals": {"t": truth["t"], "truth": truth, "estimate": estimates, "status": status,
                        "measured": dict(zip(obs.input_names, measured.T))}}


def max_abs_ay(truth: dict) -> float | None:
    """max |a_y| [m/s^2] of the run: the model's output named ``a_y`` (the lateral acceleration by the
    toolchain's convention), or None when the model has no such output. Never a made-up 0: an output
    of another name (``ay``, ``acc_lat``) is not guessed to be the lateral acceleration."""
    return float(np.abs(truth["a_y"]).max()) if "a_y" in truth else None


def format_table(result: dict) -> str:
    """Every estimated signal in the one definition of every validation
    (:func:`codegen.validation.common.format_stats`), under a line saying the sensor noise of the run."""
    from .common import format_stats
    return "\n".join(filter(None, [noise_line(result.get("noise")), format_stats(result["observer"])]))


def noise_line(record: dict | None) -> str:
    """The run's sensor noise in words: the levels and where they are declared, or why it is noise free."""
    if not record:
        return ""
    from .metrics import reported_unit
    if record["mode"] == "off":
        return "sensor noise: none (--noise-free); the [sensor_noise] levels of the parameter file are not added"
    if record["mode"] == "none declared":
        return (f"sensor noise: none declared ({record['source']} has no [sensor_noise] level for the observer's "
                f"inputs {', '.join(record['noise_free'])}): a noise-free run, the estimates' best case")
    parts = []
    for col, std in record["levels"].items():
        shown, k, _ = reported_unit(record["units"].get(col))
        parts.append(f"{col} {k * std:.3g}" + (f" {shown}" if shown else ""))
    free = f"; noise free: {', '.join(record['noise_free'])}" if record["noise_free"] else ""
    line = (f"sensor noise (std, seeded white, seed {record.get('seed', 0)}, [sensor_noise] of {record['source']}): "
            f"{', '.join(parts)}{free}")
    bound = record.get("certified_bound")
    if bound:
        at = ", ".join(f"{k} {v:.4g}" for k, v in bound["declared"].items()) or "none of its sensor channels"
        line += (f"\ncertified at this noise: {bound['norm']} of {bound['error']} <= {bound['bound']:.4g} {bound['unit']} "
                 f"(declared: {at}; {bound['where']}); at the design's own levels {bound['design_bound']:.4g} "
                 f"{bound['unit']}")
    return line
