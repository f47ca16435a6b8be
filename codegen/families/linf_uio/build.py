"""The pipeline build of the L-infinity UIO family: model -> polytope -> Theorem 1 -> certificate
-> backward-Euler step (:class:`LinfBuild`)."""
from __future__ import annotations

import dataclasses
import re
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...design.solver import FreshSolver
from ...representation import polytope
from ...certificate.artifact import artifact_head, significant
from ...certificate.certificate import Bound, Certificate, Recheck, Step, unit_ratio
from ...certificate.contraction import ContractionMetric
from ...design.precision import required_margin
from ...design import lock
from ...model import LPVModel, instantiate, load_parameters
from ...representation.substitution import offer
from ...project.observer_file import ObserverConfig
from ...errors import (CertificateError, ModelDefinitionError, RankConditionError, RepresentationError, SolverError, UILoopError,
                      UiogenError)
from ...contract.family import ObserverBuild, StepNotes
from . import design as linf_uio
from . import discrete


@dataclass(frozen=True)
class LinfBuild(ObserverBuild):
    config: ObserverConfig
    lpv: LPVModel
    poly: polytope.Polytope
    taylor_error: dict | None
    design: linf_uio.LinfDesign
    quadratic: linf_uio.LinfDesign
    recheck: dict
    data: discrete.ObserverData
    discrete_certificate: discrete.DiscreteCertificate
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    def step_function(self) -> ca.Function:
        return discrete.step_casadi(self.data, f"{self.name}_kernel")

    # signal names of the step's vectors
    @property
    def state_names(self) -> list:
        d = self.lpv.definition
        return [str(s) for s in d.states] + [str(s) for s in d.unknown_inputs]

    @property
    def input_names(self) -> list:
        d = self.lpv.definition
        return ([str(s) for s in d.known_inputs] + [f"y_{n}" for n in d.output_names]
                + [str(s.symbol) for s in d.scheduling if s.derived is None])

    @property
    def output_names(self) -> list:
        return self.state_names

    @property
    def nu(self) -> int:
        return self.lpv.nu

    @property
    def ny(self) -> int:
        return self.lpv.ny

    def scheduling_boxes(self) -> list:
        """(name, min, max, derived) of every scheduling signal, for the C header."""
        return [(str(sym), lo, hi, sym not in self.data.raw_signals)
                for sym, lo, hi in zip(self.poly.signals, self.poly.lowers, self.poly.uppers)]

    def step_notes(self) -> StepNotes:
        return StepNotes(clamp=("A scheduling signal outside its box: clamped for the membership functions and the "
                                "step\n * taken; the stability certificate does not cover this sample."),
                         warmup="never set by this observer (its step needs no previous sample).")

    @property
    def certificate(self) -> Certificate:
        d, poly, settings = self.lpv.definition, self.poly, self.design.settings
        dc = self.discrete_certificate
        units = d.units
        perf = list(settings.performance) or [str(x) for x in d.states]
        uis = [str(u) for u in d.unknown_inputs]
        rates = ", ".join(f"[{lo:.4g}, {hi:.4g}]" for lo, hi in poly.rate_bounds)
        # a common quadratic Lyapunov function holds at every vertex whatever the memberships do: no rate bound
        # enters its certificate (with rate_bounds = "none" the polytope records [0, 0], which is not a claim)
        quadratic = settings.lyapunov == "quadratic"
        trajectories = ("for every scheduling trajectory in the box, at any rate (one quadratic Lyapunov function at "
                        "every vertex)" if quadratic else
                        "for every scheduling trajectory in the box whose membership rates stay within the rate bounds")
        rate_note = ("membership rates: any (quadratic Lyapunov function)" if quadratic else
                     f"membership rates within the {poly.rate_bound_mode} bounds {rates} 1/s")
        return Certificate(
            family="linf_uio",
            claim=(f"Theorem 1 of Nguyen et al. 2019 ({settings.lyapunov} Lyapunov function): the estimation error "
                   f"decays at rate alpha = {settings.alpha:g} 1/s and its performance output z = "
                   f"({', '.join(perf)}) has the peak-to-peak gain gamma from the unknown-input estimate's error, "
                   f"{trajectories}"),
            plant_class=(f"the LPV model {d.name} with the parameters of {self.config.parameters}, on its "
                         f"{poly.kind} polytope of {poly.n_vertices} vertices ({polytope.FORMS[poly.kind]})"),
            noise="noise-free measurements; the unknown inputs any bounded signals",
            region={str(sym): (lo, hi) for sym, lo, hi in zip(poly.signals, poly.lowers, poly.uppers)},
            region_note=f"{rate_note}; SCHEDULING_CLAMPED flags a scheduling input outside its box",
            recheck=Recheck.of(self.design.solution.checks),
            step=Step(self.config.sample_time, "backward Euler, the UI filter loop closed",
                      max(dc.contraction, dc.ui_loop.contraction)),
            bounds=(Bound("gamma", self.design.gamma, unit_ratio([units.get(p, "-") for p in perf],
                                                                 [units.get(u, "-") for u in uis]),
                          "peak", f"z = ({', '.join(perf)}), the performance output's estimation error",
                          f"d - d_hat, the error of the unknown-input estimate ({', '.join(uis)})"),),
            extras=_certificate_extras(self))

    def signal_docs(self) -> tuple:
        """(state, inputs, outputs) field docs of the C API; the outputs are the state."""
        d = self.lpv.definition
        units = d.units
        state = [{"name": n, "doc": f"estimate of {n} [{units.get(n, '-')}]"} for n in self.state_names]
        inputs = ([{"name": str(s), "doc": f"known input [{units.get(str(s), '-')}]"} for s in d.known_inputs]
                  + [{"name": f"y_{n}", "doc": f"measured {n} [{units.get(n, '-')}]"} for n in d.output_names]
                  + [{"name": str(s.symbol), "doc": f"scheduling signal [{s.unit or '-'}]"} for s in d.scheduling
                     if s.derived is None])
        return state, inputs, state

    def contraction_metrics(self) -> list:
        """The UI-filter loop's common Lyapunov function: the whole step state [x_hat; d_hat]."""
        ui = self.discrete_certificate.ui_loop
        return [ContractionMetric(ui.contraction, (ui.P,), tuple(self.state_names),
                                  f"common Lyapunov function of the error with the UI filter loop, He(P Aa) <= "
                                  f"-2 beta P over the polytope, beta = {ui.beta:g} 1/s, backward Euler at Ts",
                                  knob="a faster certified UI-filter loop: [design] alpha, [ui_filter] time_constant")]

    def reference_step(self, z, u, y, rho):
        """Independent numpy step (tests, the benchmark's numpy peer)."""
        return discrete.step_numpy(self.data, z, u, y, rho)

    def lmi_problem(self):
        """A fresh LMI problem of this design (benchmark: our path vs CVXPY on the same blocks)."""
        return linf_uio.build_problem(self.poly, self.design.settings, self.design.performance,
                                      self.lpv.definition.states, self.design.ui_gain)[0]

    def input_boxes(self) -> dict:
        """{input name: [min, max]} of the inputs that schedule the step (outside: SCHEDULING_CLAMPED)."""
        return {str(sym): [lo, hi] for sym, lo, hi in zip(self.poly.signals, self.poly.lowers, self.poly.uppers)
                if sym in self.data.raw_signals}

    def derived_input_docs(self) -> list:
        return [{"name": str(sym), "unit": self.lpv.definition.units.get(str(sym), "-")}
                for sym, _ in self.lpv.derived_inputs]

    def artifact(self) -> dict:
        return artifact(self)

    def figures(self) -> dict:
        sol = self.design.solution
        return {
            "gamma": self.design.gamma, "gamma_quadratic": self.quadratic.gamma,
            "vertices": self.poly.n_vertices, "polytope": self.poly.kind, "polytope_form": polytope.FORMS[self.poly.kind],
            "lyapunov": self.design.settings.lyapunov,
            "solve_time_s": sol.solve_time_s, "build_time_s": sol.build_time_s,
            "total_design_time_s": sum(self.timings.values()),
            "solver_iterations": sol.iterations,
            "worst_block": sol.worst.label, "worst_min_eig": sol.worst.min_eig,
            "worst_relative_margin": sol.worst.relative_margin,
            "recheck_gamma": self.recheck["gamma"],
            "discrete_kappa": self.discrete_certificate.kappa,
            "discrete_contraction_per_step": self.discrete_certificate.contraction,
            "discrete_spectral_radius_max": self.discrete_certificate.augmented_radius_max,
            "ui_loop_decay_rate": self.discrete_certificate.ui_loop.beta,
            "ui_loop_contraction_per_step": self.discrete_certificate.ui_loop.contraction,
            "sample_time": self.config.sample_time,
            "taylor_error": self.taylor_error,
        }


