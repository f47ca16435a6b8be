"""What a compiled extension was built from, checked before it is used: its bytes (a truncated
extension or cached plant is never loaded), the observer file, parameters and model it was made
from (an edited one is refused by ``load``, naming it), and one snapshot of the generated folder
per build (the design hash compiled in is that of the C compiled)."""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from python_bindings import (ChangedSourceError, DamagedExtensionError, SourceFileError, StaleExtensionError,
                             UiogenError, integrity, load)
from python_bindings.runtime import open_observer
from python_bindings.workspace import Workspace
from conftest import HANG_GUARD

ROOT = Path(__file__).resolve().parents[2]

OBSERVER = 'family = "linf_uio"\nmodel = "model.py"\nparameters = "parameters.toml"\nsample_time = 0.01\n' \
           '\n[design]\nalpha = 5.0\n\n[data]\ntime = "t"\n'


def _sources(tmp_path) -> Path:
    obs = tmp_path / "obs1.toml"
    obs.write_text(OBSERVER)
    (tmp_path / "parameters.toml").write_text("M = 2052.0\n")
    (tmp_path / "model.py").write_text("# a model\nMODEL = 1\n")
    return obs


# --- the hashes (fast: no compiler) ---------------------------------------------------------------

def test_the_observer_file_is_hashed_as_parsed_less_data_and_precision(tmp_path):
    obs = _sources(tmp_path)
    digest = integrity.observer_file_sha256(obs)
    obs.write_text("# a comment\n" + OBSERVER.replace('time = "t"', 'time = "time_s"') + "\n[precision]\nx = 1\n")
    assert integrity.observer_file_sha256(obs) == digest          # no design or C derives from those
    obs.write_text(OBSERVER.replace("alpha = 5.0", "alpha = 4.0"))
    assert integrity.observer_file_sha256(obs) != digest


PARAMETERS = '# Vehicle of the paper\n[parameters]\nM = 2052.0   # kg\nl_f = 1.3\n\n[inputs]\nT_d = { min = -4.0, max = 4.0 }\n'
MODEL = '"""A model."""\nimport sympy as sp\n\nx = sp.Symbol("x")\nif True:\n    MODEL = (x, f"{x}", 2.0)  # the definition\n'


@pytest.mark.parametrize("hash_of, text, layout, meaning", [
    (integrity.parameters_sha256, PARAMETERS,
     [("# Vehicle of the paper\n", ""), ("   # kg", "  # kg, vehicle mass"), ("M = 2052.0", "M=2052.0"),
      ("\n\n[inputs]", "\n\n\n[inputs]"), ("{ min = -4.0, max = 4.0 }", "{min=-4.0,max=4.0}")],
     [("2052.0", "2000.0"), ("l_f", "l_r"), ("max = 4.0", "max = 5.0"), ("2052.0", "2052")]),
    (integrity.model_sha256, MODEL,
     [("  # the definition", ""), ("import sympy", "# a note\nimport sympy"), ("\n\nx", "\n\n\n\nx"),
      ("    MODEL", "  MODEL"), ("(x, f", "( x , f"), ('"x"', "'x'")],
     [("2.0", "3.0"), ("2.0", "2"), ('"""A model."""', '"""Another model."""'), ("{x}", "{x!r}"),
      ("if True", "if False")]),
])
def test_parameters_and_model_are_hashed_for_what_they_say_not_how_they_are_written(tmp_path, hash_of, text,
                                                                                    layout, meaning):
    """A comment, blank line or spacing edited in the parameter file or the model changes neither
    ``load``'s check nor the design's hash (both call these functions); a value, a key, the code
    or a docstring does."""
    path = tmp_path / "file"
    path.write_text(text)
    digest = hash_of(path)
    for old, new in layout:
        assert old in text
        path.write_text(text.replace(old, new))
        assert hash_of(path) == digest, (old, new)
    for old, new in meaning:
        assert old in text
        path.write_text(text.replace(old, new))
        assert hash_of(path) != digest, (old, new)
    path.write_bytes(text.encode() + b"\xff")          # not UTF-8: hashed byte for byte, never an error
    assert hash_of(path) != digest


