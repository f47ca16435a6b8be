"""The derived-results cache (codegen.model.cache): reused when its inputs are unchanged, computed
again when any of them changed, never believed when its record does not verify."""
import json
import os

import pytest
import sympy as sp

from codegen.errors import UnitError
from codegen.design import lock
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


# --- whole results kept as data (cache.encode / decode / remembered): a family's representation --------------------

def test_a_kept_value_reads_back_to_the_last_bit():
    import dataclasses

    import numpy as np
    from codegen.model import SchedulingBox
    x, y = sp.Symbol("x", real=True), sp.Symbol("y", positive=True)
    values = [1, 1.5, -0.0, float("nan"), float("-inf"), "s", None, True, (1, [2, (3,)]), {x: 2 * x + sp.sin(y) / 3},
              sp.Matrix([[x, sp.Float(0.1) * y], [sp.pi, sp.Rational(1, 3)]]), np.asfortranarray(np.arange(6.).reshape(2, 3)),
              np.float64(0.1) + np.float64(0.2), sp.Max(x, y, evaluate=False), sp.Piecewise((x, x > 0), (0, True)),
              sp.Float("0.1", 30) * x, frozenset({x, y}), SchedulingBox("v_x", 1.0, 2.0, -0.5, 0.5), sp.Dummy("d", real=True)]
    for v in values:
        back = cache.decode(cache.encode(v))
        assert cache.encode(back) == cache.encode(v) and type(back) is type(v)
        if isinstance(v, (sp.Basic, sp.MatrixBase)):
            assert sp.srepr(back) == sp.srepr(v) and back == v
        elif isinstance(v, np.ndarray):
            assert back.tobytes() == v.tobytes() and back.flags.f_contiguous == v.flags.f_contiguous
        elif dataclasses.is_dataclass(v):
            assert back == v
    with pytest.raises(cache.Unkept):
        cache.encode({"f": lambda t: t})
    with pytest.raises(cache.Unkept):
        cache.encode(sp.Function("g")(x))          # an undefined function: no class to read it back by


def _probe(calls):
    """A result derived from a starter project's model (its equations, the parameter values): what is kept."""
    def compute(cfg):
        from codegen.model import load_parameters
        calls.append(cfg.name)
        model = cfg.load_model()
        return {"dynamics": model.dynamics, "values": load_parameters(cfg.parameter_path).values,
                "sample_time": cfg.sample_time}
    return compute


@pytest.fixture
def starter_project(tmp_path):
    from codegen import families
    from codegen.project import starter
    family = next(families.get(n) for n in families.names() if families.get(n).example)
    return starter.write(tmp_path / "project", family)


def _edit(path, old_pattern, new):
    import re
    text = path.read_text()
    edited = re.sub(old_pattern, new, text, count=1)
    assert edited != text
    path.write_text(edited)


