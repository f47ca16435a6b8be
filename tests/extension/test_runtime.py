"""The runtime apart from the toolchain: python_bindings loads and steps a compiled observer with
numpy and the extension only; the extension carries its names, units, sample time and design
hash; a stale extension is refused; recording is an explicit wrapper."""
import hashlib
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen import errors
from codegen.emit.header import signals as header_signals
from codegen.extension.build import generated_names
from python_bindings import Recorder, StaleExtensionError, UnknownObserverError, load
from python_bindings.integrity import record_path
from python_bindings.workspace import Workspace
from conftest import HANG_GUARD

pytestmark = pytest.mark.slow          # the compiled extensions

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
NAME = "lpv_linf_driver_torque"
TOOLCHAIN = ("codegen", "sympy", "casadi", "clarabel", "scipy", "jinja2")
NAMES = generated_names()


def _probe(body: str, cwd: Path) -> list:
    """Run ``body`` in a fresh interpreter; the toolchain packages it imported."""
    code = (f"import sys\n{body}\n"
            f"print('imported:' + ','.join(m for m in {TOOLCHAIN!r} if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=HANG_GUARD)
    assert proc.returncode == 0, proc.stderr
    return [m for m in proc.stdout.strip().splitlines()[-1].removeprefix("imported:").split(",") if m]


STEP = ("import numpy as np\nfrom python_bindings import load\nobs = load({arg!r})\n"
        "status = obs.step(obs.initial_state(), np.full(obs.n_input, 0.1), np.empty(obs.n_output))\n"
        "assert status in (0, 1), status\n"
        # step is a C method of type(obs) itself, the one case CPython calls without a generic lookup
        "import types\nassert isinstance(type(obs).__dict__['step'], types.MethodDescriptorType)\n"
        "assert obs.step.__self__ is obs and isinstance(obs, __import__('python_bindings').CompiledObserver)\n")


def test_load_and_step_import_nothing_of_the_toolchain(tmp_path):
    assert _probe(STEP.format(arg=NAME), tmp_path) == []
    # the probe can fail: importing the toolchain shows
    assert _probe("import codegen.cli", tmp_path) == list(TOOLCHAIN)


@pytest.fixture
def project(tmp_path):
    """A project folder holding a copy of the built-in observer's generated C, lock and
    extension (with the record of its bytes), and its observer file."""
    checkout = Workspace.locate(NAME)[0]
    ws = Workspace.of(tmp_path)
    shutil.copytree(checkout.observer_dir(NAME), ws.observer_dir(NAME))
    ws.extensions.mkdir(parents=True)
    shutil.copy(checkout.extension(NAME), ws.extension(NAME))
    shutil.copy(record_path(checkout.extension(NAME)), record_path(ws.extension(NAME)))   # its bytes' hash
    shutil.copy(ROOT / "model_defs" / "observers" / f"{NAME}.toml", tmp_path / f"{NAME}.toml")
    params = re.search(r'(?m)^parameters = "([^"]+)"', (tmp_path / f"{NAME}.toml").read_text()).group(1)
    shutil.copy(ROOT / "model_defs" / "params" / params, tmp_path / params)     # an observer file of one's own
    return ws                                                                      # names its own parameter file


def test_an_observer_file_loads_by_its_folder_and_stem_without_the_toolchain(project):
    path = project.root / f"{NAME}.toml"
    assert _probe(STEP.format(arg=str(path)), project.root) == []
    obs = load(path)
    assert obs.path == project.extension(NAME) and obs.name == NAME


@pytest.mark.parametrize("name", NAMES)
def test_the_extension_carries_the_names_units_sample_time_and_hash_of_its_c_and_lock(name):
    obs = load(name)
    ws = Workspace.locate(name)[0]
    art = json.loads(ws.design_lock(name).read_text())
    sig = art["signals"]
    assert obs.state_names == tuple(sig["state"]) and obs.input_names == tuple(sig["input"])
    assert obs.output_names == tuple(sig.get("output", sig["state"]))
    assert obs.sample_time == art["config"]["sample_time"]
    assert obs.design_sha256 == hashlib.sha256(ws.design_lock(name).read_bytes()).hexdigest()
    header = header_signals((ws.observer_dir(name) / f"{name}.h").read_text(), name)
    for part, units in (("state", obs.state_units), ("input", obs.input_units), ("output", obs.output_units)):
        assert units == tuple(f[2] for f in header[part])
    assert (obs.n_state, obs.n_input, obs.n_output) == (len(obs.state_names), len(obs.input_names),
                                                        len(obs.output_names))


def test_units_are_those_the_family_documents(built):
    """Independent of the header: the build's own signal docs."""
    from codegen.emit.header import unit_of
    b = built(NAME)
    state, inputs, outputs = b.signal_docs()
    obs = load(NAME)
    assert obs.input_units == tuple(unit_of(s["doc"]) for s in inputs) == ("N m", "rad/s", "rad", "rad/s", "m/s")
    assert obs.output_units == tuple(unit_of(s["doc"]) for s in outputs)


def test_a_stale_extension_is_refused_with_the_command_to_run(project):
    lock = project.design_lock(NAME)
    load(NAME, project=project.root)                       # the copy is current
    data = json.loads(lock.read_text())
    data["design_note"] = "changed after the build"
    lock.write_text(json.dumps(data))
    with pytest.raises(StaleExtensionError, match=re.escape(f"run `uiogen build {NAME} --project {project.root}`")):
        load(NAME, project=project.root)
    with pytest.raises(errors.UiogenError):               # the toolchain's base class catches it
        load(project.root / f"{NAME}.toml")


def test_a_missing_extension_or_lock_names_the_command(project):
    project.extension(NAME).unlink()
    with pytest.raises(UnknownObserverError, match=r"not compiled .* run `uiogen build .*lpv_linf_driver_torque.toml`"):
        load(project.root / f"{NAME}.toml")
    shutil.rmtree(project.observer_dir(NAME))
    with pytest.raises(UnknownObserverError, match=r"not been generated .* run `uiogen generate "):
        load(project.root / f"{NAME}.toml")


def test_a_wrong_path_or_name_is_said_as_such(tmp_path):
    """load() of a path to no file, or of a name no built-in observer has, says that, not that the
    observer was never generated (which sends the user to run generate on a file that is not there)."""
    with pytest.raises(UnknownObserverError, match=r"no observer file .*nope\.toml .*check the path"):
        load(tmp_path / "nope.toml")
    (tmp_path / "disturbance.toml").write_text("")
    with pytest.raises(UnknownObserverError, match=r"check the path \(did you mean '.*/disturbance.toml'\?\)"):
        load(tmp_path / "disturbanc.toml")
    with pytest.raises(UnknownObserverError, match=r"'lpv_linf_driver_torqe' is not a built-in observer \(did you "
                                                   r"mean 'lpv_linf_driver_torque'\?\); .*path of its observer file"):
        load("lpv_linf_driver_torqe")
    with pytest.raises(UnknownObserverError, match=r"'my_car' is not a built-in observer \(built-in: .*stanford_sideslip"):
        load("my_car")


def test_a_bare_name_is_a_built_in_even_where_an_own_observer_is_generated(project):
    """A bare name loads a built-in observer; one of the user's own, generated in the project,
    would load without the check of its observer file, parameters and model (a wheel's load("car")
    in the project folder returned the extension of the old parameters): it is refused, and the
    observer file beside it named."""
    own = project.root / "my_car.toml"
    own.write_text((project.root / f"{NAME}.toml").read_text())
    shutil.copytree(project.observer_dir(NAME), project.observer_dir("my_car"))
    (project.observer_dir("my_car") / f"{NAME}_design.json").rename(project.design_lock("my_car"))
    with pytest.raises(UnknownObserverError, match=r"'my_car' is not a built-in observer .*pass the path of its "
                                                   r"observer file: load\('my_car.toml'\)"):
        import os
        cwd = os.getcwd()
        os.chdir(project.root)
        try:
            load("my_car", project=project.root)
        finally:
            os.chdir(cwd)


def test_a_rebuild_is_loaded_by_the_same_process(project):
    """Python keeps an extension module per file: after `uiogen build` in a shell, load() in the same
    session (a notebook) loads the new build, not the one it holds, and the old object still runs."""
    from codegen import cli
    path = project.root / f"{NAME}.toml"
    inputs = np.tile([0.5, 0.01, 0.02, 0.0, 20.0], (50, 1))
    before = load(path)
    first = before.run(inputs)[0][-1].copy()
    path.write_text(path.read_text().replace("alpha = 5.0 ", "alpha = 3.0 "))
    for verb in (["design", "--update"], ["generate"], ["build"]):
        assert cli.main([verb[0], str(path), *verb[1:]]) == 0
    after = load(path)
    assert after.design_sha256 == hashlib.sha256(project.design_lock(NAME).read_bytes()).hexdigest()
    assert after.design_sha256 != before.design_sha256
    assert not np.allclose(after.run(inputs)[0][-1], first)          # the new gains
    np.testing.assert_array_equal(before.run(inputs)[0][-1], first)  # the old object is untouched
    assert load(path).design_sha256 == after.design_sha256          # and held from now on


def test_an_observer_pickles_to_a_worker_and_copies_to_itself(project):
    """A worker process (multiprocessing, concurrent.futures) gets the observer by pickle: it opens the
    same extension file there, checked as load() checks it; a copy is the object itself (it holds no
    state). Before: PicklingError, and deepcopy's "cannot pickle 'module' object"."""
    import copy
    import pickle
    obs = load(project.root / f"{NAME}.toml")
    assert copy.copy(obs) is obs and copy.deepcopy(obs) is obs
    code = ("import pickle, sys, numpy as np\nobs = pickle.loads(sys.stdin.buffer.read())\n"
            "print(obs.design_sha256, obs.run(np.full((3, obs.n_input), 0.1))[0][-1].tolist())")
    proc = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(obs), capture_output=True, timeout=HANG_GUARD)
    assert proc.returncode == 0, proc.stderr.decode()
    sha, last = proc.stdout.decode().split(" ", 1)
    assert sha == obs.design_sha256
    assert json.loads(last) == obs.run(np.full((3, obs.n_input), 0.1))[0][-1].tolist()
    # rebuilt from another design in between: refused in the worker, not run with other gains
    data = pickle.dumps(obs)
    lock = project.design_lock(NAME)
    doc = json.loads(lock.read_text())
    doc["design_note"] = "changed"
    lock.write_text(json.dumps(doc))
    with pytest.raises(StaleExtensionError):
        pickle.loads(data)


def test_the_recorder_records_what_it_runs_and_changes_nothing():
    obs = load(NAME)
    rng = np.random.default_rng(0)
    inputs = np.column_stack([rng.standard_normal((50, 4)) * 0.01, np.full(50, 20.0)])
    rec = Recorder(obs)
    out, status, final = rec.run(inputs)
    ref = obs.run(inputs)
    assert np.array_equal(out, ref[0]) and np.array_equal(status, ref[1]) and np.array_equal(final, ref[2])
    state, row_out = obs.initial_state(), np.empty(obs.n_output)
    rec.step(state, inputs[0], row_out)
    assert len(rec.calls) == 2 and np.array_equal(rec.calls[0][0], inputs) and rec.calls[1][1] is None
    assert np.array_equal(rec.calls[1][0], inputs[0]) and rec.input_names == obs.input_names
