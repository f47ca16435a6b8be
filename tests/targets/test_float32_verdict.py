"""The float32 build's verdict on a report (codegen.targets.float32._verdict), without a build."""
from codegen.targets import float32 as precision


def _report(tolerance: float, rule: str, noise: dict, noiseless: list) -> dict:
    signal = {"unit": "N", "bound": 2.3, "deviation": 1.0, "tolerance": tolerance, "tolerance_rule": rule,
              "noise_response": 0.0, "certified": True, "within": 2.3 <= tolerance}
    return {"observer": "wheel", "source": "proj/wheel.toml", "fraction": 0.1, "noise": noise,
            "noiseless_inputs": noiseless, "uncertified_states": "refuse",
            "metrics": [{"states": ["x"], "contraction": 0.74, "margin": 0.257, "source": "[design] alpha",
                         "knob": "[design] alpha"}],
            "scenarios": {"excitation": {"signals": {"F_d": signal}, "measured_entries": [], "status_equal": True,
                                         "outside_certified_set": 0}}}


def test_a_zero_tolerance_for_want_of_sensor_noise_names_the_precision_noise_table():
    """No sensor noise known for the inputs: the rule's tolerance is 0 and the refusal said only 'a
    declared [precision] tolerance' and a contraction margin that 'cannot reach' it. It names the
    [precision] noise table (in the observer file) with the inputs that lack it."""
    v = precision._verdict(_report(0.0, "0.1 x noise response 0", {}, ["y_omega", "y_a_x"]))
    assert not v["passes"]
    r = v["reason"]
    assert "F_d on excitation: tolerance 0 N" in r and "no sensor noise of its inputs y_omega, y_a_x is known" in r
    assert "proj/wheel.toml: [precision] noise = { y_omega = SIGMA, ... }" in r and "docs/embedding.md" in r
    assert "[precision] tolerance = { F_d = ... }" in r and "margin 1 - c" not in r
    # a declared tolerance of its own, too small: the margin advice as before
    v = precision._verdict(_report(1.0, "declared", {"y_omega": 0.05}, ["y_a_x"]))
    assert "margin 1 - c = 0.257" in v["reason"] and "[precision] noise" not in v["reason"]


def test_a_misspelt_precision_signal_gets_a_did_you_mean():
    """[precision] noise names inputs (a measured output is y_NAME) and tolerance outputs; a slip
    was refused with the list alone, unlike every other key of the observer file."""
    import types
    import pytest
    from codegen.errors import ConfigurationError
    from codegen.project import observer_file as observers
    config = observers.get("lpv_linf_driver_torque", overrides={"precision.noise.r": 1e-3,
                                                                 "precision.tolerance.beat": 1e-3})
    with pytest.raises(ConfigurationError, match=r"\[precision.noise\] r: not an input .*\(did you mean 'y_r'\?\)$"):
        precision.input_noise(config, types.SimpleNamespace(input_names=("T_a", "y_r", "y_delta", "v_x")))
    with pytest.raises(ConfigurationError, match=r"\[precision.tolerance\] beat: not an output .*\(did you mean "
                                                 r"'beta'\?\)$"):
        precision._check_tolerance_keys(config, ["beta", "r", "delta", "T_d"])
