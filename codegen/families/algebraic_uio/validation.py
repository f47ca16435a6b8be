"""Validation of the Ichalal and Mammar 2015 observers (``algebraic_uio``) on the paper's plants.

Scenarios live in the observer's configuration, ``[validation.NAME]`` tables (the paper fixes the
models and the parameter box, not the test signals, which its figures do not state):

* Examples 1-2: ``rho`` and ``d`` are expressions of ``t``, ``x0`` the plant's initial state. The plant
  is the LPV model itself, integrated by scipy's DOP853 at rtol 1e-12 with the exact continuous
  rho(t) and d(t) (independent of the observer's discretization), sampled at the observer's rate.
* Example 3: ``v_x`` and ``delta`` are expressions of ``t``; the plant is ``PLANT`` of the model module
  (bicycle model (76), magic-formula tyres (79), rear relaxation), a_y and the UI truth xi from
  ``PLANT_SIGNALS``; ``noise`` gives the standard deviation of white noise on measured outputs
  (``{ v_y = 0.01 }``), seeded.

``like = "OTHER"`` copies another scenario's keys. ``period`` (s) marks signals that repeat, so the
last period of a run tiles smoothly (reliability long runs).

Reported (noise free): the differentiators' convergence time t_c (after it, every derivative the
observer uses is within 1e-6 of its truth, relative to the signal's peak), and the largest errors
of every state and UI relative to the signal's peak after t_c and after t_c + T_obs, where
T_obs = ln(1e6 sqrt(cond X)) / alpha is the time the LMI certificate needs to shrink any error by 1e6.
With noise: RMS errors in % of each signal's RMS after ``eval_after``. These windows are the
family's own table (``paper_format``); the rows of every validation
(:func:`codegen.validation.metrics.signal_report`, after the common settle time) come first.
"""
from __future__ import annotations

import math
import tomllib

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from ...errors import ModelDefinitionError
from ...validation.common import signal_stats
from . import representation as rdeg

TOL_REL = 1e-6


def scenarios(config) -> dict:
    with open(config.source, "rb") as fh:
        raw = tomllib.load(fh).get("validation", {})
    out = {}
    for name, tbl in raw.items():
        merged = dict(tbl)
        while "like" in merged:
            base = raw.get(merged.pop("like"))
            if base is None:
                raise ModelDefinitionError(f"{config.source}: [validation.{name}] is like an unknown scenario")
            merged = {**base, **merged}
        out[name] = merged
    return out


def scenario(config, name: str) -> dict:
    scn = scenarios(config)
    if name not in scn:
        raise ModelDefinitionError(f"observer {config.name!r} has no scenario {name!r}; its scenarios: "
                                   f"{', '.join(sorted(scn)) or 'none'} ([validation.NAME] in {config.source})")
    return scn[name]


_t = sp.Symbol("t", real=True)


def _signal(expr: str, orders: int = 0):
    """Callables t -> f^(m)(t), m = 0..orders, of an expression of t."""
    e = sp.sympify(expr, locals={"t": _t})
    stray = e.free_symbols - {_t}
    if stray:
        raise ModelDefinitionError(f"scenario signal {expr!r} uses {sorted(map(str, stray))}; only t is allowed")
    return [sp.lambdify(_t, sp.diff(e, _t, m), "numpy") for m in range(orders + 1)]


def _vals(fn, t):
    return np.broadcast_to(np.asarray(fn(t), dtype=float), np.shape(t)).copy()


