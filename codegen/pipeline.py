"""The pipeline, in order: model -> representation -> design -> certificate -> discrete step.

:func:`build` runs every stage for one observer configuration and returns an
:class:`ObserverBuild`; :mod:`codegen.emit` turns it into C and
:mod:`python_bindings` compiles that into an extension.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from . import design_lock, discrete, lmi, polytope, ts_fuzzy
from .designs import linf_uio, ts_fuzzy_uio
from .errors import ModelDefinitionError
from .model import LPVModel, instantiate, load_parameters
from .observers import ObserverConfig


@dataclass(frozen=True)
class ObserverBuild:
    config: ObserverConfig
    lpv: LPVModel
    poly: polytope.Polytope
    taylor_error: dict | None
    design: linf_uio.LinfDesign
    quadratic: linf_uio.LinfDesign
    certificate: dict
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

    def emit_notes(self) -> dict:
        """Family-specific text of the C API."""
        return {
            "headline": f"gamma = {self.design.gamma:.6g}",
            "stability": (f"backward Euler, certified: sqrt(V) contracts by "
                          f"{self.discrete_certificate.contraction:.6f} per step over the whole scheduling box"),
            "step_notes": [],
            "clamp_doc": ("A scheduling signal outside its box: clamped for the membership functions and the "
                          "step\n * taken; the stability certificate does not cover this sample."),
            "warmup_doc": "never set by this observer (its step needs no previous sample).",
            "has_warmup": False,
        }

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

    def reference_step(self, z, u, y, rho):
        """Independent numpy step (tests, the benchmark's numpy peer)."""
        return discrete.step_numpy(self.data, z, u, y, rho)

    def lmi_problem(self):
        """A fresh LMI problem of this design (benchmark: our path vs CVXPY on the same blocks)."""
        return linf_uio.build_problem(self.poly, self.design.settings)[0]

    def input_boxes(self) -> dict:
        """{input name: [min, max]} of the inputs that schedule the step (outside: SCHEDULING_CLAMPED)."""
        return {str(sym): [lo, hi] for sym, lo, hi in zip(self.poly.signals, self.poly.lowers, self.poly.uppers)
                if sym in self.data.raw_signals}

    def derived_input_docs(self) -> list:
        return [{"name": str(sym), "unit": self.lpv.definition.units.get(str(sym), "-")}
                for sym, _ in self.lpv.derived_inputs]

    def artifact(self) -> dict:
        return artifact(self)


@dataclass(frozen=True)
class TSFuzzyBuild:
    """A seed-004 TS fuzzy UIO: representation, design, certificates (same interface as above)."""

    config: ObserverConfig
    ts: ts_fuzzy.TSFuzzyModel
    design: ts_fuzzy_uio.TSDesign
    certificate: dict
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

    def emit_notes(self) -> dict:
        return {
            "headline": f"LMIs (27) worst margin {self.certificate['worst_min_eig']:.3g}",
            "stability": (f"seed-004 Theorem 1: V(e+) < V(e) for all memberships and DMVT parameters; "
                          f"sampled (33): sqrt(V) contracts by {self.decrease['contraction_per_step']:.6f} per step"),
            "step_notes": [
                "Each call takes y_{k+1} and returns x_hat_{k+1} and the unknown-input estimate d_hat_k",
                "of the PREVIOUS sample ((16c) needs the next output): the unknown inputs lag one sample.",
                "The state holds [zeta_k, y_k, primed, x_hat, d_hat]; the outputs are its last entries.",
            ],
            "clamp_doc": ("A measured premise signal outside the compact set D_x (clamped for the model and the\n"
                          " * memberships), or an unmeasured estimate outside D_x: the certificate does not cover this sample."),
            "warmup_doc": ("there is no previous output y_k yet, so y_{k+1} stands in for it\n"
                           " * and the unknown-input estimate of this sample is not meaningful."),
            "has_warmup": True,
        }

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
        inputs = [{"name": f"y_{n}", "doc": f"measured {n} [{units.get(n, '-')}]"} for n in d.output_names]
        return state, inputs, outs

    def artifact(self) -> dict:
        return {
            **artifact_head(self, [p.expr for p in self.ts.premises]),
            "ts_model": _sig(self.ts.to_json(), 12),
            **self.design.gains_json(),
            "certificate": solver_certificate(self.design.solution, recheck=self.certificate,
                                              lyapunov_decrease_33=self.decrease),
        }


def _settings(config: ObserverConfig, lyapunov: str | None = None) -> linf_uio.LinfDesignSettings:
    """The ``[design]`` table, every key and value checked (codegen.settings).

    The TOML key ``gain_bound_times_sample_time`` (default 1.0) is the bound on ||M|| Ts: the field
    ``gain_bound`` is its value / sample_time (``gain_bound`` itself is not a key). ``lyapunov``
    overrides the table's.
    """
    from .settings import Alias, config_error, parse_settings
    settings = parse_settings(
        linf_uio.LinfDesignSettings, config.design, source=config.source, section="design",
        aliases={"gain_bound_times_sample_time": Alias("gain_bound", lambda v: v / config.sample_time, default=1.0)},
        **({"lyapunov": lyapunov} if lyapunov else {}))
    if settings.lyapunov == "pdlf" and config.rate_bounds == "none":
        raise config_error(config.source, "design", "lyapunov", "pdlf",
                           'the parameter-dependent design needs membership rate bounds; with rate_bounds = "none" '
                           'use lyapunov = "quadratic"')
    return settings


def representation(config: ObserverConfig):
    lpv = instantiate(config.load_model(), load_parameters(config.parameter_path))
    if config.polytope == "taylor_reduced":
        poly = polytope.taylor_reduced_polytope(lpv, config.rate_bounds)
        err = polytope.taylor_error(lpv, poly)
    elif config.polytope == "sector":
        poly = polytope.sector_polytope(lpv, config.rate_bounds)
        err = None
    else:
        raise ModelDefinitionError(f"{config.source}: polytope must be 'taylor_reduced' or 'sector'")
    return lpv, poly, err


def build_ts_fuzzy(config: ObserverConfig, tol: float | None = None) -> TSFuzzyBuild:
    """Seed 004: model -> TS form + Jacobian bounds -> rank conditions, (30), LMIs (27) -> certificates."""
    from .settings import parse_settings
    settings = parse_settings(ts_fuzzy_uio.TSDesignSettings, config.design, source=config.source, section="design",
                              **({"tol": tol} if tol is not None else {}))
    t0 = time.perf_counter()
    ts = ts_fuzzy.build(config.load_model(), load_parameters(config.parameter_path), config.sample_time)
    t1 = time.perf_counter()
    design = ts_fuzzy_uio.design(ts, settings)
    t2 = time.perf_counter()
    cert = ts_fuzzy_uio.certify(ts, design)
    decrease = ts_fuzzy_uio.lyapunov_decrease(ts, design)
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1, "solve_s": design.solution.solve_time_s,
               "build_s": design.solution.build_time_s, "certificates_s": t3 - t2}
    return TSFuzzyBuild(config, ts, design, cert, decrease, timings)


