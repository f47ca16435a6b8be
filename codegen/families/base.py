"""What an observer family provides: :class:`Family` (the registry's entry) and
:class:`ObserverBuild` (what its pipeline returns). Nothing outside a family's own folder
needs to know which family it handles: the toolchain (:mod:`codegen.pipeline`,
:mod:`codegen.emit`, :mod:`codegen.cli`, :mod:`codegen.validation.run`, :mod:`codegen.validation.demo`,
:mod:`codegen.tools.bench`) only calls these members.
"""
from __future__ import annotations

import abc

import casadi as ca

from ..errors import UnsupportedError


class ObserverBuild(abc.ABC):
    """One designed, certified observer, ready for C: what ``Family.build`` returns.

    Concrete builds are frozen dataclasses with at least ``config`` (the
    :class:`~codegen.project.observer_file.ObserverConfig`) and ``timings`` ({stage: seconds}).
    """

    config: object
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    # -- signals of the step: z_next = step(z, u, y, rho) ------------------------------------------
    @property
    @abc.abstractmethod
    def state_names(self) -> list:
        """Entries of the step's state vector z (the outputs are its tail)."""

    @property
    @abc.abstractmethod
    def input_names(self) -> list:
        """Entries of the flat input vector [u, y, rho] of the C API."""

    @property
    @abc.abstractmethod
    def output_names(self) -> list:
        """Estimates the step returns (the last entries of the state)."""

    @property
    @abc.abstractmethod
    def nu(self) -> int:
        """Number of known inputs u (the first entries of the flat input)."""

    @property
    @abc.abstractmethod
    def ny(self) -> int:
        """Number of measured outputs y (after u in the flat input)."""

    @abc.abstractmethod
    def step_function(self) -> ca.Function:
        """The discrete step as a CasADi Function (z, u, y, rho) -> (z_next, excess[, warmup]);
        named ``NAME_kernel``. ``excess`` > 0 flags SCHEDULING_CLAMPED, ``warmup`` > 0 WARMING_UP."""

    @abc.abstractmethod
    def reference_step(self, z, u, y, rho):
        """An independent numpy implementation of the same step (tests, the benchmark's peer)."""

    @abc.abstractmethod
    def lmi_problem(self):
        """A fresh :class:`~codegen.design.lmi.LMIProblem` of the design (benchmark: our path vs CVXPY)."""

    @abc.abstractmethod
    def input_boxes(self) -> dict:
        """{flat input name: [min, max]} of the inputs that schedule the step."""

    @abc.abstractmethod
    def scheduling_boxes(self) -> list:
        """(name, min, max, derived) of every scheduling signal, for the C header."""

    @abc.abstractmethod
    def signal_docs(self) -> tuple:
        """(state, inputs, outputs): lists of {name, doc} for the C API's struct fields."""

    def derived_input_docs(self) -> list:
        """[{name, unit}] of known inputs the step computes from the measurements."""
        return []

    def contraction_metrics(self) -> list:
        """The Lyapunov norms in which the certificate proves the step contracting, over parts of
        its state (:class:`~codegen.certificate.contraction.ContractionMetric`): what bounds the
        float32 step's deviation (:mod:`codegen.targets.float32`); [] for none."""
        return []

    def output_lags(self) -> dict:
        """{output name: samples} by which an estimate lags the sample it is returned with (a
        step whose unknown-input estimate needs the next output returns the previous one)."""
        return {}

    @abc.abstractmethod
    def emit_notes(self) -> dict:
        """Text of the C API: headline, stability, step_notes, clamp_doc, warmup_doc, has_warmup."""

    @abc.abstractmethod
    def artifact(self) -> dict:
        """The design report written into the design lock (gains, certificates, signals)."""

    @abc.abstractmethod
    def summary(self, path) -> dict:
        """Figures ``uiogen design`` prints (``path``: where the design was written, or why not)."""

    @abc.abstractmethod
    def summary_lines(self, summary: dict) -> list:
        """``summary`` as the lines ``uiogen design`` prints."""