@pytest.mark.parametrize("change", ["none", "model", "parameters", "setting", "module", "sympy", "numpy"])
def test_each_input_of_a_kept_result_recomputes_it(fresh, starter_project, monkeypatch, tmp_path, change):
    import importlib
    import sys

    import numpy as np
    module_file = tmp_path / "deriving_probe.py"
    module_file.write_text("STEP = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "deriving_probe", raising=False)     # this test's file, removed after it
    deriving = importlib.import_module("deriving_probe")
    calls, compute = [], _probe([])
    calls_of = lambda cfg: (calls.append(1), compute(cfg))[1]             # noqa: E731

    def run():
        cfg = observers.get(str(starter_project))
        return cache.remembered("probe", lock.cache_parts(cfg), lambda: calls_of(cfg), deriving)
    first = run()
    _forget_process()
    if change == "model":                      # an equation's meaning (a comment would not be one)
        _edit(starter_project.parent / "model.py", r"\n*$", "\n_EDITED = 2\n")
    elif change == "parameters":
        _edit(starter_project.parent / "parameters.toml", r"(\n\w+ = )(\d+\.\d+)", r"\g<1>1\g<2>")
    elif change == "setting":
        _edit(starter_project, r"sample_time = [0-9.e-]+", "sample_time = 0.002")
    elif change == "module":                   # the deriving module's bytes (another mtime, another digest)
        module_file.write_text("STEP = 2\n")
        os.utime(module_file, ns=(1, 10 ** 18))
    elif change == "sympy":
        monkeypatch.setattr(sp, "__version__", "0.0-other")
    elif change == "numpy":
        monkeypatch.setattr(np, "__version__", "0.0-other")
    again = run()
    assert len(calls) == (1 if change == "none" else 2), f"a changed {change} was answered from the cache"
    if change == "none":
        assert cache.encode(again) == cache.encode(first)


@pytest.mark.parametrize("damage", ["payload", "checksum", "truncated", "not json", "empty", "unreadable data"])
def test_a_kept_result_that_does_not_verify_or_read_back_is_computed_again(fresh, starter_project, damage):
    calls = []
    compute = _probe(calls)

    def run():
        cfg = observers.get(str(starter_project))
        return cache.remembered("probe", lock.cache_parts(cfg), lambda: compute(cfg))
    first = run()
    (entry,) = (fresh / "probe").iterdir()
    record = json.loads(entry.read_text())
    if damage == "payload":
        record["payload"][1][0][1] = ["L", []]
    elif damage == "checksum":
        record["sha256"] = "0" * 64
    elif damage == "unreadable data":        # verifies, but is not what encode writes: not believed either
        record["payload"] = ["C", "os", "system", []]
        record["sha256"] = cache._payload_sha(record["payload"])
    text = json.dumps(record)
    entry.write_text({"truncated": text[:len(text) // 3], "not json": "\x00\xff", "empty": ""}.get(damage, text))
    _forget_process()
    again = run()
    assert len(calls) == 2 and cache.encode(again) == cache.encode(first)
    assert cache.read("probe", entry.stem) is not None          # and written again, whole


def test_a_refusal_is_never_kept(fresh, starter_project):
    from codegen.errors import ModelDefinitionError
    cfg = observers.get(str(starter_project))

    def refuse():
        raise ModelDefinitionError("refused")
    for _ in range(2):
        with pytest.raises(ModelDefinitionError):
            cache.remembered("probe", lock.cache_parts(cfg), refuse)
        _forget_process()
    assert not (fresh / "probe").exists()


def test_concurrent_writers_leave_one_whole_entry(fresh, starter_project):
    """Processes that derive the same result at once each write the whole entry under a temporary name and
    rename it over: a reader sees one of them, whole, never a mix."""
    import multiprocessing
    ctx = multiprocessing.get_context("fork")
    procs = [ctx.Process(target=_derive_in_child, args=(str(starter_project),)) for _ in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(600)
        assert p.exitcode == 0
    (entry,) = (fresh / "probe").iterdir()
    assert not [p for p in (fresh / "probe").iterdir() if p.name.startswith(".tmp-")]
    calls = []
    _forget_process()
    cfg = observers.get(str(starter_project))
    kept = cache.remembered("probe", lock.cache_parts(cfg), lambda: _probe(calls)(cfg))
    assert not calls and sp.Matrix(kept["dynamics"]) == cfg.load_model().dynamics


def _derive_in_child(path):
    cache.forget()
    cfg = observers.get(path)
    for _ in range(5):
        cache.remembered("probe", lock.cache_parts(cfg), lambda: _probe([])(cfg))
        cache.forget()


def _families_builtins():
    from codegen import families
    names = observers.names()
    return [next(n for n in names if observers.get(n).family == f) for f in families.names()
            if any(observers.get(n).family == f for n in names)]


@pytest.mark.slow       # a replayed build of one built-in per family, twice (about a minute on 2 cores)
@pytest.mark.parametrize("name", _families_builtins())
def test_a_build_from_kept_results_is_the_derived_build_to_the_last_bit(fresh, monkeypatch, name):
    import numpy as np
    from codegen import pipeline
    kept = []
    real = cache.remembered
    monkeypatch.setattr(cache, "remembered", lambda kind, *a, **k: kept.append((kind, real(kind, *a, **k)))
                        or kept[-1][1])
    cfg = observers.get(name)
    first = pipeline.build(cfg)
    _forget_process()
    derived = [(kind, cache.encode(v)) for kind, v in kept]
    kept.clear()
    again = pipeline.build(cfg)
    assert [(kind, cache.encode(v)) for kind, v in kept] == derived      # read back: the same, bit for bit
    assert json.dumps(first.artifact(), sort_keys=True, default=repr) == \
        json.dumps(again.artifact(), sort_keys=True, default=repr)
    f, g = first.step_function(), again.step_function()
    args = [np.linspace(0.1, 0.9, f.size1_in(i) * f.size2_in(i)).reshape(f.size2_in(i), f.size1_in(i)).T
            for i in range(f.n_in())]
    for a, b in zip(f(*args) if f.n_out() > 1 else [f(*args)], g(*args) if g.n_out() > 1 else [g(*args)]):
        assert np.array(a).tobytes() == np.array(b).tobytes()


@pytest.mark.parametrize("damage", ["none", "edited source", "checksum", "forged shape", "truncated"])
def test_the_import_statements_of_a_source_are_kept_per_content(fresh, tmp_path, monkeypatch, damage):
    import ast

    from codegen.design import sources
    source = tmp_path / "probe_module.py"
    source.write_text("import codegen.model\nfrom codegen.design import lock\n\ndef f():\n    from . import x\n")
    parses, real = [], ast.parse
    monkeypatch.setattr(ast, "parse", lambda *a, **k: parses.append(1) or real(*a, **k))
    first = sources._statements(source, False)
    assert first == [[0, ["codegen.model"]], [0, "codegen.design", ["lock"]], [1, None, ["x"]]] and len(parses) == 1
    _forget_process()
    (entry,) = (fresh / sources.IMPORT_STATEMENTS).iterdir()
    record = json.loads(entry.read_text())
    if damage == "edited source":
        source.write_text("import codegen.errors\n")
    elif damage == "checksum":
        record["payload"] = [[0, ["codegen.cli"]]]
    elif damage == "forged shape":           # verifies, but is not a list of statements: not believed
        record["payload"] = [[0, 1, 2, 3], "x"]
        record["sha256"] = cache._payload_sha(record["payload"])
    text = json.dumps(record)
    entry.write_text(text[:len(text) // 2] if damage == "truncated" else text)
    again = sources._statements(source, False)
    if damage == "none":
        assert again == first and len(parses) == 1             # read, not parsed again
    elif damage == "edited source":
        assert again == [[0, ["codegen.errors"]]] and len(parses) == 2
    else:
        assert again == first and len(parses) == 2


def test_arrays_are_keyed_by_every_byte():
    """A long array's repr elides its middle: two arrays that differ there must still be two keys."""
    import numpy as np
    from codegen.model import cache
    a = np.zeros(5000)
    b = a.copy()
    b[2500] = 1e-9
    assert repr(a) == repr(b)
    assert cache.canonical(a) != cache.canonical(b) and cache.canonical(a) == cache.canonical(a.copy())
    assert cache.canonical(a) != cache.canonical(a.astype(np.float32))
