"""The interconnected family's closed-loop runs (its own model, the CommonRoad plant) are kept across runs,
keyed by what they read: a second run is the first run's truth to the last bit; an edited input runs it again."""
import numpy as np

from codegen.families.interconnected_uio import representation as interconnected
from codegen.families.interconnected_uio import validation
from codegen.model import cache
from codegen.project import observer_file as observers


def _counted(monkeypatch, name):
    runs = []
    original = getattr(validation, name)
    monkeypatch.setattr(validation, name, lambda *a, **k: runs.append(1) or original(*a, **k))
    return runs


def test_the_model_run_is_kept_and_every_input_runs_it_again(fresh_cache, monkeypatch):
    config = observers.get("interconnected_uio")
    ts, track = interconnected.load(config), validation.satory_track()
    runs = _counted(monkeypatch, "simulate_model")

    def truth(mu=1.0, split=(0.66, 1.0), duration=3.0):
        cache.forget()
        return validation._kept_model_run(config, ts, track, mu, split, duration, 1.0 / config.sample_time)

    first, again = truth(), truth()
    assert len(runs) == 1 and all(np.array_equal(first[k], again[k], equal_nan=True) for k in first)
    for what, out in (("the friction", lambda: truth(mu=0.6)), ("the axle split", lambda: truth(split=(0.6, 1.0))),
                      ("the duration", lambda: truth(duration=2.0))):
        before = len(runs)
        out()
        assert len(runs) == before + 1, what


def test_the_commonroad_run_is_kept_read_only(fresh_cache, monkeypatch):
    track = validation.satory_track()
    runs = _counted(monkeypatch, "simulate_commonroad")

    def truth(mu=1.0):
        cache.forget()
        return validation._kept_commonroad(track, mu, 1, 0.0, 1.0, 100.0)

    first, again = truth(), truth()
    assert len(runs) == 1 and all(np.array_equal(first[k], again[k], equal_nan=True) for k in first)
    assert not any(a.flags.writeable for a in again.values())
    truth(mu=0.6)
    assert len(runs) == 2