class Family(abc.ABC):
    """An observer family: its paper, its observer-file keys, its pipeline, its validation.

    Register an instance with :func:`codegen.families.register`; an observer file selects it
    with ``family = NAME``.
    """

    #: the observer file's ``family = "..."``
    name: str = ""
    #: what it is, in the field's words
    title: str = ""
    #: the paper, in full ("Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019")
    citation: str = ""
    #: the paper, short ("Nguyen et al. 2019"), for generated headers and reports
    short_citation: str = ""
    #: top-level observer-file keys beyond the common ones: {key: codegen.project.settings.Rule}
    observer_keys: dict = {}
    #: the library scenarios ``uiogen demo`` runs
    demo_scenarios: tuple = ()
    #: the built-in observer ``uiogen new DIR --family NAME`` copies as a starter
    example: str = ""
    #: robustness campaigns (:mod:`codegen.campaign`): the kind of compiled closed-loop plant of the
    #: family's validation (a key of ``codegen.campaign.plants.KINDS``), None where it has none
    campaign_plant: str | None = None
    #: ``[design]`` keys that set how hard :mod:`codegen.representation.bounds` tries to bound the
    #: model's expressions (its tolerance, its box budget), named when a bound cannot be reached
    bounds_settings: tuple = ()
    #: the norm of the certified gain a campaign run's empirical ratio is set beside: "peak"
    #: (L-infinity: sup|x - x_hat| / sup|d|) or "l2" (|xi - xi_hat|_2 / |w|_2); None: no such gain
    certified_gain_norm: str | None = None

    def sensor_noise(self) -> dict:
        """Standard deviation per measured signal of the family's validation runs."""
        from ..validation.common import SENSOR_NOISE
        return dict(SENSOR_NOISE)

    def check_config(self, config, data: dict) -> None:
        """Check the family's own tables of an observer file (``data``: the parsed TOML) beyond
        :attr:`observer_keys`; raise :class:`~codegen.errors.ConfigurationError`."""

    @abc.abstractmethod
    def build(self, config, tol: float | None = None) -> ObserverBuild:
        """model -> representation -> design -> certificates -> discrete step."""

    def validate(self, config, scenario, plant: str = "nominal", duration: float | None = None,
                 seed: int = 0, progress=None, observer=None) -> dict:
        """Run the compiled step (``observer``: a compiled observer of ``config``, default its
        extension) on a simulated plant: {"observer": {SIGNAL: stats}, "baselines", ...}."""
        raise UnsupportedError(f"family {self.name!r} has no simulated validation scenarios")

    def format_validation(self, result: dict) -> str:
        """The validation table as text (the paper's format)."""
        raise UnsupportedError(f"family {self.name!r} has no validation table")

    def validation_header(self, name: str, result: dict) -> str:
        """The line ``uiogen validate`` prints above the table."""
        return (f"{name}: scenario {result['scenario']} on the {result['plant']} plant "
                f"({result.get('plant_model', result['plant'])}), {result['samples']} samples, "
                f"{result['status_flags']} flagged samples")

    def log_peers(self, config, run) -> dict:
        """{name: sideslip estimate [rad] per sample} of estimators the family runs beside the
        observer on a logged run in the shared format (``uiogen validate --data``), e.g. Kalman
        filters of the observer's own model and parameter file; {} for none."""
        return {}

    def demo_report(self, artifact: dict) -> dict:
        """Design figures for ``uiogen demo`` from the committed design report."""
        return {}

    def demo_lines(self, report: dict) -> list:
        """``demo_report`` as text lines."""
        return []

    def bench_inputs(self, build):
        """A realistic (n, n_input) input sequence for ``uiogen bench``, or None for constant
        mid-box samples (fine for steps without internal filters or differentiators)."""
        return None

    def bench_figures(self, build) -> dict:
        """Family-specific figures ``uiogen bench`` adds to an observer's (e.g. differentiator cost)."""
        return {}

    def bench_lines(self, figures: dict) -> list:
        return []

    def bench_family(self) -> list:
        """Rows of a family-wide study ``uiogen bench`` runs once (e.g. how the design grows with the
        number of rules); [] for none."""
        return []

    def bench_family_lines(self, rows: list) -> list:
        return []

    def applicability(self, subject, structure):
        """Whether this family can take ``subject`` (a model with its sensors and unknown inputs,
        :class:`codegen.analysis.subject.Subject`), given its ``structure``
        (:class:`codegen.analysis.structure.Structure`): a
        :class:`codegen.analysis.ranking.Applicability`, "applies" with the observer-file settings
        the family would use, or the one condition that fails and the change that satisfies it.
        ``uiogen analyze`` ranks the families by these answers; None: the family does not say."""
        return None

    def check_gains(self, config, gains: dict) -> dict:
        """Check externally supplied decision variables against the family's LMIs, without a solver.

        The generic form is the design lock's: ``{"lmi_solutions": [{"problem", "variables",
        "objective", "iterations"}, ...]}``, one record per LMI problem of the design, in order
        (as in ``generated_c/NAME/NAME_design.json``, which may be given as it is). The family's pipeline runs on them as on a
        committed design: every block is re-checked with numpy, and the discrete step certified.
        Families with a paper-specific form of their gains override this (and fall back to it).
        """
        from ..design import lmi
        from ..errors import (CertificateError, ConfigurationError, DesignLockError, DiscretizationError,
                               InfeasibleLMIError)
        raw = gains.get("lmi_solutions")
        if raw is None and isinstance(gains.get("lock"), dict):      # a design lock file, as committed
            raw = gains["lock"].get("lmi_solutions")
        if not isinstance(raw, list):
            raise ConfigurationError(
                f"gains: family {self.name!r} checks gains given as the design lock gives them: "
                f'{{"lmi_solutions": [{{"problem", "variables", "objective", "iterations"}}, ...]}} '
                f"(see generated_c/{config.name}/{config.name}_design.json)", key="lmi_solutions")
        records = [lmi.SolveRecord.from_json(r, "gains") for r in raw]
        out = {"observer": config.name, "form": "lmi_solutions", "problems": []}
        try:
            with lmi.replaying(records, source="gains") as ledger:
                self.build(config)
        except (CertificateError, DiscretizationError, InfeasibleLMIError) as exc:
            out.update(feasible=False, reason=f"{type(exc).__name__}: {exc}")
            return out
        except DesignLockError as exc:
            raise ConfigurationError(f"gains: {exc}") from None
        for rec, sol in zip(ledger.records, ledger.solutions):
            worst = sol.worst
            out["problems"].append({"problem": rec.problem, "objective": rec.objective, "blocks": len(sol.checks),
                                    "worst_block": worst.label, "worst_min_eig": worst.min_eig})
        out["feasible"] = True
        return out

    def fit(self, config, path, samples: str, folds: int = 0) -> dict:
        """Identify the observer's numbers on samples A..B-1 (``samples`` = "A:B") of a log
        (``uiogen fit``); families without an identification refuse."""
        raise UnsupportedError(f"family {self.name!r} has no identification (uiogen fit): its numbers come from its "
                               f"paper or its parameter file")

    def fit_files(self, config, result: dict) -> dict:
        """{path: text} of the files that hold the fitted numbers."""
        return {}

    def fit_lines(self, result: dict, changed: dict) -> list:
        return []

    def format_check_gains(self, result: dict, source: str) -> list:
        lines = [f"{self.title} ({self.short_citation}): check of {source} on observer {result['observer']}"]
        for p in result.get("problems", []):
            lines.append(f"  {p['problem']}: {p['blocks']} blocks re-checked with numpy, worst {p['worst_min_eig']:.6g} "
                         f"in {p['worst_block']}; objective {p['objective']:.6g}")
        lines.append("  PASS: every block and the discrete step are certified" if result["feasible"]
                     else f"  FAIL: {result['reason']}")
        return lines
