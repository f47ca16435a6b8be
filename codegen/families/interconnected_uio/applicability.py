"""Whether Sentouh et al. 2023's interconnected UIO can take a model with its sensors (``uiogen analyze``).

The family needs the vehicle written as interconnected subsystems (an
:class:`~codegen.families.interconnected_uio.representation.InterconnectedModelDefinition`), its
T-S form (premises from ``[state_bounds]`` and ``[premise_bounds]``), and in every subsystem the
matching condition (16) rank(C B) = rank(B): each unknown input reaches a measured output of its
subsystem in one integration, so (26) decouples it.
"""
from __future__ import annotations

from ...errors import RankConditionError, UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from ...project import observer_file as observers
    from . import design as ic_design
    from . import representation as icm

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "decoupled", condition, fix, tuple(checked))

    model = subject.model
    if not isinstance(model, icm.InterconnectedModelDefinition):
        return refuse(f"model {subject.name!r} is one system: this family needs its states split into interconnected "
                      f"subsystems (longitudinal, lateral) with the coupling between them",
                      "write the model as an InterconnectedModelDefinition (model_defs/interconnected_vehicle.py)")
    try:
        ts = icm.build(model, subject.parameters, subject.model_path)
    except UiogenError as exc:
        return refuse(f"{type(exc).__name__}: {exc}", "fix the model or the parameter file as the message says")
    checked = []
    for sub in ts.subsystems:
        try:
            ic_design.decoupling(sub)
        except RankConditionError as exc:
            return refuse(str(exc), structure.fix("matching", "measure, or take from a differentiator "
                                                              "(derivative_outputs), the derivative the input reaches"),
                          checked)
        checked.append((f"{sub.name}: matching condition (16) rank(C B) = rank(B) = {sub.nu} "
                        f"({', '.join(map(str, sub.unknown_inputs))} from {', '.join(sub.output_names)})", "exact"))
    own = subject.config is not None and subject.config.family == family.name
    observer, why, notes = None, {}, []
    example = observers.get(family.example)
    if not own and example.model == subject.model_path.stem and not subject.restricted:
        observer = {"family": family.name, "sample_time": example.sample_time, "design": dict(example.design)}
        why = {"design": f"the settings of the built-in {family.example} (the same model): derivative outputs, "
                         f"differentiators and the box flags are model-specific"}
    elif not own:
        notes.append("its settings (derivative_outputs, differentiators, initial) are model-specific: start from "
                     f"`uiogen new DIR --family {family.name}`")

    def figures(b) -> dict:
        subs = [s.name for s in b.ts.subsystems]
        out = {f"eta_{s}": (b.recheck[s]["eta"], "-", f"ISS gain of the {s} error from the coupling signals "
                            f"(27a)") for s in subs}
        out["contraction_per_step"] = (max(b.discrete[s]["contraction_per_step"] for s in subs), "-",
                                       "sqrt(V) per step, every membership sequence (matched premises)")
        return out
    return Applicability(family.name, True, "decoupled", checked=tuple(checked), notes=tuple(notes),
                         observer=observer, why=why, figures=figures)