def _settings(config: ObserverConfig, lyapunov: str | None = None) -> linf_uio.LinfDesignSettings:
    """The ``[design]`` table, every key and value checked (codegen.settings).

    The TOML key ``gain_bound_times_sample_time`` (default 1.0) is the bound on ||M|| Ts: the field
    ``gain_bound`` is its value / sample_time (``gain_bound`` itself is not a key). ``lyapunov``
    overrides the table's.
    """
    from ...settings import Alias, config_error, parse_settings, suggest
    settings = parse_settings(
        linf_uio.LinfDesignSettings, config.design, source=config.source, section="design",
        aliases={"gain_bound_times_sample_time": Alias("gain_bound", lambda v: v / config.sample_time, default=1.0)},
        **({"lyapunov": lyapunov} if lyapunov else {}))
    states = [str(x) for x in config.design_model().states]
    try:
        linf_uio.performance_matrix(states, settings.performance)
    except ValueError as exc:
        unknown = [p for p in settings.performance if p not in states]
        raise config_error(config.source, "design", "performance", list(settings.performance), str(exc),
                           suggest(unknown[0], states) if unknown else None) from None
    if settings.lyapunov == "pdlf" and config.rate_bounds == "none":
        raise config_error(config.source, "design", "lyapunov", "pdlf",
                           'the parameter-dependent design needs membership rate bounds; with rate_bounds = "none" '
                           'use lyapunov = "quadratic"')
    return settings


