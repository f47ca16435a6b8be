"""The pipeline build of the TS fuzzy UIO family: model -> TS form + Jacobian bounds -> Theorem 1
LMIs (27) -> certificates -> discrete step (16) (:class:`TSFuzzyBuild`)."""
from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass

import casadi as ca

from ...certificate.artifact import artifact_head, significant, solver_certificate
from ...certificate.certificate import Certificate, Recheck, Step
from ...certificate.contraction import ContractionMetric
from ...design.precision import required_margin
from ...design import lock
from ...model import cache, load_parameters
from ...project.observer_file import ObserverConfig
from ...contract.family import ObserverBuild, StepNotes
from . import design as ts_fuzzy_uio
from . import representation as ts_fuzzy


@dataclass(frozen=True)
class TSFuzzyBuild(ObserverBuild):
    """A Nguyen et al. 2021 TS fuzzy UIO: representation, design, certificates (same interface as above)."""

    config: ObserverConfig
    ts: ts_fuzzy.TSFuzzyModel
    design: ts_fuzzy_uio.TSDesign
    recheck: dict
    decrease: dict
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    def step_function(self) -> ca.Function:
        return ts_fuzzy_uio.step_casadi(self.ts, self.design, f"{self.name}_kernel")

    def step_numpy(self, z, u, y):
        return ts_fuzzy_uio.step_numpy(self.ts, self.design, z, u, y)

    def reference_step(self, z, u, y, rho):
        return self.step_numpy(z, u, y)

    def lmi_problem(self):
        return ts_fuzzy_uio.build_problem(self.ts, self.design.T, self.design.settings)

    def contraction_metrics(self) -> list:
        """(27) on the committed P_i: zeta (= x_hat - N y) contracts by the certified lambda in the
        parameter-dependent norm of P(h)."""
        lam = ts_fuzzy_uio.certified_decay(self.ts, self.design)
        if not lam < 1.0:
            return []
        states = tuple(f"zeta_{s}" for s in self.ts.definition.states)
        return [ContractionMetric(lam, tuple(self.design.P), states,
                                  f"(27) with lambda^2 P(h) in the (1,1) blocks passes on the committed matrices "
                                  f"(numpy) at lambda = {lam:.6f}: V(e+) <= lambda^2 V(e), V = e' P(h) e",
                                  knob="[design] decay (lambda imposed by the LMIs)")]

    @property
    def state_names(self) -> list:
        return ts_fuzzy_uio.state_layout(self.ts)

    @property
    def output_names(self) -> list:
        d = self.ts.definition
        return [str(s) for s in d.states] + [str(s) for s in d.unknown_inputs]

    @property
    def input_names(self) -> list:
        d = self.ts.definition
        return [str(s) for s in d.known_inputs] + [f"y_{n}" for n in d.output_names]

    @property
    def nu(self) -> int:
        return len(self.ts.definition.known_inputs)

    @property
    def ny(self) -> int:
        return self.ts.ny

    def scheduling_boxes(self) -> list:
        return [(str(s), *self.ts.state_box[s], True) for s in self.ts.measured]

    def step_notes(self) -> StepNotes:
        return StepNotes(
            notes=("Each call takes y_{k+1} and returns x_hat_{k+1} and the unknown-input estimate d_hat_k",
                   "of the PREVIOUS sample ((16c) needs the next output): the unknown inputs lag one sample.",
                   "The state holds [zeta_k, y_k, primed, x_hat, d_hat]; the outputs are its last entries."),
            clamp=("A measured premise signal outside the compact set D_x (clamped for the model and the\n"
                   " * memberships), or an unmeasured estimate outside D_x: the certificate does not cover this sample."),
            warmup=("there is no previous output y_k yet, so y_{k+1} stands in for it\n"
                    " * and the unknown-input estimate of this sample is not meaningful."))

    @property
    def certificate(self) -> Certificate:
        ts, settings = self.ts, self.design.settings
        d = ts.definition
        r = self.recheck
        lam = settings.decay
        return Certificate(
            family="ts_fuzzy_uio",
            claim=("Theorem 1 of Nguyen et al. 2021 (LMIs (27)): "
                   + (f"V(e_(k+1)) <= {lam:g}^2 V(e_k)" if lam < 1 else "V(e_(k+1)) < V(e_k)")
                   + f" for every membership sequence and every DMVT parameter of the unmeasured consequents "
                   f"{', '.join(str(p) for p in ts.phi) or '(none)'}, so the state estimation error converges; the "
                   f"unknown inputs are reconstructed from the next output (16c)"),
            plant_class=(f"the discrete-time TS model of {d.name} (Euler at Ts = {self.config.sample_time:g} s, "
                         f"parameters of {self.config.parameters}): {ts.n_rules} rules, the unmeasured nonlinearities "
                         f"within sound Jacobian bounds (interval arithmetic) over D_x"
                         + (f"; not tight within [design] bounds_max_boxes (the certificate holds for the larger DMVT "
                            f"box): {'; '.join(ts.loose_bounds)}" if ts.loose_bounds else "")),
            noise="noise-free measurements; the unknown inputs any signals (reconstructed, not bounded)",
            region={str(k): tuple(v) for k, v in ts.state_box.items()},
            region_note=("the compact set D_x of the premises and of the Jacobian bounds; SCHEDULING_CLAMPED flags a "
                         "measured premise outside it, or an estimate of an unmeasured one (the true state is not seen)"),
            recheck=Recheck(r["blocks"], r["worst_block"], r["worst_min_eig"], r["worst_relative_margin"]),
            step=Step(self.config.sample_time, "the discrete-time observer (16) itself", lam,
                      sampled=self.decrease["contraction_per_step"]),
            extras=solver_certificate(self.design.solution, recheck=self.recheck,
                                      lyapunov_decrease_33=self.decrease))

    def input_boxes(self) -> dict:
        """{input name: [min, max]}: the measured outputs that are premises (outside: SCHEDULING_CLAMPED)."""
        names = dict(zip(self.ts.measured, self.ts.definition.output_names))
        return {f"y_{names[s]}": list(self.ts.state_box[s]) for s in self.ts.measured}

    def signal_docs(self) -> tuple:
        """(state, inputs, outputs) field docs of the C API; the outputs are the state's tail."""
        d = self.ts.definition
        units = d.units
        outs = [{"name": n, "doc": f"estimate of {n} [{units.get(n, '-')}]"
                 + (" (previous sample)" if n in map(str, d.unknown_inputs) else "")} for n in self.output_names]
        state = ([{"name": n, "doc": "observer internal state zeta of (16a)"} for n in self.state_names[:self.ts.nx]]
                 + [{"name": f"y_prev_{n}", "doc": f"previous measured {n} [{units.get(n, '-')}]"}
                    for n in d.output_names]
                 + [{"name": "primed", "doc": "1 once a previous output is stored, else 0"}] + outs)
        inputs = ([{"name": str(u), "doc": f"known input {u} [{units.get(str(u), '-')}]"} for u in d.known_inputs]
                  + [{"name": f"y_{n}", "doc": f"measured {n} [{units.get(n, '-')}]"} for n in d.output_names])
        return state, inputs, outs

    def output_lags(self) -> dict:
        """(16c) needs y_{k+1}: the unknown inputs are those of the previous sample."""
        return {str(d): 1 for d in self.ts.definition.unknown_inputs}

    def figures(self) -> dict:
        sol = self.design.solution
        ts = self.ts
        return {
            "rules": ts.n_rules,
            "premises": [f"{p.expr} in [{p.lower:.6g}, {p.upper:.6g}]" for p in ts.premises],
            "unmeasured_consequents": [str(p) for p in ts.phi],
            "jacobian_bounds": {f"d({phi})/d{s}": [b_.lower, b_.upper]
                                for phi, row in zip(ts.phi, ts.jacobian_bounds)
                                for s, b_ in zip(ts.definition.states, row)},
            "dmvt_vertices": int(ts.theta_vertices.shape[0]), "lmi_blocks": len(sol.checks),
            "relaxation": self.design.relaxation,
            "solve_time_s": sol.solve_time_s, "build_time_s": sol.build_time_s,
            "total_design_time_s": self.timings["representation_s"] + self.timings["design_s"],
            "worst_block": self.recheck["worst_block"], "worst_min_eig": self.recheck["worst_min_eig"],
            "worst_relative_margin": self.recheck["worst_relative_margin"],
            "lyapunov_decrease_max_ratio": self.decrease["max_ratio"], "sample_time": self.config.sample_time,
        }

    def artifact(self) -> dict:
        return {
            **artifact_head(self, [p.expr for p in self.ts.premises]),
            "ts_model": significant(self.ts.to_json(), 12),
            **self.design.gains_json(),
        }


