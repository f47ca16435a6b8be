"""The generated C ships ready to build: next to each observer's C, a CMakeLists.txt and an
example program (NAME_example.c) that runs the step on a recorded CSV log. Every observer's
project (and its float32 variant's) configures and builds with -Werror with the host compiler and
with the ARM cross-compiler for the Cortex-M4F; the host example's estimates are bit-identical to
the extension's (double) and to the float32 library's on a validation log. Without cmake or
arm-none-eabi-gcc the tests skip naming them; under CI (CI=true) they fail instead."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from codegen.project import observer_file as observers
from codegen.targets import cortexm
from codegen.targets import float32 as precision
from codegen.extension.build import build_extension, generated_dir, load
from codegen.validation import run as validate
from conftest import require_embedded_tool as require

NAME = "lpv_linf_driver_torque"
M4F = ["-DCMAKE_SYSTEM_NAME=Generic", "-DCMAKE_C_COMPILER=arm-none-eabi-gcc",
       f"-DCMAKE_C_FLAGS={' '.join(cortexm.CPU_FLAGS)}", "-DCMAKE_EXE_LINKER_FLAGS=--specs=nosys.specs"]


def cmake(*args, cwd=None) -> subprocess.CompletedProcess:
    proc = subprocess.run(["cmake", *map(str, args)], capture_output=True, text=True, cwd=cwd)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


@pytest.fixture(scope="module")
def projects(tmp_path_factory):
    """Every observer's generated folder and its float32 variant's, as one CMake super-project."""
    require(shutil.which("cmake") is not None, "cmake")
    root = tmp_path_factory.mktemp("cmake")
    f32 = root / "float32"
    folders = {}
    for name in observers.names():
        folders[name] = generated_dir(name)
        folders[f"{name}_f32"] = precision.emit_float(name, f32)
    (root / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.13)\nproject(every_observer C)\n"
        + "".join(f'add_subdirectory("{d}" "{key}")\n' for key, d in folders.items()))
    return root, folders


def build(root, target: str, extra=()):
    out = root / f"build-{target}"
    cmake("-S", root, "-B", out, "-DCMAKE_BUILD_TYPE=Release", *extra)
    proc = cmake("--build", out, "-j", "2")
    assert "warning" not in (proc.stdout + proc.stderr).lower().replace("-wdouble", "")
    return out


@pytest.mark.slow       # cmake + a C compiler (50 s)
def test_every_observer_builds_with_werror_on_the_host_and_runs_a_log(projects, tmp_path):
    root, folders = projects
    out = build(root, "host")
    for key in folders:
        assert (out / key / f"{key}_example").is_file(), key
        assert "-Werror" in (folders[key] / "CMakeLists.txt").read_text()
    # the core observer's example on a validation log (columns shuffled, a time column added)
    build_extension(NAME)
    obs = load(NAME)
    inputs = validate.scenario_inputs(NAME, "takeover_opposing_assist")[:500]
    order = list(reversed(range(obs.n_input)))
    log = tmp_path / "log.csv"
    with log.open("w") as fh:
        fh.write("t," + ",".join(obs.input_names[j] for j in order) + "\n")
        for k, row in enumerate(inputs):
            fh.write(f"{k * obs.sample_time!r}," + ",".join(repr(float(row[j])) for j in order) + "\n")
    want, status, _ = obs.run(inputs)
    for key, dtype in ((NAME, np.float64), (f"{NAME}_f32", np.float32)):
        proc = subprocess.run([str(out / key / f"{key}_example"), str(log)], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.splitlines()
        assert lines[0] == ",".join([*obs.output_names, "status"])
        got = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
        if dtype is np.float32:
            want, status, _ = precision.load_float(NAME, tmp_path / "lib").run(inputs)
        assert np.array_equal(got[:, :-1].astype(dtype), want) and np.array_equal(got[:, -1], status)
    # a log without an input column: exit 1, the missing column named
    bad = tmp_path / "bad.csv"
    bad.write_text("T_a,y_r\n0,0\n")
    proc = subprocess.run([str(out / NAME / f"{NAME}_example"), str(bad)], capture_output=True, text=True)
    assert proc.returncode == 1 and "no column y_delta" in proc.stderr


@pytest.mark.slow       # cmake + arm-none-eabi-gcc (20 s)
def test_every_observer_cross_builds_with_werror_for_the_cortex_m4f(projects):
    require(cortexm.available(), cortexm.CC)
    root, folders = projects
    out = build(root, "m4f", M4F)
    for key in folders:
        assert (out / key / f"lib{key}.a").is_file() and (out / key / f"{key}_example").is_file(), key


def test_header_carries_the_design_hash_and_a_typed_status():
    h = (generated_dir(NAME) / f"{NAME}.h").read_text()
    import json
    from codegen.emit.generate import design_hash
    lock = (generated_dir(NAME) / f"{NAME}_design.json").read_text()
    assert f'#define LPV_LINF_DRIVER_TORQUE_DESIGN_HASH "{design_hash(lock)}"' in h
    assert len(design_hash(lock)) == 64 and json.loads(lock)["lock"]["design_inputs"] not in h
    # a re-hash of the toolchain (design_inputs and the seals over it) keeps it; a design change does not
    doc = json.loads(lock)
    doc["lock"].update(design_inputs="0" * 64, sha256="1" * 64, sections={})
    assert design_hash(json.dumps(doc)) == design_hash(lock)
    doc["L1"][0][0] += 1e-9
    assert design_hash(json.dumps(doc)) != design_hash(lock)
    assert "} lpv_linf_driver_torque_status_bit;" in h and "typedef int lpv_linf_driver_torque_status;" in h
    assert "lpv_linf_driver_torque_status lpv_linf_driver_torque_step(" in h
