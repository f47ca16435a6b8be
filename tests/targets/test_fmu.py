"""uiogen export --format fmu / fmu3: FMI 2.0 and FMI 3.0 co-simulation FMUs, checked with FMPy
(its model description validation, and a simulation over every validation scenario of the named
observers whose outputs and status are bit-identical to the Python extension's)."""
from __future__ import annotations

import platform
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from codegen import cli
from codegen import targets
from codegen.targets import fmi
from codegen.validation import run as validate
from codegen.extension.build import build_extension, load

fmpy = pytest.importorskip("fmpy", reason="FMPy is not installed (pip install -c constraints.txt '.[fmu]')")
from fmpy.validation import validate_fmu  # noqa: E402
from conftest import HANG_GUARD

pytestmark = [pytest.mark.slow,          # compiles FMU binaries
              pytest.mark.skipif(platform.system() != "Linux" or platform.machine() != "x86_64",
                                 reason="the FMU carries a linux64 binary only")]

NAMES = ("lpv_linf_driver_torque", "interconnected_uio")
FORMATS = ("fmu", "fmu3")
KEYS = [(n, f) for f in FORMATS for n in NAMES]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = {}
    for name in NAMES:
        build_extension(name)
        for fmt in FORMATS:
            path = tmp_path_factory.mktemp(fmt) / f"{name}.fmu"
            assert cli.main(["export", name, "--format", fmt, "--out", str(path)]) == 0
            out[name, fmt] = path
    return out


@pytest.mark.parametrize("name,fmt", KEYS)
def test_fmu_model_description_passes_fmpy_validation(fmus, name, fmt):
    assert validate_fmu(str(fmus[name, fmt])) == []
    assert fmpy.read_model_description(str(fmus[name, fmt])).fmiVersion == targets.get(fmt).fmi_version


@pytest.mark.parametrize("name,fmt", KEYS)
def test_fmu_holds_sources_binary_units_and_sample_time(fmus, name, fmt):
    obs = load(name)
    with zipfile.ZipFile(fmus[name, fmt]) as z:
        names = set(z.namelist())
        md = ET.fromstring(z.read("modelDescription.xml"))
    platform_dir, wrapper, header = (("linux64", f"{name}_fmu.c", "fmi2Functions.h") if fmt == "fmu" else
                                     ("x86_64-linux", f"{name}_fmu3.c", "fmi3Functions.h"))
    assert f"binaries/{platform_dir}/{name}.so" in names
    assert {f"sources/{name}.c", f"sources/{name}_kernel.c", f"sources/{wrapper}", f"sources/{header}"} <= names
    assert float(md.find("DefaultExperiment").get("stepSize")) == obs.sample_time
    if fmt == "fmu":
        variables = {v.get("name"): v for v in md.iter("ScalarVariable")}
        units = [v.find("Real").get("unit") for n, v in variables.items() if n != "status"]
        assert variables["status"].find("Integer") is not None
    else:
        assert "sources/buildDescription.xml" in names
        variables = {v.get("name"): v for v in md.find("ModelVariables")}
        assert variables.pop("time").get("causality") == "independent"
        units = [v.get("unit") for n, v in variables.items() if n != "status"]
        assert variables["status"].tag == "Int32"
        assert [o.get("valueReference") for o in md.find("ModelStructure")] == \
            [v.get("valueReference") for v in variables.values() if v.get("causality") == "output"]
    assert [n for n, v in variables.items() if v.get("causality") == "input"] == list(obs.input_names)
    assert [n for n, v in variables.items() if v.get("causality") == "output"] == [*obs.output_names, "status"]
    assert any(units) and all(v.get("description") for v in variables.values())


def _scenarios():
    return [(n, s, f) for f in FORMATS for n in NAMES for s in validate.scenario_names(n)]


@pytest.mark.parametrize("name,scenario,fmt", _scenarios())
def test_fmu_outputs_bit_identical_to_extension(fmus, name, scenario, fmt):
    obs = load(name)
    inputs = validate.scenario_inputs(name, scenario)
    out, status, _ = obs.run(inputs)
    f_out, f_status = fmi.run_fmu(fmus[name, fmt], inputs, obs.input_names, obs.output_names)
    assert f_out.shape == out.shape
    assert np.array_equal(f_out.view(np.uint64), out.view(np.uint64))
    assert np.array_equal(f_status, status)


