"""LPV L-infinity unknown-input observer with a parameter-dependent Lyapunov function.

Nguyen, Guerra, Sentouh, Zhang, "Unknown Input Observers for Simultaneous Estimation of Vehicle
Dynamics and Driver Torque: Theoretical Design and Hardware Experiments", IEEE/ASME
Transactions on Mechatronics 24(6), 2019 (Theorem 1, eqs. (19)-(23); UI filter (47)).

``representation``: :mod:`codegen.representation.polytope` (sector or Taylor-reduced polytope); ``design``:
Theorem 1; ``discrete``: the backward-Euler step and its certificate; ``build``: the pipeline;
``validation``: the paper's scenarios on the Pacejka, exact-model and CommonRoad plants.
"""
from __future__ import annotations

import math
import re

import numpy as np

from ...errors import ConfigurationError, brief
from ...settings import Rule, parse_table
from ...contract.family import Family

UI_FILTER_KEYS = {"time_constant": Rule(float, gt=0, doc="T_f of the UI filter (47), s")}


class LinfUIO(Family):
    name = "linf_uio"
    title = "LPV L-infinity unknown-input observer"
    citation = "Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019"
    short_citation = "Nguyen et al. 2019"
    observer_keys = {"polytope": Rule(str, choices=("taylor_reduced", "sector"), required=True),
                     "rate_bounds": Rule(str, choices=("exact", "at_expansion_point", "none")),
                     "ui_filter": Rule(dict)}
    example = "lpv_linf_driver_torque_sector"      # starters use the exact polytope (the paper's is an approximation)
    # capabilities (codegen.contract.capabilities): Scenarios, DemoFigures, Campaigns, Applicability, GainForms
    demo_scenarios = ("track_varying_speed", "takeover_opposing_assist")
    table_note = "angles in degrees"
    campaign_plant = "steering_torque"
    certified_gain_norm = "peak"

    def check_config(self, config, data: dict) -> None:
        parse_table(data.get("ui_filter", {}), UI_FILTER_KEYS, source=config.source, section="ui_filter")

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run
        return run(config, scenario, plant, duration, seed, progress=progress, observer=observer)

    def validation_table(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def sensor_noise(self) -> dict:
        from ...project.sensor_noise import SENSOR_NOISE
        return dict(SENSOR_NOISE)

    def demo_report(self, art: dict) -> dict:
        extras = art["certificate"]["extras"]
        return {"gamma": art["gamma"], "gamma_quadratic": art["quadratic"]["gamma"],
                "worst_lmi_margin": extras["worst_min_eig"], "worst_lmi_block": extras["worst_block"],
                "discrete": art["discrete"]}

    def check_gain_form(self, config, gains: dict, source: str):
        """P_i, X, L_i (the paper's printed form) against Theorem 1, with both rate bounds of the
        Taylor-reduced polytope (one case each)."""
        from ...certificate.gains import GainsCheck
        from ...representation import polytope
        from .build import _settings, representation
        from .design import certify, performance_matrix
        lpv, poly, _ = representation(config)
        performance = _settings(config).performance
        F = performance_matrix(lpv.definition.states, performance)
        N = poly.n_vertices
        try:
            alpha = float(gains.get("alpha", config.design.get("alpha", 5.0)))
        except (TypeError, ValueError):
            alpha = math.nan
        if not (math.isfinite(alpha) and alpha > 0):
            raise ConfigurationError(f"gains file {source}: alpha = {gains.get('alpha')!r}; allowed: a positive "
                                     f"number (the decay rate in 1/s)", source=str(source), key="alpha")
        form = f"P1..P{N}, L1..L{N} and optionally X, alpha (observer {config.name} has {N} vertices)"

        def refuse(message, key):
            raise ConfigurationError(f"gains file {source}: {message}; allowed: {form}", source=str(source), key=key)

        missing = [k for k in [*(f"P{i + 1}" for i in range(N)), *(f"L{i + 1}" for i in range(N))] if k not in gains]
        if missing:
            refuse(f"lacks {', '.join(missing)}", missing[0])
        beyond = sorted(k for k in gains if re.fullmatch(r"[PL]\d+", k) and not 1 <= int(k[1:]) <= N)
        if beyond:              # a gain of a vertex this observer does not have: the file is for another polytope
            refuse(f"has {', '.join(beyond)}", beyond[0])
        matrices = {}
        for key, shape in [("X", (lpv.nx, lpv.nx)), *((f"P{i + 1}", (lpv.nx, lpv.nx)) for i in range(N)),
                           *((f"L{i + 1}", (lpv.nx, lpv.ny)) for i in range(N))]:
            if key not in gains:            # X only: the common-plus-vertex split is optional
                matrices[key] = np.zeros(shape)
                continue
            try:
                m = np.array(gains[key], float)
            except (TypeError, ValueError):
                refuse(f"{key} = {brief(repr(gains[key]))} is not a matrix of numbers", key)
            if m.shape != shape:
                refuse(f"{key} has shape {m.shape}, expected {shape}", key)
            if not np.all(np.isfinite(m)):
                refuse(f"{key} has non-finite entries", key)
            matrices[key] = m
        P = [matrices[f"P{i + 1}"] for i in range(N)]
        L = [matrices[f"L{i + 1}"] for i in range(N)]
        X = matrices["X"]
        make = polytope.taylor_reduced_polytope if poly.kind == "taylor_reduced" else polytope.sector_polytope
        labels = {"exact": "sound rate bounds over the whole box",
                  "at_expansion_point": "rate bounds of the paper's eq. (11)"}
        cases = {}
        for mode in ("exact", "at_expansion_point") if poly.kind == "taylor_reduced" else ("exact",):
            p = make(lpv, mode)
            res = certify(p, P, X, L, alpha, F)
            cases[mode] = {"conditions": labels[mode], "rate_bounds": p.rate_bounds.tolist(),
                           **{k: res[k] for k in ("blocks", "feasible", "mu", "nu", "gamma")}}
        M = [np.linalg.solve(P[i] + X, L[i]) for i in range(N)]
        figures = {"alpha": alpha, "polytope": poly.kind, "polytope_form": polytope.FORMS[poly.kind],
                   "performance": list(performance) or [str(x) for x in lpv.definition.states],
                   "gain_norm_max_1_per_s": max(float(np.linalg.norm(m, 2)) for m in M),
                   **{f"{key}_in_file": gains[key] for key in ("gamma", "gamma_stated") if key in gains}}
        failed = [m for m, c in cases.items() if not c["feasible"]]
        reason = "" if not failed else (f"Theorem 1 fails with the {' and the '.join(labels[m] for m in failed)}: "
                                        f"a block's state part is not negative definite (blocks above)")
        return GainsCheck(config.name, "theorem_1", str(source), not failed, reason, None, cases, figures)

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_linf
        return draw_linf(rng)


FAMILY = LinfUIO()
