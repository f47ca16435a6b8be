"""The text of ``uiogen analyze`` (and the top of a failed ``uiogen design``): the subject, the
structural facts with what each rests on, what is estimable, the families ranked with their trial
designs side by side, and why the first one is first."""
from __future__ import annotations

from ..model.dimensions import unranged_note
from ..settings import toml_repr
from .ranking import GUARANTEES, Ranking, sort_key, substitution_text
from .structure import BASIS

_MARK = {True: "holds", False: "FAILS", None: "info "}


def _figures(figures: dict) -> str:
    return "; ".join(f"{k} = {v:.6g}" + (f" {u}" if u and u != "-" else "") for k, (v, u, _) in figures.items())


def _unknown(subject) -> list:
    """The analyzed unknown inputs, a substituted one with the input it stands for."""
    stands = {str(sub.symbol): str(sub.unknown) for sub in subject.substitutions}
    return [f"{u} (for {stands[u]}, [substitute])" if u in stands else u for u in subject.unknown_inputs]


def subject_lines(subject, structure) -> list:
    eq = subject.equations
    unit = subject.unit
    lines = [f"model {subject.name} ({subject.model_path}), parameters {subject.parameter_path}"
             + (f", observer file {subject.config.source} (family {subject.config.family})" if subject.config else ""),
             f"  states: {', '.join(f'{s} [{unit(s)}]' for s in subject.states)}",
             f"  measured outputs: {', '.join(subject.outputs)}"
             + (f" (--outputs; declared but not measured: {', '.join(subject.unmeasured_declared_outputs())})"
                if subject.selected.get('outputs') else ""),
             f"  known inputs: {', '.join(subject.known_inputs) or 'none'}; unknown inputs: "
             f"{', '.join(_unknown(subject)) or 'none'}"
             + (" (--unknown-inputs)" if subject.selected.get("unknown_inputs") else ""),
             *(f"  {text}" for text in substitution_text(subject)),
             *(f"  {d} enters through a nonlinearity and no [substitute] applies: {why}"
               for d, why in subject.substitution_refusals.items()),
             f"  sample time {subject.sample_time:g} s (from {subject.sample_time_source})"]
    if eq.box:
        lines.append("  box: " + ", ".join(f"{s} in [{lo:g}, {hi:g}] {eq.box_source.get(s, '')}"
                                           for s, (lo, hi) in eq.box.items()))
    lines.append(f"  checked at: {structure.lin.samples.describe()} ({BASIS[structure.basis]})")
    note = unranged_note(subject.model, subject.model_path)
    if note:
        lines.append(f"  {note}")
    return lines


def structure_lines(structure) -> list:
    lines = ["structure (what the sensors allow):"]
    for f in structure.facts:
        lines.append(f"  [{_MARK[f.holds]}] {f.key}: {f.statement} [{f.basis}]")
        if f.fix:
            lines.append(f"          fix: {f.fix}")
    if structure.hosmd_orders:
        lines.append("  output derivatives an algebraic (HOSMD) observer would need: "
                     + ", ".join(f"{k} order {v}" for k, v in structure.hosmd_orders.items()))
    return lines


def estimable_lines(structure) -> list:
    e = structure.estimable
    lines = ["what is estimable with these sensors:"]
    ui = structure.subject.unknown_inputs
    if ui:
        if e["unknown_inputs_not"]:
            lines.append(f"  unknown inputs: {', '.join(e['unknown_inputs']) or 'none'} can be told apart; "
                         f"{', '.join(e['unknown_inputs_not'])} cannot: drop {'it' if len(e['unknown_inputs_not']) == 1 else 'them'}"
                         f" or treat {'it' if len(e['unknown_inputs_not']) == 1 else 'them'} as known "
                         f"(uiogen analyze ... --unknown-inputs {','.join(e['unknown_inputs'])})")
        else:
            lines.append(f"  unknown inputs: all ({', '.join(ui)})")
        lines.append(f"  states whatever {'those' if e['unknown_inputs_not'] else 'the'} unknown inputs do: "
                     f"{', '.join(e['states_exactly']) or 'none'} exactly (from output derivatives)"
                     + (f"; {', '.join(s for s in e['states_asymptotically'] if s not in e['states_exactly'])} "
                        f"asymptotically (the zero dynamics decay)"
                        if len(e["states_asymptotically"]) > len(e["states_exactly"]) else "")
                     + (f"; NOT {', '.join(e['states_not'])}" if e["states_not"] else ""))
    if e["states_unobservable_without_unknown_inputs"]:
        lines.append(f"  unobservable even without unknown inputs: {', '.join(e['states_unobservable_without_unknown_inputs'])}")
    elif not ui:
        lines.append("  every state is observable (no unknown inputs)")
    return lines


