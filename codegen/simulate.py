"""Closed-loop simulation of an observer against a plant it was not reduced from.

The plant integrates the model's *exact* nonlinear-in-speed equations (the
symbolic definition with its parameters, true 1/v_x and 1/v_x**2, no polytope, no
Taylor reduction) with RK4 at 1 kHz; the observer sees samples at its own rate.
Scenarios are named, seeded and reproducible.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from .model import LPVModel


@dataclass(frozen=True)
class Scenario:
    name: str
    duration: float
    seed: int
    doc: str


SCENARIOS = {
    "track_varying_speed": Scenario(
        "track_varying_speed", 60.0, 1,
        "manual driving, T_a = 0, speed 10-30 m/s with |a_x| <= 2.1 m/s^2 (seed 000 scenario 1 style)"),
    "takeover_opposing_assist": Scenario(
        "takeover_opposing_assist", 30.0, 2,
        "constant 14 m/s, lane-keeping assistance torque opposing the driver (seed 000 scenario 2 style)"),
}


def _smooth_random(t: np.ndarray, rng, amplitude: float, f_lo: float, f_hi: float, n: int = 12):
    """Sum of sinusoids with random frequencies in [f_lo, f_hi] Hz and phases (band-limited torque)."""
    freqs = rng.uniform(f_lo, f_hi, n)
    phases = rng.uniform(0, 2 * np.pi, n)
    weights = rng.uniform(0.5, 1.0, n) / np.sqrt(n)
    sig = sum(w * np.sin(2 * np.pi * f * t + p) for w, f, p in zip(weights, freqs, phases))
    return amplitude * sig / max(np.abs(sig).max(), 1e-12)


def profiles(scenario: Scenario, t: np.ndarray) -> dict:
    """Speed v_x(t), driver torque T_d(t), assistance T_a(t) on the time grid ``t``."""
    rng = np.random.default_rng(scenario.seed)
    if scenario.name == "track_varying_speed":
        vx = 20.0 + 10.0 * np.sin(2 * np.pi * t / 30.0 - np.pi / 2)
        td = _smooth_random(t, rng, 3.0, 0.05, 1.5)
        # a few sharp driver interventions with 0.15 s ramps
        for t0, amp in ((12.0, 2.0), (31.0, -2.5), (47.0, 1.5)):
            td = td + amp * np.clip((t - t0) / 0.15, 0, 1) * np.clip((t0 + 2.0 - t) / 0.15, 0, 1)
        ta = np.zeros_like(t)
    elif scenario.name == "takeover_opposing_assist":
        vx = np.full_like(t, 14.0)
        td = _smooth_random(t, rng, 2.0, 0.05, 1.0)
        td = td + 4.0 * np.clip((t - 10.0) / 0.3, 0, 1) * np.clip((20.0 - t) / 0.3, 0, 1)
        ta = -0.6 * td + _smooth_random(t, rng, 0.5, 0.1, 0.8)
    else:
        raise KeyError(scenario.name)
    return {"v_x": vx, "T_d": td, "T_a": ta}


def plant_rhs(lpv: LPVModel):
    """Numeric x_dot = f(x, u, d, rho) from the symbolic definition (exact, not the polytope)."""
    d = lpv.definition
    subs = {p: lpv.parameters.values[str(p)] for p in d.parameters}
    f = sp.Matrix(d.dynamics).subs(subs)
    args = [*d.states, *d.known_inputs, *d.unknown_inputs, *(s.symbol for s in d.scheduling)]
    fn = sp.lambdify(args, f, "numpy")
    nx, nu, nd = len(d.states), len(d.known_inputs), len(d.unknown_inputs)

    def rhs(x, u, dd, rho):
        return np.asarray(fn(*x, *u, *dd, *np.atleast_1d(rho)), dtype=float).reshape(nx)
    return rhs, nx, nu, nd


def _integrate(lpv: LPVModel, n: int, substeps: int, h: float, inputs_at):
    """RK4 over n samples of substeps fine steps; inputs_at(i) -> (u, d, rho) held over fine step i."""
    rhs, nx, _, _ = plant_rhs(lpv)
    x = np.zeros(nx)
    xs = np.empty((n, nx))
    xdot = np.empty((n, nx))
    for k in range(n):
        xs[k] = x
        xdot[k] = rhs(x, *inputs_at(k * substeps))
        if k == n - 1:
            break
        for j in range(substeps):
            u, dd, rho = inputs_at(k * substeps + j)
            k1 = rhs(x, u, dd, rho)
            k2 = rhs(x + 0.5 * h * k1, u, dd, rho)
            k3 = rhs(x + 0.5 * h * k2, u, dd, rho)
            k4 = rhs(x + h * k3, u, dd, rho)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return xs, xdot


def _lateral_acceleration(lpv: LPVModel, xs, xdot, vx):
    """a_y = v_x (beta_dot + r) when the model has states beta and r (for the baselines)."""
    names = lpv.definition.state_names
    if "beta" in names and "r" in names:
        return vx * (xdot[:, names.index("beta")] + xs[:, names.index("r")])
    return None


def simulate_plant(lpv: LPVModel, scenario: Scenario, sample_time: float, substeps: int = 10):
    """RK4 at sample_time/substeps on a built-in scenario; returns samples at the observer rate."""
    n = int(round(scenario.duration / sample_time)) + 1
    h = sample_time / substeps
    t_fine = np.arange(n * substeps) * h
    prof = profiles(scenario, t_fine)
    # inputs held over the fine step (ZOH at 1 kHz)
    xs, xdot = _integrate(lpv, n, substeps, h,
                          lambda i: ([prof["T_a"][i]], [prof["T_d"][i]], prof["v_x"][i]))
    idx = np.arange(n) * substeps
    out = {"t": np.arange(n) * sample_time, "x": xs, **{k: v[idx] for k, v in prof.items()}}
    out["a_y"] = _lateral_acceleration(lpv, xs, xdot, out["v_x"])
    return out


def simulate_trajectory(lpv: LPVModel, t: np.ndarray, samples: dict, sample_time: float, substeps: int = 10):
    """RK4 of the exact model under input profiles given at the observer rate (held per sample).

    ``samples`` maps ``v_x``, ``T_d``, ``T_a`` (or the model's own signal names) to arrays on ``t``.
    """
    n = len(t)
    h = sample_time / substeps
    d = lpv.definition
    u = np.column_stack([samples[str(s)] for s in d.known_inputs])
    dd = np.column_stack([samples[str(s)] for s in d.unknown_inputs])
    rho = np.asarray(samples[str(d.scheduling[0].symbol)], float)
    xs, xdot = _integrate(lpv, n, substeps, h, lambda i: (u[i // substeps], dd[i // substeps], rho[i // substeps]))
    out = {"t": np.asarray(t, float), "x": xs, **{k: np.asarray(v, float) for k, v in samples.items()}}
    out["a_y"] = _lateral_acceleration(lpv, xs, xdot, rho)
    return out


def observer_inputs(lpv: LPVModel, sim: dict, noise: dict | None = None, seed: int = 0) -> np.ndarray:
    """Rows [u, y, rho] at every sample, y = C x (+ white noise of the given std per output)."""
    C = np.array(lpv.C, dtype=float)
    y = sim["x"] @ C.T
    if noise:
        rng = np.random.default_rng(seed)
        names = lpv.definition.output_names
        y = y + rng.standard_normal(y.shape) * np.array([noise.get(n, 0.0) for n in names])
    return np.column_stack([sim["T_a"], y, sim["v_x"]])


def error_table(truth: dict, estimate: dict, settle_time: float, t: np.ndarray, degrees: tuple = ()) -> dict:
    """Seed 000 Tables II-IV: mean |e|, max |e|, std(e), RMS(e) after ``settle_time``."""
    mask = t >= settle_time
    out = {}
    for name, true in truth.items():
        e = (estimate[name] - true)[mask]
        scale = 180 / np.pi if name in degrees else 1.0
        e = e * scale
        out[name] = {"mean_abs": float(np.mean(np.abs(e))), "max": float(np.max(np.abs(e))),
                     "std": float(np.std(e)), "rms": float(np.sqrt(np.mean(e ** 2)))}
    return out