def build(config: ObserverConfig, tol: float | None = None, fresh: bool = False):
    """The observer of ``config``: its committed design (:mod:`codegen.design_lock`) when it is
    current, replayed and re-checked block by block; otherwise (or with ``fresh`` or a solver
    ``tol``) a new solve. Use :func:`solve` to also get the LMI solutions for a new lock."""
    if not fresh and tol is None:
        data, _ = design_lock.status(config)
        if data is not None:
            where = str(design_lock.path(config))
            with lmi.replaying(design_lock.solutions(data, where), source=where):
                return _build_family(config, None)
    return _build_family(config, tol)


def solve(config: ObserverConfig, tol: float | None = None) -> tuple:
    """A fresh design of ``config`` and the LMI solutions it solved: (build, [SolveRecord])."""
    with lmi.recording() as ledger:
        b = _build_family(config, tol)
    return b, list(ledger.records)


def _build_family(config: ObserverConfig, tol: float | None = None):
    """Run the pipeline of the configuration's family; returns its build."""
    if config.family == "ts_fuzzy_uio":
        return build_ts_fuzzy(config, tol)
    if config.family == "interconnected_uio":
        from .designs import interconnected_uio
        return interconnected_uio.build(config, tol)
    if config.family == "switched_pi":
        from .switched_pipeline import build_switched_pi
        return build_switched_pi(config, tol)
    if config.family == "algebraic_uio":
        from . import algebraic_uio
        return algebraic_uio.build(config, tol)
    return build_linf(config, tol)


