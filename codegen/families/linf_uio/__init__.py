"""LPV L-infinity unknown-input observer with a parameter-dependent Lyapunov function.

Nguyen, Guerra, Sentouh, Zhang, "Unknown Input Observers for Simultaneous Estimation of Vehicle
Dynamics and Driver Torque: Theoretical Design and Hardware Experiments", IEEE/ASME
Transactions on Mechatronics 24(6), 2019 (Theorem 1, eqs. (19)-(23); UI filter (47)).

``representation``: :mod:`codegen.representation.polytope` (sector or Taylor-reduced polytope); ``design``:
Theorem 1; ``discrete``: the backward-Euler step and its certificate; ``build``: the pipeline;
``validation``: the paper's scenarios on the Pacejka, exact-model and CommonRoad plants.
"""
from __future__ import annotations

import numpy as np

from ...errors import ConfigurationError
from ...project.settings import Rule, parse_table
from ..base import Family

UI_FILTER_KEYS = {"time_constant": Rule(float, gt=0, doc="T_f of the UI filter (47), s")}


class LinfUIO(Family):
    name = "linf_uio"
    title = "LPV L-infinity unknown-input observer"
    citation = "Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019"
    short_citation = "Nguyen et al. 2019"
    observer_keys = {"polytope": Rule(str, choices=("taylor_reduced", "sector"), required=True),
                     "rate_bounds": Rule(str, choices=("exact", "at_expansion_point", "none")),
                     "ui_filter": Rule(dict)}
    demo_scenarios = ("track_varying_speed", "takeover_opposing_assist")
    example = "lpv_linf_driver_torque_sector"      # starters use the exact polytope (the paper's is an approximation)
    campaign_plant = "steering_torque"
    certified_gain_norm = "peak"

    def check_config(self, config, data: dict) -> None:
        parse_table(data.get("ui_filter", {}), UI_FILTER_KEYS, source=config.source, section="ui_filter")

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, tol=None):
        from .build import build
        return build(config, tol)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run
        return run(config, scenario, plant, duration, seed, progress=progress, observer=observer)

    def format_validation(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def validation_header(self, name: str, result: dict) -> str:
        from ...validation.common import SETTLE_TIME
        return (f"{name}: scenario {result['scenario']} on the {result['plant']} plant ({result['plant_model']}), "
                f"{result['samples']} samples, max |a_y| {result['max_abs_ay']:.2f} m/s^2, {result['status_flags']} "
                f"flagged samples; errors after {SETTLE_TIME:g} s (angles in degrees)")

    def demo_report(self, art: dict) -> dict:
        return {"gamma": art["gamma"], "gamma_quadratic": art["quadratic"]["gamma"],
                "worst_lmi_margin": art["certificate"]["worst_min_eig"],
                "worst_lmi_block": art["certificate"]["worst_block"], "discrete": art["discrete"]}

    def demo_lines(self, e: dict) -> list:
        d = e["discrete"]
        return [f"gamma {e['gamma']:.6g} (quadratic {e['gamma_quadratic']:.6g}); worst LMI margin "
                f"{e['worst_lmi_margin']:.3g} in {e['worst_lmi_block']}",
                f"discrete step Ts={d['Ts']:g}s, certified: sqrt(V) contracts by {d['contraction_per_step']:.6f}/step "
                f"(state error), {d['ui_loop_contraction_per_step']:.6f}/step with the UI filter loop; dense-grid "
                f"spectral radius {d['dense_grid_augmented_spectral_radius_max']:.6f}"]

    def check_gains(self, config, gains: dict) -> dict:
        """P_i, X, L_i (the paper's printed form) against Theorem 1, with both rate bounds of the
        Taylor-reduced polytope; anything else in the design-lock form (``lmi_solutions``)."""
        if "lmi_solutions" in gains:
            return super().check_gains(config, gains)
        from ...representation import polytope
        from .build import _settings, representation
        from .design import certify, performance_matrix
        lpv, poly, _ = representation(config)
        performance = _settings(config).performance
        F = performance_matrix(lpv.definition.states, performance)
        alpha = float(gains.get("alpha", config.design.get("alpha", 5.0)))
        N = poly.n_vertices
        missing = [k for k in [*(f"P{i + 1}" for i in range(N)), *(f"L{i + 1}" for i in range(N))] if k not in gains]
        if missing:
            raise ConfigurationError(f"gains lack {', '.join(missing)} (observer {config.name} has {N} vertices: "
                                     f"P1..P{N}, L1..L{N} and optionally X)", key=missing[0])
        try:
            P = [np.array(gains[f"P{i + 1}"], float) for i in range(N)]
            L = [np.array(gains[f"L{i + 1}"], float) for i in range(N)]
            X = np.array(gains.get("X", np.zeros_like(P[0])), float)
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"gains: a matrix is not an array of numbers ({exc})") from None
        shapes = [("X", X, (lpv.nx, lpv.nx))] + [(f"P{i + 1}", p, (lpv.nx, lpv.nx)) for i, p in enumerate(P)] \
            + [(f"L{i + 1}", m, (lpv.nx, lpv.ny)) for i, m in enumerate(L)]
        for label, m, shape in shapes:
            if m.shape != shape:
                raise ConfigurationError(f"gains: {label} has shape {m.shape}, expected {shape}", key=label)
        make = polytope.taylor_reduced_polytope if poly.kind == "taylor_reduced" else polytope.sector_polytope
        out = {"observer": config.name, "alpha": alpha, "form": "theorem_1", "results": {},
               "polytope": poly.kind, "polytope_form": polytope.FORMS[poly.kind],
               "performance": list(performance) or [str(x) for x in lpv.definition.states]}
        for mode in ("exact", "at_expansion_point") if poly.kind == "taylor_reduced" else ("exact",):
            p = make(lpv, mode)
            res = certify(p, P, X, L, alpha, F)
            res["rate_bounds"] = p.rate_bounds.tolist()
            out["results"][mode] = res
        M = [np.linalg.solve(P[i] + X, L[i]) for i in range(N)]
        out["gain_norm_max"] = max(float(np.linalg.norm(m, 2)) for m in M)
        for key in ("gamma", "gamma_stated"):
            if key in gains:
                out[f"{key}_in_file"] = gains[key]
        return out

    def format_check_gains(self, res: dict, source: str) -> list:
        if res.get("form") != "theorem_1":
            return super().format_check_gains(res, source)
        lines = [f"Theorem 1 ({self.short_citation}) check of {source} on observer {res['observer']} "
                 f"(alpha = {res['alpha']:g}, performance output z = {', '.join(res.get('performance', []))})"]
        for mode, r in res["results"].items():
            label = {"exact": "sound rate bounds over the whole box",
                     "at_expansion_point": "rate bounds of the paper's eq. (11)"}[mode]
            lines.append(f"  [{label}: phi = {r['rate_bounds'][0]}]")
            for blk in r["blocks"]:
                if "min_eig" in blk:
                    lines.append(f"    {blk['label']:45s} min eig {blk['min_eig']:.6g}")
                else:
                    lines.append(f"    {blk['label']:45s} max eig (state block) {blk['max_eig_state_block']:.6g}, "
                                 f"needs nu >= {blk['nu_needed']:.6g}")
            verdict = "PASS" if r["feasible"] else "FAIL"
            lines.append(f"    {verdict}: certified gamma = sqrt(mu nu) = sqrt({r['mu']:.6g} * {r['nu']:.6g}) = "
                         f"{r['gamma']:.6g}")
        lines.append(f"  max ||M_i|| = {res['gain_norm_max']:.4g} 1/s")
        for key in ("gamma_in_file", "gamma_stated_in_file"):
            if key in res:
                lines.append(f"  {key.replace('_in_file', '')} stated in the file: {res[key]}")
        return lines


FAMILY = LinfUIO()