REPRESENTATION = "linf_representation"
"""The kind of the kept representations (:func:`codegen.model.cache.remembered`)."""


def representation(config: ObserverConfig):
    """(LPV model, polytope, its Taylor error or None) of ``config``: the same for the same model, parameters
    and settings every run, so kept across runs (:func:`codegen.model.cache.remembered`, keyed by the design's
    inputs)."""
    import sys

    from ...model import cache
    return cache.remembered(REPRESENTATION, lock.cache_parts(config), lambda: _representation(config),
                            sys.modules[__name__])


def _representation(config: ObserverConfig):
    lpv = instantiate(config.design_model(), load_parameters(config.parameter_path), unknown_input_hint=offer)
    if config.polytope == "taylor_reduced":
        poly = polytope.taylor_reduced_polytope(lpv, config.rate_bounds)
        err = polytope.taylor_error(lpv, poly)
    elif config.polytope == "sector":
        poly = polytope.sector_polytope(lpv, config.rate_bounds)
        err = None
    else:
        raise ModelDefinitionError(f"{config.source}: polytope must be 'taylor_reduced' or 'sector'")
    return lpv, poly, err


def build(config: ObserverConfig, solver) -> LinfBuild:
    """Run model -> polytope -> LMI design -> certificate -> discrete certificate, the design
    problems answered by ``solver`` (:mod:`codegen.design.solver`)."""
    t0 = time.perf_counter()
    lpv, poly, err = representation(config)
    t1 = time.perf_counter()
    settings = _settings(config)
    if solver.tol is not None:
        settings = dataclasses.replace(settings, tol=solver.tol)
    if err is not None and err["relative_error_there"] > settings.taylor_error_limit:
        raise RepresentationError(
            f"{config.source}: the Taylor-reduced polytope misses A(rho) by {100 * err['relative_error_there']:.1f} % "
            f"(entry A{tuple(err['entry'])} at {poly.signal} = {err['at']:g}: {err['max_abs_error']:.4g}), more than "
            f"[design] taylor_error_limit = {settings.taylor_error_limit:g}; use the exact form, polytope = \"sector\" "
            f"({2 ** len(polytope.scheduling_nonlinearities(lpv))} vertices), or narrow the scheduling box")
    bound, vertex = linf_uio.decay_bound(poly, settings.gain_bound)
    if not settings.alpha < bound:
        from ...settings import config_error
        bound_ts = settings.gain_bound * config.sample_time
        raise config_error(
            config.source, "design", "alpha", config.design.get("alpha", settings.alpha),
            f"must be < {bound:.4g} 1/s with sample_time = {config.sample_time:g} s and gain_bound_times_sample_time "
            f"= {bound_ts:g}: the observer gain is bounded by ||M|| <= {bound_ts:g} / {config.sample_time:g} s = "
            f"{settings.gain_bound:.4g} 1/s, and Theorem 1 then certifies no decay rate alpha >= (||M|| ||C||_* - "
            f"tr A) / n = {bound:.4g} 1/s (the trace of LMI (21) at vertex {vertex + 1}); a faster decay needs a "
            f"shorter sample_time or a larger gain_bound_times_sample_time")
    try:
        design = linf_uio.design(poly, settings, solver, lpv.definition.states)
        quadratic = design if settings.lyapunov == "quadratic" else \
            linf_uio.design(poly, dataclasses.replace(settings, lyapunov="quadratic"), solver, lpv.definition.states)
    except RankConditionError as exc:
        raise RankConditionError(f"{config.source}: {exc}") from None
    except (SolverError, CertificateError) as exc:
        if time.perf_counter() - t1 > RETRY_WITHIN_S:
            raise
        said, remedy = _solver_remedies(poly, settings, lpv.definition.states)
        text = str(exc)
        if remedy:          # the generic ways out give way to the one measured
            text = re.sub(r"; loosen the tolerance \(now [^)]*\), rescale the data, or relax the design constraints",
                          "", text)
        exc.args = (f"{config.source}: {text}{said}",)   # the same error, its advice measured
        exc.remedy = remedy
        raise exc from None
    if design.gamma > quadratic.gamma:
        # the quadratic design is a point of the PDLF problem (P_i = P, X = 0, the rate terms
        # cancel): PDLF never returns worse than what it contains
        design = dataclasses.replace(quadratic, settings=settings, fallback="quadratic (the PDLF optimum was worse)")
    t2 = time.perf_counter()
    cert = linf_uio.certify(poly, design.P, design.X, design.L, settings.alpha, design.performance)
    data = discrete.ObserverData(poly, design.Q, design.L,
                                 float(config.ui_filter.get("time_constant", 0.005)), config.sample_time,
                                 lpv.derived, lpv.definition.output_symbols, lpv.derived_inputs)
    try:
        dcert = discrete.certify_step(data, settings.alpha, solver, min_margin=required_margin(settings))
    except UILoopError as exc:
        raise UILoopError(f"{config.source}: {exc}"
                          f"{_measured_remedies(poly, settings, data, config.sample_time, lpv.definition.states)}",
                          remedy=exc.remedy) from None
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1,
               "solve_s": design.solution.solve_time_s, "build_s": design.solution.build_time_s,
               "certificates_s": t3 - t2}
    return LinfBuild(config, lpv, poly, err, design, quadratic, cert, data, dcert, timings)


