"""The TS family's refusal of an output that is not a state points where the output can go: an output linear in
the states to the L-infinity UIO (y = C(rho) x + Du(rho) u), an output nonlinear in them (a tyre law of v_y in
a_y) to the DMVT observer, which takes y = h(x) (issue 42, also weak: the advice pointed to linf_uio, which cannot
take it). What the
output does with the measured states (scheduling signals) does not count."""
import pytest
import sympy as sp

from codegen.errors import ModelDefinitionError
from codegen.families.ts_fuzzy_uio.representation import _output_selection
from codegen.model import ModelDefinition

v_y, r, delta = sp.symbols("v_y r delta")


def _model(output):
    return ModelDefinition(name="lat", states=(v_y, r), known_inputs=(delta,), unknown_inputs=(),
                           dynamics=sp.Matrix([-v_y + delta, -r + delta]), outputs=(("r", r), ("a_y", output)),
                           scheduling=(), parameters=())


def test_a_nonlinear_output_is_not_sent_to_the_linear_output_family():
    with pytest.raises(ModelDefinitionError) as exc:
        _output_selection(_model(3.0 * sp.tanh(v_y - 0.5 * r)))
    said = str(exc.value)
    assert "output 'a_y'" in said and "nonlinear in v_y," in said and "no linear-output family" in said
    assert "takes outputs y = C(rho) x" not in said
    assert "family dmvt_observer) takes y = h(x)" in said


@pytest.mark.parametrize("output", [v_y + 1.2 * r, v_y * sp.sin(r)])   # nonlinear in the measured r: a scheduling
def test_an_output_linear_in_the_unmeasured_states_is_sent_to_the_l_infinity_uio(output):
    with pytest.raises(ModelDefinitionError) as exc:
        _output_selection(_model(output))
    said = str(exc.value)
    assert "The L-infinity UIO (family linf_uio) takes outputs y = C(rho) x + Du(rho) u" in said
    assert "nonlinear" not in said
