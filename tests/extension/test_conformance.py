"""C == model: ``uiogen build`` installs a compiled step only when it agrees with its model.

* every built-in observer's installed extension passes the check it was installed under;
* a TS model with a known input (the step once read past its input row) builds to a step whose
  header, extension and model agree, and which estimates its unknown input;
* a kernel whose emitted C swaps two inputs (re-stamped, as a toolchain bug would leave it) is
  refused by ``uiogen build`` with a typed error naming a signal and a sample, and the previously
  installed extension is left as it was;
* a hand-edited C file is refused before it is compiled (its stamp), a lock whose signal order
  differs from the model's is refused by the layout check.
"""
import hashlib
import json
import re
import textwrap

import numpy as np
import pytest

from codegen import cli, pipeline
from codegen.design import lock as design_lock
from codegen.emit import generate as emit
from codegen.errors import ConformanceError
from codegen.extension import conformance
from codegen.extension.build import build_extension, conformance_record, load
from codegen.project import observer_file as observers

BUILTIN = observers.names()


@pytest.mark.slow          # builds
@pytest.mark.parametrize("name", BUILTIN)
def test_every_builtin_extension_conforms(name, built):
    config = observers.get(name)
    lock_path = design_lock.path(config)
    report = conformance.check(built(name), load(config).module, lock_path.parent,
                               json.loads(lock_path.read_text()))
    assert report.samples == conformance.SAMPLES
    assert report.worst["numpy"][0] <= conformance.TOLERANCE
    assert report.worst["casadi"][0] <= conformance.CASADI_TOLERANCE
    # the samples reach beyond the scheduling boxes (clamped and flagged) as well as inside them
    assert report.status_samples.get(0, 0) > 0
    assert sum(n for bits, n in report.status_samples.items() if bits & 1) > 0


KNOWN_INPUT_MODEL = '''
"""Nguyen et al. 2021 vehicle with the steering angle measured: a known input beside the outputs."""
import sympy as sp
from codegen.model import ModelDefinition

v_y, r = sp.symbols("v_y r")
v_x = sp.Symbol("v_x", positive=True)
T_eng, delta = sp.symbols("T_eng delta")
M, l_f, l_r, I_e, I_z, C_f, C_r = sp.symbols("M l_f l_r I_e I_z C_f C_r", positive=True)
F_yf = 2 * C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = 2 * C_r * (l_r * r - v_y) / v_x
MODEL = ModelDefinition(
    name="steered_car", states=(v_x, v_y, r), known_inputs=(delta,), unknown_inputs=(T_eng,),
    dynamics=sp.Matrix([T_eng / I_e + v_y * r, (F_yf + F_yr) / M - v_x * r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("v_x", v_x), ("r", r)), scheduling=(), parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r),
    units={"v_x": "m/s", "v_y": "m/s", "r": "rad/s", "T_eng": "N m", "delta": "rad"})
'''

KNOWN_INPUT_PARAMS = """[parameters]
M = 1476.0
l_f = 1.13
l_r = 1.49
I_e = 442.8
I_z = 1810.0
C_f = 57000.0
C_r = 59000.0

[state_bounds]
v_x = [5.0, 30.0]
v_y = [-1.5, 1.5]
r = [-0.55, 0.55]

[inputs]
T_eng = { min = 0.0, max = 400.0, bandwidth = 0.3 }
delta = { min = -0.04, max = 0.04, bandwidth = 0.5 }
"""


@pytest.fixture(scope="module")
def known_input_project(tmp_path_factory):
    """A user's TS project with a known input, designed, generated and built by the CLI."""
    folder = tmp_path_factory.mktemp("known_input")
    (folder / "car.py").write_text(KNOWN_INPUT_MODEL)
    (folder / "car.toml").write_text(KNOWN_INPUT_PARAMS)
    path = folder / "steered.toml"
    path.write_text('family = "ts_fuzzy_uio"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n')
    for argv in (["design", str(path), "--update"], ["generate", str(path)], ["build", str(path)]):
        assert cli.main(argv) == 0
    return path


