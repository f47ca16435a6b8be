"""The units a certificate states its bounds in (codegen.certificate.certificate.unit_ratio): one
unit per side when its signals share it, else every signal's unit in the signals' order."""
import pytest

from codegen.certificate.certificate import unit_ratio


@pytest.mark.parametrize("errors, inputs, expected", [
    (["rad"], ["N m"], "rad per N m"),
    (["rad"], ["rad"], "rad per rad"),                                  # output and unknown input in rad
    (["rad", "rad"], ["N m", "N m"], "rad per N m"),                     # one unit a side: said once
    # z = (beta, r, delta, delta_dot) of the steering models: the k-th unit is the k-th signal's
    (["rad", "rad/s", "rad", "rad/s"], ["N m"], "(rad, rad/s, rad, rad/s) per N m"),
    (["rad", "rad", "rad/s"], ["N", "N m"], "(rad, rad, rad/s) per (N, N m)"),   # two unknown inputs
    (["m", None, ""], ["N"], "(m, -, -) per N"),                        # an undeclared unit is "-"
])
def test_a_gain_unit_keeps_one_unit_per_signal_in_order(errors, inputs, expected):
    assert unit_ratio(errors, inputs) == expected
