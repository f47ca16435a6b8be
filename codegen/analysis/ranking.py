"""Which observer families apply to a subject, ranked, with trial designs where they are cheap.

Every registered family is asked (:meth:`codegen.families.Family.applicability`; nothing here
knows a family by name): it answers with an :class:`Applicability`, "applies" or the one condition
that fails and the change that would satisfy it, and the observer-file settings it would use.
Applicable families whose design takes seconds are designed through the normal pipeline
(:func:`codegen.pipeline.solve`) on an observer file written in a temporary folder, never in
the user's project; an observer file's own family is tried with the file's own settings.

The ranking puts first what guarantees most (:data:`GUARANTEES`), among what applies:

1. the family applies (every structural condition holds and the parameter file has what it needs);
2. its trial design is certified (before one not tried, before one that failed);
3. a proposal that reads every measured scheduling signal before one that holds some at a
   constant value (:attr:`Applicability.frozen`: its estimate is of another car whenever the
   signal leaves that value);
4. the guarantee: the error does not depend on the unknown inputs (decoupled), before a certified
   gain over the whole scheduling box, before a gain at fixed operating points only, before
   states without the unknown inputs;
5. fewer differentiated outputs (the sum of the HOSMD orders: noise is amplified by each);
6. the registry's order.
"""
from __future__ import annotations

import dataclasses
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..design.solver import progress_after
from ..errors import UiogenError
from ..settings import toml_repr
from .subject import Subject

#: guarantee classes, strongest first: (rank, what the certificate says)
GUARANTEES = {
    "decoupled": (0, "the estimation error does not depend on the unknown inputs (exact decoupling, certified decay)"),
    "attenuated_box": (1, "a certified gain from the unknown inputs to the error over the whole scheduling box"),
    "attenuated_points": (2, "a certified gain at fixed operating points (modes); the model between them is not "
                             "covered"),
    "states_only": (3, "the states on a certified set; the unknown inputs are not estimated"),
    "unknown": (4, "the family gives no applicability check"),
}


@dataclass(frozen=True)
class Applicability:
    """A family's answer for one model with its sensors (what ``Family.applicability`` returns).

    Attributes
    ----------
    family : str
        The family's registry name.
    applies : bool
        Every condition of the family holds (as far as it can tell without designing).
    guarantee : str
        A key of :data:`GUARANTEES`: what a certified design of this family says.
    condition : str
        When it does not apply: the ONE condition that fails, naming the signals.
    fix : str
        The change that would satisfy it (measure this output, treat this input as known, add a
        differentiator of order k, change the premises, restrict this box, ...).
    checked : tuple
        (statement, basis) of what the family checked, basis a key of
        :data:`codegen.analysis.structure.BASIS`.
    notes : tuple
        What the user should know even though it applies (an unknown input only attenuated, ...).
    observer : dict or None
        The observer-file table the family would use (``family``, ``sample_time``, ``[design]``, ...;
        ``model`` and ``parameters`` are filled in by the analysis); None: no proposal.
    why : dict
        {dotted key: the reason for its value}, written as comments by ``uiogen new --from-model``.
    differentiators : dict
        {signal: derivative order} the observer needs from HOSMD differentiators.
    design_cost : str
        "seconds" (the analysis designs it) or "minutes" (it does not).
    figures : callable or None
        ``build -> {name: (value, unit, meaning)}``: the certified figures of a trial design.
    decay_key : str
        The dotted key of the family's certified decay rate of the error (1/s), which an
        unobservable mode bounds (:meth:`codegen.analysis.structure.Structure.decay_limit`): a
        trial that fails with it at or above that mode's rate says so.
    """

    family: str
    applies: bool
    guarantee: str
    condition: str = ""
    fix: str = ""
    checked: tuple = ()
    notes: tuple = ()
    observer: dict | None = None
    why: dict = field(default_factory=dict)
    differentiators: dict = field(default_factory=dict)
    design_cost: str = "seconds"
    figures: Callable | None = None
    decay_key: str = ""
    frozen: dict = field(default_factory=dict)

    def frozen_text(self) -> str:
        """One sentence on the measured signals the proposal freezes ("" when none)."""
        if not self.frozen:
            return ""
        held = ", ".join(f"{s} = {v:g}" for s, v in self.frozen.items())
        return (f"FROZEN measured signal{'s' if len(self.frozen) > 1 else ''}: this proposal holds {held} (mid-box) "
                f"and its observer does not read {'them' if len(self.frozen) > 1 else 'it'}: away from "
                f"{'those values' if len(self.frozen) > 1 else 'that value'} the estimates are of another model, "
                f"with no status raised; ranked after the proposals that read every measured signal")

    def to_json(self) -> dict:
        return {"family": self.family, "applies": self.applies, "guarantee": self.guarantee,
                "guarantee_means": GUARANTEES.get(self.guarantee, (9, ""))[1], "condition": self.condition,
                "fix": self.fix, "checked": [{"statement": s, "basis": b} for s, b in self.checked],
                "notes": list(self.notes), "observer": self.observer, "differentiators": self.differentiators,
                "design_cost": self.design_cost, "frozen": dict(self.frozen), "frozen_means": self.frozen_text()}


