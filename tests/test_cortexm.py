"""Cortex-M4F cross build (arm-none-eabi-gcc, strict flags, hard float): the core observer's
step within 8 KB of code and 1 KB of stack, double and float32; the same build executed under
QEMU (mps2-an386, semihosting) on a recorded validation input sequence, its outputs and status
bit-identical to the host build of the same precision. Without the tools the tests skip with a
message naming them; under CI (CI=true), where `make test` installs them, they fail instead."""
from __future__ import annotations

import os

import numpy as np
import pytest

from codegen.targets import cortexm
from codegen.tools import qemu
from codegen.extension.build import build_extension

pytestmark = pytest.mark.slow          # arm-none-eabi-gcc and QEMU

NAME = "lpv_linf_driver_torque"


def require(ok: bool, what: str) -> None:
    if not ok:
        message = f"{what} not installed (make embedded-tools / scripts/install_embedded_tools.sh)"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)


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
