"""The float32 variant: same API with an _f32 suffix in float, built with the strict flags
(-Wdouble-promotion: nothing computed in double), the same status semantics on float bit
patterns, the committed double C untouched; its deviation from the double step bounded per
signal, in the signal's unit, with the certified contraction in the Lyapunov norm, against a
tolerance that is a declared fraction of what the sensor noise does to the estimate."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from codegen.certificate.contraction import ContractionMetric
from codegen.design import lock as design_lock, precision as design_precision
from codegen.emit import generate as emit
from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.targets import float32 as precision
from codegen.errors import CertificateError, ConfigurationError, DiscretizationError
from codegen.extension.build import build_extension, load

pytestmark = pytest.mark.slow          # float32 builds

NAME = "lpv_linf_driver_torque"


@pytest.fixture(scope="module")
def fobs(tmp_path_factory):
    build_extension(NAME)
    return precision.load_float(NAME, tmp_path_factory.mktemp("f32"))


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    build_extension(NAME)
    return precision.compare(NAME, out_dir=tmp_path_factory.mktemp("f32cmp"))


def test_float_variant_has_the_same_api_in_float_and_the_committed_double_c_is_unchanged():
    b = pipeline.build(observers.get(NAME))
    files = emit.render(b, "float32")
    assert set(files) == {f"{NAME}_f32.c", f"{NAME}_f32.h", f"{NAME}_f32_kernel.c", f"{NAME}_f32_kernel.h",
                          f"{NAME}_f32_example.c", "CMakeLists.txt"}
    h = files[f"{NAME}_f32.h"]
    assert (f"{NAME}_f32_status {NAME}_f32_step({NAME}_f32_state *s, const {NAME}_f32_input *in, "
            f"{NAME}_f32_output *out);") in h
    assert "    float beta;" in h and "double" not in h
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


def test_core_observer_float32_is_accepted_with_a_bound_per_signal_in_its_unit(report):
    """Every output's bound covers its measured deviation and lies within its tolerance; the
    certified contraction is the UI-filter loop's, and the step's own Jacobian never exceeds it in
    that norm (the norm is mapped onto the right state entries, in the right units)."""
    assert report["passes"], report["reason"]
    (m,) = report["metrics"]
    assert m["contraction"] == pytest.approx(0.976831, abs=1e-6)
    units = {"beta": "rad", "r": "rad/s", "delta": "rad", "delta_dot": "rad/s", "T_d": "N m"}
    for row in report["scenarios"].values():
        assert row["status_equal"] and row["measured_entries"] == []
        assert row["self_gain"][0] <= m["contraction"] * (1 + 1e-9)
        for name, s in row["signals"].items():
            assert s["unit"] == units[name]
            assert 0 < s["deviation"] <= s["bound"] <= s["tolerance"]
            # the tolerance: 0.1 x the RMS response of the estimate to the sensor noise, in its unit
            assert s["tolerance"] == pytest.approx(0.1 * s["noise_response"])
    # the bound accumulates the roundings through the contraction: far below worst / (1 - c)
    t_d = report["scenarios"]["track_varying_speed"]["signals"]["T_d"]
    assert t_d["bound"] < 1e-3            # N m, for a driver torque of ~10 N m RMS


def test_bound_is_a_bound_of_a_contracting_linear_recursion():
    """deviation_bound on e+ = A e + d with |A|_P = c exactly: the bound covers the true
    deviation at every sample and is reached by the worst-aligned roundings; a metric claiming a
    smaller c than the step has is caught by the self-gain figure."""
    rng = np.random.default_rng(1)
    P = np.array([[4.0, 1.0], [1.0, 2.0]])
    w, v = np.linalg.eigh(P)
    root, inv_root = (v * np.sqrt(w)) @ v.T, (v / np.sqrt(w)) @ v.T
    c = 0.9
    Q, _ = np.linalg.qr(rng.standard_normal((2, 2)))
    A = inv_root @ (c * Q) @ root                         # |P^(1/2) A P^(-1/2)| = c
    n = 400
    d = 1e-6 * rng.standard_normal((n, 2))
    e = np.zeros((n + 1, 2))
    for k in range(n):
        e[k + 1] = A @ e[k] + d[k]
    J = np.repeat(A[None], n, axis=0)
    names = ["x1", "x2"]
    good = ContractionMetric(c, (P,), tuple(names), "test")
    res = precision.deviation_bound([good], names, J, d, np.abs(e))
    assert np.all(res["bound"] >= np.abs(e) * (1 - 1e-12))
    assert res["self_gain"][0] == pytest.approx(c)
    lie = ContractionMetric(0.5, (P,), tuple(names), "claims too much")
    assert precision.deviation_bound([lie], names, J, d, np.abs(e))["self_gain"][0] > lie.contraction


def test_a_tolerance_below_the_bound_is_refused_with_the_margin_and_the_option(tmp_path):
    config = observers.get(NAME, overrides={"precision.tolerance.beta": 1e-9})
    with pytest.raises(CertificateError, match=r"beta .*bound .*rad > tolerance 1e-09 rad.*margin 1 - c = 0\.0231"):
        precision.check(config, scenarios=["takeover_opposing_assist"], out_dir=tmp_path)


@pytest.mark.parametrize("table,match", [
    ({"fraction": 2.0}, r"\[precision\] fraction = 2\.0: must be a finite number in \(0, 1\]"),
    ({"noise": {"y_r": -1.0}}, r"\[precision\.noise\] y_r = -1\.0: must be a finite number > 0"),
    ({"uncertified_states": "ignore"}, r"uncertified_states = \"ignore\": must be one of \"refuse\", \"measured\""),
    ({"accumulation": "kahan"}, r"accumulation = \"kahan\": must be one of \"plain\", \"compensated\""),
    ({"tolerances": {}}, r"unknown \[precision\] keys \['tolerances'\] \(did you mean 'tolerance'\?\)"),
])
def test_bad_precision_tables_are_typed_errors_naming_the_file_and_key(table, match):
    with pytest.raises(ConfigurationError, match=match):
        observers.get(NAME, overrides={f"precision.{k}": v for k, v in table.items()})


def test_precision_names_must_be_signals_of_the_observer(tmp_path):
    config = observers.get(NAME, overrides={"precision.noise.v_y": 0.1})
    with pytest.raises(ConfigurationError, match=r"\[precision.noise\] v_y: not an input of lpv_linf_driver_torque; "
                                                 r"its inputs: T_a, y_r"):
        precision.compare(config, out_dir=tmp_path)


def test_float32_design_option_requires_the_margin_or_names_what_would_fix_it():
    """[design] precision = "float32" on the nonlinear-tyre observer: its LMIs impose the decay
    rate whose step contracts by 1 - float32_margin. The double design certifies a margin of
    1.3e-4 per step; asked for 5e-4 the design certifies it; the default 0.01 is beyond the
    largest rate a common Lyapunov matrix certifies on the set (6.5e-4): refused, typed, naming
    the knobs."""
    name = "stanford_sideslip_nonlinear_tyre"
    (double,) = pipeline.build(observers.get(name)).contraction_metrics()
    assert double.margin < 2e-4
    base = {"design.precision": "float32"}
    b, _ = pipeline.solve(observers.get(name, overrides={**base, "design.float32_margin": 5e-4}))
    (m,) = b.contraction_metrics()
    assert m.margin >= 5e-4 * (1 - 1e-6)
    assert design_precision.required_margin(b.settings) == 5e-4
    with pytest.raises(CertificateError, match=r"precision = \"float32\" needs the decay rate .*\(contraction margin 0\.01 "
                                               r"per step.*lower sliding_fraction, or a smaller \[design\] float32_margin"):
        pipeline.solve(observers.get(name, overrides=base))
    # a design held to more margin than it certifies is refused, naming the setting to change
    asked = observers.get(name, overrides={**base, "design.float32_margin": 0.5})
    with pytest.raises(DiscretizationError, match=r"needs a certified contraction margin 1 - c >= 0\.5 per step; the design "
                                                  r"certifies 0\.0005.*Options: \[design\] decay"):
        design_precision.check(dataclasses.replace(b, config=asked))


def test_tyre_contraction_metric_is_the_certified_one_in_the_physical_state():
    """The tyre observer's P is solved in the scaled state D x; its metric on (v_y, r) is D' P D.
    On the Stanford log the step's own gain in that metric stays within the certified c on every
    sample of the certified set and exceeds it only outside (SCHEDULING_CLAMPED), where the
    certificate says nothing: with P itself as the metric it would exceed c inside too."""
    name = "stanford_sideslip_nonlinear_tyre"
    config = observers.get(name)
    b = pipeline.build(config)
    obs = load(config)
    (inputs,) = precision.scenario_inputs(config, obs, ["stanford log"]).values()
    z, status = precision.double_states(obs, inputs)
    J = precision.StepTerms(b).jacobian(z[:-1], inputs)[:, :2, :2]
    (m,) = b.contraction_metrics()
    gain = m.self_gain(J)
    clamped = (status & obs.status_bits["SCHEDULING_CLAMPED"]) != 0
    assert clamped.any() and (~clamped).sum() > 20000
    assert gain[~clamped].max() <= m.contraction * (1 + 1e-12)
    assert gain[clamped].max() > 1.0
    scaled = ContractionMetric(m.contraction, (b.P,), m.states, m.source)
    assert scaled.self_gain(J)[~clamped].max() > m.contraction


def test_stanford_ts_observer_is_accepted_on_the_log_through_its_float32_design(tmp_path):
    """ts_fuzzy_uio_stanford's observer file asks for [design] precision = "float32": (27) is solved
    with lambda <= 1 - float32_margin (0.01), and the certified margin (1.3e-4 per step at decay = 1,
    whose bounds on the log were 3.5x the tolerance of delta) now covers the rounding on the shared
    log, every signal's bound within its tolerance and above its measured deviation."""
    name = "ts_fuzzy_uio_stanford"
    config = observers.get(name)
    assert config.design["precision"] == "float32"
    build_extension(name)
    r = precision.compare(name, out_dir=tmp_path)
    assert r["passes"], r["reason"]
    (m,) = r["metrics"]
    assert m["margin"] >= 0.01 * (1 - 1e-6)
    log = r["scenarios"]["stanford log"]
    assert log["samples"] == 27500 and log["outside_certified_set"] == 0 and log["status_equal"]
    for s in log["signals"].values():
        assert s["deviation"] <= s["bound"] <= s["tolerance"]
    # the delta bound is an order of magnitude inside its tolerance, not at its edge
    assert log["signals"]["delta"]["bound"] < 0.2 * log["signals"]["delta"]["tolerance"]