@pytest.mark.slow          # builds
def test_a_known_input_is_read_where_the_model_puts_it(known_input_project, capsys):
    config = observers.get(str(known_input_project))
    obs = load(config)
    assert obs.input_names == ("delta", "y_v_x", "y_r")
    header = (design_lock.path(config).parent / "steered.h").read_text()
    layout = conformance.header_layout(header, "steered")
    assert layout["N_INPUT"] == 3 and layout["input"] == ["delta", "y_v_x", "y_r"]
    assert obs.n_input == 3
    # the build recorded the check that installed it, for the installed design
    record = conformance_record(config)
    assert record["design_sha256"] == obs.design_sha256 and record["samples"] >= 1000
    assert set(record["worst"]) == {"numpy", "casadi"} and record["line"].startswith("conformance: ")
    # the estimates on the model's own equations: the unknown engine torque is recovered
    assert cli.main(["validate", str(known_input_project), "--scenario", "excitation", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    # nmse_percent: 100 (1 - |error|^2 / |truth|^2), over the run after the settle time
    assert result["observer"]["T_eng"]["nmse_percent"] > 99.0
    assert result["observer"]["v_y"]["nmse_percent"] > 99.0


def _restamp(folder, fname):
    """Rewrite the stamp row of ``fname`` as ``generate`` would have written it: the corruption then
    looks like a toolchain bug, not a hand edit, and only the conformance check stands in its way."""
    stamp = folder / emit.STAMP
    digest = hashlib.sha256((folder / fname).read_text().encode()).hexdigest()
    stamp.write_text(re.sub(rf"^[0-9a-f]{{64}}  {re.escape(fname)}$", f"{digest}  {fname}", stamp.read_text(),
                            flags=re.M))


@pytest.mark.slow          # builds
def test_a_kernel_that_swaps_two_inputs_is_refused(known_input_project, capsys):
    config = observers.get(str(known_input_project))
    folder = design_lock.path(config).parent
    kernel = folder / "steered_kernel.c"
    installed = next(config.workspace.extensions.glob("_steered.*"))
    before = installed.read_bytes()
    record_before = conformance_record(config)
    original = kernel.read_text()
    try:
        # arg[2] is the measured outputs (y_v_x, y_r): read them the other way round
        swapped = original.replace("arg[2][0]", "@@").replace("arg[2][1]", "arg[2][0]").replace("@@", "arg[2][1]")
        assert swapped != original
        kernel.write_text(swapped)
        _restamp(folder, kernel.name)
        assert cli.main(["build", str(known_input_project)]) == 2
        err = capsys.readouterr().err
        assert "ConformanceError" in err and "sample" in err and "signal" in err and "not installed" in err
        assert "Traceback" not in err
        assert installed.read_bytes() == before          # the previous extension is left as it was
        assert conformance_record(config) == record_before   # and the record of the check that installed it
        with pytest.raises(ConformanceError, match="disagrees"):
            build_extension(config)
    finally:
        kernel.write_text(original)
        _restamp(folder, kernel.name)


@pytest.mark.slow          # builds
def test_a_hand_edited_c_file_is_not_compiled(known_input_project, capsys):
    config = observers.get(str(known_input_project))
    api = design_lock.path(config).parent / "steered.c"
    original = api.read_text()
    try:
        edited = original + "\n/* edited */\n"           # any edit (the template's lines change; this one cannot miss)
        api.write_text(edited)
        assert cli.main(["build", str(known_input_project)]) == 2
        err = capsys.readouterr().err
        assert "GenerationError" in err and "stamp" in err and "uiogen generate" in err
    finally:
        api.write_text(original)


@pytest.mark.slow          # builds
def test_a_lock_whose_signal_order_differs_from_the_model_is_refused():
    name = "lpv_linf_driver_torque"
    config = observers.get(name)
    build = pipeline.build(config)
    lock_path = design_lock.path(config)
    lock = json.loads(lock_path.read_text())
    header = (lock_path.parent / f"{name}.h").read_text()
    module = load(config).module
    conformance.check_layout(build, lock, header, module)          # as committed: agrees
    names = lock["signals"]["input"]
    names[0], names[1] = names[1], names[0]
    with pytest.raises(ConformanceError, match="design lock's input signals"):
        conformance.check_layout(build, lock, header, module)
    swapped = header.replace("double y_r;", "double @@;").replace("double T_a;", "double y_r;").replace("@@", "T_a")
    with pytest.raises(ConformanceError, match="C header's input struct"):
        conformance.check_layout(build, json.loads(lock_path.read_text()), swapped, module)


@pytest.mark.slow       # 5 s in the measured fast lane (pytest --durations, a loaded machine): full lane only
def test_boxes_come_from_the_declarations():
    build = pipeline.build(observers.get("ts_fuzzy_uio"))
    boxes = conformance.sample_boxes(build, np.random.default_rng(1))
    assert (boxes["y_v_x"].lower, boxes["y_v_x"].upper) == (5.0, 30.0) and boxes["y_v_x"].clamped
    assert (boxes["y_r"].lower, boxes["y_r"].upper) == (-0.55, 0.55)
    linf = pipeline.build(observers.get("lpv_linf_driver_torque"))
    boxes = conformance.sample_boxes(linf, np.random.default_rng(1))
    assert boxes["v_x"].source == "scheduling box" and (boxes["v_x"].lower, boxes["v_x"].upper) == (5.0, 35.0)
