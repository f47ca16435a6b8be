"""The nominal plant: an observer's own symbolic model, integrated exactly, in closed loop.

The plant integrates the model's *exact* nonlinear-in-speed equations (the symbolic
definition with its parameters, true 1/v_x and 1/v_x**2, no polytope, no Taylor
reduction) with RK4 at a tenth of the observer's sample time, steered by the scenario's
driver model (:mod:`codegen.validation.scenarios`). The independent plant is
:mod:`codegen.validation.commonroad_plant`; :mod:`codegen.validate` runs either.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from .errors import ModelDefinitionError, SampleError
from .model import LPVModel


def plant_rhs(lpv: LPVModel, definition=None):
    """Numeric x_dot = f(x, u, d, rho) from a symbolic definition (exact, not the polytope).

    ``definition`` defaults to the observer's own model; a truth-plant definition (same
    states and inputs, e.g. Pacejka tyres) takes its extra values from the ``[plant]`` table.
    """
    d = definition or lpv.definition
    values = {**lpv.parameters.values, **lpv.parameters.plant}
    missing = [str(p) for p in d.parameters if str(p) not in values]
    if missing:
        raise ModelDefinitionError(f"plant {d.name!r} needs {', '.join(missing)} in the [plant] table of "
                                   f"{lpv.parameters.source}")
    subs = {p: values[str(p)] for p in d.parameters}
    f = sp.Matrix(d.dynamics).subs(subs)
    args = [*d.states, *d.known_inputs, *d.unknown_inputs, *(s.symbol for s in d.scheduling)]
    fn = sp.lambdify(args, f, "numpy")
    nx, nu, nd = len(d.states), len(d.known_inputs), len(d.unknown_inputs)

    def rhs(x, u, dd, rho):
        return np.asarray(fn(*x, *u, *dd, *np.atleast_1d(rho)), dtype=float).reshape(nx)
    return rhs, nx, nu, nd


def nominal_plant(config, lpv: LPVModel, scn, definition=None, progress=None) -> dict:
    """The observer's own symbolic model, integrated exactly (RK4 at Ts/10: true 1/v_x terms, no
    polytope, no Taylor reduction) with planar pose kinematics, closed with the scenario's driver.

    Returns the truth per sample: t, v_x, beta, r, delta, delta_dot, T_d, T_a and
    a_y = v_x (beta_dot + r) (for the baselines' measurement)."""
    d = lpv.definition
    names = d.state_names
    if not {"beta", "r", "delta", "delta_dot"} <= set(names):
        raise ModelDefinitionError(f"the nominal closed-loop plant needs states beta, r, delta, delta_dot; "
                                   f"model {d.name!r} has {names}")
    rhs, nx, _, _ = plant_rhs(lpv, definition)
    # scheduling signals a plant may use, by name: the speed and its derivative (load transfer)
    known = ("v_x", "a_x")
    sched = [str(g.symbol) for g in (definition or lpv.definition).scheduling]
    unknown = [n for n in sched if n not in known]
    if unknown:
        raise ModelDefinitionError(f"the nominal plant provides scheduling signals {known}, not {unknown}")
    ib, ir, idl, idd = (names.index(k) for k in ("beta", "r", "delta", "delta_dot"))
    n, sub = scn.t.size, 10
    h = config.sample_time / sub
    driver = scn.make_driver()
    x = np.zeros(nx + 3)             # model states + (X, Y, psi)
    v0, k0 = float(scn.v_ref[0]), (0.0 if scn.kappa_ref is None else float(scn.kappa_ref[0]))
    x[ir] = v0 * k0                  # start in steady cornering on a curved path, as the CommonRoad plant

    def f(z, t_d, t_a, vx, ax):
        dz = np.empty_like(z)
        values = {"v_x": vx, "a_x": ax}
        dz[:nx] = rhs(z[:nx], [t_a], [t_d], [values[n] for n in sched])
        vy = np.tan(z[ib]) * vx
        dz[nx] = vx * np.cos(z[nx + 2]) - vy * np.sin(z[nx + 2])
        dz[nx + 1] = vx * np.sin(z[nx + 2]) + vy * np.cos(z[nx + 2])
        dz[nx + 2] = z[ir]
        return dz

    out = {k: np.empty(n) for k in ("beta", "r", "delta", "delta_dot", "T_d", "T_a", "v_x", "a_y")}
    for k in range(n):
        if progress is not None and (k % max(n // 50, 1) == 0 or k == n - 1):
            progress((k + 1) / n)
        vx, ax = float(scn.v_ref[k]), float(scn.a_ref[k])
        meas = {"X": x[nx], "Y": x[nx + 1], "psi": x[nx + 2], "v_x": vx, "v_y": np.tan(x[ib]) * vx,
                "r": x[ir], "delta": x[idl], "delta_dot": x[idd]}
        t_d, t_a = float(driver(k, meas)), float(scn.T_a[k])
        dz = f(x, t_d, t_a, vx, ax)
        for key, idx in (("beta", ib), ("r", ir), ("delta", idl), ("delta_dot", idd)):
            out[key][k] = x[idx]
        out["T_d"][k], out["T_a"][k], out["v_x"][k] = t_d, t_a, vx
        out["a_y"][k] = vx * (dz[ib] + x[ir])
        if k == n - 1:
            break
        for _ in range(sub):
            k1 = f(x, t_d, t_a, vx, ax)
            k2 = f(x + 0.5 * h * k1, t_d, t_a, vx, ax)
            k3 = f(x + 0.5 * h * k2, t_d, t_a, vx, ax)
            k4 = f(x + h * k3, t_d, t_a, vx, ax)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)):
            raise SampleError(f"nominal plant diverged at t = {scn.t[k]:.2f} s in scenario {scn.name!r}")
    out["t"] = np.asarray(scn.t, float)
    return out


def add_sensor_noise(truth: dict, noise: dict, seed: int = 0) -> dict:
    """Measured signals: truth plus seeded white noise of the given standard deviation."""
    rng = np.random.default_rng(seed)
    return {k: truth[k] + rng.standard_normal(truth[k].shape) * s for k, s in noise.items()}


def observer_input_matrix(input_names, truth: dict, measured: dict) -> np.ndarray:
    """Rows of an observer's inputs (names ``y_X`` are measurements of X), measured where available."""
    columns = []
    for col in input_names:
        key = col[2:] if col.startswith("y_") else col
        source = measured if key in measured else truth
        if key not in source:
            raise SampleError(f"the plant does not provide the observer input {col!r}")
        columns.append(source[key])
    return np.column_stack(columns)
