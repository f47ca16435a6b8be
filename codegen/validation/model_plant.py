"""A model's own equations as a truth plant: one sample of RK4 as a CasADi ``Function``.

Any :class:`~codegen.model.ModelDefinition` (a family's richer definition through its
``as_model_definition``) becomes ``step(x, e, theta) -> (x_next, y)``:

* ``x``: the model's states;
* ``e``: every external signal (known inputs, unknown inputs, input scheduling signals, in that
  order) at the ``2 * substeps + 1`` stage times of the sample (``t_k + j h / 2``, ``h =
  Ts / substeps``): the inputs vary continuously between the samples, as a real car's do;
* ``theta``: the model's parameters, in the order of ``definition.parameters`` (so a campaign
  disperses them without rebuilding anything);
* ``y``: the truth at the sample, before the step: the states, then the outputs (``y_NAME``).

Derived scheduling signals and derived inputs (functions of the measured outputs) are evaluated
from the plant's own noise-free outputs. The same ``Function`` is the excitation scenario's plant
(:mod:`codegen.validation.excitation`, in CasADi's virtual machine) and a campaign's compiled
plant for every family (:mod:`codegen.campaign.plants`, kind ``model``).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp

from ..emit.stepgen import CASADI_FUNCTIONS
from ..errors import ModelDefinitionError

SUBSTEPS = 10


@dataclass(frozen=True, eq=False)
class ModelPlant:
    """The plant of one model at one sample time (see the module)."""

    name: str
    states: tuple           # names, rows of x
    external: tuple         # names of the external signals, per stage of e
    parameters: tuple       # names, rows of theta
    outputs: tuple          # names of the rows of y: the states, then y_<output>
    step: ca.Function       # (x, e, theta) -> (x_next, y)
    sample_time: float
    substeps: int

    @property
    def n_stage(self) -> int:
        return 2 * self.substeps + 1

    def stage_times(self, t: np.ndarray) -> np.ndarray:
        """(n, 2 substeps + 1): the times at which sample k's step reads its inputs."""
        h = self.sample_time / self.substeps
        return np.asarray(t, float)[:, None] + 0.5 * h * np.arange(self.n_stage)[None, :]

    def stage_inputs(self, t: np.ndarray, functions: dict) -> np.ndarray:
        """The (len(e), n) matrix E of a run: ``functions`` maps every external signal to a function of time."""
        missing = [k for k in self.external if k not in functions]
        if missing:
            raise ModelDefinitionError(f"plant {self.name!r}: no signal for {', '.join(missing)}")
        t = np.asarray(t, float)
        n, ne = t.size, len(self.external)
        # row m * n_ext + i: signal i at stage m, written in place one row at a time (the same doubles as
        # stage_times(t)): the stage-time matrix, its signals stacked and their transposed copy were three
        # more matrices of the size of E
        offsets = 0.5 * (self.sample_time / self.substeps) * np.arange(self.n_stage)
        E = np.empty((self.n_stage * ne, n))
        for m in range(self.n_stage if ne else 0):
            tm = t + offsets[m]
            for i, k in enumerate(self.external):
                E[m * ne + i] = np.asarray(functions[k](tm), float)
        return E

    def simulate(self, x0, E: np.ndarray, theta) -> dict:
        """Truth per sample ({name: array}) of a run from state ``x0`` with stage inputs ``E``."""
        n = E.shape[1]
        run = self.step.mapaccum("plant_run", n)
        th = np.asarray(theta, float).reshape(-1, 1)
        _, Y = run(np.asarray(x0, float), E, np.repeat(th, n, axis=1))
        Y = np.asarray(Y)
        return {name: np.ascontiguousarray(Y[i]) for i, name in enumerate(self.outputs)}


