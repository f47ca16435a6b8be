"""Whether Nguyen et al. 2021's TS fuzzy UIO can take a model with its sensors (``uiogen analyze``).

The TS form needs outputs that measure states (its premises are measured states), a compact
state set ``[state_bounds]``, the rank conditions (15a) rank(C D) = rank(D) and (15b)
rank [[I, D], [C, 0]] = n_x + n_d (every unknown input reaches a measured state in one step, so
(16c) can reconstruct it), and LMIs (27) that can only be feasible when the decoupled error has no
mode the outputs cannot see: an invariant zero z of (A, D, C) whose Euler image 1 + T_s z lies on
or outside the unit circle refutes them.
"""
from __future__ import annotations

import numpy as np

from ...errors import RankConditionError, RepresentationError, UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from . import design as ts_design
    from . import representation

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "decoupled", condition, fix, tuple(checked))

    model = subject.model
    if not hasattr(model, "known_inputs"):
        return refuse(f"model {subject.name!r} is a {type(model).__name__}: the TS form is derived from one system "
                      f"(a ModelDefinition)", "write the model as a ModelDefinition")
    sched = [str(g.symbol) for g in model.scheduling]
    if sched:
        return refuse(f"{', '.join(sched)} {'is a scheduling signal' if len(sched) == 1 else 'are scheduling signals'}"
                      f": the TS family's premises are measured states",
                      f"make {' and '.join(sched)} a state with its own equation and measure it (an output = "
                      f"{sched[0]}), with its range in [state_bounds]")
    try:
        representation._output_selection(model)
    except UiogenError as exc:
        return refuse(str(exc).split(": ", 1)[-1], "measure states directly (y = the state), or take a family whose "
                      "outputs may be functions of the states")
    # the same bounds representation.build takes: [state_bounds], or a known input's [inputs.NAME] range
    bounds, inputs = subject.parameters.state_bounds, subject.parameters.inputs
    missing = [str(s) for s in model.states if str(s) not in bounds]
    missing += [str(u) for u in model.known_inputs if str(u) not in bounds and str(u) not in inputs]
    if missing:
        known = set(map(str, model.known_inputs))
        return refuse(f"{subject.parameter_path.name} has no bound for {', '.join(missing)}: the TS form "
                      f"needs the compact set D_x (eq. (5))",
                      "add " + " and ".join(f"[inputs.{m}] with min and max (or {m} under [state_bounds])" if m in known
                                            else f"[state_bounds] {m} = [min, max]" for m in missing)
                      + f" to {subject.parameter_path.name}")
    settings = ts_design.TSDesignSettings()
    size = {}

    def guard(n_rules, nx, ny, nphi):
        size.update(n_rules=n_rules, nx=nx, ny=ny)
    try:
        ts = representation.build(model, subject.parameters, subject.sample_time, before_bounds=guard)
    except UiogenError as exc:
        return refuse(f"{type(exc).__name__}: {exc}", "fix the model or the parameter file as the message says")
    checked = []
    try:
        ts_design.decoupling_matrices(ts)
    except RankConditionError as exc:
        C, D = ts.C, ts.D
        unseen = [str(model.unknown_inputs[j]) for j in range(ts.nd) if np.abs(C @ D[:, j]).max() <= 1e-12]
        drives = {u: [str(s) for k, s in enumerate(model.states) if abs(D[k, j]) > 0 and s not in ts.measured]
                  for j, u in enumerate(str(x) for x in model.unknown_inputs) if u in unseen}
        who = "; ".join(f"{u} drives {', '.join(s) or 'no unmeasured state'}" for u, s in drives.items())
        return refuse(f"{exc}" + (f" ({', '.join(unseen)} reach{'es' if len(unseen) == 1 else ''} no measured state "
                                  f"in one step: {who})" if unseen else ""),
                      structure.fix("matching", "measure a state that every unknown input drives"),
                      [("rank conditions (15a), (15b) on the TS form's constant D and C", "exact")])
    checked.append(("rank conditions (15a) rank(C D) = rank(D) and (15b) on the TS form's constant C, D", "exact"))
    zeros = [(abs(1 + subject.sample_time * z), z, structure.lin.samples.at(k)) for k, p in enumerate(structure.points)
             if p.zeros is not None for z in p.zeros]
    if zeros:
        worst, z, at = max(zeros, key=lambda t: t[0])
        if worst >= 1.0:
            if z.real < 0:
                fix = (f"sample_time < {-2 * z.real / abs(z) ** 2:.3g} s (|1 + T_s z| < 1 for the zero z = "
                       f"{z.real:.4g}{'' if abs(z.imag) < 1e-9 else f' {z.imag:+.4g}j'})")
            else:
                fix = structure.fix("strong_detectability", "measure a signal along the zero's direction")
            return refuse(f"the LMIs (27) cannot be feasible: the invariant zero s = {z.real:.4g}"
                          f"{'' if abs(z.imag) < 1e-9 else f' {z.imag:+.4g}j'} of the linearization at {at} maps to "
                          f"|1 + T_s s| = {worst:.4g} >= 1 at T_s = {subject.sample_time:g} s: the decoupled error "
                          f"does not decay along it, whatever the gain", fix,
                          checked + [("zeros of the frozen linearizations at the samples (a refutation, not a "
                                      "proof of feasibility)", structure.basis)])
        checked.append((f"every sampled invariant zero z has |1 + T_s z| < 1 (largest {worst:.4g})", structure.basis))
    try:
        counts = ts_design.size_guard(ts.n_rules, ts.nx, ts.ny, int(ts.theta_vertices.shape[0]), settings,
                                      subject.name)
    except RepresentationError as exc:
        return refuse(str(exc), "fewer premises (measure a signal, or move a nonlinearity into the unmeasured "
                                "consequents), or raise [design] max_lmi_blocks", checked)
    observer = {"family": family.name, "sample_time": subject.sample_time,
                "design": {"decay": 1.0, "margin": 1e-4}}
    why = {"sample_time": f"s, the Euler discretization (9); from {subject.sample_time_source}",
           "design.decay": "the paper's (27): V(e+) < V(e); lower it (< 1) to certify a decay rate",
           "design.margin": "every LMI block >= margin I, so the numpy re-check has slack"}

    def figures(b) -> dict:
        return {"contraction_per_step": (b.decrease["contraction_per_step"], "-",
                                         "sqrt(V) per step, (33) on 20000 random memberships and DMVT parameters"),
                "worst_lmi_margin": (b.recheck["worst_min_eig"], "-", "smallest eigenvalue of the LMIs (27), "
                                                                        "numpy re-check")}
    cost = "seconds" if counts["lmi_blocks"] <= 2000 else "minutes"
    notes = ()
    if len(ts.phi):
        notes = (f"unmeasured nonlinear consequents {', '.join(map(str, ts.phi))}: their Jacobian bounds over "
                 f"[state_bounds] add {int(ts.theta_vertices.shape[0])} DMVT vertices",)
    return Applicability(family.name, True, "decoupled", checked=tuple(checked), notes=notes, observer=observer,
                         why=why, design_cost=cost, figures=figures)