def test_an_extension_recorded_by_an_older_uiogen_is_checked_byte_for_byte(tmp_path):
    """A record without ``hashing`` (an extension built before the files were hashed for what
    they say) holds byte hashes: it is checked by that rule, so it is neither refused for an
    unchanged file nor accepted after an edit."""
    obs = _sources(tmp_path)
    old = {"observer file": [obs.name, integrity.observer_file_sha256(obs)],
           "parameters": ["parameters.toml", integrity.file_sha256(tmp_path / "parameters.toml")],
           "model": ["model.py", integrity.file_sha256(tmp_path / "model.py")]}
    assert integrity.changed_sources(old, obs) == []
    (tmp_path / "model.py").write_text("# another comment\nMODEL = 1\n")
    assert integrity.changed_sources(old, obs) == [("model", tmp_path / "model.py")]
    assert integrity.changed_sources(integrity.source_digests(obs, tmp_path / "parameters.toml",
                                                              tmp_path / "model.py"), obs) == []
    with pytest.raises(ValueError, match="hashing rule 3"):      # a newer uiogen's record: refused by load
        integrity.changed_sources({**old, "hashing": 3}, obs)


def test_changed_sources_names_each_changed_file_and_skips_absent_ones(tmp_path):
    obs = _sources(tmp_path)
    recorded = integrity.source_digests(obs, tmp_path / "parameters.toml", tmp_path / "model.py")
    assert recorded["parameters"][0] == "parameters.toml" and recorded["model"][0] == "model.py"
    assert integrity.changed_sources(recorded, obs) == []
    (tmp_path / "parameters.toml").write_text("M = 2000.0\n")
    (tmp_path / "model.py").write_text("# a model\nMODEL = 2\n")
    assert integrity.changed_sources(recorded, obs) == [("parameters", tmp_path / "parameters.toml"),
                                                         ("model", tmp_path / "model.py")]
    (tmp_path / "parameters.toml").unlink()      # a deployment without its sources: nothing to compare
    (tmp_path / "model.py").unlink()
    assert integrity.changed_sources(recorded, obs) == []
    obs.write_bytes(OBSERVER.encode() + b"\xff\xfe")
    with pytest.raises(integrity.SourceFileUnreadable, match="not UTF-8"):
        integrity.changed_sources(recorded, obs)


def _fake_project(tmp_path, sources: dict) -> tuple:
    """A project whose extension is a module object already in sys.modules (what ``load`` finds
    when the module was loaded before): the source checks without a compiler."""
    obs = _sources(tmp_path)
    ws = Workspace.of(tmp_path)
    ws.observer_dir("obs1").mkdir(parents=True)
    ws.design_lock("obs1").write_text("{}\n")
    path = ws.extension("obs1")
    key = f"uiogen_ext_{hashlib.sha256(str(path).encode()).hexdigest()[:16]}_obs1"
    module = types.ModuleType("_obs1")
    module.NAME, module.SOURCES = "obs1", json.dumps(sources)
    module.DESIGN_SHA256 = hashlib.sha256(b"{}\n").hexdigest()
    module.observer_type = lambda base: type("Obs", (base,), {})
    for k in ("STATE_NAMES", "INPUT_NAMES", "OUTPUT_NAMES", "STATE_UNITS", "INPUT_UNITS", "OUTPUT_UNITS"):
        setattr(module, k, ())
    module.SAMPLE_TIME = 0.01
    sys.modules[key] = module
    return obs, ws, key


def test_load_refuses_an_extension_whose_parameters_model_or_observer_file_changed(tmp_path):
    recorded = integrity.source_digests(_sources(tmp_path), tmp_path / "parameters.toml", tmp_path / "model.py")
    obs, ws, key = _fake_project(tmp_path, recorded)
    try:
        assert load(obs).name == "obs1"
        obs.write_text("# only a comment more\n" + OBSERVER)
        assert load(obs).name == "obs1"
        (tmp_path / "parameters.toml").write_text("# a comment\nM   = 2052.0  # kg\n")
        (tmp_path / "model.py").write_text("# a model, commented\n\nMODEL  =  1   # one\n")
        assert load(obs).name == "obs1"           # comments and layout: the design's hash keeps them too
        _sources(tmp_path)
        for path, edit in ((tmp_path / "parameters.toml", ("2052.0", "2000.0")),
                           (tmp_path / "model.py", ("MODEL = 1", "MODEL = 2")),
                           (obs, ("alpha = 5.0", "alpha = 4.0"))):
            before = path.read_text()
            path.write_text(before.replace(*edit))
            with pytest.raises(ChangedSourceError, match=rf"{path.name} \(the .* of obs1\) changed since the "
                                                         rf"extension .* run `uiogen generate {obs}` .* "
                                                         rf"`uiogen build {obs}`") as info:
                load(obs)
            assert Path(info.value.path) == path and isinstance(info.value, StaleExtensionError)
            path.write_text(before)
            assert load(obs).name == "obs1"
        obs.write_bytes(OBSERVER.encode() + b"\xff")
        with pytest.raises(SourceFileError, match=rf"{obs}: the observer file cannot be read: it is not UTF-8"):
            load(obs)
        obs.write_text(OBSERVER + "alpha = [\n")
        with pytest.raises(SourceFileError, match="not valid TOML"):
            load(obs)
        obs.unlink()             # deployed without its sources: loads (module docstring of integrity)
        assert open_observer(ws, "obs1", observer_file=obs).name == "obs1"
    finally:
        del sys.modules[key]


