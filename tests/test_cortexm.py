"""Cortex-M4F cross build (arm-none-eabi-gcc, strict flags, hard float): the core observer's
step within 8 KB of code and 1 KB of stack, double and float32."""
from __future__ import annotations

import pytest

from codegen import cortexm

pytestmark = pytest.mark.skipif(not cortexm.available(), reason="arm-none-eabi-gcc is not installed "
                                "(make embedded-tools / scripts/install_embedded_tools.sh)")


def test_core_observer_fits_8k_code_and_1k_stack():
    rows = cortexm.table(["lpv_linf_driver_torque"])
    assert {r["precision"] for r in rows} == {"double", "float32"}
    for r in rows:
        assert 0 < r["code_bytes"] <= 8192
        assert 0 < r["stack_bytes"] <= 1024
        assert r["unbounded"] == []
