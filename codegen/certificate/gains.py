"""``uiogen check-gains``: externally supplied gains against a family's LMIs, without a solver.

The generic form is the design lock's, ``{"lmi_solutions": [{"problem", "variables", "objective",
"iterations"}, ...]}`` (or a design lock file as committed, its ``lock.lmi_solutions``): the family's pipeline runs on them as on a committed design (a
:class:`~codegen.design.solver.LockReplay`, matched by problem name), every block is re-checked
with numpy and the discrete step certified; the result carries the build's
:class:`~codegen.certificate.certificate.Certificate`. A family with a printed form of its gains
(the :class:`~codegen.families.capabilities.GainForms` capability) checks that form itself and
returns the same record. :mod:`codegen.certificate.text` renders it.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..errors import (CertificateError, ConfigurationError, DesignLockError, DiscretizationError,
                      InfeasibleLMIError)
from .certificate import Certificate


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
    from ..families.capabilities import GainForms
    if isinstance(family, GainForms) and "lmi_solutions" not in gains:
        return family.check_gain_form(config, gains, source)
    return check_lock_form(family, config, gains, source)


def is_lock_file(gains: dict) -> bool:
    """Whether ``gains`` is a design lock file (its LMI solutions under ``lock``)."""
    return isinstance(gains.get("lock"), dict) and "lmi_solutions" in gains["lock"]


def check_lock_form(family, config, gains: dict, source: str) -> GainsCheck:
    """The generic check: ``gains["lmi_solutions"]`` replayed through the family's pipeline."""
    from ..design.lmi import SolveRecord
    from ..design.solver import LockReplay
    raw = gains.get("lmi_solutions")
    if raw is None and isinstance(gains.get("lock"), dict):      # a design lock file, as committed
        raw = gains["lock"].get("lmi_solutions")
    if not isinstance(raw, list):
        raise ConfigurationError(
            f"gains file {source}: no lmi_solutions; allowed: family {family.name!r} checks gains given as the design "
            f"lock gives them: "
            f'{{"lmi_solutions": [{{"problem", "variables", "objective", "iterations"}}, ...]}} '
            f"(see generated_c/{config.name}/{config.name}_design.json)", key="lmi_solutions", source=str(source))
    records = [SolveRecord.from_json(r, str(source)) for r in raw]
    try:
        replay = LockReplay(records, source=str(source))
        build = family.build(config, replay)
        replay.check_complete()
    except (CertificateError, DiscretizationError, InfeasibleLMIError) as exc:
        return GainsCheck(config.name, "lmi_solutions", str(source), False, f"{type(exc).__name__}: {exc}")
    except DesignLockError as exc:
        raise ConfigurationError(str(exc), source=str(source)) from None
    cases = {}
    for rec, sol in zip(replay.records, replay.solutions.values()):
        worst = sol.worst
        cases[rec.problem] = {"objective": rec.objective, "blocks_checked": len(sol.checks),
                              "worst_block": worst.label, "worst_min_eig": worst.min_eig}
    return GainsCheck(config.name, "lmi_solutions", str(source), True, "", build.certificate, cases)
