"""The nominal plant: an observer's own symbolic model, integrated exactly, in closed loop.

The plant integrates the model's *exact* nonlinear-in-speed equations (the symbolic
definition with its parameters, true 1/v_x and 1/v_x**2, no polytope, no Taylor
reduction) with RK4 at a tenth of the observer's sample time, steered by the scenario's
driver model (:mod:`codegen.validation.scenarios`). The independent plant is
:mod:`codegen.validation.commonroad_plant`; :mod:`codegen.validation.run` runs either.
"""
from __future__ import annotations

import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError, SampleError
from ..model import LPVModel


def rk4_step(rhs, x, h: float, stage_inputs=None):
    """One classical Runge-Kutta step of x' = rhs(x): the integrator of every truth plant in the library.

    With ``stage_inputs = (e0, e_half, e1)``, the inputs at the step's start, middle and end, it
    integrates x' = rhs(x, e(t)) with inputs that vary within the step."""
    if stage_inputs is None:
        k1 = rhs(x)
        k2 = rhs(x + 0.5 * h * k1)
        k3 = rhs(x + 0.5 * h * k2)
        k4 = rhs(x + h * k3)
    else:
        e0, e_half, e1 = stage_inputs
        k1 = rhs(x, e0)
        k2 = rhs(x + 0.5 * h * k1, e_half)
        k3 = rhs(x + 0.5 * h * k2, e_half)
        k4 = rhs(x + h * k3, e1)
    return x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)


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
    sched = [s.symbol for s in d.scheduling]
    args = [*d.states, *d.known_inputs, *d.unknown_inputs, *sched]
    nx, nu, nd = len(d.states), len(d.known_inputs), len(d.unknown_inputs)
    if d.derived_inputs:
        # derived known inputs: the same functions of the measurements as in the observer,
        # here of the plant's own (noise-free) outputs
        outputs = {sp.Symbol(f"y_{n}"): expr for n, expr in d.outputs}
        w_of_x = [sp.sympify(g.expr).subs(outputs).subs(subs) for g in d.derived_inputs]
        f = f.subs({g.symbol: e for g, e in zip(d.derived_inputs, w_of_x)})
    fn = sp.lambdify(args, f, "numpy")

    def rhs(x, u, dd, rho):
        return np.asarray(fn(*x, *u, *dd, *np.atleast_1d(rho)), dtype=float).reshape(nx)
    return rhs, nx, nu, nd


def scenario_digest(scn) -> str:
    """SHA-256 of everything a closed-loop run of scenario ``scn`` reads: its name, seed and rate, every array
    byte for byte, the circle, the driver's gains and the friction."""
    import hashlib
    import json

    from ..model import cache
    parts = [scn.name, scn.seed, scn.sample_rate, scn.circle, scn.mu, scn.driver, scn.arrays()]
    return hashlib.sha256(json.dumps(cache.canonical(parts), sort_keys=True).encode()).hexdigest()


NOMINAL = "nominal_plant"
"""The kind of the kept closed-loop runs (:func:`codegen.model.cache.remembered`): the same model, parameters,
sample time and scenario give the same truth, every run."""


def nominal_plant(config, lpv: LPVModel, scn, definition=None, progress=None) -> dict:
    """The observer's own symbolic model, integrated exactly (RK4 at Ts/10: true 1/v_x terms, no
    polytope, no Taylor reduction) with planar pose kinematics, closed with the scenario's driver.

    Returns the truth per sample: t, v_x, beta, r, delta, delta_dot, T_d, T_a and
    a_y = v_x (beta_dot + r) (for the baselines' measurement). A run is kept across runs, keyed by the
    model's content (and the truth plant's), the parameter values, the sample time and the scenario
    (:func:`scenario_digest`), with this module's and the driver's code; ``progress`` is then not called."""
    import sys

    from ..model import cache
    from . import scenarios
    parts = {"model": cache.model_digest(lpv.definition),
             "plant": None if definition is None else cache.model_digest(definition),
             "values": dict(lpv.parameters.values), "plant_values": dict(lpv.parameters.plant),
             "sample_time": float(config.sample_time), "scenario": scenario_digest(scn)}
    return cache.remembered(NOMINAL, parts, lambda: _integrate(config, lpv, scn, definition, progress),
                            sys.modules[__name__], scenarios)


