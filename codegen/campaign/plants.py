"""Closed-loop truth plants at C speed: the Python reference plants, rebuilt in CasADi.

Each plant here is the same closed loop as a Python plant of the library, sample for sample:

* ``steering_torque``: :func:`codegen.validation.simulate.nominal_plant` (the observer model module's
  ``PLANT``, e.g. Pacejka tyres with load transfer, with planar pose kinematics, closed by the
  scenario's handwheel-torque driver :class:`codegen.validation.scenarios._Driver`; inputs held
  over each sample, RK4 at Ts/10);
* ``banked_road``: :func:`codegen.families.switched_pi.validation.banked_plant` (the roll/bank
  Pacejka plant with the yaw-rate driver setting the road-wheel angle; speed, acceleration and
  bank linear within a sample, RK4 at Ts/10);
* ``model``, for every family: the observer's own model equations, derived from its symbolic
  definition (:mod:`codegen.validation.model_plant`), driven by the generic ``excitation``
  scenario (:mod:`codegen.validation.excitation`): no driver, every parameter of the model
  dispersible.

One sample is a CasADi ``Function`` ``step(x, p, theta) -> (x_next, y)``: ``x`` the plant's
states with the pose and the driver's integrators, ``p`` the scenario's values at the sample,
``theta`` every plant parameter and driver gain (so dispersions need no recompilation), ``y``
the truth at the sample (taken before the step, as the Python plants do). ``mapaccum`` turns it
into one function of a run of up to :data:`CHUNK` samples (a longer run is one call per chunk,
the state carried over), whose C is compiled once (``cc -O2``, no fast-math) into a
shared object cached on disk under a hash of its source, then loaded with ``casadi.external``:
a 60 s run at 100 Hz is one C call of a few milliseconds.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError, UnsupportedError
from ..emit.stepgen import lambdify

SUBSTEPS = 10
CHUNK = 10_000          # samples of one call of a compiled plant (a run is as many calls as it needs)
CACHE_ENV = "UIOGEN_PLANT_CACHE"
DRIVER_KEYS = ("wheelbase", "R_s", "k_e", "k_edot", "k_r", "k_ri", "k_p", "k_i", "k_d")


def cache_dir(config=None) -> Path:
    """Where compiled plants live: ``$UIOGEN_PLANT_CACHE``, else the observer's project's
    ``build/plants/`` (:mod:`python_bindings.workspace`; without an observer, the built-in observers')."""
    from python_bindings.workspace import Workspace, source_checkout
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    return config.workspace.plants if config is not None else Workspace.of(source_checkout()).plants


def _rk4(f, x, h, e0, em, e1):
    k1 = f(x, e0)
    k2 = f(x + 0.5 * h * k1, em)
    k3 = f(x + 0.5 * h * k2, em)
    k4 = f(x + h * k3, e1)
    return x + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)


def _casadi_rhs(definition, params: dict):
    """(f(states, known, unknown, scheduling, theta) as CasADi SX, parameter names in theta order)."""
    names = [str(p) for p in definition.parameters]
    missing = [n for n in names if n not in params]
    if missing:
        raise ModelDefinitionError(f"plant {definition.name!r} needs {', '.join(missing)} in the parameter file")
    if getattr(definition, "derived_inputs", None):
        raise UnsupportedError(f"campaign plants do not support derived inputs (model {definition.name!r})")
    args = [*definition.states, *definition.known_inputs, *definition.unknown_inputs,
            *(s.symbol for s in definition.scheduling), *definition.parameters]
    fn = lambdify(args, list(sp.Matrix(definition.dynamics)))
    return fn, names


@dataclass
class PlantSpec:
    """What a compiled plant needs to know, and how to read its outputs."""

    kind: str
    definition: object
    params: dict                 # nominal values of every plant parameter (name -> float)
    param_names: tuple           # theta order: plant parameters, then the driver's gains
    driver_keys: tuple
    input_names: tuple           # rows of p
    output_names: tuple          # rows of y
    n_state: int
    sample_time: float
    extra: object = None         # e.g. the lateral-acceleration expression of the banked plant


# --- the steering-torque plant (simulate.nominal_plant) -----------------------------------------------

