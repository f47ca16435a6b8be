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

from . import discrete, polytope
from .designs import linf_uio
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


def _settings(config: ObserverConfig, lyapunov: str | None = None) -> linf_uio.LinfDesignSettings:
    d = dict(config.design)
    known = {"alpha", "lyapunov", "gain_bound_times_sample_time", "margin", "tol"}
    unknown = set(d) - known
    if unknown:
        raise ModelDefinitionError(f"{config.source}: unknown [design] keys {sorted(unknown)}")
    return linf_uio.LinfDesignSettings(
        alpha=float(d.get("alpha", 5.0)),
        lyapunov=lyapunov or d.get("lyapunov", "pdlf"),
        gain_bound=float(d.get("gain_bound_times_sample_time", 1.0)) / config.sample_time,
        margin=float(d.get("margin", 1e-5)),
        tol=float(d.get("tol", 1e-8)))


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


def build(config: ObserverConfig, tol: float | None = None) -> ObserverBuild:
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
                                 lpv.derived, lpv.definition.output_symbols)
    dcert = discrete.certify_step(data, settings.alpha)
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1,
               "solve_s": design.solution.solve_time_s, "build_s": design.solution.build_time_s,
               "certificates_s": t3 - t2}
    return ObserverBuild(config, lpv, poly, err, design, quadratic, cert, data, dcert, timings)


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
    return {
        "observer": b.name,
        "config": b.config.to_json(),
        "signals": {"state": b.state_names, "input": b.input_names,
                    "scheduling": [str(x) for x in b.poly.signals]},
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