def test_fmu_refuses_a_step_that_is_not_whole_samples(fmus):
    name = NAMES[0]
    obs = load(name)
    md = fmpy.read_model_description(str(fmus[name, "fmu"]))
    unzipped = fmpy.extract(str(fmus[name, "fmu"]))
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=name, instanceName="x")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=3 * obs.sample_time)
    with pytest.raises(FMICallException):
        slave.doStep(currentCommunicationPoint=3 * obs.sample_time, communicationStepSize=0.5 * obs.sample_time)
    slave.terminate()
    slave.freeInstance()


def test_fmu3_refuses_a_step_that_is_not_whole_samples_and_a_foreign_token(fmus):
    name = NAMES[0]
    obs = load(name)
    md = fmpy.read_model_description(str(fmus[name, "fmu3"]))
    unzipped = fmpy.extract(str(fmus[name, "fmu3"]))
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Slave
    slave = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=name,
                      instanceName="x")
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    slave.setFloat64([1, 2], [0.1, 0.01])
    slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=3 * obs.sample_time)
    assert slave.getFloat64([0])[0] == pytest.approx(3 * obs.sample_time)
    with pytest.raises(FMICallException):
        slave.doStep(currentCommunicationPoint=3 * obs.sample_time, communicationStepSize=0.5 * obs.sample_time)
    with pytest.raises(FMICallException):
        slave.getFloat32([0])                    # not offered: fmi3Error, not a missing symbol
    slave.terminate()
    slave.freeInstance()
    foreign = FMU3Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzipped,
                        modelIdentifier=name, instanceName="y")
    with pytest.raises(Exception, match="Failed to instantiate FMU"):
        foreign.instantiate()


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_refuses_a_file_that_is_not_fmu(tmp_path, capsys, fmt):
    assert cli.main(["export", NAMES[0], "--format", fmt, "--out", str(tmp_path / "x.zip")]) == 2
    err = capsys.readouterr().err
    assert "ConfigurationError" in err and ".fmu" in err and "Traceback" not in err


DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String f, ...)
{ (void)e; (void)n; (void)s; (void)c; printf("log: %s\n", f); }
int main(void)
{
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    double steps[] = {NAN, INFINITY, -INFINITY, 1e300, -1.0, 0.0};
    int i, refused = 0;
    fmi2Component c = fmi2Instantiate("x", fmi2CoSimulation, GUID, "", &cb, fmi2False, fmi2False);
    if (c == NULL) return 2;
    fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    fmi2EnterInitializationMode(c);
    fmi2ExitInitializationMode(c);
    for (i = 0; i < 6; ++i) refused += fmi2DoStep(c, 0.0, steps[i], fmi2True) == fmi2Error;
    printf("refused %d, then %d\n", refused, fmi2DoStep(c, 0.0, 2 * SAMPLE_TIME, fmi2True) == fmi2OK);
    fmi2FreeInstance(c);
    return 0;
}
"""


def test_fmu_step_size_nan_or_huge_is_refused_without_undefined_behaviour(fmus, tmp_path):
    """fmi2DoStep(NaN), (+-inf), (1e300): refused before any conversion to an integer (converting
    them to long is undefined behaviour: UBSan's float-cast-overflow reported it before the fix)."""
    proc = _sanitized_driver(fmus, "fmu", DRIVER, tmp_path)
    assert proc.returncode == 0 and "runtime error" not in proc.stderr, proc.stderr
    assert "refused 6, then 1" in proc.stdout, proc.stdout


def _sanitized_driver(fmus, kind: str, driver: str, folder):
    """Compile the C sources of the core observer's FMU (``kind`` "fmu" or "fmu3") with ``driver``
    under UBSan (its GUID or instantiation token and the sample time as macros) and run it."""
    import subprocess
    from codegen.emit.toolchain import compiler
    name = NAMES[0]
    with zipfile.ZipFile(fmus[name, kind]) as z:
        for f in z.namelist():
            if f.startswith("sources/"):
                (folder / f[len("sources/"):]).write_bytes(z.read(f))
        root = ET.fromstring(z.read("modelDescription.xml"))
    token = (f'-DGUID="{root.get("guid")}"' if kind == "fmu" else f'-DTOKEN="{root.get("instantiationToken")}"')
    assert "None" not in token, token
    (folder / "driver.c").write_text(driver)
    exe = folder / "driver"
    srcs = [str(folder / f) for f in (f"{name}_kernel.c", f"{name}.c", f"{name}_{kind}.c", "driver.c")]
    subprocess.run([compiler(), "-O1", "-fsanitize=float-cast-overflow,undefined", "-fno-sanitize-recover=all",
                    token, f"-DSAMPLE_TIME={load(name).sample_time!r}", "-I", str(folder), *srcs,
                    "-o", str(exe), "-lm"], check=True, capture_output=True)
    return subprocess.run([str(exe)], capture_output=True, text=True, timeout=HANG_GUARD)


DRIVER3 = r"""
#include <math.h>
#include <stdio.h>
#include "fmi3Functions.h"
static void logger(fmi3InstanceEnvironment e, fmi3Status s, fmi3String category, fmi3String message)
{ (void)e; (void)s; printf("log %s: %s\n", category, message); }
int main(void)
{
    double steps[] = {NAN, -NAN, INFINITY, -INFINITY, 1e300, -1e300, -1.0, 0.0,
                      0.5 * SAMPLE_TIME, 1.5 * SAMPLE_TIME, 2.25 * SAMPLE_TIME, 2e9 * SAMPLE_TIME};
    const int n_steps = (int)(sizeof steps / sizeof steps[0]);
    const fmi3ValueReference time_ref[1] = {0u};
    fmi3Boolean event, terminate, early;
    fmi3Float64 last, t;
    int i, refused = 0, held = 0;
    fmi3Instance c = fmi3InstantiateCoSimulation("x", TOKEN, "", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0u,
                                                 NULL, logger, NULL);
    if (c == NULL) return 2;
    if (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK) return 3;
    if (fmi3ExitInitializationMode(c) != fmi3OK) return 4;
    for (i = 0; i < n_steps; ++i) {
        last = -1.0;
        refused += fmi3DoStep(c, 0.0, steps[i], fmi3True, &event, &terminate, &early, &last) == fmi3Error;
        /* a refused step leaves the time where it was and says so */
        if (fmi3GetFloat64(c, time_ref, 1u, &t, 1u) != fmi3OK) return 5;
        held += (t == 0.0 && last == 0.0 && !event && !terminate && !early);
    }
    printf("refused %d of %d, held %d\n", refused, n_steps, held);
    printf("then %d", fmi3DoStep(c, 0.0, 2 * SAMPLE_TIME, fmi3True, &event, &terminate, &early, &last) == fmi3OK);
    if (fmi3GetFloat64(c, time_ref, 1u, &t, 1u) != fmi3OK) return 6;
    printf(" at %d\n", t == 2 * SAMPLE_TIME && last == t);
    fmi3FreeInstance(c);
    return 0;
}
"""


def test_fmu3_step_size_nan_huge_or_off_the_sample_grid_is_refused_without_undefined_behaviour(fmus, tmp_path):
    """fmi3DoStep with a NaN, an infinite, a huge (1e300, or 2e9 samples), a non-positive or a
    communication step that is no whole number of sample times: fmi3Error, the time held, before
    any conversion to an integer (UBSan's float-cast-overflow would report a NaN or 1e300 cast to
    long); a whole number of samples afterwards is taken. The FMI 2.0 test's counterpart."""
    proc = _sanitized_driver(fmus, "fmu3", DRIVER3, tmp_path)
    assert proc.returncode == 0 and "runtime error" not in proc.stderr, (proc.returncode, proc.stderr)
    assert "refused 12 of 12, held 12" in proc.stdout, proc.stdout
    assert "then 1 at 1" in proc.stdout, proc.stdout
    assert proc.stdout.count("log logStatusError: fmi3DoStep") == 12, proc.stdout
