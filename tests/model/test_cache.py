"""The derived-results cache (codegen.model.cache): reused when its inputs are unchanged, computed
again when any of them changed, never believed when its record does not verify."""
import json
import os

import pytest
import sympy as sp

from codegen.errors import UnitError
from codegen.model import ModelDefinition, cache, dimensions
from codegen.project import observer_file as observers

v_y, r, delta = sp.symbols("v_y r delta")
v_x = sp.Symbol("v_x", positive=True)
M, C, l, I_z = sp.symbols("M C l I_z", positive=True)


def _model(units_r="rad/s", coefficient=C) -> ModelDefinition:
    from codegen.model import SchedulingSignal
    force = coefficient * (delta - v_y / v_x)
    return ModelDefinition(
        name="cache_probe", states=(v_y, r), known_inputs=(delta,), unknown_inputs=(),
        dynamics=sp.Matrix([force / M - v_x * r, l * force / I_z]), outputs=(("r", r),),
        scheduling=(SchedulingSignal(v_x, unit="m/s"),), parameters=(C, I_z, M, l),
        units={"v_y": "m/s", "r": units_r, "delta": "rad", "M": "kg", "C": "N/rad", "l": "m", "I_z": "kg m^2"})


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    """An empty cache folder; nothing held in memory; the per-object memo emptied."""
    monkeypatch.setenv("UIOGEN_CACHE_DIR", str(tmp_path / "cache"))
    cache.forget()
    dimensions._CACHE.clear()
    yield tmp_path / "cache"
    cache.forget()
    dimensions._CACHE.clear()


def _count_infer(monkeypatch) -> list:
    calls, real = [], dimensions.infer
    monkeypatch.setattr(dimensions, "infer", lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def _forget_process():
    """What a new process has: the files only."""
    cache.forget()
    dimensions._CACHE.clear()


def test_a_second_run_reuses_the_unit_analysis(fresh, monkeypatch):
    calls = _count_infer(monkeypatch)
    dimensions.check_units(_model())
    assert calls and sorted(p.name for p in fresh.iterdir()) == [dimensions.ANALYSIS, dimensions.UNITS_CHECKED]
    n = len(calls)
    _forget_process()
    dimensions.check_units(_model())          # an equal model, another object: read from the files
    dimensions.analysis_of(_model())
    dimensions.analysis_of(_model(), free_numbers=True)
    assert len(calls) == n + 1                # only the reading not yet asked for (free_numbers=False)


def test_an_edited_model_is_checked_again_and_refused(fresh):
    dimensions.check_units(_model())
    _forget_process()
    with pytest.raises(UnitError):            # r declared in m/s: r' = l F / I_z is in rad/s^2
        dimensions.check_units(_model(units_r="m/s", coefficient=C))


@pytest.mark.parametrize("change", ["model", "code", "sympy"])
def test_every_input_of_the_key_recomputes(fresh, monkeypatch, change):
    dimensions.check_units(_model())
    _forget_process()
    calls = _count_infer(monkeypatch)
    if change == "model":
        model = _model(coefficient=2 * C)
    else:
        model = _model()
        if change == "code":
            monkeypatch.setattr(cache, "code_digest", lambda *m: "another toolchain")
        else:
            monkeypatch.setattr(sp, "__version__", "0.0-other")
    dimensions.check_units(model)
    assert calls, f"a changed {change} was answered from the cache"


@pytest.mark.parametrize("damage", ["payload", "checksum", "key", "truncated", "not json"])
def test_a_record_that_does_not_verify_is_computed_again(fresh, monkeypatch, damage):
    model = _model()
    dimensions.analysis_of(model)
    entry = next((fresh / dimensions.ANALYSIS).iterdir())
    record = json.loads(entry.read_text())
    if damage == "payload":
        record["payload"]["same"] = [["C", "M"]]
    elif damage == "checksum":
        record["sha256"] = "0" * 64
    elif damage == "key":
        record["key"] = "0" * 64
    text = json.dumps(record)
    entry.write_text({"truncated": text[:len(text) // 2], "not json": "\x00\xff"}.get(damage, text))
    _forget_process()
    calls = _count_infer(monkeypatch)
    assert dimensions.analysis_of(model) == dimensions.infer(model)
    assert len(calls) == 2                     # computed again (then once more by the comparison)
    assert cache.read(dimensions.ANALYSIS, entry.stem) is not None     # and written again, whole


def test_a_folder_that_cannot_be_written_costs_time_not_a_result(fresh, monkeypatch):
    fresh.parent.mkdir(exist_ok=True)
    fresh.write_text("a file where the folder should be")
    dimensions.check_units(_model())           # no error
    _forget_process()
    calls = _count_infer(monkeypatch)
    dimensions.check_units(_model())
    assert calls                               # nothing kept: computed again
    assert not any(p.name.startswith(".tmp-") for p in fresh.parent.iterdir())


@pytest.mark.parametrize("name", [n for n in observers.names()])
def test_the_stored_analysis_is_the_analysis(fresh, name):
    try:
        model = observers.get(name).load_model()
    except Exception:                          # a family whose model is not one ModelDefinition
        pytest.skip("not a ModelDefinition")
    for free in (False, True):
        dimensions.analysis_of(model, free_numbers=free)
        _forget_process()
        assert dimensions.analysis_of(model, free_numbers=free) == dimensions.infer(model, free_numbers=free)


def test_the_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("UIOGEN_CACHE_DIR", str(tmp_path / "a"))
    assert cache.folder() == tmp_path / "a"
    monkeypatch.delenv("UIOGEN_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.folder() == tmp_path / "xdg" / "uiogen"
    assert os.environ["XDG_CACHE_HOME"]