def test_an_extension_without_a_record_of_its_sources_is_refused(tmp_path):
    obs, ws, key = _fake_project(tmp_path, {})
    try:
        del sys.modules[key].SOURCES
        with pytest.raises(StaleExtensionError, match=r"built by an older uiogen \(it has no SOURCES\); run `uiogen build"):
            load(obs)
    finally:
        del sys.modules[key]


def test_a_truncated_or_unrecorded_extension_is_refused_before_it_is_loaded(tmp_path):
    """A truncated shared object that is loaded dies of SIGBUS (no message, rc 135): ``load``
    checks its bytes against the build's record first. Run in a child: a crash shows as its rc."""
    _sources(tmp_path)
    ws = Workspace.of(tmp_path)
    ws.observer_dir("obs1").mkdir(parents=True)
    ws.design_lock("obs1").write_text("{}\n")
    ws.extensions.mkdir(parents=True)
    import _ctypes
    data = Path(_ctypes.__file__).read_bytes()         # a real shared object, truncated below
    ws.extension("obs1").write_bytes(data)
    integrity.record_path(ws.extension("obs1")).write_text(integrity.record_text(data, ws.extension("obs1").name))
    with open(ws.extension("obs1"), "r+b") as fh:
        fh.truncate(len(data) // 3)
    probe = ("import sys\nfrom python_bindings import load, UiogenError\ntry:\n    load(sys.argv[1])\n"
             "except UiogenError as e:\n    print(type(e).__name__, e)\n")
    run = lambda: subprocess.run([sys.executable, "-c", probe, str(tmp_path / "obs1.toml")], cwd=ROOT,
                                 capture_output=True, text=True, timeout=HANG_GUARD)
    proc = run()
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert proc.stdout.startswith("DamagedExtensionError the extension ") and "truncated" in proc.stdout
    assert "run `uiogen build " in proc.stdout
    integrity.record_path(ws.extension("obs1")).unlink()
    proc = run()
    assert proc.returncode == 0 and "has no build record" in proc.stdout, (proc.returncode, proc.stdout, proc.stderr)
    assert issubclass(DamagedExtensionError, StaleExtensionError) and issubclass(SourceFileError, UiogenError)
    # truncated and its record recomputed for the cut bytes: the ELF structure says it is cut (no SIGBUS)
    cut = ws.extension("obs1").read_bytes()
    integrity.record_path(ws.extension("obs1")).write_text(integrity.record_text(cut, ws.extension("obs1").name))
    assert integrity.binary_mismatch(ws.extension("obs1")) == ""
    proc = run()
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert proc.stdout.startswith("DamagedExtensionError the extension ") and "past its end" in proc.stdout, proc.stdout
    assert integrity.elf_truncation(Path(_ctypes.__file__)) == ""       # a whole object passes
    for keep in (40, 63, 2000, len(data) - 1):
        part = tmp_path / f"cut{keep}.so"
        part.write_bytes(data[:keep])
        assert integrity.elf_truncation(part), keep


# --- builds (slow) --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A project made by ``uiogen new`` (linf_uio), generated once for the module's builds."""
    from codegen import workflow
    from codegen.project import starter
    root = tmp_path_factory.mktemp("integrity")
    from codegen import families
    starter.write(root, families.get("linf_uio"), "obs1")
    workflow.generate([str(root / "obs1.toml")], log=lambda *_: None)
    return root


@pytest.mark.slow          # generates and compiles an extension
def test_the_design_hash_compiled_in_is_that_of_the_lock_compiled(project, monkeypatch):
    """The lock changes on disk after the build's check and before its compile (a ``design
    --update`` during the build): the extension carries the hash of the lock its C was compiled
    from, so ``load`` refuses it beside the new lock (it carried the new lock's hash over the old
    design's numbers). A staging folder left by a killed build is removed by the next one."""
    from codegen.extension import build
    obs = project / "obs1.toml"
    ws = Workspace.of(project)
    lock = ws.design_lock("obs1")
    compiled = lock.read_bytes()
    leftover = ws.extensions / ".obs1.new-killed"
    (leftover / "generated").mkdir(parents=True)
    original = build.header_signals

    def changed_meanwhile(*args, **kwargs):
        lock.write_bytes(compiled + b"\n")          # another lock, the same design (its JSON parses equal)
        return original(*args, **kwargs)
    monkeypatch.setattr(build, "header_signals", changed_meanwhile)
    try:
        path = build.build_extension(str(obs))
        monkeypatch.undo()
        out = subprocess.run([sys.executable, "-c", "import sys\nfrom python_bindings import load\n"
                              "print(load(sys.argv[1]).design_sha256)", str(obs)],
                             capture_output=True, text=True, timeout=HANG_GUARD, cwd=ROOT)
        assert out.returncode != 0 and "StaleExtensionError" in out.stderr and "another design" in out.stderr
        proc = subprocess.run([sys.executable, "-c", "import sys, importlib.util\n"
                               "s = importlib.util.spec_from_file_location('_obs1', sys.argv[1])\n"
                               "m = importlib.util.module_from_spec(s); s.loader.exec_module(m)\n"
                               "print(m.DESIGN_SHA256)", str(path)], capture_output=True, text=True, timeout=HANG_GUARD, cwd=ROOT)
        assert proc.stdout.strip() == hashlib.sha256(compiled).hexdigest()
    finally:
        lock.write_bytes(compiled)
    assert not leftover.exists() and not list(ws.extensions.glob(".obs1.new-*"))


@pytest.mark.slow          # generates and compiles an extension
def test_a_built_extension_records_its_bytes_and_sources_and_load_checks_them(project):
    from codegen.extension import build
    obs = project / "obs1.toml"
    path = build.build_extension(str(obs))
    assert integrity.binary_mismatch(path) == ""
    code = ("import sys, numpy as np\nfrom python_bindings import load, UiogenError\ntry:\n"
            "    o = load(sys.argv[1]); print('ok', o.run(np.zeros((2, o.n_input)))[1].tolist())\n"
            "except UiogenError as e:\n    print(type(e).__name__, e)\n")
    run = lambda: subprocess.run([sys.executable, "-c", code, str(obs)], capture_output=True, text=True,
                                 timeout=HANG_GUARD, cwd=ROOT).stdout
    assert run().startswith("ok")
    params = project / "parameters.toml"
    before = params.read_text()
    try:
        params.write_text(before.replace("M = 2052.0", "M = 2000.0"))
        assert run().startswith(f"ChangedSourceError {params} (the parameters of obs1) changed")
    finally:
        params.write_text(before)
    # a truncated copy in its place (this process has the built file loaded: never truncate it in place)
    saved = path.with_name("saved.so")
    os.replace(path, saved)
    try:
        path.write_bytes(saved.read_bytes()[:20000])
        assert run().startswith("DamagedExtensionError")
    finally:
        os.replace(saved, path)
    assert run().startswith("ok")


@pytest.mark.slow          # compiles a plant with the C compiler
def test_a_truncated_cached_plant_is_compiled_again(tmp_path):
    import casadi as ca
    from codegen.campaign import plants
    x = ca.SX.sym("x", 2)
    f = ca.Function("plant_run", [x], [2 * x])
    path = plants._compile(f, tmp_path)
    size = path.stat().st_size
    assert integrity.binary_mismatch(path) == ""
    with open(path, "r+b") as fh:
        fh.truncate(size // 3)
    assert plants._compile(f, tmp_path) == path and path.stat().st_size == size
    assert integrity.binary_mismatch(path) == ""
    integrity.record_path(path).unlink()              # a cache of an older uiogen: compiled again, recorded
    assert plants._compile(f, tmp_path) == path and integrity.binary_mismatch(path) == ""
    assert np.allclose(np.asarray(ca.external("plant_run", str(path))([1.0, 2.0])).ravel(), [2.0, 4.0])