@dataclass(frozen=True)
class Trial:
    """A trial design of one family through the normal pipeline."""

    family: str
    status: str                 # "certified" | "failed" | "not tried"
    settings: str               # "the observer file's settings" | "the analysis's settings" | ...
    seconds: float = 0.0
    headline: str = ""
    figures: dict = field(default_factory=dict)
    reason: str = ""
    error: type | None = None       # the exception class of a failed design
    remedy: dict = field(default_factory=dict)  # a failed design's measured fix {dotted key: value} (UILoopError)
    kept: bool = False              # the design's outcome kept from an earlier run on the same inputs

    def record(self) -> dict:
        """The trial as data (:func:`codegen.model.cache.remembered` keeps it): the error by its name."""
        return {"family": self.family, "status": self.status, "settings": self.settings, "seconds": self.seconds,
                "headline": self.headline, "figures": {k: list(v) for k, v in self.figures.items()},
                "reason": self.reason, "error": None if self.error is None else self.error.__name__,
                "remedy": dict(self.remedy)}

    @classmethod
    def from_record(cls, r: dict, kept: bool) -> "Trial":
        from .. import errors
        error = None if r["error"] is None else getattr(errors, r["error"], UiogenError)
        return cls(r["family"], r["status"], r["settings"], r["seconds"], r["headline"],
                   {k: tuple(v) for k, v in r["figures"].items()}, r["reason"], error, dict(r["remedy"]), kept)

    def to_json(self) -> dict:
        return {"family": self.family, "status": self.status, "settings": self.settings, "seconds": self.seconds,
                "kept": self.kept, "headline": self.headline, "reason": self.reason,
                "figures": {k: {"value": v, "unit": u, "meaning": m} for k, (v, u, m) in self.figures.items()}}


@dataclass
class Ranking:
    """Families in rank order, each with its applicability and trial."""

    entries: list                # [(Applicability, Trial)]
    own_family: str | None       # the observer file's family, if one was named
    seconds: float = 0.0
    what_if: dict | None = None  # the own family's design with the sensor the structure names
    completed: dict | None = None  # the own family's design with the file's settings completed by the analysis

    @property
    def own_trial(self):
        return next((t for a, t in self.entries if a.family == self.own_family), None)

    @property
    def best(self) -> Applicability | None:
        return self.entries[0][0] if self.entries and self.entries[0][0].applies else None

    def position(self, family: str) -> int:
        return next(k for k, (a, _) in enumerate(self.entries) if a.family == family)

    def to_json(self) -> dict:
        return {"order": [a.family for a, _ in self.entries], "best": self.best.family if self.best else None,
                "own_family": self.own_family, "seconds": self.seconds,
                "what_if": None if self.what_if is None else {**self.what_if, "trial": self.what_if["trial"].to_json()},
                "completed": None if self.completed is None else {
                    **{k: v for k, v in self.completed.items() if k not in ("trial", "file_trial")},
                    "trial": self.completed["trial"].to_json()},
                "families": [{**a.to_json(), "trial": t.to_json()} for a, t in self.entries]}


_TRIAL_ORDER = {"certified": 0, "not tried": 1, "failed": 2}


