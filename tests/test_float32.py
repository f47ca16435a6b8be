"""The float32 variant: same API with an _f32 suffix in float, built with the strict flags
(-Wdouble-promotion: nothing computed in double), the same status semantics on float bit
patterns, the committed double C untouched, and the deviation from the double step measured
against the certificate's contraction margin (refused where the margin does not cover it)."""
from __future__ import annotations

import numpy as np
import pytest

from codegen.design import lock as design_lock
from codegen.emit import generate as emit
from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.targets import float32 as precision
from codegen.errors import CertificateError
from codegen.extension.build import build_extension, load

pytestmark = pytest.mark.slow          # float32 builds

NAME = "lpv_linf_driver_torque"


@pytest.fixture(scope="module")
def fobs(tmp_path_factory):
    build_extension(NAME)
    return precision.load_float(NAME, tmp_path_factory.mktemp("f32"))


def test_float_variant_has_the_same_api_in_float_and_the_committed_double_c_is_unchanged():
    b = pipeline.build(observers.get(NAME))
    files = emit.render(b, "float32")
    assert set(files) == {f"{NAME}_f32.c", f"{NAME}_f32.h", f"{NAME}_f32_kernel.c", f"{NAME}_f32_kernel.h"}
    h = files[f"{NAME}_f32.h"]
    assert f"int {NAME}_f32_step({NAME}_f32_state *s, const {NAME}_f32_input *in, {NAME}_f32_output *out);" in h
    assert "    float beta;" in h and "double" not in h.replace("past double range", "")
    assert "#define casadi_real float" in files[f"{NAME}_f32_kernel.c"]
    assert "UINT32_C(0x7f800000)" in files[f"{NAME}_f32.c"]
    home = design_lock.path(b.config).parent
    for fname, text in emit.render(b).items():
        assert (home / fname).read_text() == text


def test_float_status_semantics_on_float_bit_patterns(fobs):
    obs = load(NAME)
    good = np.array([[0.0, 0.01, 0.02, 0.0, 20.0]] * 3)
    out, status, state = fobs.run(good)
    assert list(status) == [obs.status_bits["OK"]] * 3
    held = state.copy()
    bad = good[:1].copy()
    bad[0, 1] = np.nan
    out, status, state2 = fobs.run(bad, held)
    assert status[0] == obs.status_bits["NONFINITE_INPUT"] and np.array_equal(state2, held)
    huge = good[:1].copy()
    huge[0, 1] = 3e38            # a finite float y_r: the step overflows float range
    out, status, state3 = fobs.run(huge, held)
    assert status[0] & obs.status_bits["NUMERICAL_FAILURE"] and not state3.any()
    clamped = good[:1].copy()
    clamped[0, 4] = 50.0          # v_x above its box
    _, status, _ = fobs.run(clamped)
    assert status[0] == obs.status_bits["SCHEDULING_CLAMPED"]


def test_float_deviation_is_measured_against_the_contraction_margin(tmp_path):
    r = precision.compare(NAME, out_dir=tmp_path)
    # the margin is the committed design's certified contraction (UI-filter loop, docs/embedding.md)
    assert r["contraction_per_step"] == pytest.approx(0.976831, abs=1e-6)
    assert r["bound"] == pytest.approx(r["max_rounding_per_step"] / (1 - r["contraction_per_step"]))
    for row in r["scenarios"].values():
        assert row["status_equal"]
        assert 0 < row["max_deviation"] < 1e-3          # float rounding, amplified by the slow contraction
    assert r["passes"] == (r["max_deviation"] <= precision.TOLERANCE and r["bound"] <= precision.TOLERANCE)
    if not r["passes"]:
        with pytest.raises(CertificateError, match="margin"):
            precision.check(NAME, out_dir=tmp_path)