def steering_torque_spec(config) -> PlantSpec:
    from ..model import load_parameters
    from ..validation.common import truth_plant
    params = load_parameters(config.parameter_path)
    lpv_def = config.load_model()
    definition = truth_plant(config, params) or lpv_def
    names = definition.state_names
    if not {"beta", "r", "delta", "delta_dot"} <= set(names):
        raise ModelDefinitionError(f"the steering-torque plant needs states beta, r, delta, delta_dot; "
                                   f"model {definition.name!r} has {names}")
    sched = [str(s.symbol) for s in definition.scheduling]
    if not set(sched) <= {"v_x", "a_x"}:
        raise ModelDefinitionError(f"the steering-torque plant provides scheduling signals v_x, a_x, not {sched}")
    values = {**params.values, **params.plant}
    pnames = tuple(str(p) for p in definition.parameters)
    return PlantSpec("steering_torque", definition, {n: float(values[n]) for n in pnames if n in values},
                     pnames + tuple(f"driver.{k}" for k in DRIVER_KEYS + ("has_path", "has_circle", "xc", "yc", "R")),
                     DRIVER_KEYS, ("v_ref", "a_ref", "T_a", "T_d_open", "kappa_ref"),
                     ("beta", "r", "delta", "delta_dot", "T_d", "a_y"), len(names) + 5, config.sample_time)


def _steering_torque_step(spec: PlantSpec) -> ca.Function:
    d = spec.definition
    fn, pnames = _casadi_rhs(d, spec.params)
    nx = len(d.states)
    names = d.state_names
    ib, ir, idl, idd = (names.index(k) for k in ("beta", "r", "delta", "delta_dot"))
    sched = [str(s.symbol) for s in d.scheduling]
    np_ = len(pnames)
    x = ca.SX.sym("x", nx + 5)             # model states, X, Y, psi, i_r, i_th
    p = ca.SX.sym("p", 5)
    theta = ca.SX.sym("theta", len(spec.param_names))
    th = [theta[i] for i in range(np_)]
    g = dict(zip(DRIVER_KEYS, [theta[np_ + i] for i in range(len(DRIVER_KEYS))]))
    has_path, has_circle, xc, yc, R = (theta[np_ + len(DRIVER_KEYS) + i] for i in range(5))
    vx, ax, t_a, td_open, kap_ref = (p[i] for i in range(5))
    dt = spec.sample_time
    # the driver (scenarios._Driver), on the plant's truth at the sample
    X, Y, psi = x[nx], x[nx + 1], x[nx + 2]
    vy = ca.tan(x[ib]) * vx
    v = ca.fmax(vx, 1.0)
    dx, dy = X - xc, Y - yc
    dist = ca.sqrt(dx * dx + dy * dy)
    c, s = ca.cos(psi), ca.sin(psi)
    vX, vY = vx * c - vy * s, vx * s + vy * c
    edot = (vX * dx + vY * dy) / ca.fmax(dist, 1e-6)
    kap = kap_ref + ca.if_else(has_circle != 0, (g["k_e"] * (dist - R) + g["k_edot"] * edot) / (v * v), 0.0)
    er = v * kap - x[ir]
    i_r = x[nx + 3] + er * dt
    d_ref = g["wheelbase"] * kap + g["k_r"] * er + g["k_ri"] * i_r
    eth = g["R_s"] * (d_ref - x[idl])
    i_th = x[nx + 4] + eth * dt
    t_path = g["k_p"] * eth + g["k_i"] * i_th - g["k_d"] * g["R_s"] * x[idd] + td_open
    t_d = ca.if_else(has_path != 0, t_path, td_open)
    i_r = ca.if_else(has_path != 0, i_r, x[nx + 3])
    i_th = ca.if_else(has_path != 0, i_th, x[nx + 4])
    sv = {"v_x": vx, "a_x": ax}

    def f(z, _e):
        dz = ca.vertcat(*fn(*[z[i] for i in range(nx)], t_a, t_d, *[sv[n] for n in sched], *th))
        vyz = ca.tan(z[ib]) * vx
        return ca.vertcat(dz, vx * ca.cos(z[nx + 2]) - vyz * ca.sin(z[nx + 2]),
                          vx * ca.sin(z[nx + 2]) + vyz * ca.cos(z[nx + 2]), z[ir])

    z = x[:nx + 3]
    dz0 = f(z, None)
    a_y = vx * (dz0[ib] + x[ir])
    h = dt / SUBSTEPS
    for _ in range(SUBSTEPS):
        z = _rk4(f, z, h, None, None, None)
    x_next = ca.vertcat(z, i_r, i_th)
    y = ca.vertcat(x[ib], x[ir], x[idl], x[idd], t_d, a_y)
    return ca.Function("plant_step", [x, p, theta], [x_next, y])


