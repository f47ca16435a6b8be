"""Cortex-M4F cross build (arm-none-eabi-gcc, strict flags, hard float): the core observer's
step within 8 KB of code and 1 KB of stack, double and float32; the same build executed under
QEMU (mps2-an386, semihosting) on a recorded validation input sequence, its outputs and status
bit-identical to the host build of the same precision. Without the tools the tests skip with a
message naming them; under CI (CI=true), where `make test` installs them, they fail instead."""
from __future__ import annotations

import numpy as np
import pytest

from codegen.targets import cortexm
from codegen.tools import qemu
from codegen.extension.build import build_extension
from conftest import require_embedded_tool as require

pytestmark = pytest.mark.slow          # arm-none-eabi-gcc and QEMU

NAME = "lpv_linf_driver_torque"


def test_core_observer_fits_8k_code_and_1k_stack():
    require(cortexm.available(), cortexm.CC)
    rows = cortexm.table([NAME])
    assert {r["precision"] for r in rows} == {"double", "float32"}
    for r in rows:
        assert 0 < r["code_bytes"] <= 8192
        assert 0 < r["stack_bytes"] <= 1024
        assert r["unbounded"] == []


@pytest.fixture(scope="module")
def recorded():
    require(qemu.available(), qemu.missing())
    build_extension(NAME)
    scenario, inputs = qemu.record_inputs(NAME)
    return scenario, inputs


@pytest.mark.parametrize("precision", ["double", "float32"])
def test_core_observer_under_qemu_is_bit_identical_to_the_host_build(recorded, precision, tmp_path):
    scenario, inputs = recorded
    assert inputs.shape == (qemu.SAMPLES, 5) and np.all(np.isfinite(inputs))
    r = qemu.compare(NAME, precision, inputs, scenario, work=tmp_path)
    assert r["samples"] == qemu.SAMPLES
    assert r["differing_values"] == 0 and r["status_equal"] and r["bit_identical"], qemu.format_row(r)


def test_cycle_count_reads_the_executed_instructions_of_the_step(recorded, tmp_path):
    """Cycles per step of the core observer (codegen/tools/m4cycles.py): the float32 step runs on
    the FPU (about one float instruction per flop of the CasADi graph, no soft-float routine), the
    double step in libgcc's soft-float routines; cycles are at least the instructions, and grow
    with the refill P. (Figures, not speed claims: `uiogen bench` reports them.)"""
    from codegen.tools import m4cycles
    require(m4cycles.available(), f"{qemu.missing() or m4cycles.OBJDUMP}")
    scenario, inputs = recorded
    flops = m4cycles.flops(NAME)
    f32 = m4cycles.measure(NAME, "float32", inputs, tmp_path / "f32")
    # one call per step, the harness's of NAME_step_flat: the kernel is inlined (-flto)
    assert f32["soft_float_instructions"] == 0 and f32["mnemonics"].get("bl", 0) == 1
    assert 0.9 * flops <= f32["by_kind"]["float"] <= 1.2 * flops
    assert f32["instructions"] <= f32["cycles_p1"] < f32["cycles_p3"]
    assert f32["mnemonics"]["vdiv"] >= 1
    dbl = m4cycles.measure(NAME, "double", inputs, tmp_path / "f64")
    arithmetic = ("vadd", "vsub", "vmul", "vdiv", "vsqrt", "vmla", "vmls", "vnmls", "vnmla", "vfma")
    assert not any(m in dbl["mnemonics"] for m in arithmetic)          # moves only: the FPU has no double
    assert dbl["soft_float_instructions"] > 0.8 * dbl["instructions"]


def test_instruction_timings_of_the_cycle_count():
    from codegen.tools import m4cycles
    assert m4cycles._base("vldrle") == "vldr" and m4cycles._base("bls.n") == "b" and m4cycles._base("bl") == "bl"
    assert m4cycles._base("vmul.f32") == "vmul" and m4cycles._base("movgt") == "mov"
    assert m4cycles._registers("{d8-d15}") == 16 and m4cycles._registers("{r4, r5, r6, lr}") == 4
