"""Whether the DMVT observer can take a model with its sensors (``uiogen analyze``).

It takes any model x' = f(x, w), y = h(x, w) whose Jacobians are bounded on a box of the states and
of the measured signals: nonlinear outputs included. It needs no unknown input (it estimates the
state), a box for every state (``[state_bounds]``) and every signal it reads, and the sensors' noise
levels of the outputs (the gains minimise the certified RMS bound at them): the parameter file's
``[sensor_noise]``, which the proposal copies into ``[design] noise``. Whether one Lyapunov matrix
holds at every corner of the Jacobian box is what the trial design finds out.
"""
from __future__ import annotations

from ...errors import UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from ...model import ModelDefinition
    from . import representation

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "states_only", condition, fix, tuple(checked))

    model = subject.model
    if not isinstance(model, ModelDefinition):
        return refuse("the model is not one system of equations (a ModelDefinition)",
                      "write the model as a ModelDefinition (x' = f(x, u), outputs y = h(x, u))")
    if model.unknown_inputs:
        return refuse(f"unknown inputs {', '.join(map(str, model.unknown_inputs))}: the DMVT observer estimates the "
                      f"state of a model without them",
                      "measure each unknown input (a known input), or model it as a state with d' = 0")
    try:
        rep = representation.build(model, subject.parameters)
    except UiogenError as exc:
        text = str(exc).split(": ", 1)[-1]
        return refuse(text, "add the boxes it names to the parameter file ([state_bounds], [inputs.NAME], "
                            "[scheduling.NAME])" if "lacks" in text else "see the condition")
    checked = [(f"every entry of the Jacobians of f and h bounded over the box of the states and the measured "
                f"signals ({2 ** len(rep.free_entries)} corners; sound interval bounds)", "proof")]
    from ...project.sensor_noise import declared as declared_noise
    outputs = [n for n, _ in model.outputs]
    try:
        declared = declared_noise(model, subject.parameters)      # in the model's units
    except UiogenError as exc:
        return refuse(str(exc).split(": ", 1)[-1], "correct [sensor_noise] of the parameter file", checked)
    missing = [n for n in outputs if n not in declared]
    if missing:
        return Applicability(family.name, True, "states_only", checked=tuple(checked),
                             notes=(f"no sensor noise declared for {', '.join(missing)}: the design needs every "
                                    f"output's level ([sensor_noise] of the parameter file, or [design] noise); the "
                                    f"analysis proposes no settings without them",))
    observer = {"family": family.name, "sample_time": subject.sample_time,
                "design": {"noise": {n: declared[n] for n in outputs}}}
    why = {"sample_time": f"s, from {subject.sample_time_source}",
           "design.noise": f"the outputs' sensor noise from [sensor_noise] of {subject.parameter_path.name}: the gains "
                           f"minimise the certified RMS bound at these levels"}

    def figures(b) -> dict:
        d = b.synthesis
        return {"contraction_per_step": (d.contraction, "-", "sqrt(V) per step in the state box"),
                **{f"rms_{n}": (float(v), b.rep.definition.units.get(n, ""), "certified RMS error at the noise levels")
                   for n, v in zip(b.output_names, d.rms)}}
    return Applicability(family.name, True, "states_only", checked=tuple(checked), observer=observer, why=why,
                         figures=figures, decay_key="design.decay")