def steering_torque_inputs(spec: PlantSpec, scn, driver_gains: dict) -> tuple:
    """(x0, p (5, n), theta) of a scenario and the plant's parameter values."""
    d = spec.definition
    n = scn.t.size
    kap = np.zeros(n) if scn.kappa_ref is None else np.asarray(scn.kappa_ref, float)
    p = np.vstack([scn.v_ref, scn.a_ref, scn.T_a, scn.T_d_open, kap])
    x0 = np.zeros(spec.n_state)
    x0[d.state_names.index("r")] = float(scn.v_ref[0]) * float(kap[0])
    circle = scn.circle if scn.circle is not None else (0.0, 0.0, 0.0)
    has_path = float(scn.driver is not None and scn.kappa_ref is not None)
    extra = [driver_gains[k] for k in DRIVER_KEYS] + [has_path, float(scn.circle is not None), *map(float, circle)]
    return x0, p, extra


# --- the banked-road plant (switched_pi.validation.banked_plant) ----------------------------------------

BANKED_DRIVER_KEYS = ("k_r", "k_ri")
BANKED_DRIVER = {"k_r": 0.5, "k_ri": 0.3}


def banked_road_spec(config) -> PlantSpec:
    from ..model import load_parameters
    from ..project.observer_file import builtin_model
    params = load_parameters(config.parameter_path)
    mod = builtin_model("roll_single_track")
    d = mod.PLANT
    values = {**params.values, **params.plant}
    pnames = tuple(str(p) for p in d.parameters)
    return PlantSpec("banked_road", d, {n: float(values[n]) for n in pnames if n in values},
                     pnames + tuple(f"driver.{k}" for k in BANKED_DRIVER_KEYS), BANKED_DRIVER_KEYS,
                     ("v_ref", "a_ref", "bank", "kappa_ref", "v_next", "a_next", "bank_next"),
                     ("v_y", "beta", "r", "phi", "phi_dot", "delta", "a_y"), 5, config.sample_time,
                     extra=mod.PLANT_LATERAL_ACCELERATION)


def _banked_road_step(spec: PlantSpec) -> ca.Function:
    d = spec.definition
    fn, pnames = _casadi_rhs(d, spec.params)
    np_ = len(pnames)
    args = [*d.states, *d.known_inputs, *d.unknown_inputs, *(s.symbol for s in d.scheduling), *d.parameters]
    acc_fn = lambdify(args, spec.extra)
    x = ca.SX.sym("x", 5)                  # v_y, r, phi, phi_dot, i_r
    p = ca.SX.sym("p", 7)
    theta = ca.SX.sym("theta", len(spec.param_names))
    th = [theta[i] for i in range(np_)]
    k_r, k_ri = theta[np_], theta[np_ + 1]
    vx, ax, pr, kap, vx1, ax1, pr1 = (p[i] for i in range(7))
    Ts = spec.sample_time
    values = dict(zip(pnames, th))
    L = values["l_f"] + values["l_r"]
    err = vx * kap - x[1]
    i_r = x[4] + err * Ts
    delta = L * kap + k_r * err + k_ri * i_r
    z = x[:4]
    zs = [z[i] for i in range(4)]
    a_y = acc_fn(*zs, delta, pr, vx, ax, *th)

    def f(zz, e):
        return ca.vertcat(*fn(*[zz[i] for i in range(4)], delta, e[2], e[0], e[1], *th))

    h = Ts / SUBSTEPS
    for s in range(SUBSTEPS):
        c0, c1, c2 = s / SUBSTEPS, (s + 0.5) / SUBSTEPS, (s + 1) / SUBSTEPS
        e0, em, e1 = ([vx + c * (vx1 - vx), ax + c * (ax1 - ax), pr + c * (pr1 - pr)] for c in (c0, c1, c2))
        z = _rk4(f, z, h, e0, em, e1)
    y = ca.vertcat(x[0], ca.atan2(x[0], vx), x[1], x[2], x[3], delta, a_y)
    return ca.Function("plant_step", [x, p, theta], [ca.vertcat(z, i_r), y])


