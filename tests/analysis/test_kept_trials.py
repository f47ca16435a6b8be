"""``uiogen analyze`` keeps each trial design's outcome across runs (``ranking._solve``), keyed by the design's
inputs as the design lock hashes them: a second analysis of the same files says the trials were kept and gives
the same answer; an edited input designs again."""
import shutil
from pathlib import Path


from codegen import analysis
from codegen.model import cache

CASE = Path(__file__).resolve().parent / "models" / "algebraic_no_differentiators"


def _trials(a) -> dict:
    out = {f: t for f, t in ((app.family, t) for app, t in a.ranking.entries) if t.status != "not tried"}
    c = a.ranking.completed
    if c is not None:
        out["completed"] = c["trial"]
    return out


def test_a_second_analysis_keeps_its_trials_and_an_edit_designs_again(tmp_path, fresh_cache, monkeypatch):
    from codegen.analysis import ranking
    case = tmp_path / "case"
    shutil.copytree(CASE, case)
    obs = case / "observer.toml"

    def run():
        cache.forget()                      # a new process: the entries read from their files
        monkeypatch.setattr(ranking, "_TRIALS", {})
        return analysis.analyze(str(obs))

    first = run()
    trials = _trials(first)
    assert trials and not any(t.kept for t in trials.values())
    assert {t.status for t in trials.values()} >= {"certified"}
    again = run()
    kept = _trials(again)
    assert kept.keys() == trials.keys() and all(t.kept for t in kept.values())
    for family, t in trials.items():
        k = kept[family]
        assert (k.status, k.settings, k.headline, k.reason, k.error, k.remedy) == \
            (t.status, t.settings, t.headline, t.reason, t.error, t.remedy), family
        assert k.figures == t.figures and k.seconds == t.seconds
    assert [a.family for a, _ in again.ranking.entries] == [a.family for a, _ in first.ranking.entries]
    assert "kept: an earlier run designed the same inputs" in again.text()
    # the scheduling box edited in the parameter file: every trial designed again
    params = case / "parameters.toml"
    params.write_text(params.read_text().replace("max = 5.0", "max = 4.5"))
    edited = _trials(run())
    assert edited and not any(t.kept for t in edited.values())


def test_the_equations_are_kept_and_every_input_edited_derives_them_again(tmp_path, fresh_cache, monkeypatch):
    """The parameters put into a model's equations (``subject.equations_of``) are kept across runs: read
    back, the same expressions; a parameter value, the model or the parameter file's [exogenous] table
    edited, derived again."""
    import dataclasses

    import sympy as sp

    from codegen.analysis import subject
    from codegen.model import load_parameters
    from codegen.project import observer_file as observers
    derived = []
    real = subject._equations_of
    monkeypatch.setattr(subject, "_equations_of", lambda m, p: derived.append(1) or real(m, p))

    def equations(model, params):
        cache.forget()                      # a new process: the entries read from their files
        return subject.equations_of(model, params)
    for name in ("niki_sideslip_nonlinear_tyre", "interconnected_uio"):
        cfg = observers.get(name)
        model = cfg.load_definition()           # the interconnected model as subsystems, its [exogenous] read
        path = tmp_path / f"{name}.toml"
        path.write_text(cfg.parameter_path.read_text())
        params = load_parameters(path)
        derived.clear()
        first = equations(model, params)
        again = equations(model, params)
        assert derived == [1], name                     # the second read back
        assert sp.srepr(again.f) == sp.srepr(first.f) and sp.srepr(again.h) == sp.srepr(first.h)
        assert (again.box, again.fixed, again.states, again.outputs) == (first.box, first.fixed, first.states,
                                                                          first.outputs)
        # a parameter value edited
        key, value = next((k, v) for k, v in params.values.items() if v)
        edited = dataclasses.replace(params, values={**params.values, key: 1.01 * value})
        equations(model, edited)
        assert derived == [1, 1], name
        # the model edited (one more output)
        bigger = dataclasses.replace(model, outputs=(*model.outputs, ("extra", model.states[0])))
        equations(bigger, params)
        assert derived == [1, 1, 1], name
    # the [exogenous] table of the file edited (the interconnected model reads it from the file)
    text = path.read_text()
    assert "\nF_rr = 155.3 " in text
    path.write_text(text.replace("\nF_rr = 155.3 ", "\nF_rr = 160.0 ", 1))
    moved = equations(model, load_parameters(path))
    assert derived == [1, 1, 1, 1]
    assert {str(k): v for k, v in moved.fixed.items()}["F_rr"] == 160.0