def sort_key(app: Applicability, trial: Trial, index: int) -> tuple:
    return (not app.applies, _TRIAL_ORDER[trial.status], bool(app.frozen), GUARANTEES.get(app.guarantee, (9,))[0],
            sum(app.differentiators.values()), index)


def not_affine_fix(subject: Subject, exc, default: str) -> str:
    """The fix of a family's :class:`~codegen.errors.NotAffineError`, consistent with what it names:
    for an unknown input inside a nonlinearity, the change of variables (``[substitute]``) or why
    none applies on the box (:attr:`Subject.substitution_refusals`); ``default`` (a measured
    scheduling signal, ...) when a state or a known input is not affine."""
    from ..representation.substitution import find_carrier, new_name
    names = getattr(exc, "unknown_inputs", ())
    if not names:
        return default
    fixes = []
    for d in names:
        why = subject.substitution_refusals.get(d)
        if why is not None:
            fixes.append(f"no [substitute] applies to {d} ({why}): write the model so that {d} enters affinely, or "
                         f"through one expression strictly monotone in {d} over its [inputs.{d}] range and the box")
            continue
        symbol = next((s for s in subject.model.unknown_inputs if str(s) == d), None)
        carrier = find_carrier(subject.model, symbol)[0] if symbol is not None else None
        name = new_name(subject.model, carrier, d) if carrier is not None else f"{d}_carrier"
        fixes.append(f"add [substitute] {d} = \"{name}\" to the observer file (the family then estimates that "
                     f"expression's value and the step recovers {d}; docs/tutorial.md, 'Unknown inputs inside a "
                     f"nonlinearity')")
    return "; ".join(fixes)


def substitution_text(subject: Subject) -> list:
    """One sentence per substituted unknown input: the table, what the observer then estimates and
    how the input is recovered."""
    out = []
    for sub in subject.substitutions:
        out.append(f"[substitute] {sub.unknown} = \"{sub.symbol}\" ({subject.substitution_origin}): {sub.unknown} "
                   f"enters only through {sub.carrier}, so the family estimates {sub.symbol} = {sub.carrier} "
                   f"(in [{sub.lower:.6g}, {sub.upper:.6g}] on the box) and the step recovers {sub.unknown} = "
                   f"{sub.inverse}, an output of the observer under its own name")
    return out


def _with_substitution(subject: Subject, app: Applicability) -> Applicability:
    """``app`` for a subject whose unknown inputs were substituted: the ``[substitute]`` table in the
    settings it proposes (so the trial design and ``uiogen new --from-model`` design what was
    analyzed) and, when it applies, a note that says what it estimates."""
    table = subject.substitute_table
    if not table:
        return app
    observer, why = app.observer, dict(app.why)
    if observer is not None and "substitute" not in observer:
        observer = {**observer, "substitute": dict(table)}
        why["substitute"] = "; ".join(
            f"{sub.unknown} enters only through {sub.carrier}: the observer estimates {sub.symbol} and recovers "
            f"{sub.unknown} = {sub.inverse} (found by uiogen analyze, proven invertible on the box)"
            for sub in subject.substitutions)
    notes = app.notes
    if app.applies:
        notes = (*(f"applies with {text}" for text in substitution_text(subject)), *notes)
    return dataclasses.replace(app, observer=observer, why=why, notes=tuple(notes))


def assess(subject: Subject, structure) -> list:
    """Every registered family's :class:`Applicability` for ``subject``, in registry order (with the
    subject's ``[substitute]`` table in each family's settings, :func:`_with_substitution`)."""
    from ..contract import registry
    from ..contract.capabilities import Applicability as HasApplicability
    out = []
    for name in registry.names():
        fam = registry.get(name)
        try:
            app = fam.applicability(subject, structure) if isinstance(fam, HasApplicability) else None
        except UiogenError as exc:          # the family's own refusal is its condition
            app = Applicability(name, False, "unknown", condition=f"{type(exc).__name__}: {exc}")
        except Exception as exc:            # a model the family's check cannot read: say so, rank it last
            app = Applicability(name, False, "unknown", condition=f"the family's check could not read this model "
                                f"({type(exc).__name__}: {exc})")
        if app is None:
            app = Applicability(name, False, "unknown", condition="the family gives no applicability check "
                                "(the Applicability capability): design it to find out")
        out.append(_with_substitution(subject, app))
    return out