def banked_road_inputs(spec: PlantSpec, scn, driver_gains: dict) -> tuple:
    n = scn.t.size
    bank = np.zeros(n) if getattr(scn, "bank", None) is None else np.asarray(scn.bank, float)
    kap = np.zeros(n) if scn.kappa_ref is None else np.asarray(scn.kappa_ref, float)
    v, a = np.asarray(scn.v_ref, float), np.asarray(scn.a_ref, float)

    def nxt(u):
        return np.concatenate([u[1:], u[-1:]])
    p = np.vstack([v, a, bank, kap, nxt(v), nxt(a), nxt(bank)])
    x0 = np.zeros(5)
    x0[1] = float(v[0]) * kap[0]
    return x0, p, [driver_gains[k] for k in BANKED_DRIVER_KEYS]


# --- the model's own equations (codegen.validation.model_plant), for every family ---------------------------

EXCITATION = "excitation"
"""The scenario of the ``model`` plant: the generic excitation of :mod:`codegen.validation.excitation`."""


def model_spec(config) -> PlantSpec:
    from ..model import load_parameters
    from ..validation import model_plant
    params = load_parameters(config.parameter_path)
    definition = config.load_model()
    plant = model_plant.plant(definition, config.sample_time)
    names = tuple(str(p) for p in definition.parameters)
    stages = tuple(f"{k}@{m}" for m in range(plant.n_stage) for k in plant.external)   # rows of E
    return PlantSpec("model", definition, {n: float(params.values[n]) for n in names}, names, (),
                     stages, plant.outputs, len(plant.states), config.sample_time, extra=plant)


def _model_step(spec: PlantSpec) -> ca.Function:
    return spec.extra.step


def model_inputs(spec: PlantSpec, scn, driver_gains: dict) -> tuple:
    """(x0, E, []) of an excitation run (:func:`codegen.validation.excitation.scenario`)."""
    return scn.x0, scn.stages, []


KINDS = {"steering_torque": (steering_torque_spec, _steering_torque_step, steering_torque_inputs),
         "banked_road": (banked_road_spec, _banked_road_step, banked_road_inputs),
         "model": (model_spec, _model_step, model_inputs)}


def families_with_plants() -> list:
    """The registered families with a compiled plant of their own library scenarios (the
    ``Campaigns`` capability); every family has the ``model`` plant of the excitation scenario."""
    from .. import families
    from ..contract.capabilities import Campaigns
    return [n for n in families.names() if isinstance(families.get(n), Campaigns)]


def plant_kind(config, scenarios=(EXCITATION,)) -> str:
    """The kind of compiled plant of a campaign of ``config`` on ``scenarios``: ``model`` for the
    excitation scenario (every family), else the family's own (``Family.campaign_plant``)."""
    from .. import families
    from ..contract.capabilities import Campaigns
    if scenarios and all(s == EXCITATION for s in scenarios):
        return "model"
    family = families.get(config.family)
    kind = family.campaign_plant if isinstance(family, Campaigns) else None
    if kind is None:
        raise UnsupportedError(f"campaigns on the library scenarios have compiled plants for the families "
                               f"{', '.join(families_with_plants())}; observer {config.name!r} is of family "
                               f"{config.family!r}: its campaigns run the scenario {EXCITATION!r} on its own model")
    return kind


def default_driver_gains(kind: str, scn) -> dict:
    if kind == "model":
        return {}
    if kind == "banked_road":
        return dict(BANKED_DRIVER)
    from ..validation.scenarios import DriverGains
    g = scn.driver if scn.driver is not None else DriverGains()
    return {k: float(getattr(g, k)) for k in DRIVER_KEYS}


# --- compile, cache, load ---------------------------------------------------------------------------------