def _integrate(config, lpv: LPVModel, scn, definition=None, progress=None) -> dict:
    d = lpv.definition
    names = d.state_names
    if not {"beta", "r", "delta", "delta_dot"} <= set(names):
        raise ModelDefinitionError(f"the nominal closed-loop plant needs states beta, r, delta, delta_dot; "
                                   f"model {d.name!r} has {names}: a model of your own runs on its own equations "
                                   f"(uiogen validate NAME --scenario excitation)")
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
            x = rk4_step(lambda xs: f(xs, t_d, t_a, vx, ax), x, h)
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
        # the measurement, else the truth of the output itself (y_X, a model plant's), else of the signal X
        value = measured.get(key, truth.get(col, truth.get(key)))
        if value is None:
            raise SampleError(f"the plant does not provide the observer input {col!r}")
        columns.append(value)
    return np.column_stack(columns)


class AngleDriver:
    """Path follower commanding the road-wheel angle: curvature of the scenario (with a radial
    correction on circular paths), a yaw-rate loop with integral action (gains from the
    scenario's :class:`DriverGains`), and a speed controller for a longitudinal acceleration
    demand (feed-forward of the reference acceleration, PI on the speed error)."""

    def __init__(self, scn, wheelbase: float, sample_time: float):
        self.scn, self.g, self.Ts = scn, scn.driver, sample_time
        self.L = self.g.wheelbase if self.g is not None else wheelbase
        self.k_r, self.k_ri = (self.g.k_r, self.g.k_ri) if self.g is not None else (0.05, 0.3)
        self.i_r = self.i_v = 0.0

    def preload(self, delta0: float) -> None:
        """Start holding ``delta0`` (steady cornering)."""
        kap0 = 0.0 if self.scn.kappa_ref is None else float(self.scn.kappa_ref[0])
        self.i_r = (delta0 - self.L * kap0) / self.k_ri

    def __call__(self, k: int, X, Y, psi, vx, vy, r) -> tuple:
        """(delta command [rad], acceleration demand [m/s^2]) at sample ``k``."""
        scn, g = self.scn, self.g
        kap = 0.0 if scn.kappa_ref is None else float(scn.kappa_ref[k])
        if scn.circle is not None and g is not None:
            xc, yc, R = scn.circle
            dx, dy = X - xc, Y - yc
            dist = np.hypot(dx, dy)
            e = dist - R                                           # > 0: outside the circle
            e_dot = (dx * (vx * np.cos(psi) - vy * np.sin(psi)) + dy * (vx * np.sin(psi) + vy * np.cos(psi))) / dist
            kap = kap + (g.k_e * e + g.k_edot * e_dot) / max(vx, 1.0) ** 2
        err_r = vx * kap - r
        self.i_r += err_r * self.Ts
        delta = self.L * kap + 10.0 * self.k_r * err_r + self.k_ri * self.i_r
        err_v = float(scn.v_ref[k]) - vx
        self.i_v += err_v * self.Ts
        return delta, float(scn.a_ref[k]) + 2.0 * err_v + 0.5 * self.i_v