# ---- observer files ------------------------------------------------------------------------------------

def _nested_array(value) -> bool:
    return (isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
            and any(isinstance(x, (dict, list)) and not _inline(x) for v in value for x in v.values()))


def _inline(value) -> bool:
    """A value written on one line (scalars, arrays of scalars or of flat tables)."""
    if isinstance(value, dict):
        return all(not isinstance(v, (dict, list)) for v in value.values())
    if isinstance(value, list):
        return all(not isinstance(v, (dict, list)) or (isinstance(v, dict) and _inline(v)) for v in value)
    return True


def _key(key: str) -> str:
    """A TOML key: bare when it may be, else quoted ("q_f*v_x")."""
    import re
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else toml_repr(key, 10 ** 6)


def toml_lines(table: dict, why: dict | None = None, prefix: str = "") -> list:
    """``table`` as TOML lines, each value followed by its reason from ``why`` ({dotted key: text})."""
    why = why or {}
    lines, later = [], []
    for key, value in table.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            later.append((key, value))
            continue
        if _nested_array(value):
            later.append((key, value))
            continue
        text = f"{_key(key)} = {toml_repr(value, 10 ** 9)}"
        lines.append(text + (f"    # {why[path]}" if path in why else ""))
    for key, value in later:
        path = f"{prefix}{_key(key)}"
        if isinstance(value, dict):
            lines.append("")
            lines.append(f"[{path}]" + (f"    # {why[path]}" if path in why else ""))
            lines += toml_lines(value, why, f"{path}.")
        else:
            for item in value:
                lines.append("")
                lines.append(f"[[{path}]]" + (f"    # {why[path]}" if path in why else ""))
                lines += toml_lines(item, why, f"{path}.")
    return lines


def wrapper_model(subject: Subject, add_states: tuple = (), beside: Path | None = None) -> str:
    """A model file that imports the subject's model and applies --outputs/--unknown-inputs (and
    measures ``add_states``: declared outputs or states, by name), so a trial design runs on exactly
    what was analyzed. ``beside``: the folder the file is written to, which it then imports the
    model relative to (``uiogen new --from-model --outputs``: a project that moves as a whole)."""
    import os

    from ..design import sources
    from ..project import observer_file as observers
    path = subject.model_path
    shown = str(path)
    if path.parent == observers.MODELS_DIR:
        load = [f"_base = observers.builtin_model({path.stem!r})"]
    else:
        # BASE_MODEL names the file it builds on, which the design's stamp then holds (codegen.design.sources)
        shown = os.path.relpath(path.resolve(), Path(beside).resolve()) if beside is not None else str(path)
        load = [f"{sources.BASE_MODEL} = {shown!r}   # the model this file builds on (in the design's stamp)",
                f"_base = observers.load_base(__file__, {sources.BASE_MODEL})"]
    outputs = list(subject.outputs)
    lines = ['"""uiogen analyze: the model of ' + shown + ' with the sensors and unknown inputs analyzed."""',
             "import dataclasses", "from pathlib import Path", "",
             "from codegen.project import observer_file as observers", "", *load,
             "globals().update({k: v for k, v in vars(_base).items() if not k.startswith('__')})",
             "_m = _base.MODEL",
             f"_add = {list(add_states)!r}",
             "_declared = [o for o in _m.outputs if o[0] in _add]",
             "_extra = tuple(_declared) + tuple((str(s), s) for s in _m.states if str(s) in _add and str(s) not in "
             "[o[0] for o in _declared])",
             f"_changes = {{'outputs': tuple(o for o in _m.outputs if o[0] in {outputs!r}) + _extra}}"]
    if subject.selected.get("unknown_inputs") is not None:
        unknown = list(subject.selected["unknown_inputs"])    # the model's names ([substitute] applies after)
        lines += ["_inputs = (*_m.known_inputs, *_m.unknown_inputs)",
                  f"_changes['known_inputs'] = tuple(s for s in _inputs if str(s) not in {unknown!r})",
                  f"_changes['unknown_inputs'] = tuple(s for s in _inputs if str(s) in {unknown!r})"]
    lines += ["MODEL = dataclasses.replace(_m, **_changes)", ""]
    return "\n".join(lines)