def test_niki_tyre_observer_is_accepted_in_float32_on_its_own_shared_run(tmp_path):
    """niki_sideslip_nonlinear_tyre's parameter file names its car's shared run ([meta] shared_log =
    "niki"): the float build is held to it as well as to the excitation run. The log stays inside the
    certified set (no sample flagged), and the certified contraction bounds the rounding within 0.1 of
    the response to the sensor noise levels the fit identified ([precision] noise)."""
    name = "niki_sideslip_nonlinear_tyre"
    build_extension(name)
    r = precision.compare(name, out_dir=tmp_path)
    assert r["passes"], r["reason"]
    log = r["scenarios"]["niki log"]
    assert log["samples"] == 17631 and log["outside_certified_set"] == 0 and log["status_equal"]
    for s in log["signals"].values():
        assert s["deviation"] <= s["bound"] <= s["tolerance"]
    assert set(r["scenarios"]) == {"excitation", "niki log"}


def test_algebraic_uio_differentiators_keep_their_digits_in_float32(tmp_path):
    """The HOSMD differentiators of algebraic_uio_example1 run in error coordinates (first entry =
    estimate - held sample): in float32 sigma is formed from small quantities, so the float run of
    a differentiator's second derivative deviates from the double run on the same (float-rounded)
    inputs by its own rounding only: rms 1.0e-4 (y_x1) and 2.2e-5 (rho) where the Taylor form's
    z_0 - y lost 4.4e-3 and 3.6e-3. Through the exact coupling, x2's bound falls from 2.24e-4 to
    1.26e-4 (tolerance 1.03e-4), what is left being the rounding of the certified states themselves
    (the compensated update below removes it)."""
    name = "algebraic_uio_example1"
    config = observers.get(name)
    build_extension(name)
    obs = load(name)
    fobs = precision.load_float(name, tmp_path / "f32")
    inputs = precision.scenario_inputs(config, obs)["paper"]
    z_r, status_r = precision.double_states(obs, inputs.astype(np.float32).astype(np.float64))
    states_f, status_f = fobs.states(inputs)
    _, z_f = precision.own_state(fobs, states_f)          # the observer's entries, past the _comp ones
    assert np.array_equal(status_r, status_f)
    names = list(pipeline.build(config).state_names)
    for entry, measured in (("hosmd_y_x1_d2", 1.0e-4), ("hosmd_rho_d2", 2.2e-5)):
        i = names.index(entry)
        own = float(np.sqrt(np.mean((z_f[:, i].astype(np.float64) - z_r[:, i]) ** 2)))
        assert own <= 3 * measured, (entry, own)          # Taylor coordinates: 4.4e-3 and 3.6e-3
    r = precision.compare(name, out_dir=tmp_path / "cmp")
    paper = r["scenarios"]["paper"]
    assert {"held_y_x1", "held_rho", "hosmd_y_x1_d0"} <= set(paper["measured_entries"])
    x2 = paper["signals"]["x2"]
    assert x2["deviation"] <= x2["bound"] <= 1.6e-4          # 2.24e-4 in Taylor coordinates


