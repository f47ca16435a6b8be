"""The switched PI family's closed-loop truth (the banked Pacejka plant) is kept across runs, keyed by what it
reads: a second run is the first run's truth to the last bit; an edited parameter value, scenario or model runs
it again."""
import dataclasses

import numpy as np

from codegen.families.switched_pi import validation
from codegen.model import cache, load_parameters
from codegen.project import observer_file as observers
from codegen.validation import common

NAME = "switched_pi_bank_angle"


def test_the_banked_plant_is_kept_and_every_input_runs_it_again(fresh_cache, monkeypatch):
    config = observers.get(NAME)
    params = load_parameters(config.parameter_path)
    scn = common.scenario_for(config, "banked_road_braking", 1.5)
    runs = []
    banked = validation.banked_plant
    monkeypatch.setattr(validation, "banked_plant", lambda *a, **k: runs.append(1) or banked(*a, **k))

    def truth(p=params, s=scn, exact=False):
        cache.forget()                      # as a new process: read from the file, verified
        return validation._kept_banked_plant(config, p, s, None, exact_model=exact)

    first, again = truth(), truth()
    assert len(runs) == 1 and first.keys() == again.keys()
    assert all(np.array_equal(first[k], again[k]) for k in first)
    key = "K_r" if "K_r" in params.values else next(iter(params.values))
    edits = {"a parameter value": lambda: truth(p=dataclasses.replace(
                 params, values={**params.values, key: params.values[key] * 1.05})),
             "the scenario's bank": lambda: truth(s=dataclasses.replace(scn, bank=np.asarray(scn.bank) + 0.01)),
             "the observer's own model instead of the plant": lambda: truth(exact=True)}
    for what, run in edits.items():
        before = len(runs)
        out = run()
        assert len(runs) == before + 1, what
        assert not all(np.array_equal(out[k], first[k]) for k in ("phi", "v_y", "r")), what
