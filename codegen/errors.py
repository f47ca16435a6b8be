"""Typed errors of the uiogen toolchain.

Every error a user can provoke with a model definition, a parameter file, a
design setting or a sensor sample is one of these classes, so scripts can catch
precisely what they expect and the message names the cause.
"""
from __future__ import annotations

# The runtime's errors (python_bindings needs no toolchain to raise them), re-exported here.
from python_bindings.errors import (ChangedSourceError, DamagedExtensionError, SampleError, SourceFileError,  # noqa: F401
                                    StaleExtensionError, UiogenError, UnknownObserverError)


class ModelDefinitionError(UiogenError, ValueError):
    """A symbolic model definition is malformed (shapes, names, structure)."""


class ConfigurationError(ModelDefinitionError):
    """A key or value of an observer file, a parameter file or a design table is not allowed.

    The message reads ``FILE: [section] key = value: what is allowed`` (with a did-you-mean for a
    misspelt key or choice); the parts are also attributes, for scripts. :mod:`codegen.settings`
    raises it.
    """

    def __init__(self, message: str, *, source: str = "", section: str | None = None, key: str | None = None,
                 value=None, allowed: str = ""):
        super().__init__(message)
        self.source, self.section, self.key, self.value, self.allowed = source, section, key, value, allowed


class MissingParameterError(ModelDefinitionError):
    """A parameter used by the equations has no value in the parameter file."""


class UnknownParameterError(ModelDefinitionError):
    """The parameter file sets a name the model does not use (likely a typo)."""


class UnitError(ModelDefinitionError):
    """A model's equations contradict the units it declares (a term of another dimension, an
    output declared in a unit its expression is not in)."""


class NotAffineError(ModelDefinitionError):
    """The dynamics are not affine in states/inputs, so no LPV form exists.

    ``unknown_inputs``: the names of the unknown inputs the equations are not affine in, when
    they are the cause (the fix is then a change of variables, ``[substitute]``, not a
    scheduling signal); empty when a state or a known input is."""

    def __init__(self, message: str, *, unknown_inputs: tuple = ()):
        super().__init__(message)
        self.unknown_inputs = tuple(str(u) for u in unknown_inputs)


class SchedulingBoundsError(ModelDefinitionError):
    """A scheduling signal lacks bounds, or its bounds/rate bounds are invalid."""


class RankConditionError(UiogenError, ValueError):
    """A rank or detectability condition of the observer family fails."""


class NonAffineLMIError(UiogenError, TypeError):
    """An LMI expression is not affine in the decision variables."""


class LMIShapeError(UiogenError, ValueError):
    """An LMI block is not square or not symmetric."""


class SolverError(UiogenError, RuntimeError):
    """The SDP solver did not return a usable solution."""


class InfeasibleLMIError(SolverError):
    """The LMI problem is (primal) infeasible; the message names the blocks involved.

    ``status``: the solver's verdict when it gave one (Clarabel's ``PrimalInfeasible`` at its full
    tolerances, ``AlmostPrimalInfeasible`` at reduced ones), else None (an infeasibility proven
    before any solve)."""

    def __init__(self, message: str, *, status: str | None = None):
        super().__init__(message)
        self.status = status


class InaccurateSolveError(SolverError):
    """The solver stopped short of its tolerances (almost solved, iteration limit)."""


class IllConditionedError(SolverError):
    """The solution is too ill-conditioned to be trusted or implemented."""


class CertificateError(UiogenError, RuntimeError):
    """A returned solution does not satisfy its LMIs when re-checked with numpy."""


class DiscretizationError(UiogenError, RuntimeError):
    """The discrete-time observer step could not be certified stable."""


class UILoopError(DiscretizationError):
    """The observer's error with its unknown-input filter loop closed cannot be certified.

    ``remedy``: {dotted observer-file key: value} that a measurement found to certify the loop
    (``{"ui_filter.time_constant": 0.1}``), or empty when none was found; ``uiogen analyze`` designs
    its trial again with it and ``uiogen new --from-model`` writes it.
    """

    def __init__(self, message: str, *, remedy: dict | None = None):
        super().__init__(message)
        self.remedy = dict(remedy or {})


class DesignLockError(UiogenError, ValueError):
    """A committed design (``NAME_design.json``) is missing, unreadable, stale or does not fit
    the problem it is replayed into; ``uiogen design NAME --update`` re-solves it."""


class GenerationError(UiogenError, RuntimeError):
    """One or more observers failed to generate (each failure was reported; the others ran)."""


class RelativeDegreeError(RankConditionError):
    """An output has no (uniform) relative degree w.r.t. the unknown inputs on the box."""


class DatasetError(SampleError):
    """A data file is missing, unreadable, or has wrong columns, units or non-finite values."""


class ScenarioError(ModelDefinitionError):
    """Unknown scenario name or invalid scenario settings."""


class MetricInputError(SampleError):
    """Reference/estimate arrays are empty, of different shapes, or hold NaN/Inf."""


class PlantError(UiogenError, RuntimeError):
    """The plant simulation left its valid domain (steering stop, spin, non-finite state)."""


class BoundsError(ModelDefinitionError):
    """An expression cannot be bounded over the box (singularity, unsupported function).

    ``singular``: the box's signals (names) over which a division reaches 0, e.g. ``("vx",)`` for
    ``1/vx`` with ``vx = [0, 20]``: no refinement of the bound can fix that, only their boxes
    (empty for the other causes).
    """

    def __init__(self, message: str, *, singular: tuple = ()):
        super().__init__(message)
        self.singular = tuple(singular)


class ToolchainError(UiogenError, RuntimeError):
    """The C toolchain failed: no compiler, a compiler error on generated code, or a CasADi
    version whose output the emitter does not recognize."""


class UnsupportedError(UiogenError, ValueError):
    """The request is valid but the chosen observer family does not offer it (the message says
    which families do)."""


class UnknownFamilyError(ConfigurationError):
    """No observer family is registered under that name."""


class RepresentationError(ModelDefinitionError):
    """A representation of the model (a reduced polytope, a TS form) is too far from the model,
    or too large, to be designed with; the message names the better choice."""


class ConformanceError(UiogenError, RuntimeError):
    """A compiled step disagrees with its model (signal layout, or numbers on samples across the
    declared boxes): ``uiogen build`` does not install it; the message names the signal and the
    sample (:mod:`codegen.extension.conformance`)."""


class OutputError(UiogenError, OSError):
    """An output file or folder cannot be written (a read-only or full file system, no
    permission): the message names the path and the cause; nothing partial is left there
    (:mod:`codegen.project.outputs`)."""


class CampaignError(UiogenError, RuntimeError):
    """A campaign could not finish or continue: its workers were lost, or ``--resume`` found the
    results of another campaign; the runs already finished are kept (the message says where)."""


#: The errors with which a design refuses a setting: in a study over settings (``uiogen sweep``, ``uiogen fit
#: --choose``) such a point is a result, not a failure; anything else (a misspelt key, a value out of range:
#: ConfigurationError) stops the study.
REFUSALS = (SolverError, CertificateError, DiscretizationError, RankConditionError, RepresentationError)


def brief(expr, limit: int = 160) -> str:
    """``expr`` as text for an error message: whole when short, else its head and its length (the
    derivative of a user's tyre law can run to thousands of characters, which no reader needs)."""
    text = str(expr)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def install_hint(extra: str) -> str:
    """How to install one of pyproject's extras, from a wheel and in a checkout (for the message of
    a verb whose optional dependency is missing)."""
    return f"pip install 'uiogen[{extra}]' (in a checkout: pip install -c constraints.txt -e '.[{extra}]')"
