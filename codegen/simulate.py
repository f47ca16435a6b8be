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


def simulate_plant(lpv: LPVModel, scenario: Scenario, sample_time: float, substeps: int = 10):
    """RK4 at sample_time/substeps; returns samples at the observer rate."""
    rhs, nx, nu, nd = plant_rhs(lpv)
    n = int(round(scenario.duration / sample_time)) + 1
    h = sample_time / substeps
    t_fine = np.arange(n * substeps) * h
    prof = profiles(scenario, t_fine)
    x = np.zeros(nx)
    xs = np.empty((n, nx))
    for k in range(n):
        xs[k] = x
        if k == n - 1:
            break
        for j in range(substeps):
            i = k * substeps + j
            u, dd, rho = [prof["T_a"][i]], [prof["T_d"][i]], prof["v_x"][i]
            # inputs held over the fine step (ZOH at 1 kHz)
            k1 = rhs(x, u, dd, rho)
            k2 = rhs(x + 0.5 * h * k1, u, dd, rho)
            k3 = rhs(x + 0.5 * h * k2, u, dd, rho)
            k4 = rhs(x + h * k3, u, dd, rho)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    idx = np.arange(n) * substeps
    return {"t": np.arange(n) * sample_time, "x": xs,
            **{k: v[idx] for k, v in prof.items()}}


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
