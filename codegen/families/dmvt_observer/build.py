"""model -> DMVT form (Jacobian bounds over the box) -> gains by LMIs -> numpy re-check -> step.

The step (z = [x_hat of sample k+1, x_hat of sample k]; the estimate of sample k is the last half)::

    x_hat_k+1 = x_hat_k + Ts f(x_hat_k, w_k) + L (y_k - h(x_hat_k, w_k))

No signal is clamped: the step evaluates the model at the estimate and the measured signals as they
are, and flags SCHEDULING_CLAMPED (``excess`` > 0) when the estimate leaves the state box X or a
measured signal its box, where the certificate does not hold.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...certificate.artifact import artifact_head, significant, solver_certificate
from ...certificate.certificate import Bound, Certificate, Recheck, Step
from ...contract.family import ObserverBuild, StepNotes
from ...errors import ConfigurationError
from ...model import load_parameters
from ...settings import parse_settings
from . import design as dsn
from . import representation


@dataclass(frozen=True)
class Build(ObserverBuild):
    """A certified DMVT observer (see the module docstring)."""

    config: object
    rep: representation.DMVTModel
    settings: dsn.DMVTSettings
    scaled: dsn.Scaled
    synthesis: dsn.Design
    timings: dict

    @property
    def L(self) -> np.ndarray:
        return self.synthesis.L

    def _unit(self, name: str) -> str:
        return self.rep.definition.units.get(name, "")

    output_names = property(lambda self: [str(s) for s in self.rep.states])
    state_names = property(lambda self: [f"{n}_next" for n in self.output_names] + self.output_names)
    input_names = property(lambda self: [*(str(s) for s in self.rep.known_inputs),
                                         *(f"y_{n}" for n, _ in self.rep.definition.outputs),
                                         *(str(s) for s in self.rep.scheduling)])
    nu = property(lambda self: len(self.rep.known_inputs))
    ny = property(lambda self: self.rep.ny)

    def _parts(self, z, u, y, rho, fns, xp):
        f_fn, h_fn = fns
        fmax = ca.fmax if xp is ca else max
        nx = self.rep.nx
        x = [z[j] for j in range(nx)]
        w = [u[k] for k in range(self.nu)] + [rho[k] for k in range(len(self.rep.scheduling))]
        excess = 0.0
        for v, (lo, hi) in zip([*x, *w], [*self.rep.state_box, *self.rep.signal_box]):
            excess = excess + fmax(0.0, fmax(lo - v, v - hi))
        f = [fn(*x, *w) for fn in f_fn]
        innovation = [y[i] - fn(*x, *w) for i, fn in enumerate(h_fn)]
        Ts, L = self.config.sample_time, self.L
        nxt = [x[j] + Ts * f[j] + sum(float(L[j, i]) * innovation[i] for i in range(self.ny) if L[j, i] != 0.0)
               for j in range(nx)]
        return nxt, x, excess

    def step_function(self):
        nx = self.rep.nx
        z, u = ca.SX.sym("z", 2 * nx), ca.SX.sym("u", self.nu)
        y, rho = ca.SX.sym("y", self.ny), ca.SX.sym("rho", len(self.rep.scheduling))
        nxt, x, excess = self._parts(z, u, y, rho, self.rep.functions(ca), ca)
        outs = ca.cse([ca.vertcat(*nxt, *x), excess])
        return ca.Function(f"{self.name}_kernel", [z, u, y, rho], outs, ["z", "u", "y", "rho"], ["z_next", "excess"])

    def reference_step(self, z, u, y, rho):
        z, u, y, rho = (np.asarray(a, float).ravel() for a in (z, u, y, rho))
        nxt, x, excess = self._parts(z, u, y, rho, self.rep.numpy_functions, np)
        return np.array([*nxt, *x], dtype=float), float(excess)

    def contraction_metrics(self):
        """The common P over the corners of the Jacobian box, in physical units, on the prediction."""
        from ...certificate.contraction import ContractionMetric
        S = self.scaled.S
        P = self.synthesis.P / S[:, None] / S[None, :]
        return [ContractionMetric(self.synthesis.contraction, (P,), tuple(self.state_names[:self.rep.nx]),
                                  "common P over the corners of the Jacobian box (DMVT): Phi' P Phi <= c^2 P in X",
                                  knob="[design] decay (the rate the LMIs impose)")]

    def lmi_problem(self):
        return dsn.problem(self.scaled, self.synthesis.rate, margin=self.settings.margin)

    def input_boxes(self):
        return {str(s): list(b) for s, b in zip(self.rep.signals, self.rep.signal_box)}

    def scheduling_boxes(self):
        box = dict(zip(self.rep.signals, self.rep.signal_box))
        return [(str(s), *box[s], False) for s in self.rep.scheduling]

    def signal_docs(self):
        u = self._unit
        names = self.output_names
        state = ([{"name": f"{n}_next", "doc": f"predicted {n} for the next sample [{u(n)}]"} for n in names]
                 + [{"name": n, "doc": f"estimate of {n} at this sample, from the samples before it [{u(n)}]"}
                    for n in names])
        inputs = ([{"name": str(s), "doc": f"measured {s} [{u(str(s))}]"} for s in self.rep.known_inputs]
                  + [{"name": f"y_{n}", "doc": f"measured output {n} [{u(n)}]"} for n, _ in self.rep.definition.outputs]
                  + [{"name": str(s), "doc": f"measured scheduling signal {s} [{u(str(s))}]"}
                     for s in self.rep.scheduling])
        return state, inputs, state[len(names):]

    def step_notes(self):
        return StepNotes(
            notes=("Each call takes the measurements of sample k and returns the estimate of sample k made",
                   "from the samples before it; the state's head is the prediction for sample k+1."),
            clamp=("the estimate outside the state box or a measured signal outside its box: nothing is clamped,\n"
                   " * the step corrects as everywhere, but the certificate does not cover this sample."),
            warmup="never set.")

    @property
    def certificate(self):
        d, rep, Ts = self.synthesis, self.rep, self.config.sample_time
        names = self.output_names
        outs = [n for n, _ in rep.definition.outputs]
        levels = ", ".join(f"{n} {s:.4g} {self._unit(n)}".rstrip() for n, s in zip(outs, self.scaled.sigma))
        bounds = tuple(Bound(f"rms_{n}", v, self._unit(n), "rms", f"{n}, the estimation error",
                             f"white sensor noise at its level sigma ({levels}), steady state")
                       for n, v in zip(names, d.rms))
        bounds += tuple(Bound(f"peak_{n}", v, self._unit(n), "peak", f"{n}, the estimation error (steady state)",
                              "the sensor noise, each channel's peak in units of its sigma")
                        for n, v in zip(names, d.peak))
        loose = rep.loose_bounds
        return Certificate(
            family="dmvt_observer",
            claim=(f"one quadratic Lyapunov matrix at all {len(self.scaled.corners)} corners of the box of Jacobians "
                   f"of f and h (DMVT, gains designed by LMIs): the estimation error contracts by {d.contraction:.6g} "
                   f"per step (decay {d.rate:g} 1/s imposed), and with white sensor noise at the levels of [design] "
                   f"noise its steady RMS is at most the bounds below (E V <= trace(L' P L) / (1 - c^2))"),
            plant_class=(f"the model {self.config.model} with the values of {self.config.parameters}, Euler-discretized "
                         f"at Ts = {Ts:g} s (x+ = x + Ts f(x, w), y = h(x, w) + n); no model error"
                         + (f"; Jacobian bounds that are sound enclosures short of their tolerance: {'; '.join(loose)}"
                            if loose else "")),
            noise=f"white noise on the outputs at the levels {levels}, independent of the past; the measured signals "
                  f"w ({', '.join(map(str, rep.signals)) or 'none'}) exact",
            region={**dict(zip(names, rep.state_box)), **{str(s): b for s, b in zip(rep.signals, rep.signal_box)}},
            region_note=("the car's state AND the estimate in the state box X (the DMVT segment between them lies in "
                         "X), the measured signals in theirs; SCHEDULING_CLAMPED flags the estimate or a measured "
                         "signal outside its box: the car's own state is not seen"),
            recheck=Recheck.of(d.solution.checks),
            step=Step(Ts, "Euler step of the model with the output injection L (y - h(x_hat, w))", d.contraction),
            bounds=bounds,
            extras=solver_certificate(d.solution, corner_contraction=d.contraction, slowest_corner=d.slowest_corner))

    def artifact(self):
        return {**artifact_head(self, [str(s) for s in self.rep.scheduling]),
                "representation": self.rep.to_json(), "L": self.L.tolist(), "P_scaled": self.synthesis.P.tolist(),
                "state_scale": self.scaled.S.tolist(), "noise_levels": self.scaled.sigma.tolist(),
                "decay": self.synthesis.rate}

    def figures(self):
        d = self.synthesis
        return {"decay": d.rate, "contraction_per_step": d.contraction, "dmvt_corners": len(self.scaled.corners),
                "L": self.L.tolist(), "rms_bound": dict(zip(self.output_names, map(significant, d.rms.tolist()))),
                "peak_bound": dict(zip(self.output_names, map(significant, d.peak.tolist())))}


def parse(config, tol=None) -> dsn.DMVTSettings:
    return parse_settings(dsn.DMVTSettings, config.design, source=config.source, section="design",
                          **({"tol": tol} if tol is not None else {}))


def noise_levels(config, settings: dsn.DMVTSettings, model) -> np.ndarray:
    """The [design] noise level of every output, in the model's output order.

    Raises
    ------
    ConfigurationError
        an output without a level, or a level for a name that is no output.
    """
    outs = [n for n, _ in model.outputs]
    unknown = sorted(set(settings.noise) - set(outs))
    if unknown:
        raise ConfigurationError(f"{config.source}: [design] noise: {', '.join(unknown)} is no output of model "
                                 f"{model.name!r}; its outputs: {', '.join(outs)}", source=config.source,
                                 section="design.noise", key=unknown[0], allowed=", ".join(outs))
    missing = [n for n in outs if n not in settings.noise]
    if missing:
        units = model.units
        raise ConfigurationError(
            f"{config.source}: [design] noise lacks {', '.join(missing)}: the gains minimise the error bound at the "
            f"sensors' noise levels, one per output, e.g. noise = {{ "
            + ", ".join(f"{n} = SIGMA" + (f" ({units[n]})" if units.get(n) else "") for n in outs) + " }",
            source=config.source, section="design", key="noise")
    return np.array([settings.noise[n] for n in outs], float)


def build(config, solver):
    """model -> DMVT form -> LMIs answered by ``solver`` (:mod:`codegen.design.solver`) -> re-check -> step."""
    t0 = time.perf_counter()
    settings = parse(config, solver.tol)
    model = config.load_model()
    params = load_parameters(config.parameter_path)
    sigma = noise_levels(config, settings, model)
    rep = representation.build(model, params, rel_tol=settings.bounds_rel_tol, max_boxes=settings.bounds_max_boxes,
                               max_corners=settings.max_corners)
    t1 = time.perf_counter()
    scaled = dsn.Scaled.of(rep, sigma, config.sample_time)
    synthesis = dsn.design(scaled, settings, solver)
    t2 = time.perf_counter()
    return Build(config, rep, settings, scaled, synthesis,
                 {"representation_s": round(t1 - t0, 3), "design_s": round(t2 - t1, 3)})
