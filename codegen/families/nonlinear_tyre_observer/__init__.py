"""Nonlinear single-track observer with a saturating (Fiala) tyre per axle, certified by the
differential mean-value theorem over slip angles up to a fraction of each axle's sliding limit.

The DMVT treatment of unmeasured nonlinearities is that of Nguyen, Dinh, Guerra, Pan 2021 (the
``ts_fuzzy_uio`` family), applied here to the tyre force itself: its Jacobian along the
unmeasured lateral speed is bounded soundly over a set of slip values (:mod:`codegen.representation.bounds`),
and one quadratic Lyapunov matrix certifies the fixed-gain error map at every vertex. See
``build.py`` for the equations, ``docs/validation.md`` for the real-data results.
"""
from __future__ import annotations

from ...contract.family import Family


class NonlinearTyreObserver(Family):
    name = "nonlinear_tyre_observer"
    title = "nonlinear single-track observer with saturating axle tyres (DMVT certificate)"
    citation = "DMVT certificate after Nguyen, Dinh, Guerra, Pan, IEEE/ASME T-Mech 26(3), 2021; Fiala tyre (Pacejka 2012, Sec. 3.2)"
    short_citation = "nonlinear-tyre DMVT"
    observer_keys = {}
    bounds_settings = ("bounds_rel_tol",)
    # capabilities (codegen.contract.capabilities): DemoFigures, Applicability, GainForms, LogPeers,
    # Identification, NoiseBound
    example = "stanford_sideslip_nonlinear_tyre"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def demo_report(self, art: dict) -> dict:
        c = art["certificate"]["extras"]["recheck"]
        return {"worst_lmi_margin": c["worst_min_eig"], "worst_lmi_block": c["worst_block"],
                "contraction_per_step": c["contraction_per_step"], "time_constant_s": c["time_constant_s"],
                "decay_rate": c["decay_rate"], "best_decay_rate": c["best_decay_rate"], "gamma_deg": c["gamma_deg"],
                "bound_deg_at_levels": c["bound_deg_at_levels"], "gains": art["gains"]}

    def noise_bound(self, b, levels: dict) -> dict:
        """The certificate's RMS bound of the sideslip error with its sensor channels (a_y, yaw rate) at
        the declared sensor noise ``levels`` ({signal: std}, the model's units) and every other channel
        at the design's level: the multiplier inequality of :mod:`.design` gives RMS(z) <=
        sqrt(T_s sum_i mu_i (sigma'_i / sigma_i)^2) for channels of RMS sigma'_i (on the gain set)."""
        import math
        from .design import CHANNELS
        names, c = b.rep.signals, b.recheck
        design = dict(zip(CHANNELS, b.settings.sigma.tolist()))
        sensors = {"ay": names.a_y, "r": names.yaw_rate}
        at = {ch: float(levels[sensors[ch]]) if sensors.get(ch) in levels else design[ch] for ch in CHANNELS}
        share = c["bound_deg_by_channel"]
        bound = math.sqrt(sum((share[ch] * at[ch] / design[ch]) ** 2 for ch in CHANNELS))
        return {"error": "beta, the sideslip estimation error", "norm": "rms", "unit": "deg", "bound": bound,
                "design_bound": float(c["bound_deg_at_levels"]), "levels": at, "design_levels": design,
                "declared": {sensors[ch]: at[ch] for ch in sensors if sensors[ch] in levels},
                "where": "on the gain set of the certificate; the other channels (axle force and Euler residuals) "
                         "at the design's levels"}

    def log_peers(self, config, run) -> dict:
        """The EKF and UKF of the same symbolic model and parameter file
        (:func:`codegen.validation.peers.nonlinear_tyre_peers`), for an observer of that model
        (``model_defs/single_track_nonlinear_tyre.py`` or an unedited copy of it)."""
        from ...project.observer_file import builtin_model
        from ...validation import peers
        if config.load_model() != builtin_model("single_track_nonlinear_tyre").MODEL:
            return {}
        return {k: v.beta for k, v in peers.nonlinear_tyre_peers(run, config.parameter_path).items()}

    def fit(self, config, path, samples: str, folds: int | None = None, judge=(), choose=(),
            jobs: int | None = None) -> dict:
        from .fit import fit
        return fit(config, path, samples, folds, judge=judge, choose=choose, jobs=jobs)

    def fit_plot(self, result: dict, path) -> None:
        from .fit import plot_runs
        plot_runs(result, path)

    def fit_files(self, config, result: dict) -> dict:
        from .fit import files
        return files(config, result)

    def fit_table(self, result: dict) -> list:
        from .fit import lines
        return lines(result)

    def check_gain_form(self, config, gains: dict, source: str):
        """Gains given as ``{"L": [[L_vy_ay, L_vy_r], [L_r_ay, L_r_r]]}`` (rows v_y, r; columns a_y, r),
        certified like the observer file's given gains: the largest decay rate a common Lyapunov
        matrix certifies, the l2 gain at the decay the design requires."""
        import dataclasses

        import numpy as np

        from ...certificate.gains import GainsCheck, check_lock_form, is_lock_file
        from ...design.solver import FreshSolver
        from ...errors import CertificateError, ConfigurationError, SolverError, brief
        if is_lock_file(gains):
            # a design lock is re-checked as committed: this form re-derives the decay from the settings
            # (decay_fraction of the committed rate again: 0.38 1/s stated for a lock certified at 1.9 1/s)
            return check_lock_form(self, config, gains, source)
        L = gains.get("L")
        try:
            L = np.array(L, dtype=float)
        except (TypeError, ValueError):
            L = None
        if L is None or L.shape != (2, 2) or not np.all(np.isfinite(L)):
            raise ConfigurationError(f"gains file {source}: L = {brief(repr(gains.get('L')))}; allowed: "
                                     f"{{\"L\": [[L_vy_ay, L_vy_r], [L_r_ay, L_r_r]]}} (finite numbers; rows v_y, r; "
                                     f"columns a_y, r) or the design lock's lmi_solutions", source=str(source), key="L")
        stray = sorted(set(gains) - {"L"})
        if stray:               # the printed form is the gain alone: a decay or P here would be silently unused
            raise ConfigurationError(f"gains file {source}: key {stray[0]!r} is not read; allowed: only \"L\" (the "
                                     f"decay and the Lyapunov matrix are re-derived from the observer file's "
                                     f"[design]), or the design lock's lmi_solutions", source=str(source), key=stray[0])
        given = dict(zip(("gain_vy_ay", "gain_vy_r", "gain_r_ay", "gain_r_r"), L.ravel().tolist()))
        cfg = dataclasses.replace(config, design={**{k: v for k, v in config.design.items() if k != "decay"}, **given})
        figures = {"L": L.tolist()}
        try:
            b = self.build(cfg, FreshSolver())
        except (CertificateError, SolverError) as exc:
            return GainsCheck(config.name, "L", str(source), False, f"{type(exc).__name__}: {exc}", figures=figures)
        c = b.recheck
        case = {"blocks_checked": c["blocks"], **{k: c[k] for k in ("worst_block", "worst_min_eig", "slowest_vertex")}}
        return GainsCheck(config.name, "L", str(source), True, "", b.certificate, {"vertex LMIs": case}, figures)

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_nonlinear_tyre
        return draw_nonlinear_tyre(rng)


FAMILY = NonlinearTyreObserver()
