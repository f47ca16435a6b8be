"""What an observer family provides: :class:`Family` (the registry's entry) and
:class:`ObserverBuild` (what its pipeline returns).

The required part is what the pipeline needs: ``Family.build(config, solver)`` returning an
:class:`ObserverBuild` with its step (``step_function``, ``reference_step``), its signals (names,
counts, boxes) and its :class:`~codegen.certificate.certificate.Certificate`, plus the design data
the lock records (``artifact``). Everything else a family may offer is an optional capability,
declared by a small protocol of :mod:`codegen.contract.capabilities` (validation scenarios, demo
figures, bench figures, campaign plants, applicability, paper forms of check-gains, an
identification) and discovered with ``isinstance``; text is rendered in one place,
:mod:`codegen.certificate.text`. Nothing outside a family's own folder needs to know which family
it handles.
"""
from __future__ import annotations

import abc
from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class StepNotes:
    """What the C API says about the step beyond its certificate (the header's prose).

    ``notes``: lines on what one call does (which sample the estimates are of, the state's
    layout); ``clamp``: when the step sets SCHEDULING_CLAMPED; ``warmup``: what WARMING_UP means
    (only read when the step has a warm-up output)."""

    notes: tuple = ()
    clamp: str = ("A scheduling input outside its box: clamped for the step; the certificate does not cover "
                  "this sample.")
    warmup: str = "never set by this observer."


class ObserverBuild(abc.ABC):
    """One designed, certified observer, ready for C: what ``Family.build`` returns.

    Concrete builds are frozen dataclasses with at least ``config`` (the
    :class:`~codegen.project.observer_file.ObserverConfig`) and ``timings`` ({stage: seconds}).
    The abstract members are required; the others have defaults a family may override.
    """

    config: object
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    # -- required: signals of the step z_next = step(z, u, y, rho) ------------------------------
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
    def input_boxes(self) -> dict:
        """{flat input name: [min, max]} of the inputs that schedule the step."""

    @abc.abstractmethod
    def scheduling_boxes(self) -> list:
        """(name, min, max, derived) of every scheduling signal, for the C header."""

    # -- required: the step and its certificate --------------------------------------------------
    @abc.abstractmethod
    def step_function(self) -> ca.Function:
        """The discrete step as a CasADi Function (z, u, y, rho) -> (z_next, excess[, warmup]);
        named ``NAME_kernel``. ``excess`` > 0 flags SCHEDULING_CLAMPED, ``warmup`` > 0 WARMING_UP."""

    @abc.abstractmethod
    def reference_step(self, z, u, y, rho):
        """An independent numpy implementation of the same step (tests, the benchmark's peer)."""

    @property
    @abc.abstractmethod
    def certificate(self):
        """What the design certifies: a :class:`~codegen.certificate.certificate.Certificate`."""

    @abc.abstractmethod
    def artifact(self) -> dict:
        """The design data the design lock records beside the certificate (the head of
        :func:`~codegen.certificate.artifact.artifact_head`, gains, Lyapunov matrices, the
        representation): everything needed to re-check the design without uiogen."""

    # -- optional, with defaults ---------------------------------------------------------------
    def signal_docs(self) -> tuple:
        """(state, inputs, outputs): lists of {name, doc} for the C API's struct fields; a signal
        without a doc is documented by its name and unit."""
        return [], [], []

    def derived_input_docs(self) -> list:
        """[{name, unit}] of known inputs the step computes from the measurements."""
        return []

    def contraction_metrics(self) -> list:
        """The Lyapunov norms in which the certificate proves the step contracting, over parts of
        its state (:class:`~codegen.certificate.contraction.ContractionMetric`): what bounds the
        float32 step's deviation (:mod:`codegen.targets.float32`); [] for none."""
        return []

    def increment_function(self):
        """(the step with a fourth output ``dz``, the increment of some state entries computed at
        its own scale, not as ``z_next - z``; those entries' names), or None: what a compensated
        float32 update adds to the state by TwoSum (:mod:`codegen.project.precision`,
        ``accumulation``). Its first three outputs are :meth:`step_function`'s."""
        return None

    def output_lags(self) -> dict:
        """{output name: samples} by which an estimate lags the sample it is returned with (a
        step whose unknown-input estimate needs the next output returns the previous one)."""
        return {}

    def step_notes(self) -> StepNotes:
        """The C API's prose about the step (:class:`StepNotes`)."""
        return StepNotes()

    def figures(self) -> dict:
        """Design figures beside the certificate (JSON), which ``uiogen design`` prints and
        ``uiogen sweep`` tabulates (e.g. ``gamma``, the representation's size, timings)."""
        return {}

    def lmi_problem(self):
        """A fresh :class:`~codegen.design.lmi.LMIProblem` of the design (the benchmark: our path
        against CVXPY), or None."""
        return None


class Family(abc.ABC):
    """An observer family: its paper, its observer-file keys and its pipeline.

    Register an instance with :func:`codegen.families.register`; an observer file selects it
    with ``family = NAME``. Optional capabilities: :mod:`codegen.contract.capabilities`.
    """

    #: the observer file's ``family = "..."``
    name: str = ""
    #: what it is, in the field's words
    title: str = ""
    #: the paper, in full ("Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019")
    citation: str = ""
    #: the paper, short ("Nguyen et al. 2019"), for generated headers and reports
    short_citation: str = ""
    #: top-level observer-file keys beyond the common ones: {key: codegen.settings.Rule}
    observer_keys: dict = {}
    #: the built-in observer ``uiogen new DIR --family NAME`` copies as a starter ("": none)
    example: str = ""
    #: ``[design]`` keys that set how hard :mod:`codegen.representation.bounds` tries to bound the
    #: model's expressions (its tolerance, its box budget), named when a bound cannot be reached
    bounds_settings: tuple = ()

    def check_config(self, config, data: dict) -> None:
        """Check the family's own tables of an observer file (``data``: the parsed TOML) beyond
        :attr:`observer_keys`; raise :class:`~codegen.errors.ConfigurationError`."""

    @abc.abstractmethod
    def build(self, config, solver) -> ObserverBuild:
        """model -> representation -> design -> certificates -> discrete step; every design LMI
        problem answered by ``solver`` (:mod:`codegen.design.solver`: a fresh solve or a replay)."""

    def capabilities(self) -> tuple:
        """The names of the optional capabilities this family has (:mod:`codegen.contract.capabilities`)."""
        from .capabilities import of
        return of(self)
