"""A campaign's excitation run is held whole in memory: a ``duration`` whose run cannot fit is the
campaign file's mistake, named before anything is allocated (before: ``duration = 1e6`` ended in a
numpy ``_ArrayMemoryError`` traceback, "Unable to allocate 188. GiB", after the 17 GiB stage-time
matrix had been allocated)."""
import pytest

from codegen.campaign import runner, spec as campaign_spec
from codegen.errors import ConfigurationError
from codegen.project import observer_file as observers


def _spec(source: str, duration: float):
    return campaign_spec.parse({"observer": "lpv_linf_driver_torque", "scenarios": ["excitation"], "runs": 2,
                                "duration": duration}, source)


def test_a_duration_whose_run_cannot_fit_in_memory_is_refused_naming_the_key():
    config = observers.get("lpv_linf_driver_torque")
    with pytest.raises(ConfigurationError, match=r"long.toml: duration = 1000000000.0: a run that fits in memory "
                                                 r"\(1e\+11 samples at the sample time 0.01 s: it holds about .* GiB, "
                                                 r"the limit is .* GiB \((physical memory|available memory, .*|"
                                                 r"cgroup v. .*|RLIMIT_AS)\)\)"):
        runner._excitation(_spec("long.toml", 1e9), config, 0)


def test_a_duration_that_fits_gives_its_run():
    config = observers.get("lpv_linf_driver_torque")
    run = runner._excitation(_spec("short.toml", 3.0), config, 0)
    assert run.t.size == 301                   # t = 0, 0.01, ..., 3


def test_the_refusal_of_an_interrupted_folder_names_the_folder_to_resume(tmp_path):
    """The hint was `uiogen campaign SPEC --resume`, which continues the default folder
    (build/campaigns/SPEC_STEM), not the --out folder that holds the interrupted runs."""
    import json
    from codegen.campaign import engine
    from codegen.errors import CampaignError
    out = tmp_path / "my_out"
    out.mkdir()
    header = {"format": 1, "observer": "obs.toml", "design": "d", "spec_sha256": "s"}
    (out / engine.JOURNAL).write_text(json.dumps(header) + "\n" + json.dumps({"run": 0, "status": "ok"}) + "\n")
    with pytest.raises(CampaignError, match=rf"holds 1 finished runs of an interrupted campaign; `uiogen campaign "
                                            rf"c.toml --resume --out {out}` continues it"):
        engine.Journal(out / engine.JOURNAL, header, resume=False, source="c.toml")
