"""The nominal closed-loop run is kept across runs (``simulate.nominal_plant``), keyed by everything it reads:
a second run is the first run's truth to the last bit, and an edit of any input runs it again."""
import dataclasses

import numpy as np

from codegen.model import cache
from codegen.project import observer_file as observers
from codegen.validation import common, simulate
from codegen.families.linf_uio.build import representation

NAME = "lpv_linf_driver_torque"


def test_a_closed_loop_run_is_kept_and_every_input_runs_it_again(fresh_cache, monkeypatch):
    config = observers.get(NAME)
    lpv = representation(config)[0]
    scn = common.scenario_for(config, "track_varying_speed", 1.5)
    plant = common.truth_plant(config, lpv.parameters)
    runs = []
    integrate = simulate._integrate
    monkeypatch.setattr(simulate, "_integrate", lambda *a, **k: runs.append(1) or integrate(*a, **k))

    def truth(cfg=config, model=lpv, s=scn, definition=plant):
        cache.forget()                      # as a new process: from the file, verified
        return simulate.nominal_plant(cfg, model, s, definition)

    first = truth()
    again = truth()
    assert len(runs) == 1
    assert first.keys() == again.keys() and all(np.array_equal(first[k], again[k]) for k in first)
    assert all(first[k].dtype == again[k].dtype for k in first)
    # each input edited: run again (and the edit changes the truth, so a stale entry would be seen)
    values = dict(lpv.parameters.values)
    key = next(iter(values))
    edits = {
        "a parameter value": lambda: truth(model=dataclasses.replace(lpv, parameters=dataclasses.replace(
            lpv.parameters, values={**values, key: values[key] * 1.01}))),
        "the scenario's assistance torque": lambda: truth(s=dataclasses.replace(scn, T_a=scn.T_a + 0.5)),
        "the driver's gains": lambda: truth(s=dataclasses.replace(scn, driver=dataclasses.replace(scn.driver,
                                                                                              k_p=41.0))),
        "the model (the exact model instead of the truth plant)": lambda: truth(definition=None),
    }
    for what, run in edits.items():
        before = len(runs)
        out = run()
        assert len(runs) == before + 1, what
        assert not np.array_equal(out["T_d"], first["T_d"]) or not np.array_equal(out["beta"], first["beta"]), what
    # a corrupted entry is not believed
    entries = sorted((cache.folder() / simulate.NOMINAL).glob("*.json"))
    assert len(entries) == 1 + len(edits)
    for entry in entries:                   # one byte of every kept array's data changed, the record's hash not
        text = entry.read_text()
        at = text.index('"<f8"') + 40
        entry.write_text(text[:at] + ("A" if text[at] != "A" else "B") + text[at + 1:])
    before = len(runs)
    assert np.array_equal(truth()["beta"], first["beta"]) and len(runs) == before + 1
