"""Any family's observer with unknown inputs recovered through their carriers' inverses.

When an observer file substitutes an unknown input ``d`` by the value ``w`` of the one expression it
enters through (``[substitute]``, :mod:`codegen.representation.substitution`), the family designs and
certifies an observer of ``w``. :class:`RecoveredInputs` wraps that family's build and appends
``d`` to the step's state and outputs, computed after the family's step as

    d_hat = c^{-1}(clamp(w_hat, w_min, w_max); x_hat, u, rho),

with the states it needs clamped to their declared boxes: the inverse is proven to exist there
and nowhere else. A sample where ``w_hat`` or such a state leaves its range is flagged
SCHEDULING_CLAMPED. Where the family's estimate of ``w`` lags one sample (a step that needs the
next output), the inverse takes the state estimates of that same sample, which the step receives in
its state. Everything else (design, certificate, LMIs) is the family's own.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp

from .stepgen import lambdify
from ..errors import ModelDefinitionError
from ..contract.family import ObserverBuild


@dataclass(frozen=True)
class RecoveredInputs(ObserverBuild):
    """A family's build plus the recovered unknown inputs (module docstring)."""

    inner: ObserverBuild
    substitutions: tuple

    def __getattr__(self, name):            # family-specific members (validation, bench) of the inner build
        if name in ("inner", "substitutions") or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def config(self):
        return self.inner.config

    @property
    def timings(self) -> dict:
        return self.inner.timings

    @property
    def recovered(self) -> list:
        return [str(s.unknown) for s in self.substitutions]

    @property
    def state_names(self) -> list:
        return [*self.inner.state_names, *self.recovered]

    @property
    def input_names(self) -> list:
        return list(self.inner.input_names)

    @property
    def output_names(self) -> list:
        return [*self.inner.output_names, *self.recovered]

    @property
    def nu(self) -> int:
        return self.inner.nu

    @property
    def ny(self) -> int:
        return self.inner.ny

    # -- where each symbol of an inverse is read ---------------------------------------------------
    def _plan(self) -> list:
        """[(substitution, lag, {symbol: (vector, index)}, [(symbol, lo, hi)] clamped states)] with
        vector one of "w" (the step's next state), "z" (its state), "u", "rho"."""
        from ..model import load_parameters
        params = load_parameters(self.config.parameter_path)
        names = list(self.inner.state_names)
        inputs = list(self.inner.input_names)
        nu, ny = self.nu, self.ny
        lags = self.inner.output_lags()
        plans = []
        for sub in self.substitutions:
            lag = lags.get(str(sub.symbol), 0)
            where, clamps = {}, []
            for s in sorted(sub.inverse.free_symbols, key=str):
                n = str(s)
                if s == sub.symbol:
                    where[s] = ("next", len(names) - 1 - names[::-1].index(n))
                elif n in names:
                    where[s] = ("z" if lag else "next", len(names) - 1 - names[::-1].index(n))
                    if n in params.state_bounds:
                        clamps.append((s, *params.state_bounds[n]))
                elif n in inputs[:nu]:
                    where[s] = ("u", inputs.index(n))
                elif n in inputs[nu + ny:]:
                    where[s] = ("rho", inputs.index(n) - nu - ny)
                else:
                    raise ModelDefinitionError(
                        f"{self.config.source}: [substitute] {sub.unknown}: its inverse needs {n}, which the "
                        f"{self.config.family} step neither estimates nor receives")
            plans.append((sub, lag, where, clamps))
        return plans

    def step_function(self) -> ca.Function:
        f = self.inner.step_function()
        nz0, k = len(self.inner.state_names), len(self.substitutions)
        z = ca.SX.sym("z", nz0 + k)
        u, y, rho = (ca.SX.sym(n, f.numel_in(i)) for i, n in ((1, "u"), (2, "y"), (3, "rho")))
        res = f(z[:nz0], u, y, rho)
        res = list(res) if isinstance(res, (list, tuple)) else [res]
        nxt, excess = res[0], res[1]
        vectors = {"next": nxt, "z": z, "u": u, "rho": rho}
        recovered = []
        for sub, _, where, clamps in self._plan():
            env = {}
            for s, (vec, i) in where.items():
                env[s] = vectors[vec][i]
            for s, lo, hi in clamps:
                v = env[s]
                env[s] = ca.if_else(v < lo, lo, ca.if_else(v > hi, hi, v))
                out = ca.if_else(v < lo, lo - v, ca.if_else(v > hi, v - hi, 0))
                excess = ca.if_else(out > excess, out, excess)
            w = env[sub.symbol]
            env[sub.symbol] = ca.if_else(w < sub.lower, sub.lower, ca.if_else(w > sub.upper, sub.upper, w))
            out = ca.if_else(w < sub.lower, sub.lower - w, ca.if_else(w > sub.upper, w - sub.upper, 0))
            excess = ca.if_else(out > excess, out, excess)
            syms = list(env)
            fn = lambdify(syms, sub.inverse)
            recovered.append(fn(*[env[s] for s in syms]))
        z_next = ca.vertcat(nxt, *recovered)
        outs = [z_next, excess, *res[2:]]
        names = ["z_next", "excess", *(["warmup"] if len(res) > 2 else [])]
        return ca.Function(f.name(), [z, u, y, rho], outs, ["z", "u", "y", "rho"], names)

    def reference_step(self, z, u, y, rho):
        z = np.asarray(z, float)
        nz0 = len(self.inner.state_names)
        res = self.inner.reference_step(z[:nz0], u, y, rho)
        res = list(res) if isinstance(res, tuple) else [res, 0.0]
        nxt, excess = np.asarray(res[0], float), float(res[1])
        vectors = {"next": nxt, "z": z[:nz0], "u": np.asarray(u, float), "rho": np.asarray(rho, float)}
        recovered = []
        for sub, _, where, clamps in self._plan():
            env = {s: float(vectors[vec][i]) for s, (vec, i) in where.items()}
            for s, lo, hi in clamps:
                v = env[s]
                env[s] = min(max(v, lo), hi)
                excess = max(excess, lo - v, v - hi)
            w = env[sub.symbol]
            env[sub.symbol] = min(max(w, sub.lower), sub.upper)
            excess = max(excess, sub.lower - w, w - sub.upper)
            syms = list(env)
            fn = lambdify(syms, sub.inverse, np)
            recovered.append(float(np.real(fn(*[env[s] for s in syms]))))
        return (np.concatenate([nxt, recovered]), excess, *res[2:])

    # -- everything else is the family's ------------------------------------------------------------
    def contraction_metrics(self) -> list:
        # the family's certificate, over the family's own state entries (same names here); a
        # recovered input is a function of the next state with no dynamics of its own, so the float32
        # bound reaches it through the step's Jacobian (ObserverBuild's [] would leave the
        # substituted observer with no certificate at all)
        return self.inner.contraction_metrics()

    def lmi_problem(self):
        return self.inner.lmi_problem()

    def input_boxes(self) -> dict:
        return self.inner.input_boxes()

    def scheduling_boxes(self) -> list:
        return self.inner.scheduling_boxes()

    def derived_input_docs(self) -> list:
        return self.inner.derived_input_docs()

    def output_lags(self) -> dict:
        lags = dict(self.inner.output_lags())
        for sub in self.substitutions:
            if str(sub.symbol) in lags:
                lags[str(sub.unknown)] = lags[str(sub.symbol)]
        return lags

    def signal_docs(self) -> tuple:
        state, inputs, outputs = self.inner.signal_docs()
        units = self.config.load_model().units       # the recovered input keeps the unit its model declares
        extra = [{"name": str(s.unknown), "doc": f"estimate of {s.unknown}, recovered from {s.symbol} = {s.carrier} "
                                                 f"[{units.get(str(s.unknown), '-')}]"}
                 for s in self.substitutions]
        return [*state, *extra], inputs, [*outputs, *extra]

    @property
    def certificate(self):
        return self.inner.certificate

    def step_notes(self):
        from dataclasses import replace
        notes = self.inner.step_notes()
        return replace(notes, notes=(*notes.notes, *[
            f"{s.unknown} is recovered after the step: {s.unknown} = {s.inverse}, with {s.symbol} kept in "
            f"[{s.lower:.6g}, {s.upper:.6g}] (beyond: flagged)" for s in self.substitutions]))

    def artifact(self) -> dict:
        art = dict(self.inner.artifact())
        signals = dict(art.get("signals", {}))
        signals.update(state=self.state_names, output=self.output_names)
        art["signals"] = signals
        art["substitutions"] = [s.to_json() for s in self.substitutions]
        return art

    def figures(self) -> dict:
        return {**self.inner.figures(), "substitutions": [s.to_json() for s in self.substitutions]}


def wrap(build: ObserverBuild) -> ObserverBuild:
    """``build`` with its observer file's substituted unknown inputs recovered, or ``build`` itself."""
    subs = build.config.substitutions()
    return RecoveredInputs(build, tuple(subs)) if subs else build