#: a failed solve that took less than this many seconds is retried with the settings that may work
#: (:func:`_solver_remedies`): a few designs of about its cost, so the error names a measured fix
RETRY_WITHIN_S = 30.0


def _solver_remedies(poly, settings, states: tuple = ()) -> tuple:
    """(text, remedy) after a solver failure of Theorem 1: the design again with [design] lyapunov =
    "quadratic" (one Lyapunov matrix: fewer, better-conditioned blocks), then with alpha at a half
    and a tenth, then both; the first that the solver answers and the numpy re-check certifies is
    named (remedy {"design.KEY": value}, which ``uiogen analyze`` designs again with), else the
    text says that none of them does. Measurements with their own solver: nothing is committed."""
    tries = []
    if settings.lyapunov != "quadratic":
        tries.append({"lyapunov": "quadratic"})
    for factor in (2, 10):
        tries.append({"alpha": float(f"{settings.alpha / factor:.3g}")})
        if settings.lyapunov != "quadratic":
            tries.append({"lyapunov": "quadratic", "alpha": float(f"{settings.alpha / factor:.3g}")})
    for change in tries:
        try:
            d = linf_uio.design(poly, dataclasses.replace(settings, **change), FreshSolver(), states)
        except UiogenError:
            continue
        shown = " with ".join(f"{k} = {toml_value(v)}" for k, v in change.items())
        return (f"; measured: with [design] {shown} the design is solved and certified (gamma = {d.gamma:.4g}; "
                f"a lower alpha certifies a slower decay)" if "alpha" in change else
                f"; measured: with [design] {shown} the design is solved and certified (gamma = {d.gamma:.4g})",
                {f"design.{k}": v for k, v in change.items()})
    tried = ", ".join(" with ".join(f"{k} = {toml_value(v)}" for k, v in c.items()) for c in tries)
    return f"; measured: [design] {tried} do not solve either", {}


