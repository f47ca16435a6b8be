"""Optional capabilities of an observer family, each a small protocol.

The required part of a family is :class:`~codegen.contract.family.Family` (its paper, its keys and
``build``). A family that can do more defines the members of a protocol below, and the toolchain
asks for it explicitly, ``isinstance(family, Scenarios)``, or with :func:`require` where the
command cannot go on without it (a typed :class:`~codegen.errors.UnsupportedError` naming the
family and what it lacks). ``Family.capabilities()`` lists what a family has.

========================  =====================================================================
protocol                  used by
========================  =====================================================================
:class:`Scenarios`        ``uiogen validate --scenario``, ``uiogen demo``: the paper's scenarios
:class:`DemoPlant`        ``uiogen demo``: the plant an observer's scenarios run on
:class:`DemoFigures`      ``uiogen demo``, ``uiogen docs``: design figures from the committed lock
:class:`BenchFigures`     ``uiogen bench``: a realistic input sequence, family figures of the step
:class:`BenchStudy`       ``uiogen bench``: a family-wide study (design growth)
:class:`Campaigns`        ``uiogen campaign``: the compiled closed-loop plant, noise, gain norm
:class:`Applicability`    ``uiogen analyze``: whether the family takes a model
:class:`GainForms`        ``uiogen check-gains``: the paper's printed form of the gains
:class:`LogPeers`         ``uiogen validate --data``: estimators run beside the observer on a log
:class:`Identification`   ``uiogen fit``: identify the observer's numbers on a log
:class:`NoiseBound`       ``uiogen validate``: the certified noise-to-estimate bound at the declared noise
========================  =====================================================================
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..certificate.gains import GainForms  # noqa: F401 -- defined where check-gains asks for it, listed here
from ..errors import UnsupportedError


@runtime_checkable
class Scenarios(Protocol):
    """The paper's validation scenarios on plants the observer was not derived from."""

    #: the library scenarios ``uiogen demo`` runs
    demo_scenarios: tuple
    #: what the validation table's figures are in (``uiogen validate``'s header): "angles in degrees"
    table_note: str

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None,
                 observer=None) -> dict:
        """Run the compiled step (``observer``: a compiled observer of ``config``, default its
        extension) on a simulated plant: {"observer": {SIGNAL: stats}, "baselines", ...}."""

    def validation_table(self, result: dict) -> str:
        """The validation table as text, in the paper's format."""


@runtime_checkable
class DemoPlant(Protocol):
    """``uiogen demo`` runs an observer's scenarios on another plant than the nominal one."""

    def demo_plant(self, config) -> str:
        """The plant (a ``uiogen validate --plant`` choice) of ``config``'s demo scenarios."""


@runtime_checkable
class DemoFigures(Protocol):
    """Design figures of the demo (and the docs' design tables) from the committed design lock."""

    def demo_report(self, artifact: dict) -> dict:
        """{figure: value} (nested one level at most) from the design lock ``artifact``."""


@runtime_checkable
class BenchFigures(Protocol):
    """What ``uiogen bench`` needs beyond the generic measurement."""

    def bench_inputs(self, build):
        """A realistic (n, n_input) input sequence, or None for constant mid-box samples."""

    def bench_figures(self, build) -> dict:
        """Family figures of the step (e.g. the differentiators' share of the flops)."""


@runtime_checkable
class BenchStudy(Protocol):
    """A family-wide study ``uiogen bench`` runs once (e.g. how the design grows with the rules)."""

    def bench_family(self) -> list:
        """Rows of the study."""

    def bench_family_table(self, rows: list) -> list:
        """The study's rows as text lines (its own table format)."""


@runtime_checkable
class Campaigns(Protocol):
    """Robustness campaigns (:mod:`codegen.campaign`) on a compiled closed-loop plant."""

    #: the kind of compiled plant (a key of ``codegen.campaign.plants.KINDS``)
    campaign_plant: str
    #: the norm of the certified gain a run's empirical ratio is set beside ("peak" or "l2")
    certified_gain_norm: str

    def sensor_noise(self) -> dict:
        """Standard deviation per measured signal of the family's validation runs."""