REPRESENTATION = "ts_fuzzy_representation"
"""The kind of the kept TS forms and Jacobian bounds (:func:`codegen.model.cache.remembered`: the same for the
same model, parameters and settings every run; a size guard's refusal is never kept)."""


def build(config: ObserverConfig, solver) -> TSFuzzyBuild:
    """Nguyen et al. 2021: model -> TS form + Jacobian bounds -> rank conditions, (30), LMIs (27) -> certificates;
    the LMIs answered by ``solver`` (:mod:`codegen.design.solver`)."""
    from ...settings import parse_settings
    settings = parse_settings(ts_fuzzy_uio.TSDesignSettings, config.design, source=config.source, section="design",
                              **({"tol": solver.tol} if solver.tol is not None else {}))
    if required_margin(settings):       # precision = "float32": (27) imposes lambda <= 1 - float32_margin
        settings = dataclasses.replace(settings, decay=min(settings.decay, 1.0 - required_margin(settings)))
    t0 = time.perf_counter()
    ts = cache.remembered(
        REPRESENTATION, lock.cache_parts(config, settings=settings),
        lambda: ts_fuzzy.build(config.design_model(), load_parameters(config.parameter_path), config.sample_time,
                               rel_tol=settings.bounds_rel_tol, max_boxes=settings.bounds_max_boxes,
                               before_bounds=lambda n, nx, ny, nphi: ts_fuzzy_uio.size_guard(n, nx, ny, 1, settings,
                                                                                             config.source)),
        sys.modules[__name__], ts_fuzzy)
    t1 = time.perf_counter()
    design = ts_fuzzy_uio.design(ts, settings, solver)
    t2 = time.perf_counter()
    cert = ts_fuzzy_uio.certify(ts, design)
    decrease = ts_fuzzy_uio.lyapunov_decrease(ts, design)
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1, "solve_s": design.solution.solve_time_s,
               "build_s": design.solution.build_time_s, "certificates_s": t3 - t2}
    return TSFuzzyBuild(config, ts, design, cert, decrease, timings)