def toml_value(v) -> str:
    return f'"{v}"' if isinstance(v, str) else f"{v:g}"


def _measured_remedies(poly, settings, data, sample_time: float, states: tuple = ()) -> str:
    """Re-design with alpha halved, the gain bound halved, and both, and say which of them closes
    a certifiable UI filter loop (the designs are measurements, not committed)."""
    tries = (("alpha", dataclasses.replace(settings, alpha=settings.alpha / 2)),
             ("gain_bound_times_sample_time", dataclasses.replace(settings, gain_bound=settings.gain_bound / 2)),
             ("both", dataclasses.replace(settings, alpha=settings.alpha / 2, gain_bound=settings.gain_bound / 2)))
    works = []
    for label, s in tries:
        try:        # a measurement: its own solver, nothing goes to the design lock
            d = linf_uio.design(poly, s, FreshSolver(), states)
        except UiogenError:
            continue
        if discrete.loop_is_certifiable(dataclasses.replace(data, Q=d.Q, L=d.L)):
            works.append({"alpha": f"alpha = {s.alpha:g}",
                          "gain_bound_times_sample_time": f"gain_bound_times_sample_time = {s.gain_bound * sample_time:g}",
                          "both": f"alpha = {s.alpha:g} with gain_bound_times_sample_time = "
                                  f"{s.gain_bound * sample_time:g}"}[label])
    if works:
        return f"; re-designed with [design] {' or '.join(works[:2])}, it certifies"
    return "; re-designed with [design] alpha, the gain bound, or both halved, it does not certify either"


def _certificate_extras(b: LinfBuild) -> dict:
    """The family's own figures of the certificate: every solver block, the numpy re-check of
    Theorem 1 on the emitted matrices (mu, nu, gamma), the discrete step's certificates."""
    sol = b.design.solution
    worst = sol.worst
    return {
        "solver_blocks": [significant({"label": c.label, "min_eig": c.min_eig,
                                       "relative_margin": c.relative_margin}) for c in sol.checks],
        "worst_block": worst.label,
        "worst_min_eig": significant(worst.min_eig),
        "worst_relative_margin": significant(worst.relative_margin),
        "recheck": significant(b.recheck),
    }


def artifact(b: LinfBuild) -> dict:
    """The design artifact: everything needed to re-check the design without uiogen."""
    gains = {f"M{i + 1}": np.linalg.solve(q, l).tolist() for i, (q, l) in enumerate(zip(b.design.Q, b.design.L))}
    derived = ({"derived_inputs": {str(sym): str(expr) for sym, expr in b.lpv.derived_inputs}}
               if b.lpv.derived_inputs else {})
    return {
        **artifact_head(b, b.poly.signals, **derived),
        "polytope": b.poly.to_json(),
        "taylor_error": significant(b.taylor_error),
        **b.design.gains_json(),
        "alpha": b.design.settings.alpha,
        "gain_bound": b.design.settings.gain_bound,
        "gains_at_vertices": gains,
        "quadratic": {"gamma": b.quadratic.gamma, "P": b.quadratic.P[0].tolist(),
                      "L": [l.tolist() for l in b.quadratic.L]},
        "discrete": {"ui_filter_time_constant": b.data.Tf, **significant(b.discrete_certificate.to_json())},
    }