def test_compensated_update_carries_the_storage_rounding_of_the_certified_state(tmp_path):
    """algebraic_uio_example1 asks for [precision] accumulation = "compensated": its float32 step adds
    the Gauss step's increment h (b1 K1 + b2 K2), formed at its own scale, to x1 and x2 by TwoSum and
    carries the rounding error in x1_comp and x2_comp (the first entries of the float state). The
    recursion runs on z + c, the outputs' bounds add |c|. Measured on the paper scenario: the
    one-sample error of x2 rms 1.61e-8 -> 8.4e-9 (of x1 2.78e-8 -> 6.0e-9), and x2's bound
    1.26e-4 -> 2.83e-5 against its tolerance 1.03e-4: accepted, where the plain update is refused."""
    name = "algebraic_uio_example1"
    config = observers.get(name)
    assert config.precision.accumulation == "compensated"
    b = pipeline.build(config)
    files = emit.render(b, "float32")
    h, c = files[f"{name}_f32.h"], files[f"{name}_f32.c"]
    assert "    float x1_comp;" in h and "    float x2_comp;" in h
    assert "inc = dz[1] + state[1];" in c and "arg[0] = &state[2];" in c
    # the double C is the committed one, compensated or not
    home = design_lock.path(config).parent
    for fname, text in emit.render(b).items():
        assert (home / fname).read_text() == text
    build_extension(name)
    r = precision.compare(name, out_dir=tmp_path / "comp")
    assert r["passes"], r["reason"]
    assert r["compensated"] == ["x1", "x2"]
    paper = r["scenarios"]["paper"]
    assert paper["status_equal"]
    x2 = paper["signals"]["x2"]
    assert x2["deviation"] <= x2["bound"] <= 0.4 * x2["tolerance"]          # 2.83e-5 / 1.03e-4
    plain = precision.compare(observers.get(name, overrides={"precision.accumulation": "plain"}),
                              out_dir=tmp_path / "plain")
    assert not plain["passes"] and plain["compensated"] == []
    x2p = plain["scenarios"]["paper"]["signals"]["x2"]
    assert x2p["bound"] > x2p["tolerance"] and x2p["bound"] > 4 * x2["bound"]   # 1.26e-4


def test_compensated_update_needs_a_step_with_an_increment_form():
    config = observers.get(NAME, overrides={"precision.accumulation": "compensated"})
    with pytest.raises(ConfigurationError, match=r"lpv_linf_driver_torque.toml: \[precision\] accumulation = "
                                                 r"\"compensated\": the step of family 'linf_uio' has no increment form"):
        emit.render(pipeline.build(config), "float32")
