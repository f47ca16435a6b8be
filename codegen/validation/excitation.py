"""``uiogen validate NAME --scenario excitation``: a validation scenario for any model.

No driver, no track, nothing of a particular paper: the model's own nonlinear equations (the
symbolic ``MODEL``, before any polytope or TS reduction) are integrated (RK4 at Ts/10, the
inputs evaluated continuously between the samples, as a real car's are) with

* every input scheduling signal swept inside its box: a sine of 0.9 of the half-range about the
  box's centre whose slope stays within the box's rate bounds (at its centre when it has none);
* every known and unknown input a seeded, smooth random signal (a sum of sinusoids below its
  ``bandwidth``, 1 Hz by default) filling the range ``[inputs.NAME] min, max`` of the parameter
  file;
* the state starting at the centre of its ``[state_bounds]`` box (or at 0).

The compiled step runs over the sampled outputs (noise-free), and its estimates are compared
with the simulated states and unknown inputs after the settle time; the result has the shape of
every validation (``observer.SIGNAL.rms``, ``nmse_percent``).
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError
from ..model import load_parameters, parameter_substitution
from .simulate import rk4_step
from .common import SETTLE_TIME, signal_stats

DURATION = 30.0


def _smooth(t: np.ndarray, rng, lo: float, hi: float, bandwidth: float):
    """A seeded sum of sinusoids in [0.05, bandwidth] Hz, scaled to fill [lo, hi] (90 % of it on
    the sample times ``t``); returned as a function of time."""
    f = np.exp(rng.uniform(np.log(0.05), np.log(bandwidth), 12))
    ph = rng.uniform(0.0, 2 * np.pi, 12)
    raw = lambda tt: (np.sin(2 * np.pi * f[:, None] * np.atleast_1d(tt)[None, :] + ph[:, None]) / f[:, None]).sum(axis=0)
    x = raw(t)
    x_min, width = x.min(), max(x.max() - x.min(), 1e-300)
    return lambda tt: lo + (0.05 + 0.9 * (raw(tt) - x_min) / width) * (hi - lo)


def _sweep(box):
    mid, half = 0.5 * (box.lower + box.upper), 0.45 * (box.upper - box.lower)
    rate = min(abs(box.rate_lower), abs(box.rate_upper))
    if rate <= 0:
        return lambda tt: np.full(np.shape(np.atleast_1d(tt)), mid)
    omega = 0.9 * rate / half                  # |d/dt half sin(omega t)| <= 0.9 rate
    return lambda tt: mid - half * np.cos(omega * np.atleast_1d(tt))


def signal_functions(config, duration: float = DURATION, seed: int = 0) -> tuple:
    """(sample times, {name: function of time}) of the scenario's raw scheduling signals and inputs."""
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    t = np.arange(0.0, duration + 0.5 * config.sample_time, config.sample_time)
    rng = np.random.default_rng(seed)
    out = {}
    for sig in model.scheduling:
        if sig.derived is None:
            box = params.scheduling.get(str(sig.symbol))
            if box is None:
                raise ModelDefinitionError(f"{params.source}: the excitation scenario sweeps {sig.symbol} inside "
                                           f"[scheduling.{sig.symbol}], which is missing")
            out[str(sig.symbol)] = _sweep(box)
    for u in (*model.known_inputs, *model.unknown_inputs):
        spec = params.inputs.get(str(u))
        if spec is None:
            raise ModelDefinitionError(
                f"{params.source}: the excitation scenario needs the range of input {u}: add a table "
                f"[inputs.{u}] with min = ..., max = ... (and optionally bandwidth = ... Hz)")
        out[str(u)] = _smooth(t, rng, spec["min"], spec["max"], spec.get("bandwidth", 1.0))
    return t, out


def signals(config, duration: float = DURATION, seed: int = 0) -> dict:
    """The scenario's inputs at the observer's sample times: {name: array}, with ``t``."""
    t, funcs = signal_functions(config, duration, seed)
    return {"t": t, **{name: f(t) for name, f in funcs.items()}}