def simulate(b, scn: dict, duration: float | None = None, seed: int = 0) -> dict:
    """Truth and measurements sampled at the observer's rate: {"t", states, UIs, scheduling, inputs,
    "measured": {output: noisy samples}, "derivatives": {symbol: truth}, "Y": y^(r) truth (LPV plants)}."""
    h = b.config.sample_time
    T = float(duration if duration is not None else scn.get("duration", 20.0))
    t = np.arange(int(round(T / h)) + 1) * h
    module = b.config.load_model_module()
    d = b.lpv.definition
    out = {"t": t}
    sched = {}
    for sym in b.base:
        if str(sym) not in scn:
            raise ModelDefinitionError(f"scenario lacks the scheduling signal {sym}")
        fns = _signal(scn[str(sym)], max(b.dec.derivative_orders[sym], 0) + 1)
        sched[sym] = fns
        out[str(sym)] = _vals(fns[0], t)
        for m in range(1, len(fns)):
            out[str(rdeg.derivative_symbol(sym, m))] = _vals(fns[m], t)
    plant = getattr(module, "PLANT", None)
    if plant is None:
        # the LPV model itself with exact continuous signals
        ui = [_signal(scn[str(s)])[0] for s in d.unknown_inputs]
        A = sp.lambdify(b.base, b.lpv.A, "numpy")
        D = sp.lambdify(b.base, b.lpv.D, "numpy")

        def rhs(tt, x):
            rv = [sched[s][0](tt) for s in b.base]
            dv = np.array([float(f(tt)) for f in ui])
            return np.asarray(A(*rv), float) @ x + np.asarray(D(*rv), float) @ dv
        x0 = np.asarray(scn.get("x0", np.zeros(b.lpv.nx)), float)
        sol = solve_ivp(rhs, (0.0, T), x0, method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
        X = sol.sol(t).T
        for k, s in enumerate(d.states):
            out[str(s)] = X[:, k]
        for s, f in zip(d.unknown_inputs, ui):
            out[str(s)] = _vals(f, t)
        # y^(r) truth from the derived M and Gamma (exact parameter derivatives)
        env = {sym: out[str(sym)] for sym in b.dec.symbols}
        Mcal = sp.lambdify(b.dec.symbols, b.dec.Mcal.evalf(20), "numpy")
        G = sp.lambdify(b.dec.symbols, b.dec.Gamma.evalf(20), "numpy")
        dd = np.column_stack([out[str(s)] for s in d.unknown_inputs])
        Y = []
        for k in range(t.size):
            args = [env[s][k] for s in b.dec.symbols]
            Y.append(np.asarray(Mcal(*args), float) @ X[k] + np.asarray(G(*args), float) @ dd[k])
        out["Y"] = np.array(Y)
        out["plant_model"] = f"{d.name} (the LPV model, DOP853 rtol 1e-12)"
    else:
        values = {**b.lpv.parameters.values, **b.lpv.parameters.plant}
        missing = [str(p) for p in plant.parameters if str(p) not in values]
        if missing:
            raise ModelDefinitionError(f"plant {plant.name!r} needs {', '.join(missing)} in the [plant] table")
        subs = {p: values[str(p)] for p in plant.parameters}
        inputs = [_signal(scn[str(s)])[0] for s in plant.known_inputs]
        args = [*plant.states, *plant.known_inputs, *(g.symbol for g in plant.scheduling)]
        f = sp.lambdify(args, sp.Matrix(plant.dynamics).subs(subs), "numpy")
        sched_fns = [_signal(scn[str(g.symbol)])[0] for g in plant.scheduling]

        def rhs(tt, x):
            return np.asarray(f(*x, *[g(tt) for g in inputs], *[g(tt) for g in sched_fns]), float).ravel()
        x0 = np.asarray(scn.get("x0", np.zeros(len(plant.states))), float)
        sol = solve_ivp(rhs, (0.0, T), x0, method="DOP853", rtol=1e-11, atol=1e-10, max_step=10 * h,
                        dense_output=True)
        X = sol.sol(t).T
        for k, s in enumerate(plant.states):
            out[str(s)] = X[:, k]
        for s, g in zip(plant.known_inputs, inputs):
            out[str(s)] = _vals(g, t)
        extra = getattr(module, "PLANT_SIGNALS", {})
        for key, expr in extra.items():
            fn = sp.lambdify(args, sp.sympify(expr).subs(subs), "numpy")
            out[key] = np.asarray(fn(*[out[str(a)] for a in args]), float)
        out["plant_model"] = f"{plant.name} (DOP853 rtol 1e-11)"
    for s in (*d.known_inputs, *d.unknown_inputs, *d.states):
        if str(s) not in out:
            raise ModelDefinitionError(f"the plant does not provide {s}")
    rng = np.random.default_rng(seed)
    noise = dict(scn.get("noise", {}))
    out["measured"] = {n: out[n] + (rng.standard_normal(t.size) * float(noise[n]) if n in noise else 0.0)
                       for n in d.output_names}
    return out


def input_matrix(b, truth: dict) -> np.ndarray:
    cols = []
    for name in b.input_names:
        key = name[2:] if name.startswith("y_") else name
        cols.append(truth["measured"][key] if name.startswith("y_") else truth[key])
    return np.column_stack(cols)


def periodic_inputs(b, scenario_name: str = "paper", periods: int = 3) -> np.ndarray:
    """Input rows of the last full period of a run ``periods`` periods long (plant transients gone):
    tiled, they form a smooth periodic input (reliability long runs)."""
    scn = scenario(b.config, scenario_name)
    if "period" not in scn:
        raise ModelDefinitionError(f"scenario {scenario_name!r} of {b.name} has no period")
    T = float(scn["period"])
    truth = simulate(b, scn, duration=periods * T)
    rows = input_matrix(b, truth)
    n = int(round(T / b.config.sample_time))
    return rows[-n - 1:-1]


def _history(obs, inputs: np.ndarray):
    """Step by step through the compiled C: outputs, status and the whole state history."""
    state = obs.initial_state()
    out = np.empty(obs.n_output)
    states = np.empty((inputs.shape[0], obs.n_state))
    outs = np.empty((inputs.shape[0], obs.n_output))
    status = np.empty(inputs.shape[0], dtype=np.int32)
    step = obs.step
    for k in range(inputs.shape[0]):
        status[k] = step(state, inputs[k], out)
        states[k] = state
        outs[k] = out
    return outs, status, states


def _rel_max(err, ref):
    return float(np.max(np.abs(err)) / max(float(np.max(np.abs(ref))), 1e-300)) if err.size else float("nan")


def run(config, scenario_name: str, plant: str = "nominal", duration: float | None = None, seed: int = 0,
        progress=None, observer=None) -> dict:
    """Simulate the scenario, run the compiled C step over it, and tabulate the errors."""
    from ...extension.build import load
    from ... import pipeline
    if plant not in ("nominal", "model"):
        raise ModelDefinitionError(f"the Ichalal and Mammar 2015 observers run on their own plants: --plant nominal (or model), "
                                   f"not {plant!r}")
    b = pipeline.build(config)
    scn = scenario(config, scenario_name)
    truth = simulate(b, scn, duration, seed)
    if progress is not None:
        progress(0.5)
    obs = observer if observer is not None else load(config)
    inputs = input_matrix(b, truth)
    out, status, states = _history(obs, inputs)
    if progress is not None:
        progress(1.0)
    t = truth["t"]
    d = b.lpv.definition
    est = {n: out[:, obs.output_index(n)] for n in b.output_names}
    result = {"family": "algebraic_uio", "observer": {}, "baselines": {}, "plant": plant,
              "plant_model": truth["plant_model"], "scenario": scenario_name,
              "status_flags": int(np.count_nonzero(status[1:])), "samples": int(t.size),
              "max_abs_ay": float(np.abs(truth["a_y"]).max()) if "a_y" in truth else None,
              "noise": dict(scn.get("noise", {})), "units": dict(d.units),
              "relative_degrees": list(b.dec.relative_degrees), "alpha": b.settings.alpha,
              "signals": {"t": t, "truth": {n: truth[n] for n in b.output_names}, "estimate": est, "status": status}}
    # differentiator convergence (noise free runs): derivative estimates at t_j from the state history
    conv = {}
    for k_in, name in enumerate(b.input_names):
        if not (name.startswith("y_") or name in map(str, b.base)) or result["noise"]:
            continue
        spec = b.spec(name)
        zs = states[:, b.slices[f"hosmd_{name}"]].copy()
        zs[:, 0] += states[:, b.slices[f"held_{name}"]][:, 0]       # error coordinates: the value is held + d0
        # the state after sample j is the Taylor polynomial at t_{j+1}: shift back one sample
        back = np.array([[(-spec.sample_time) ** (l - m) / math.factorial(l - m) if l >= m else 0.0
                          for l in range(spec.order + 1)] for m in range(spec.order + 1)])
        w = zs @ back.T
        if name.startswith("y_"):
            i = d.output_names.index(name[2:])
            checks = {f"{name}^({b.dec.relative_degrees[i]})": (w[:, b.dec.relative_degrees[i]], truth["Y"][:, i]),
                      name: (w[:, 0], truth[name[2:]])} if "Y" in truth else {}
        else:
            sym = next(s for s in b.base if str(s) == name)
            checks = {str(rdeg.derivative_symbol(sym, m)): (w[:, m], truth[str(rdeg.derivative_symbol(sym, m))])
                      for m in range(b.dec.derivative_orders[sym] + 1)}
        for label, (e, ref) in checks.items():
            rel = np.abs(e - ref) / max(float(np.abs(ref).max()), 1e-300)
            bad = np.nonzero(rel[:-1] > TOL_REL)[0]
            conv[label] = float(t[bad[-1] + 1]) if bad.size else 0.0
    eval_after = float(scn.get("eval_after", 0.0))
    if conv:
        t_c = max(conv.values())
        cond = float(np.linalg.cond(b.design.X))
        t_obs = math.log(1e6 * math.sqrt(cond)) / b.settings.alpha
        result["differentiator_convergence"] = {"t_c": t_c, "per_signal": conv, "T_obs": t_obs}
        windows = {"after_t_c": t >= t_c, "after_t_c_plus_T_obs": t >= t_c + t_obs}
    else:
        windows = {f"after_{eval_after:g}s": t >= eval_after}
    rows = {}
    for n in b.output_names:
        result["observer"][n] = signal_stats(truth[n], est[n], t, unit=d.units.get(n))
        row = {}
        for label, m in windows.items():
            m = m & (np.arange(t.size) > 0)
            err = est[n][m] - truth[n][m]
            row[f"max_rel_{label}"] = _rel_max(err, truth[n])
            row[f"rms_percent_{label}"] = float(100 * np.sqrt(np.mean(err ** 2)) / max(np.sqrt(np.mean(truth[n][m] ** 2)), 1e-300))
        rows[n] = row
    result["paper_format"] = {"table": PAPER_TABLE, "rows": rows}
    return result


PAPER_TABLE = ("Ichalal and Mammar 2015 terms: the largest error relative to the signal's peak (max_rel) and the RMS "
               "error in % of the signal's RMS (rms_percent, as the one definition's), per window: after the "
               "differentiators' convergence t_c, after t_c + T_obs (noise free), or after eval_after (with noise)")


def format_table(result: dict) -> str:
    lines = []
    dc = result.get("differentiator_convergence")
    if dc:
        lines.append(f"differentiators converged (all used derivatives within 1e-6 of truth) at t_c = {dc['t_c']:.3f} s; "
                     f"certified observer settling T_obs = {dc['T_obs']:.2f} s")
    rows = result["paper_format"]["rows"]
    keys = list(next(iter(rows.values())).keys())
    head = f"{'signal':10s}" + "".join(f" {k:>30s}" for k in keys)
    lines.append(head)
    for sig, row in rows.items():
        lines.append(f"{sig:10s}" + "".join(f" {row[k]:30.3e}" for k in keys))
    if result["noise"]:
        ay = f"; max |a_y| {result['max_abs_ay']:.2f} m/s^2" if result.get("max_abs_ay") is not None else ""
        lines.append(f"(white output noise, std {result['noise']}{ay})")
    from ...validation.common import format_stats
    lines.append(format_stats(result["observer"]))
    return "\n".join(lines)

