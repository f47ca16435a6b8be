"""``uiogen check-gains``: externally supplied gains against a family's LMIs, without a solver.

The generic form is the design lock's, ``{"lmi_solutions": [{"problem", "variables", "objective",
"iterations"}, ...]}`` (or a design lock file as committed, its ``lock.lmi_solutions``): the family's pipeline runs on them as on a committed design (a
:class:`~codegen.design.solver.LockReplay`, matched by problem name), every block is re-checked
with numpy and the discrete step certified; the result carries the build's
:class:`~codegen.certificate.certificate.Certificate`. A family with a printed form of its gains
(the :class:`GainForms` capability, defined here where it is asked for and listed with the others in
:mod:`codegen.contract.capabilities`) checks that form itself and returns the same record.
:mod:`codegen.certificate.text` renders it.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

import math
import re
from typing import Protocol, runtime_checkable

from ..errors import (CertificateError, ConfigurationError, DesignLockError, DiscretizationError,
                      InfeasibleLMIError, brief)
from .certificate import Certificate

@runtime_checkable
class GainForms(Protocol):
    """Gains in the paper's printed form, checked by ``uiogen check-gains`` (the design-lock form
    ``lmi_solutions`` works for every family without this)."""

    def check_gain_form(self, config, gains: dict, source: str):
        """A :class:`GainsCheck` of ``gains`` (read from ``source``), which are not in the design-lock form;
        a :class:`~codegen.errors.ConfigurationError` naming both forms when they are in neither."""


# the keys of one record of lmi_solutions (codegen.design.lmi.SolveRecord)
RECORD_KEYS = ("problem", "variables", "objective", "iterations", "data")


@dataclass(frozen=True)
class GainsCheck:
    """The verdict on a gains file.

    Attributes
    ----------
    observer, form, source : str
        The observer, the form of the gains ("lmi_solutions" or the family's own), the file.
    feasible : bool
        Every block passes and the step is certified.
    reason : str
        Why not (the failing block or certificate), "" when feasible.
    certificate : Certificate or None
        What the gains certify, when the family's pipeline ran on them.
    cases : dict
        {case: {"blocks": [{"label", "min_eig" | ...}], figure: value, ...}}: the re-checked blocks
        of each LMI problem (or each set of conditions a printed form is checked under).
    figures : dict
        Further figures of the check (the family's), JSON.
    """

    observer: str
    form: str
    source: str
    feasible: bool
    reason: str = ""
    certificate: Certificate | None = None
    cases: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        out = {k: v for k, v in dataclasses.asdict(self).items() if k != "certificate"}
        out["certificate"] = None if self.certificate is None else self.certificate.to_json()
        return out


def check(family, config, gains: dict, source: str) -> GainsCheck:
    """Check ``gains`` (parsed JSON) against ``family``'s LMIs for observer ``config``: the
    family's printed form when it has one and ``gains`` is in it, else the design-lock form.

    Raises
    ------
    ConfigurationError
        ``gains`` is in no form the family checks, or a record does not fit the design (names
        the problem and the variable).
    """
    import numpy as np

    if isinstance(family, GainForms) and "lmi_solutions" not in gains:
        if not is_lock_file(gains):
            _printed_form_entries(gains, source)
        try:
            # finite entries can still be unusable: P_i + X singular, or products that overflow (1e308)
            with np.errstate(over="ignore", invalid="ignore"):
                result = family.check_gain_form(config, gains, source)
        except np.linalg.LinAlgError as exc:
            return GainsCheck(config.name, "printed", str(source), False,
                              f"the gains cannot be evaluated in double precision (LinAlgError: {exc}): a matrix the "
                              f"conditions invert is singular, or the entries are so large that products overflow")
        return _stated_gamma_checked(result, gains, source)
    return check_lock_form(family, config, gains, source)


#: the significant digits of a stated gamma compared with the re-derived one at most: a design's own gamma (the
#: solver's nu, with its margins) and the numpy re-check's smallest nu of the same gains differ from the 5th digit
#: on (measured: lpv_linf_driver_torque's lock 0.01957027, its re-check 0.0195701 and 0.0195699)
STATED_DIGITS = 4


def _written_digits(value: float) -> int:
    """The significant digits a number is written with (its shortest repr: 0.0095 has 2), at most
    :data:`STATED_DIGITS`."""
    mantissa = repr(abs(float(value))).lower().split("e")[0].replace(".", "").lstrip("0").rstrip("0")
    return max(1, min(len(mantissa), STATED_DIGITS))


def agrees_to_written_digits(stated: float, derived: float) -> bool:
    """Whether ``derived`` rounds to ``stated`` at the digits ``stated`` is written with (at most
    :data:`STATED_DIGITS`): half a unit of its last written digit apart, or closer."""
    if not (math.isfinite(stated) and math.isfinite(derived)) or stated <= 0:
        return False
    unit = 10.0 ** (math.floor(math.log10(stated)) - _written_digits(stated) + 1)
    return abs(stated - derived) <= 0.5 * unit * (1 + 1e-12)


def _stated_gamma_checked(result: GainsCheck, gains: dict, source) -> GainsCheck:
    """A printed-form check whose gains file states ``gamma``: that gamma must be the one the check
    re-derives from the gains (any of its cases, to the digits written), else the file is refused naming
    the key -- a forged or stale gamma would otherwise be printed beside PASS. ``gamma_stated`` is a
    file's quote of its source's claim (the published design's paper), not a claim about what the gains
    certify: it stays, with what they do certify beside it when the two differ."""
    derived = [c["gamma"] for c in result.cases.values()
               if isinstance(c, dict) and isinstance(c.get("gamma"), (int, float)) and math.isfinite(c["gamma"])]
    if not derived:
        return result               # no gamma re-derived (a failing check): the FAIL verdict is what is shown
    shown = " / ".join(dict.fromkeys(f"{g:.6g}" for g in derived))
    if "gamma" in gains:
        stated = number(gains["gamma"], "gamma", source, "a positive number")
        if not any(agrees_to_written_digits(stated, g) for g in derived):
            allowed = (f"the gamma these gains certify, {shown} (to the digits written, at most {STATED_DIGITS} "
                       f"significant), or no gamma key; a source's own claim goes under gamma_stated")
            raise ConfigurationError(f"gains file {source}: gamma = {brief(repr(gains['gamma']))}: these gains certify "
                                     f"gamma = {shown} (re-checked with numpy), not {stated:.6g}; allowed: {allowed}",
                                     source=str(source), key="gamma", value=gains["gamma"], allowed=allowed)
    if isinstance(gains.get("gamma_stated"), (int, float)) and not isinstance(gains["gamma_stated"], bool) \
            and not any(agrees_to_written_digits(float(gains["gamma_stated"]), g) for g in derived):
        figures = dict(result.figures)
        figures["gamma_stated_in_file_checked"] = (f"not certified by these gains: they certify {shown} (the "
                                                   f"file's quote of its source, shown as written)")
        result = dataclasses.replace(result, figures=figures)
    return result


# the names of the printed forms' gains (linf_uio: P1..PN, L1..LN, X, alpha; nonlinear_tyre_observer: L), and the
# design-lock form's key: a key that is a near miss of one of them, while that one is absent, is a misspelling
_PRINTED = re.compile(r"^(?:[PL]\d+|X|L|alpha)$")


def _printed_form_entries(gains: dict, source) -> None:
    """Refuse what a family's printed form would otherwise take silently (this module, not the family
    packages, holds it: those are design inputs, and editing them re-solves every committed design):

    - a misspelt gain name (``x`` for ``X``, ``alfa`` for ``alpha``, ``l`` for ``L``): the gain would be
      unused (X taken as 0, the observer's alpha) and the verdict wrong;
    - a boolean or a string among a gain's entries (``true`` or ``"1.5"``, which ``np.array(.., float)``
      turns into a number).

    Keys resembling no gain stay allowed: a design artifact or a published design carries annotations
    (``source``, ``gamma_stated``, ``certificate``, ...) beside its gains.
    """
    from ..settings import suggest
    present = [k for k in gains if _PRINTED.match(k)]
    vertices = max([int(k[1:]) for k in present if k[1:].isdigit()] + [0])
    names = ["X", "L", "alpha", "lmi_solutions", *(f"{c}{i}" for c in "PL" for i in range(1, vertices + 2))]
    for key in gains:
        if key in names:
            continue
        close = suggest(key, names)
        if close is not None and close not in gains:
            raise ConfigurationError(f"gains file {source}: key {key!r} is not read (did you mean {close!r}?); "
                                     f"allowed: the family's printed form of its gains or the design lock's "
                                     f"lmi_solutions", source=str(source), key=key)
    for key in present:
        if key == "alpha":
            number(gains[key], key, source, "a positive number (the decay rate in 1/s)")
        else:
            number_matrix(gains[key], key, source, "finite numbers, a matrix as nested lists")


def number_matrix(value, key: str, source, allowed: str):
    """``value`` (parsed JSON) as a float matrix, refusing what ``np.array(value, float)`` would quietly
    accept: a boolean (``true`` read as 1.0) or a string of digits (``"1.5"``) among the entries.

    Parameters
    ----------
    value : object
        A number, a list of numbers or a list of lists of numbers.
    key : str
        The gains file's key it was read from, named in the error.
    source : str or Path
        The gains file.
    allowed : str
        What the file may hold, for the error.

    Returns
    -------
    numpy.ndarray
        The entries, 2-D for a matrix (its shape is the caller's to check).

    Raises
    ------
    ConfigurationError
        An entry is not a finite JSON number, or the rows are ragged.
    """
    import numpy as np

    def leaves(v):
        if isinstance(v, list):
            for x in v:
                yield from leaves(x)
        else:
            yield v
    # a bool is an int to Python and a digit string parses as float: both would be a wrong number, silently
    bad = next((x for x in leaves(value) if isinstance(x, bool) or not isinstance(x, (int, float))), None)
    if bad is not None or (not isinstance(value, list) and value is None):
        raise ConfigurationError(f"gains file {source}: {key} = {brief(repr(value))}: entry {bad!r} is not a number; "
                                 f"allowed: {allowed}", source=str(source), key=key, value=value, allowed=allowed)
    try:
        m = np.array(value, dtype=float)
    except ValueError:          # ragged rows
        raise ConfigurationError(f"gains file {source}: {key} = {brief(repr(value))} has rows of different lengths; "
                                 f"allowed: {allowed}", source=str(source), key=key, value=value,
                                 allowed=allowed) from None
    if not np.all(np.isfinite(m)):
        raise ConfigurationError(f"gains file {source}: {key} has non-finite entries (NaN or Infinity); allowed: "
                                 f"{allowed}", source=str(source), key=key, value=value, allowed=allowed)
    return m


def number(value, key: str, source, allowed: str) -> float:
    """``value`` as a finite float; a boolean or a string is refused (see :func:`number_matrix`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigurationError(f"gains file {source}: {key} = {brief(repr(value))}; allowed: {allowed}",
                                 source=str(source), key=key, value=value, allowed=allowed)
    return float(value)


def refuse_misspelt(gains: dict, read: list, source, allowed: str) -> None:
    """Refuse a key that is not read but is a near miss of one that is (``x`` for ``X``, ``alfa`` for
    ``alpha``, ``l1`` for ``L1``): it would be silently unused and the verdict computed without it.

    Keys that resemble no read key stay allowed: a design artifact or a published design carries
    annotations (``source``, ``gamma_stated``, ``certificate``, ...) beside its gains.
    """
    from ..settings import suggest
    for key in gains:
        if key in read:
            continue
        close = suggest(key, read)
        if close is not None:
            raise ConfigurationError(f"gains file {source}: key {key!r} is not read (did you mean {close!r}?); "
                                     f"allowed: {allowed}", source=str(source), key=key, allowed=allowed)


def _lock_records(raw: list, source) -> list:
    """The records of ``lmi_solutions`` as :class:`~codegen.design.lmi.SolveRecord`, each refused with
    its index and key when it is not one (a gains file is the user's, not a damaged lock: the error is a
    ConfigurationError naming what is allowed, not advice to re-solve)."""
    from ..design.lmi import SolveRecord
    allowed = ('lmi_solutions: a list of {"problem": str, "variables": {name: number or matrix}, "objective": '
               'number, "iterations": integer} as the design lock writes them')
    records = []
    for i, rec in enumerate(raw):
        where = f"lmi_solutions[{i}]"
        if not isinstance(rec, dict):
            raise ConfigurationError(f"gains file {source}: {where} = {brief(repr(rec))} is not an object; allowed: "
                                     f"{allowed}", source=str(source), key=where, value=rec, allowed=allowed)
        from ..settings import suggest
        for key in rec:
            if key not in RECORD_KEYS:
                hint = suggest(key, RECORD_KEYS)
                raise ConfigurationError(
                    f"gains file {source}: {where} has key {key!r}" + (f" (did you mean {hint!r}?)" if hint else "")
                    + f"; allowed: {', '.join(RECORD_KEYS)}", source=str(source), key=f"{where}.{key}",
                    allowed=", ".join(RECORD_KEYS))
        missing = [k for k in RECORD_KEYS[:4] if k not in rec]
        if missing:
            raise ConfigurationError(f"gains file {source}: {where} lacks {', '.join(missing)}; allowed: {allowed}",
                                     source=str(source), key=f"{where}.{missing[0]}", allowed=allowed)
        if not isinstance(rec["variables"], dict):
            raise ConfigurationError(f"gains file {source}: {where}.variables = {brief(repr(rec['variables']))} is "
                                     f"not an object; allowed: {allowed}", source=str(source),
                                     key=f"{where}.variables", allowed=allowed)
        for name, value in rec["variables"].items():
            number_matrix(value, f"{where}.variables.{name}", source, "finite numbers, a matrix as nested lists")
        number(rec["objective"], f"{where}.objective", source, "a finite number")
        if isinstance(rec["iterations"], bool) or not isinstance(rec["iterations"], int):
            raise ConfigurationError(f"gains file {source}: {where}.iterations = {brief(repr(rec['iterations']))}; "
                                     f"allowed: an integer", source=str(source), key=f"{where}.iterations")
        try:
            records.append(SolveRecord.from_json(rec, str(source)))
        except DesignLockError as exc:
            raise ConfigurationError(f"gains file {source}: {where}: {exc}", source=str(source), key=where) from None
    return records


def is_lock_file(gains: dict) -> bool:
    """Whether ``gains`` is a design lock file (its LMI solutions under ``lock``)."""
    return isinstance(gains.get("lock"), dict) and "lmi_solutions" in gains["lock"]


def _lock_entries_checked(gains: dict, config, build, source) -> None:
    """A design lock file given as gains, of the observer's current design (its ``design_inputs``): every
    entry it reports (gamma, gains, the certificate) must be what its LMI solutions give when replayed,
    as :func:`codegen.design.lock.check_reproduced` requires of a committed lock; a forged entry (gamma
    x 1000 with the checksums recomputed) is refused naming it. A lock of another configuration is
    checked for its solutions only (its entries describe that configuration's design)."""
    from ..design import lock as design_lock
    if not is_lock_file(gains) or gains["lock"].get("design_inputs") != design_lock.design_inputs(config):
        return
    try:
        design_lock.check_reproduced(gains, build, str(source), config.name if config.builtin else config.source)
    except DesignLockError as exc:
        fresh = json.loads(json.dumps({**build.artifact(), "certificate": build.certificate.to_json()},
                                      sort_keys=True))
        wrong = sorted(k for k in gains if k != "lock" and (k not in fresh or design_lock._differs(fresh[k], gains[k])))
        raise ConfigurationError(f"gains file {exc}", source=str(source),
                                 key=wrong[0] if wrong else None, value=gains.get(wrong[0]) if wrong else None,
                                 allowed="the entries its own LMI solutions give") from None


def check_lock_form(family, config, gains: dict, source: str) -> GainsCheck:
    """The generic check: ``gains["lmi_solutions"]`` replayed through the family's pipeline."""
    import numpy as np

    from ..design.solver import LockReplay
    raw = gains.get("lmi_solutions")
    if raw is None and isinstance(gains.get("lock"), dict):      # a design lock file, as committed
        raw = gains["lock"].get("lmi_solutions")
    if not isinstance(raw, list):
        from ..settings import suggest
        near = next((k for k in gains if k != "lmi_solutions" and suggest(k, ["lmi_solutions"])), None)
        what = ("no lmi_solutions" if raw is None and near is None
                else f"key {near!r} is not read (did you mean 'lmi_solutions'?)" if raw is None
                else f"lmi_solutions = {brief(repr(raw))} is not a list")
        raise ConfigurationError(
            f"gains file {source}: {what}; allowed: family {family.name!r} checks gains given as the design "
            f"lock gives them: "
            f'{{"lmi_solutions": [{{"problem", "variables", "objective", "iterations"}}, ...]}} '
            f"(see generated_c/{config.name}/{config.name}_design.json)", key="lmi_solutions", source=str(source))
    if not is_lock_file(gains):
        # a hand-written file holds lmi_solutions alone: any other key would be silently unused
        from ..settings import suggest
        stray = sorted(k for k in gains if k != "lmi_solutions")
        if stray:
            hint = suggest(stray[0], ["lmi_solutions"])
            raise ConfigurationError(
                f"gains file {source}: key {stray[0]!r} is not read" + (f" (did you mean {hint!r}?)" if hint else "")
                + f'; allowed: only "lmi_solutions" (or a design lock file as committed)', source=str(source),
                key=stray[0], allowed="lmi_solutions")
    records = _lock_records(raw, source)
    try:
        replay = LockReplay(records, source=str(source))
        build = family.build(config, replay)
        replay.check_complete()
    except (CertificateError, DiscretizationError, InfeasibleLMIError) as exc:
        return GainsCheck(config.name, "lmi_solutions", str(source), False, f"{type(exc).__name__}: {exc}")
    except (ZeroDivisionError, np.linalg.LinAlgError) as exc:
        # forming the gains inverts or divides by a matrix of the solution; one singular or overflowing in
        # floating point (the re-check refuses a block that is singular beyond rounding, not every such
        # product) makes the gains not certified
        return GainsCheck(config.name, "lmi_solutions", str(source), False,
                          f"{type(exc).__name__}: a matrix the gains are formed with is singular ({exc}): the "
                          f"solution is on the boundary of its LMIs, not inside")
    except DesignLockError as exc:
        raise ConfigurationError(str(exc), source=str(source)) from None
    _lock_entries_checked(gains, config, build, source)
    cases = {}
    for rec, sol in zip(replay.records, replay.solutions.values()):
        worst = sol.worst
        cases[rec.problem] = {"objective": rec.objective, "blocks_checked": len(sol.checks),
                              "worst_block": worst.label, "worst_min_eig": worst.min_eig}
    return GainsCheck(config.name, "lmi_solutions", str(source), True, "", build.certificate, cases)