def _merge(table: dict, proposal: dict, prefix: str = "") -> tuple:
    """``table`` with the keys of ``proposal`` it lacks (recursively), and the dotted keys added."""
    out, added = dict(table), []
    for key, value in proposal.items():
        if key in ("family", "model", "parameters"):
            continue
        if key not in out:
            out[key] = value
            added.append((f"{prefix}{key}", value))
        elif isinstance(value, dict) and isinstance(out[key], dict):
            out[key], more = _merge(out[key], value, f"{prefix}{key}.")
            added += more
    return out, added


def observer_table(subject: Subject, app: Applicability, folder: Path, add_states: tuple = ()) -> tuple:
    """(table, settings label) of the trial of ``app``: the observer file's own table for its own
    family, else the family's proposal; model and parameters by absolute path (or a wrapper)."""
    own = subject.config is not None and subject.config.family == app.family
    if own:
        with open(subject.config.source, "rb") as fh:
            table = tomllib.load(fh)
        table.pop("data", None)
        label = "the observer file's settings"
    else:
        table = dict(app.observer)
        label = "the analysis's settings"
    if subject.restricted or add_states:
        model = folder / f"{subject.name}_analyzed.py"
        model.write_text(wrapper_model(subject, add_states))
    elif subject.is_builtin_model:
        model = subject.model_path.stem          # a built-in model by its name (some families load it so)
    else:
        model = subject.model_path
    table = {"family": app.family, **{k: v for k, v in table.items() if k != "family"}}
    table["model"] = str(model)
    table["parameters"] = str(subject.parameter_path)
    return table, label


def trial(subject: Subject, app: Applicability, folder: Path, add_states: tuple = (), force: bool = False,
          complete: bool = False, progress=None) -> Trial:
    """Design ``app``'s family for ``subject`` through :func:`codegen.pipeline.solve` from an
    observer file written in ``folder`` (a temporary folder); ``force``: even where the family
    said it does not apply (with ``add_states`` measured, it may)."""
    if not app.applies and not force:
        return Trial(app.family, "not tried", "", reason="does not apply")
    own = subject.config is not None and subject.config.family == app.family
    if app.observer is None and not own:
        return Trial(app.family, "not tried", "", reason="the family proposes no settings for this model")
    if app.design_cost != "seconds":
        return Trial(app.family, "not tried", "", reason=f"its design takes {app.design_cost}")
    table, label = observer_table(subject, app, folder, add_states)
    if complete:
        table, _ = _merge(table, app.observer or {})
        label = "the observer file's settings, completed by the analysis"
    path = folder / f"{subject.name}_{app.family}.toml"
    text = "\n".join(toml_lines(table)) + "\n"
    path.write_text(text)
    key = _trial_key(text, subject, add_states)
    if key in _TRIALS:               # the same observer file on the same files: designed once per process
        return _TRIALS[key]
    _TRIALS[key] = result = _solve(path, app, label, progress)
    return result


#: trial designs of this process, by observer file text and the digests of the files it reads
_TRIALS: dict = {}


def _trial_key(text: str, subject: Subject, add_states: tuple) -> str:
    import hashlib
    h = hashlib.sha256(text.encode())
    for f in (subject.model_path, subject.parameter_path):
        h.update(Path(f).read_bytes())
    h.update(repr((subject.selected, add_states)).encode())
    return h.hexdigest()


TRIAL = "analysis_trial"
"""The kind of the kept trial designs (:func:`codegen.model.cache.remembered`): the same observer file on the
same model and parameters, with the same code and packages, designs the same way every run."""


def _solve(path: Path, app: Applicability, label: str, progress=None) -> Trial:
    """The trial design of the observer file ``path``; ``progress``: the analysis's, which gets the
    design's LMI solves once it has run :data:`~codegen.design.solver.PROGRESS_AFTER` seconds. Its outcome
    is kept across runs, keyed by the design's inputs as the design lock hashes them (the observer file as
    parsed, the model and parameter files as they read, every module the family and the model import, the
    packages' versions), the files' paths and this module's code (``Trial.kept`` says so)."""
    import sys

    from ..design import lock
    from ..model import cache
    from ..project import observer_file as observers
    try:
        config = observers.get(str(path))
        parts = {"design_inputs": lock.design_inputs(config), "model": str(config.model_path),
                 "parameters": str(config.parameter_path), "family": app.family, "settings": label}
    except UiogenError:             # the file itself is refused: the trial says why, every time
        return _design(path, app, label, progress)
    designed = []
    record = cache.remembered(TRIAL, parts, lambda: designed.append(1) or _design(path, app, label, progress).record(),
                              sys.modules[__name__])
    return Trial.from_record(record, kept=not designed)