class CompiledPlant:
    """A closed-loop plant of ``n`` samples as one compiled C function."""

    def __init__(self, config, n: int, kind: str | None = None):
        kind = kind or plant_kind(config, ())
        make_spec, make_step, self._inputs = KINDS[kind]
        self.kind, self.n = kind, int(n)
        # compiled for a chunk of samples at most, called once per chunk with the state carried over: the
        # C of a whole run of n samples grows with n (its sparsity arrays), and compiling it took 6.6 kB
        # a sample in this process and as much in the compiler (a 30,000 s run: 20 GB each)
        self.chunk = min(self.n, CHUNK)
        self.spec = make_spec(config)
        step = make_step(self.spec)
        whole = step.mapaccum("plant_run", self.chunk, 1, {})
        # one function: (x0, P, theta) -> (Y, the state after the chunk's last sample)
        x0, P, th = ca.MX.sym("x0", self.spec.n_state), ca.MX.sym("P", len(self.spec.input_names), self.chunk), \
            ca.MX.sym("theta", len(self.spec.param_names))
        X, Y = whole(x0, P, ca.repmat(th, 1, self.chunk))
        run = ca.Function("plant_run", [x0, P, th], [Y, X[:, self.chunk - 1]])
        self.path = _compile(run, cache_dir(config))
        self._fn = ca.external("plant_run", str(self.path))

    @property
    def parameter_names(self) -> tuple:
        """The plant parameters a campaign may disperse (the model's, not the driver's)."""
        return tuple(n for n in self.spec.param_names if not n.startswith("driver."))

    def simulate(self, scn, params: dict | None = None, driver_gains: dict | None = None) -> dict:
        """Truth per sample (dict of arrays, keys of the Python plant) of scenario ``scn``."""
        if scn.t.size != self.n:
            raise ModelDefinitionError(f"compiled plant has {self.n} samples, scenario {scn.name!r} {scn.t.size}")
        values = {**self.spec.params, **(params or {})}
        gains = {**default_driver_gains(self.kind, scn), **(driver_gains or {})}
        x0, P, extra = self._inputs(self.spec, scn, gains)
        theta = np.array([values[k] for k in self.parameter_names] + list(extra), float)
        P = np.asarray(P, float)
        Y, x = None, np.asarray(x0, float)
        for a in range(0, self.n, self.chunk):
            b = min(a + self.chunk, self.n)
            part = P[:, a:b]
            if b - a < self.chunk:        # the last chunk, padded with its last column: a sample's outputs
                part = np.concatenate([part, np.repeat(part[:, -1:], self.chunk - (b - a), axis=1)], axis=1)
            y, x = self._fn(x, part, theta)          # never read those of the samples after it
            y = np.asarray(y)
            if Y is None:
                Y = np.empty((y.shape[0], self.n))
            Y[:, a:b] = y[:, :b - a]
        out = {k: np.ascontiguousarray(Y[i]) for i, k in enumerate(self.spec.output_names)}
        out["t"] = np.asarray(scn.t, float)
        if self.kind == "model":
            return {**scn.signals, **out}
        out["v_x"] = np.asarray(scn.v_ref, float)
        if self.kind == "steering_torque":
            out["T_a"] = np.asarray(scn.T_a, float)
        else:
            out["a_x"] = np.asarray(scn.a_ref, float)
            out["phi_r"] = P[2].copy()
        return out


def _compile(f: ca.Function, where: Path) -> Path:
    """The shared object of ``f``'s C, compiled once per source hash (atomic rename: safe for
    several worker processes compiling at once). The SHA-256 of its bytes is recorded beside it
    (``plant_KEY.so.sha256``, :mod:`python_bindings.integrity`) and checked before it is reused: a
    cached object that is truncated, altered or unrecorded is compiled again, never loaded (a
    truncated shared object dies of SIGBUS when loaded)."""
    from python_bindings import integrity
    from ..emit.toolchain import compiler, run
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator("plant_run.c", {"with_header": False})
        cg.add(f)
        cg.generate(tmp + "/")
        code = Path(tmp, "plant_run.c").read_text()
    cc = compiler()
    flags = ["-O2", "-fPIC", "-shared", "-fno-fast-math"]
    key = hashlib.sha256("\0".join([code, cc, *flags, ca.__version__]).encode()).hexdigest()[:20]
    out = Path(where) / f"plant_{key}.so"
    if out.is_file() and not integrity.binary_mismatch(out):
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        src = Path(tmp, "plant_run.c")
        src.write_text(code)
        so = Path(tmp, out.name)
        run([cc, *flags, str(src), "-o", str(so), "-lm"])
        record = integrity.record_path(so)
        record.write_text(integrity.record_text(so.read_bytes(), out.name))
        os.replace(record, integrity.record_path(out))
        os.replace(so, out)
    return out