def angle_torque_plant(config, definition, params, scn, progress=None, substeps: int = 10) -> dict:
    """Closed-loop truth for models driven by steering angle and engine torque (Nguyen et al. 2021, eq. (1)).

    ``definition`` is the truth plant (states v_x, v_y, r; unknown inputs T_eng, delta), its values
    from the parameter file's [parameters] and [plant] tables; a ``mu`` parameter follows the
    scenario's friction (time-varying grip). :class:`AngleDriver` sets delta and the acceleration
    demand, turned into T_eng with the car's own I_e and C_x; both are held over each sample
    (zero-order hold, as a digital controller does), the plant is integrated with RK4 substeps.
    Returns the truth per sample: t, v_x, v_y, r, T_eng, delta, a_y, mu.
    """
    names = definition.state_names
    if set(names) != {"v_x", "v_y", "r"} or {str(s) for s in definition.unknown_inputs} != {"T_eng", "delta"}:
        raise ModelDefinitionError(f"the angle/torque plant needs states v_x, v_y, r and inputs T_eng, delta; "
                                   f"{definition.name!r} has {names}")
    values = {**params.values, **params.plant}
    free = [p for p in definition.parameters if str(p) == "mu"]
    missing = [str(p) for p in definition.parameters if str(p) not in values and str(p) != "mu"]
    if missing:
        raise ModelDefinitionError(f"plant {definition.name!r} needs {', '.join(missing)} in {params.source}")
    subs = {p: values[str(p)] for p in definition.parameters if p not in free}
    fn = sp.lambdify([*definition.states, *definition.unknown_inputs, *free],
                     sp.Matrix(definition.dynamics).subs(subs), "numpy")
    order = [str(s) for s in definition.unknown_inputs]
    iv, iy, ir = (names.index(k) for k in ("v_x", "v_y", "r"))
    I_e, C_x = values["I_e"], values["C_x"]
    driver = AngleDriver(scn, values["l_f"] + values["l_r"], config.sample_time)

    def f(z, T, delta, mu):
        dz = np.empty(6)
        dd = {"T_eng": T, "delta": delta}
        dz[:3] = np.asarray(fn(*z[:3], *[dd[k] for k in order], *([mu] if free else [])), float).ravel()
        vx, vy, psi = z[iv], z[iy], z[5]
        dz[3] = vx * np.cos(psi) - vy * np.sin(psi)
        dz[4] = vx * np.sin(psi) + vy * np.cos(psi)
        dz[5] = z[ir]
        return dz

    n, Ts = scn.t.size, config.sample_time
    h = Ts / substeps
    z = np.zeros(6)
    z[iv] = float(scn.v_ref[0])
    kap0 = 0.0 if scn.kappa_ref is None else float(scn.kappa_ref[0])
    z[ir] = z[iv] * kap0
    if kap0 != 0.0:
        # start in steady cornering: v_y and delta with v_y' = r' = 0 on the plant itself
        from scipy.optimize import fsolve
        mu0 = scn.friction(0.0, 0.0, 0.0)
        T0 = C_x * z[iv] ** 2

        def lateral(p):
            zz = z.copy()
            zz[iy] = p[0]
            return f(zz, T0, p[1], mu0)[[iy, ir]]
        vy0, delta0 = fsolve(lateral, [0.0, driver.L * kap0], xtol=1e-10)
        z[iy] = vy0
        driver.preload(delta0)
    out = {k: np.empty(n) for k in ("v_x", "v_y", "r", "T_eng", "delta", "a_y", "mu")}
    for k in range(n):
        if progress is not None and (k % max(n // 50, 1) == 0 or k == n - 1):
            progress((k + 1) / n)
        vx, vy, r = z[iv], z[iy], z[ir]
        delta, a_cmd = driver(k, z[3], z[4], z[5], vx, vy, r)
        T = I_e * (a_cmd - vy * r) + C_x * vx ** 2
        mu = scn.friction(float(scn.t[k]), z[3], z[4])
        dz = f(z, T, delta, mu)
        out["v_x"][k], out["v_y"][k], out["r"][k] = vx, vy, r
        out["T_eng"][k], out["delta"][k], out["mu"][k] = T, delta, mu
        out["a_y"][k] = dz[iy] + vx * r
        if k == n - 1:
            break
        for _ in range(substeps):
            z = rk4_step(lambda zs: f(zs, T, delta, mu), z, h)
        if not np.all(np.isfinite(z)):
            raise SampleError(f"plant diverged at t = {scn.t[k]:.2f} s in scenario {scn.name!r}")
    out["t"] = np.asarray(scn.t, float)
    return out