@runtime_checkable
class Applicability(Protocol):
    """The family's answer to ``uiogen analyze``."""

    def applicability(self, subject, structure):
        """A :class:`codegen.analysis.ranking.Applicability` for ``subject`` (a model with its
        sensors and unknown inputs) given its ``structure``; None: the family does not say."""


@runtime_checkable
class LogPeers(Protocol):
    """Estimators the family runs beside the observer on a logged run in the shared format."""

    def log_peers(self, config, run) -> dict:
        """{name: sideslip estimate [rad] per sample} of the peers (e.g. Kalman filters of the
        observer's own model and parameter file) on ``run``; {} for none."""


@runtime_checkable
class Identification(Protocol):
    """``uiogen fit``: the observer's numbers identified on part of a log."""

    def fit(self, config, path, samples: str, folds: int | None = None, judge=(), choose=(),
            jobs: int | None = None) -> dict:
        """Identify the observer's numbers on samples A..B-1 (``samples`` = "A:B") of a log; ``judge``:
        other runs of the same car to run the identified observer and its peers on (``result["runs"]``);
        ``choose``: ``[(KEY, [values...]), ...]`` of settings chosen on the held-out folds; ``jobs``: the
        processes the work may use (None: every CPU), the result the same with any number."""

    def fit_plot(self, result: dict, path) -> None:
        """The fit run and the judged runs of ``result`` as a figure (PNG) at ``path``."""

    def fit_files(self, config, result: dict) -> dict:
        """{path: text} of the files that hold the fitted numbers."""

    def fit_table(self, result: dict) -> list:
        """The identification's result as text lines (its own table format; the files' state is the verb's)."""


@runtime_checkable
class RandomModels(Protocol):
    """Random small valid models of the family, for the acceptance of C == model on models nobody wrote
    (:mod:`codegen.acceptance.random_models`): every registered family with this capability is drawn."""

    def draw_random_model(self, rng):
        """A :class:`codegen.families.random_models.RandomModel` drawn from the numpy generator ``rng``."""


@runtime_checkable
class NoiseBound(Protocol):
    """A certificate that bounds the estimation error from the sensors' noise, restated at the levels
    the parameter file's ``[sensor_noise]`` declares (``uiogen validate`` prints it beside the run)."""

    def noise_bound(self, b, levels: dict) -> dict:
        """The bound of build ``b``'s certificate at sensor noise ``levels`` ({measured signal: std, in
        the model's unit}): {"error", "norm", "unit", "bound", "design_bound" (at the design's own
        levels), "levels" (every channel's, as used), "declared" (the signals taken from ``levels``),
        "where" (the conditions the bound holds under)}."""


CAPABILITIES = (Scenarios, DemoPlant, DemoFigures, BenchFigures, BenchStudy, Campaigns, Applicability, GainForms,
                LogPeers, Identification, NoiseBound)

# what each capability is called in an error
_WHAT = {Scenarios: "simulated validation scenarios (uiogen validate --scenario, uiogen demo)",
         DemoPlant: "demo plant", DemoFigures: "demo figures", BenchFigures: "bench figures",
         BenchStudy: "family-wide bench study", Campaigns: "compiled campaign plant (uiogen campaign)",
         Applicability: "applicability check (uiogen analyze)",
         GainForms: "printed form of its gains (uiogen check-gains takes the design lock's lmi_solutions)",
         LogPeers: "estimators run beside the observer on a log",
         Identification: "identification (uiogen fit): its numbers come from its paper or its parameter file",
         NoiseBound: "certified noise-to-estimate bound"}


def of(family) -> tuple:
    """The names of the capabilities ``family`` has."""
    return tuple(c.__name__ for c in CAPABILITIES if isinstance(family, c))


def require(family, capability):
    """``family`` itself when it has ``capability``; else an :class:`UnsupportedError` naming what it lacks."""
    if not isinstance(family, capability):
        raise UnsupportedError(f"family {family.name!r} has no {_WHAT[capability]}")
    return family