def build_linf(config: ObserverConfig, tol: float | None = None) -> ObserverBuild:
    """Run model -> polytope -> LMI design -> certificate -> discrete certificate."""
    t0 = time.perf_counter()
    lpv, poly, err = representation(config)
    t1 = time.perf_counter()
    settings = _settings(config)
    if tol is not None:
        settings = dataclasses.replace(settings, tol=tol)
    design = linf_uio.design(poly, settings)
    quadratic = design if settings.lyapunov == "quadratic" else \
        linf_uio.design(poly, dataclasses.replace(settings, lyapunov="quadratic"))
    t2 = time.perf_counter()
    cert = linf_uio.certify(poly, design.P, design.X, design.L, settings.alpha)
    data = discrete.ObserverData(poly, design.Q, design.L,
                                 float(config.ui_filter.get("time_constant", 0.005)), config.sample_time,
                                 lpv.derived, lpv.definition.output_symbols, lpv.derived_inputs)
    dcert = discrete.certify_step(data, settings.alpha)
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1,
               "solve_s": design.solution.solve_time_s, "build_s": design.solution.build_time_s,
               "certificates_s": t3 - t2}
    return ObserverBuild(config, lpv, poly, err, design, quadratic, cert, data, dcert, timings)


def artifact_head(b, scheduling: list, **signals) -> dict:
    """The part of every family's design artifact that names the observer and its signals."""
    return {"observer": b.name, "config": b.config.to_json(),
            "signals": {"state": b.state_names, "input": b.input_names, "output": b.output_names,
                        "scheduling": [str(x) for x in scheduling], "input_boxes": b.input_boxes(), **signals}}


def solver_certificate(sol, **rechecks) -> dict:
    """Solver's worst block and the independent re-checks, as every family's artifact reports them."""
    return {"solver_blocks": len(sol.checks), "solver_worst_block": sol.worst.label,
            "solver_worst_min_eig": _sig(sol.worst.min_eig), **{k: _sig(v) for k, v in rechecks.items()}}


def _sig(x, digits=6):
    """Round report figures so the committed artifact does not depend on last-bit noise."""
    if isinstance(x, dict):
        return {k: _sig(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_sig(v, digits) for v in x]
    if isinstance(x, float) and np.isfinite(x):
        return float(f"{x:.{digits}g}")
    return x


def artifact(b: ObserverBuild) -> dict:
    """The design artifact: everything needed to re-check the design without uiogen."""
    sol = b.design.solution
    worst = sol.worst
    gains = {f"M{i + 1}": np.linalg.solve(q, l).tolist() for i, (q, l) in enumerate(zip(b.design.Q, b.design.L))}
    derived = ({"derived_inputs": {str(sym): str(expr) for sym, expr in b.lpv.derived_inputs}}
               if b.lpv.derived_inputs else {})
    return {
        **artifact_head(b, b.poly.signals, **derived),
        "polytope": b.poly.to_json(),
        "taylor_error": _sig(b.taylor_error),
        **b.design.gains_json(),
        "alpha": b.design.settings.alpha,
        "gain_bound": b.design.settings.gain_bound,
        "gains_at_vertices": gains,
        "quadratic": {"gamma": b.quadratic.gamma, "P": b.quadratic.P[0].tolist(),
                      "L": [l.tolist() for l in b.quadratic.L]},
        "certificate": {
            "solver_blocks": [_sig({"label": c.label, "min_eig": c.min_eig,
                                    "relative_margin": c.relative_margin}) for c in sol.checks],
            "worst_block": worst.label,
            "worst_min_eig": _sig(worst.min_eig),
            "worst_relative_margin": _sig(worst.relative_margin),
            "recheck": _sig(b.certificate),
        },
        "discrete": {"ui_filter_time_constant": b.data.Tf, **_sig(b.discrete_certificate.to_json())},
    }