def simulate(config, duration: float = DURATION, seed: int = 0, substeps: int = 10) -> dict:
    """Truth of the excitation scenario on the model's own equations: states, inputs, outputs
    (as ``y_NAME`` and NAME), scheduling signals, at the observer's sample times."""
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    subs = parameter_substitution(model, params)
    t_s, funcs = signal_functions(config, duration, seed)
    sig = {"t": t_s, **{name: f(t_s) for name, f in funcs.items()}}
    x_s, u_s, d_s = tuple(model.states), tuple(model.known_inputs), tuple(model.unknown_inputs)
    sched = tuple(s.symbol for s in model.scheduling)
    derived = {s.symbol: s.derived for s in model.scheduling if s.derived is not None}
    outputs = {sp.Symbol(f"y_{n}"): expr for n, expr in model.outputs}
    f = sp.Matrix(model.dynamics)
    if model.derived_inputs:      # functions of the measurements, here of the model's own outputs
        f = f.subs({w.symbol: sp.sympify(w.expr).subs(outputs) for w in model.derived_inputs})
    f = f.subs({s: sp.sympify(e).subs(outputs) for s, e in derived.items()}).subs(subs)
    raw = tuple(s for s in sched if s not in derived)
    args = (*x_s, *u_s, *d_s, *raw)
    fn = sp.lambdify(args, f, "numpy")
    h = sp.lambdify(args, sp.Matrix([sp.sympify(e).subs(subs) for _, e in model.outputs]), "numpy")
    n = len(sig["t"])
    x = np.array([0.5 * sum(params.state_bounds[str(s)]) if str(s) in params.state_bounds else 0.0 for s in x_s])
    X, Y = np.zeros((n, len(x_s))), np.zeros((n, len(model.outputs)))
    ext = np.column_stack([sig[str(s)] for s in (*u_s, *d_s, *raw)]) if (u_s or d_s or raw) else np.zeros((n, 0))
    ext_funcs = [funcs[str(s)] for s in (*u_s, *d_s, *raw)]
    Ts = config.sample_time
    h_sub = Ts / substeps
    rhs = lambda z, e: np.asarray(fn(*z, *e), dtype=float).ravel()
    # the inputs between two samples at the RK4 stages' times (t, t + h/2, t + h of each substep)
    stage_t = lambda k: t_s[k] + 0.5 * h_sub * np.arange(2 * substeps + 1)
    for k in range(n):
        X[k] = x
        Y[k] = np.asarray(h(*x, *ext[k]), dtype=float).ravel()
        if k + 1 < n:
            tt = stage_t(k)
            E = np.column_stack([f(tt) for f in ext_funcs]) if ext_funcs else np.zeros((tt.size, 0))
            for j in range(substeps):
                x = rk4_step(rhs, x, h_sub, (E[2 * j], E[2 * j + 1], E[2 * j + 2]))
            if not np.all(np.isfinite(x)):
                raise ModelDefinitionError(f"model {model.name!r}: the excitation run left the finite numbers at "
                                           f"t = {sig['t'][k + 1]:.3g} s; narrow the [inputs.*] ranges")
    truth = dict(sig)
    truth.update({str(s): X[:, i] for i, s in enumerate(x_s)})
    for j, (name, _) in enumerate(model.outputs):
        truth[f"y_{name}"] = Y[:, j]
        truth.setdefault(name, Y[:, j])
    return truth


def run(config, duration: float | None = None, seed: int = 0, progress=None, observer=None) -> dict:
    """The compiled step (``observer``, default the observer's extension) over the excitation
    scenario; tables in the shape of every validation."""
    from .. import pipeline
    from ..extension.build import load
    model = config.load_model()
    truth = simulate(config, duration or DURATION, seed)
    obs = observer if observer is not None else load(config)
    missing = [c for c in obs.input_names if c not in truth]
    if missing:
        raise ModelDefinitionError(f"observer {config.name!r}: its inputs {missing} are not signals of the model")
    out, status, _ = obs.run(np.column_stack([truth[c] for c in obs.input_names]))
    lags = pipeline.build(config).output_lags()
    units = dict(model.units)
    table, estimates = {}, {}
    for i, s in enumerate(obs.output_names):
        lag = lags.get(s, 0)
        est = np.concatenate([out[lag:, i], np.full(lag, np.nan)])
        estimates[s] = est
        if s in truth:
            keep = slice(0, len(est) - lag)
            table[s] = signal_stats(truth[s][keep], est[keep], truth["t"][keep],
                                    angle=units.get(s, "").startswith("rad"))
    return {"observer": table, "baselines": {}, "status_flags": int(np.count_nonzero(status)),
            "samples": int(len(status)), "max_abs_ay": float(np.abs(truth.get("a_y", np.zeros(1))).max()),
            "plant": "model", "plant_model": f"{model.name} (its own equations, excitation)",
            "scenario": "excitation", "table_format": "generic", "units": units,
            "signals": {"t": truth["t"], "truth": truth, "estimate": estimates}}


def format_table(result: dict) -> str:
    """Every estimated signal: RMS, max and mean absolute error, NMSE % (eq. (32) of Sentouh et al.)."""
    lines = [f"{'signal':16s} {'RMS':>11s} {'max':>11s} {'MAE':>11s} {'NMSE %':>8s}   (after {SETTLE_TIME:g} s; "
             f"angles in degrees)"]
    for sig, r in result["observer"].items():
        nmse = "–" if r["nmse_percent"] is None else f"{r['nmse_percent']:.2f}"
        lines.append(f"{sig:16s} {r['rms']:11.4g} {r['max']:11.4g} {r['mae']:11.4g} {nmse:>8s}")
    return "\n".join(lines)