def _casadi(exprs, symbols, values, model_name: str) -> list:
    fn = sp.lambdify(list(symbols), [sp.sympify(e) for e in exprs], [CASADI_FUNCTIONS, "math"])
    try:
        out = fn(*values)
    except (TypeError, RuntimeError, NotImplementedError, NameError) as exc:
        raise ModelDefinitionError(
            f"model {model_name!r}: its equations cannot be simulated as a plant ({exc}); a model may use "
            f"{', '.join(sorted(CASADI_FUNCTIONS))} and arithmetic") from None
    return [ca.SX(o) for o in out]


def plant(definition, sample_time: float, substeps: int = SUBSTEPS) -> ModelPlant:
    """The plant of ``definition`` (a ModelDefinition) sampled at ``sample_time``."""
    d = definition
    x_s, u_s, d_s = tuple(d.states), tuple(d.known_inputs), tuple(d.unknown_inputs)
    raw = tuple(s.symbol for s in d.scheduling if s.derived is None)
    derived = {s.symbol: sp.sympify(s.derived) for s in d.scheduling if s.derived is not None}
    # derived signals read the measured outputs, here the plant's own (functions of x, u, d, raw scheduling)
    outputs = {sp.Symbol(f"y_{n}"): sp.sympify(e) for n, e in d.outputs}
    on_outputs = {**{s: e.subs(outputs) for s, e in derived.items()},
                  **{w.symbol: sp.sympify(w.expr).subs(outputs) for w in d.derived_inputs}}
    f = [sp.sympify(e).subs(on_outputs) for e in d.dynamics]
    h = [sp.sympify(e).subs(on_outputs) for _, e in d.outputs]
    params = tuple(d.parameters)
    ext = (*u_s, *d_s, *raw)
    stray = set().union(*(e.free_symbols for e in (*f, *h))) - set((*x_s, *ext, *params))
    if stray:
        raise ModelDefinitionError(f"model {d.name!r}: its plant's equations still use {', '.join(sorted(map(str, stray)))} "
                                   f"after the derived signals are replaced by the outputs they read (an output that "
                                   f"reads a derived signal?)")
    nx, ne, ns = len(x_s), len(ext), 2 * substeps + 1
    x = ca.SX.sym("x", nx)
    e = ca.SX.sym("e", ne * ns)
    theta = ca.SX.sym("theta", len(params))
    z, ee = ca.SX.sym("z", nx), ca.SX.sym("ee", ne)
    symbols = (*x_s, *ext, *params)
    values = ([z[i] for i in range(nx)] + [ee[i] for i in range(ne)] + [theta[i] for i in range(len(params))])
    rhs = ca.Function("rhs", [z, ee, theta], [ca.vertcat(*_casadi(f, symbols, values, d.name))]) if nx else None
    out = ca.Function("out", [z, ee, theta], [ca.vertcat(*_casadi(h, symbols, values, d.name))])
    stage = [e[m * ne:(m + 1) * ne] for m in range(ns)]
    hh = sample_time / substeps
    xk = x
    for j in range(substeps if nx else 0):
        e0, em, e1 = stage[2 * j], stage[2 * j + 1], stage[2 * j + 2]
        k1 = rhs(xk, e0, theta)
        k2 = rhs(xk + 0.5 * hh * k1, em, theta)
        k3 = rhs(xk + 0.5 * hh * k2, em, theta)
        k4 = rhs(xk + hh * k3, e1, theta)
        xk = xk + (hh / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    y = ca.vertcat(x, out(x, stage[0], theta))
    step = ca.Function("plant_step", [x, e, theta], [xk, y])
    return ModelPlant(d.name, tuple(map(str, x_s)), tuple(map(str, ext)), tuple(map(str, params)),
                      (*map(str, x_s), *(f"y_{n}" for n, _ in d.outputs)), step, float(sample_time), int(substeps))


def initial_state(definition, params) -> np.ndarray:
    """The centre of each state's ``[state_bounds]`` box (0 without one)."""
    return np.array([0.5 * sum(params.state_bounds[str(s)]) if str(s) in params.state_bounds else 0.0
                     for s in definition.states])