def _design(path: Path, app: Applicability, label: str, progress=None) -> Trial:
    from .. import pipeline
    from ..project import observer_file as observers
    t0 = time.perf_counter()
    try:
        config = observers.get(str(path))
        # a trial commits nothing: a feasibility problem's first certified point will do
        b, _ = pipeline.solve(config, progress=progress_after(
            None if progress is None else (lambda line: progress(f"{app.family}: {line}"))), least_norm=False)
    except UiogenError as exc:
        return Trial(app.family, "failed", label, time.perf_counter() - t0,
                     reason=f"{type(exc).__name__}: {str(exc).replace(str(path), label)}", error=type(exc),
                     remedy=dict(getattr(exc, "remedy", None) or {}))
    figures = app.figures(b) if app.figures is not None else {}
    from ..certificate.text import headline
    return Trial(app.family, "certified", label, time.perf_counter() - t0, headline(b.certificate), figures)


def rank(subject: Subject, structure, design: bool = True, progress=None) -> Ranking:
    """:func:`assess` every family, design the cheap applicable ones (``design``), rank them."""
    t0 = time.perf_counter()
    apps = assess(subject, structure)
    trials = {}
    own = subject.config.family if subject.config is not None else None
    with tempfile.TemporaryDirectory(prefix="uiogen_analyze_") as tmp:
        for k, app in enumerate(apps):
            if design and app.applies:
                if progress is not None:
                    progress(f"designing {app.family} ...")
                trials[app.family] = trial(subject, app, Path(tmp), progress=progress)
                if own is None:          # from a model alone: the proposal new --from-model writes
                    apps[k], trials[app.family] = _remedied(subject, app, trials[app.family], Path(tmp), progress)
            else:
                reason = "does not apply" if not app.applies else "no trial designs requested"
                trials[app.family] = Trial(app.family, "not tried", "", reason=reason)
        what_if = completed = None
        if design and own is not None and trials[own].status != "certified":
            own_app = next(a for a in apps if a.family == own)
            completed = _completed(subject, own_app, trials[own], Path(tmp), progress)
            if completed is not None and completed["trial"].status == "certified":
                trials[own] = completed["trial"]        # the family can: the file lacked settings
            else:
                what_if = _with_sensor(subject, structure, own_app, Path(tmp), progress)
    limit = structure.decay_limit() if hasattr(structure, "decay_limit") else None
    for app in apps:
        trials[app.family] = _decay_explained(subject, app, trials[app.family], limit)
    order = sorted(range(len(apps)), key=lambda k: sort_key(apps[k], trials[apps[k].family], k))
    return Ranking([(apps[k], trials[apps[k].family]) for k in order], own, time.perf_counter() - t0, what_if,
                   completed)


def _dotted(table: dict, key: str):
    """The value at the dotted ``key`` of ``table`` ("design.alpha"), or None."""
    for part in key.split("."):
        if not isinstance(table, dict) or part not in table:
            return None
        table = table[part]
    return table