def family_lines(ranking: Ranking) -> list:
    from ..contract import registry
    lines = ["observer families, best first:"]
    for k, (app, trial) in enumerate(ranking.entries, start=1):
        fam = registry.get(app.family)
        head = f"  {k}. {app.family} ({fam.short_citation or fam.title})"
        if app.applies:
            head += f": applies; {GUARANTEES[app.guarantee][1]}"
        else:
            head += f": does not apply: {app.condition}"
        lines.append(head)
        if not app.applies and app.fix:
            lines.append(f"       fix: {app.fix}")
        if trial.status == "certified":
            lines.append(f"       trial design ({trial.settings}): certified {_took(trial)}: "
                         f"{_figures(trial.figures) or trial.headline}")
        elif trial.status == "failed":
            lines.append(f"       trial design ({trial.settings}): FAILED {_took(trial)}: "
                         f"{trial.reason}")
        elif app.applies:
            lines.append(f"       trial design: not tried ({trial.reason})")
        if app.frozen and app.applies:
            lines.append(f"       {app.frozen_text()}")
        for text, basis in app.checked:
            lines.append(f"       checked: {text} [{basis}]")
        for note in app.notes:
            lines.append(f"       note: {note}")
        if app.differentiators and app.applies:
            lines.append("       differentiators: " + ", ".join(f"{s} order {o}" for s, o in app.differentiators.items()))
    return lines


def explain(ranking: Ranking) -> str:
    """Why the first family is first, and where the observer file's own family stands."""
    if ranking.best is None:
        return "no family applies to these sensors: the fixes above say what would change that"
    best, bt = ranking.entries[0]
    text = f"best: {best.family} ({GUARANTEES[best.guarantee][1]}"
    text += f"; certified: {_figures(bt.figures)})" if bt.status == "certified" else ")"
    if best.frozen:
        text += f"; {best.frozen_text()}"
    table = (best.observer or {}).get("substitute")
    if table:
        text += " with " + ", ".join(f"[substitute] {d} = \"{w}\"" for d, w in table.items())
    own = ranking.own_family
    if own is None or own == best.family:
        done = ("" if ranking.completed is None or ranking.completed["trial"] is not bt else
                " (with the settings the analysis completes, below)")
        return text + (f"; it is the observer file's own family{done}" if own == best.family else "")
    k = ranking.position(own)
    app, trial = ranking.entries[k]
    kb, ko = sort_key(best, bt, 0), sort_key(app, trial, 0)
    if not app.applies:
        why = f"it does not apply ({app.condition})"
    elif ko[1] != kb[1]:
        why = (f"its trial design {'failed' if trial.status == 'failed' else 'was not tried'}"
               + (f" ({trial.reason})" if trial.reason else "") + f", {best.family}'s is certified")
    elif ko[2] != kb[2]:
        why = (f"its proposal holds measured signals constant ({', '.join(app.frozen)}), {best.family}'s reads "
               f"every one")
    elif ko[3] != kb[3]:
        why = (f"{best.family}'s guarantee is stronger: {GUARANTEES[best.guarantee][1]}, against "
               f"{GUARANTEES[app.guarantee][1]}")
        if trial.status == "certified":
            why += f" (measured: {own} {_figures(trial.figures)})"
    elif ko[4] != kb[4]:
        why = (f"{best.family} differentiates less (HOSMD orders {sum(best.differentiators.values())} against "
               f"{sum(app.differentiators.values())})")
    else:
        why = "the registry's order (everything else equal)"
    return text + f"; the observer file's family {own} ranks {k + 1}: {why}"


def _took(trial) -> str:
    """How long the trial design took, and whether this run kept its outcome from an earlier one."""
    return f"in {trial.seconds:.1f} s" + (" (kept: an earlier run designed the same inputs)" if trial.kept else "")


def lines(analysis) -> list:
    out = subject_lines(analysis.subject, analysis.structure) + [""] + structure_lines(analysis.structure) + [""] \
        + estimable_lines(analysis.structure)
    if analysis.ranking is not None:
        out += [""] + family_lines(analysis.ranking) + ["", explain(analysis.ranking)]
        c = analysis.ranking.completed
        if c is not None:
            t = c["trial"]
            result = (f"certified {_took(t)}: {_figures(t.figures) or t.headline}" if t.status == "certified"
                      else f"{t.status}: {t.reason}")
            added = "; ".join(f"{k} = {toml_repr(v, 10 ** 6)}" for k, v in c["added"].items())
            out.append(f"the fix, measured: the observer file's settings completed with {added}: the {c['family']} "
                       f"design is {result}")
        w = analysis.ranking.what_if
        if w is not None:
            t = w["trial"]
            result = (f"certified {_took(t)}: {_figures(t.figures) or t.headline}" if t.status == "certified"
                      else f"{t.status}: {t.reason}")
            out.append(f"the fix, measured: with {w['sensor']} measured too ({w['fact']}), the observer file's "
                       f"{w['family']} design is {result}")
    t = analysis.seconds
    out.append(f"time: structure {t['structure']:.2f} s, families {t.get('families', 0.0):.2f} s "
               f"(trial designs included), total {t['total']:.2f} s")
    return out


def text(analysis) -> str:
    return "\n".join(lines(analysis))
