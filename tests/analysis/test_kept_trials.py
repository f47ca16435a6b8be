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