def _decay_explained(subject: Subject, app: Applicability, tried: Trial, limit: dict | None) -> Trial:
    """``tried``, its failure reason completed when the LMIs failed with the family's decay rate
    (``app.decay_key``) at or above the rate of an unobservable mode (``limit``): no output injection
    moves that mode, so no observer's error decays faster than it, and the LMIs asking for it are
    infeasible however the rest is set."""
    from ..errors import SolverError
    if (limit is None or not app.decay_key or tried.status != "failed" or tried.error is None
            or not issubclass(tried.error, SolverError)):
        return tried
    own = subject.config is not None and subject.config.family == app.family and tried.settings.startswith(
        "the observer file's settings")
    if own:
        with open(subject.config.source, "rb") as fh:
            value = _dotted(tomllib.load(fh), app.decay_key)
    else:
        value = _dotted(app.observer or {}, app.decay_key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value < limit["rate"]:
        return tried
    section, _, name = app.decay_key.rpartition(".")
    shown = f"[{section}] {name}" if section else name
    states = ", ".join(limit["states"])
    half = float(f"{0.5 * limit['rate']:.3g}")
    why = (f"{shown} = {value:g} 1/s asks the error to decay at least that fast, but {states} "
           f"{'is' if len(limit['states']) == 1 else 'are'} unobservable with a mode at Re = {-limit['rate']:.4g} 1/s "
           f"(at {limit['at']}): no observer moves it, so no error decays faster than {limit['rate']:.4g} 1/s; "
           f"take {shown} below it (e.g. {half:g}) or measure {states}")
    return dataclasses.replace(tried, reason=f"{why}. The solver: {tried.reason}")


def decay_proposal(default: float, limit: dict | None) -> tuple:
    """(rate, reason) a family proposes for its certified decay rate of the error: ``default``, or
    half the rate of the slowest unobservable mode (:meth:`Structure.decay_limit`) when that is lower,
    since no observer's error decays faster than that mode."""
    if limit is None or default <= 0.5 * limit["rate"]:
        return default, ""
    rate = float(f"{0.5 * limit['rate']:.3g}")
    states = ", ".join(limit["states"])
    return rate, (f"half the decay of the unobservable mode along {states} (Re = {-limit['rate']:.4g} 1/s at "
                  f"{limit['at']}): no observer's error decays faster than that mode")


def _set_dotted(table: dict, key: str, value) -> dict:
    """A copy of ``table`` with the dotted ``key`` ("ui_filter.time_constant") set to ``value``."""
    head, _, rest = key.partition(".")
    out = dict(table)
    out[head] = _set_dotted(dict(out.get(head) or {}), rest, value) if rest else value
    return out


def _remedied(subject: Subject, app: Applicability, failed: Trial, folder: Path, progress=None) -> tuple:
    """(app, trial): when the trial of the analysis's proposal failed with a measured fix (a
    UILoopError names the UI filter constant that certifies), the proposal with that fix, designed
    again; certified, it replaces the proposal (what ``uiogen new --from-model`` writes, with a
    comment that says so), else the first trial stands. Only for a model analysed alone: beside an
    observer file the other families' trials are of the analysis's proposal as it is, their
    failure reported with the fix it measured (the reason names it), so the file's own family is
    compared with what the analysis proposes, not with a second, tuned attempt."""
    if failed.status != "failed" or not failed.remedy or not app.observer:
        return app, failed
    observer, why = dict(app.observer), dict(app.why)
    changes = []
    for key, value in failed.remedy.items():
        section, _, name = key.rpartition(".")
        old = observer.get(section, {}).get(name) if section else observer.get(name)
        observer = _set_dotted(observer, key, value)
        shown = f"[{section}] {name}" if section else name
        changes.append(f"{shown} = {toml_repr(value, 10 ** 9)}")
        why[key] = ((f"{app.why[key]}; " if key in app.why else "") +
                    f"measured by uiogen analyze: the proposed {toml_repr(old, 10 ** 9)} failed "
                    f"({failed.error.__name__ if failed.error else 'the design failed'}), this value certifies")
    if progress is not None:
        progress(f"designing {app.family} again with {', '.join(changes)} ...")
    fixed = dataclasses.replace(app, observer=observer, why=why)
    second = trial(subject, fixed, folder)
    if second.status != "certified":
        return app, failed
    label = (f"the analysis's settings with {', '.join(changes)}, measured: the first trial failed with "
             f"{failed.error.__name__ if failed.error else 'an error'}")
    return fixed, dataclasses.replace(second, settings=label)


def _completed(subject: Subject, app: Applicability, failed: Trial, folder: Path, progress=None) -> dict | None:
    """The observer file's own design again, its settings completed with the keys of the family's
    proposal it lacks, when it failed for a setting (a missing differentiator, ...): that fix, measured."""
    from ..errors import ModelDefinitionError
    if failed.status != "failed" or failed.error is None or not issubclass(failed.error, ModelDefinitionError) \
            or not app.observer:
        return None
    table, _ = observer_table(subject, app, folder)
    _, added = _merge(table, app.observer)
    if not added:
        return None
    if progress is not None:
        progress(f"designing {app.family} again with the settings the analysis completes ...")
    return {"family": app.family, "added": {k: v for k, v in added},
            "trial": trial(subject, app, folder, force=True, complete=True), "file_trial": failed}


def _with_sensor(subject: Subject, structure, app: Applicability, folder: Path, progress=None) -> dict | None:
    """The observer file's own design again with the first sensor the structure names for its first
    failing fact (matching, observability, strong detectability, left invertibility): the fix,
    measured."""
    for key in ("matching", "observability", "strong_detectability", "left_invertibility"):
        fact = structure.fact(key)
        found = structure.candidates.get(key) or []
        if fact is not None and fact.holds is False and found:
            sensor = found[0]["sensor"]
            if progress is not None:
                progress(f"designing {app.family} again with {sensor} measured ...")
            return {"family": app.family, "fact": key, "sensor": sensor,
                    "trial": trial(subject, app, folder, add_states=(sensor,), force=True)}
    return None


def starter_text(subject: Subject, app: Applicability, folder: Path, structure=None, trial: Trial | None = None,
                 chosen_by: str | None = None, model_file: Path | None = None) -> str:
    """The observer file ``uiogen new --from-model`` writes for ``app``: its settings with the
    reasons as comments, the model and parameter file by paths relative to ``folder``; ``trial``,
    the analysis's trial design of these settings, is said in the header (certified, or the failure
    that ``uiogen design`` will repeat). ``chosen_by``: how the user chose a family that is not
    the best-ranked (``--family``); a family that proposes no settings gets the family's defaults
    (family and sample time only)."""
    import os
    proposal = app.observer
    why = {"family": f"{GUARANTEES[app.guarantee][1]}", "model": "your equations", "parameters": "your car",
           **app.why}
    if proposal is None:
        proposal = {"sample_time": subject.sample_time}
        why = {**why, "sample_time": f"s, from {subject.sample_time_source}"}
        if subject.substitute_table:
            proposal["substitute"] = subject.substitute_table
            why["substitute"] = "the change of variables the analysis applied (docs/analyze.md)"
    if model_file is not None:          # --outputs/--unknown-inputs: the model as analyzed, written beside
        why["model"] = (f"your equations ({os.path.relpath(subject.model_path, folder)}) with the sensors and "
                        f"unknown inputs analyzed: {', '.join(subject.outputs)}; "
                        f"{', '.join(subject.declared_unknown_inputs) or 'none'}")
    table = {"family": app.family, "model": os.path.relpath(model_file or subject.model_path, folder),
             "parameters": os.path.relpath(subject.parameter_path, folder),
             **{k: v for k, v in proposal.items() if k != "family"}}
    if chosen_by is None:
        head = [f"# {subject.name}: {app.family}, chosen by uiogen analyze {subject.target}",
                f"# (the best-ranked family that applies to these sensors: {', '.join(subject.outputs)};"]
    else:
        head = [f"# {subject.name}: {app.family}, {chosen_by} (uiogen analyze {subject.target};",
                f"# it applies to these sensors: {', '.join(subject.outputs)};"]
    head += [f"# unknown inputs {', '.join(subject.declared_unknown_inputs) or 'none'}).",
             "# next: uiogen design THIS_FILE --update && uiogen generate THIS_FILE && uiogen build THIS_FILE"]
    if app.observer is None:
        head.append(f"# the analysis proposes no settings for {app.family} on this model: its [design] defaults "
                    f"apply; the keys it takes are those of uiogen new DIR --family {app.family}")
    if trial is not None and trial.status == "certified":
        head.append(f"# trial design by uiogen analyze ({trial.settings}): certified")
    elif trial is not None and trial.status == "failed":
        head.append(f"# WARNING: uiogen analyze's trial design of these settings failed: {trial.reason}")
    elif trial is not None and app.observer is not None and chosen_by is not None:
        head.append(f"# not designed by uiogen analyze ({trial.reason}): the analysis's proposal, unmeasured")
    if app.frozen:
        head.append(f"# WARNING: {app.frozen_text()}")
    for note in app.notes:
        head.append(f"# note: {note}")
    return "\n".join(head + [""] + toml_lines(table, why)) + "\n"

