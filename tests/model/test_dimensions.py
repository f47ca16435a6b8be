"""Dimensional analysis of models and the plausibility of parameter files (codegen.model.dimensions).

A kN beside an N (C_f in kN/rad, C_r in N/rad) is refused with the ratio before any design, in a
model that declares no parameter unit at all (the equations say the two stiffnesses are of one
kind); a declared unit brings the plausible range of its quantity; a value that is right although
it looks wrong is accepted by name.
"""
import json
import textwrap
from fractions import Fraction

import pytest
import sympy as sp

from codegen import cli
from codegen.errors import ConfigurationError
from codegen.model import ModelDefinition, SchedulingSignal, dimensions, load_parameters, parameter_substitution
from codegen.project import observer_file as observers


@pytest.mark.parametrize("text, dims, factor", [
    ("N m s/rad", (2, 1, -1, 0), 1.0), ("kg m^2", (2, 1, 0, 0), 1.0), ("m/s^2", (1, 0, -2, 0), 1.0),
    ("1/m", (-1, 0, 0, 0), 1.0), ("kN/rad", (1, 1, -2, 0), 1e3), ("-", (0, 0, 0, 0), 1.0),
    ("km/h", (1, 0, -1, 0), 1 / 3.6), ("kg m²", (2, 1, 0, 0), 1.0), ("Nm", (2, 1, -2, 0), 1.0),
    ("mm", (1, 0, 0, 0), 1e-3),
    # an assist motor's units: current, voltage (W/A), resistance, inductance, torque constant
    ("mA", (0, 0, 0, 1), 1e-3), ("V", (2, 1, -3, -1), 1.0), ("Ohm", (2, 1, -3, -2), 1.0), ("Ω", (2, 1, -3, -2), 1.0),
    ("mH", (2, 1, -2, -2), 1e-3), ("N m/A", (2, 1, -2, -1), 1.0), ("V s/rad", (2, 1, -2, -1), 1.0),
])
def test_units_are_read(text, dims, factor):
    d, f = dimensions.unit(text)
    assert d == dims and f == pytest.approx(factor)


def test_an_unknown_unit_is_a_typed_error():
    with pytest.raises(dimensions.DimensionError, match="cannot read 'furlong'"):
        dimensions.unit("furlong/s")


def _single_track(units: dict) -> ModelDefinition:
    beta, r, delta, a_y = sp.symbols("beta r delta a_y")
    v_x = sp.Symbol("v_x", positive=True)
    M, I_z, l_f, l_r, C_f, C_r = sp.symbols("M I_z l_f l_r C_f C_r", positive=True)
    F_f = C_f * (delta - beta - l_f * r / v_x)
    F_r = C_r * (l_r * r / v_x - beta)
    return ModelDefinition(
        "user_single_track", (beta, r), (delta,), (), sp.Matrix([(F_f + F_r) / (M * v_x) - r,
                                                                  (l_f * F_f - l_r * F_r) / I_z]),
        (("r", r),), (SchedulingSignal(v_x, "m/s"),), (M, I_z, l_f, l_r, C_f, C_r),
        units={"beta": "rad", "r": "rad/s", "delta": "rad", "v_x": "m/s", **units})


def test_dimensions_follow_from_the_equations():
    a = dimensions.infer(_single_track({"M": "kg"}))
    F = (Fraction(1), Fraction(1), Fraction(-2), Fraction(0))
    assert a.dims["C_f"] == F and a.dims["C_r"] == F             # N (per radian)
    assert a.dims["l_f"] == (1, 0, 0, 0) and a.dims["I_z"] == (2, 1, 0, 0)
    assert not a.inconsistencies
    # without any parameter unit the absolute dimension of a mass is free, the kinds are not
    free = dimensions.infer(_single_track({}))
    assert free.dims["M"] is None and free.dims["C_f"] is None
    assert ("C_f", "C_r") in free.same and ("l_f", "l_r") in free.same
    assert ("M", "C_f") not in free.same


def test_an_inconsistent_unit_is_reported():
    a = dimensions.infer(_single_track({"M": "kg", "l_f": "kg"}))
    assert a.inconsistencies                  # l_f is a length by the slip angle, declared a mass


CAR = '''
import sympy as sp
from codegen.model import ModelDefinition
v_y, r = sp.symbols("v_y r")
v_x = sp.Symbol("v_x", positive=True)
T_eng, delta = sp.symbols("T_eng delta")
M, l_f, l_r, I_e, I_z, C_f, C_r = sp.symbols("M l_f l_r I_e I_z C_f C_r", positive=True)
F_yf = 2 * C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = 2 * C_r * (l_r * r - v_y) / v_x
MODEL = ModelDefinition(
    name="unit_slip_car", states=(v_x, v_y, r), known_inputs=(), unknown_inputs=(T_eng, delta),
    dynamics=sp.Matrix([T_eng / I_e + v_y * r, (F_yf + F_yr) / M - v_x * r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("v_x", v_x), ("r", r)), scheduling=(), parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r),
    units={"v_x": "m/s", "v_y": "m/s", "r": "rad/s", "T_eng": "N m", "delta": "rad"{extra}})
'''
PARAMS = """[parameters]
M = {M}
l_f = 1.13
l_r = 1.49
I_e = 442.8
I_z = 1810.0
C_f = {C_f}     # N/rad ... or kN/rad?
C_r = 59000.0
{plausibility}
[state_bounds]
v_x = [5.0, 30.0]
v_y = [-1.5, 1.5]
r = [-0.55, 0.55]
"""


def _project(tmp_path, C_f="57000.0", M="1476.0", extra="", plausibility=""):
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "car.py").write_text(CAR.replace("{extra}", extra))
    (tmp_path / "car.toml").write_text(PARAMS.format(C_f=C_f, M=M, plausibility=plausibility))
    path = tmp_path / "obs.toml"
    path.write_text('family = "ts_fuzzy_uio"\nmodel = "car.py"\nparameters = "car.toml"\nsample_time = 0.01\n')
    return path


def test_a_kn_beside_an_n_is_refused_with_the_ratio(tmp_path, capsys):
    path = _project(tmp_path, C_f="57.0")            # kN/rad beside N/rad; no parameter unit declared
    assert cli.main(["design", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert "car.toml: [parameters] C_f, C_r = [57.0, 59000.0]:" in err and "1035x" in err and "unit slip" in err
    assert "[plausibility] accept" in err


def test_the_same_values_in_consistent_units_design(tmp_path):
    config = observers.get(str(_project(tmp_path)))
    model = config.load_model()
    assert parameter_substitution(model, load_parameters(config.parameter_path))


def test_accepting_a_value_by_name(tmp_path):
    path = _project(tmp_path, C_f="57.0", plausibility='[plausibility]\naccept = ["C_f"]\n')
    config = observers.get(str(path))
    parameter_substitution(config.load_model(), load_parameters(config.parameter_path))
    bad = _project(tmp_path, C_f="57.0", plausibility='[plausibility]\naccept = ["C_ff"]\n')
    config = observers.get(str(bad))
    with pytest.raises(ConfigurationError, match=r"\[plausibility\] accept .*did you mean 'C_f'"):
        load_parameters(config.parameter_path)


def test_a_declared_unit_brings_its_range(tmp_path):
    # M declared in kg, written in grams
    path = _project(tmp_path / "g", M="1476000.0", extra=', "M": "kg"')
    config = observers.get(str(path))
    with pytest.raises(ConfigurationError, match=r"M = 1476000.0: a mass of a road vehicle in kg .* \[0.5, 1e\+05\] kg"):
        parameter_substitution(config.load_model(), load_parameters(config.parameter_path))
    # the same number in a unit that makes it plausible
    ok = _project(tmp_path / "t", M="1.476", extra=', "M": "t"')
    config = observers.get(str(ok))
    parameter_substitution(config.load_model(), load_parameters(config.parameter_path))


def test_every_builtin_parameter_file_is_plausible_and_consistent():
    for name in observers.names():
        config = observers.get(name)
        try:
            model = config.load_model()
        except Exception:          # a family whose model module is not one ModelDefinition
            continue
        parameter_substitution(model, load_parameters(config.parameter_path))
    core = observers.get("lpv_linf_driver_torque").load_model()
    analysis = dimensions.infer(core)
    assert not analysis.inconsistencies
    assert all(d is not None for d in analysis.dims.values())     # every parameter's dimension is fixed


# --- a model whose equations contradict its declared units is refused before any design ----------

def _truck(extra_term=0, gyro_unit="rad/s", gyro=None, units=None) -> ModelDefinition:
    """A single-track truck with a first-order steering actuator: every signal and parameter unit declared."""
    v_y, r, steer, cmd, F_w = sp.symbols("v_y r steer cmd F_w")
    u = sp.Symbol("u", positive=True)
    m, J, a, b, C_f, C_r, tau = sp.symbols("m J a b C_f C_r tau", positive=True)
    F_f, F_r = C_f * (steer - (v_y + a * r) / u), C_r * (b * r - v_y) / u
    terms = {"r": r}
    return ModelDefinition(
        "truck_actuator", (v_y, r, steer), (cmd,), (F_w,),
        sp.Matrix([(F_f + F_r + F_w) / m - u * r + sp.sympify(extra_term).subs(terms),
                   (a * F_f - b * F_r) / J, (cmd - steer) / tau]),
        (("gyro", gyro if gyro is not None else r), ("steer_meas", steer)), (SchedulingSignal(u, "m/s"),),
        (m, J, a, b, C_f, C_r, tau),
        units={"v_y": "m/s", "r": "rad/s", "steer": "rad", "cmd": "rad", "F_w": "N", "gyro": gyro_unit,
               "steer_meas": "rad", "m": "kg", "J": "kg m^2", "a": "m", "b": "m", "C_f": "N/rad", "C_r": "N/rad",
               "tau": "s", **(units or {})})


def test_a_consistent_model_passes_the_units_check():
    dimensions.check_units(_truck())
    dimensions.check_units(_single_track({"M": "kg"}))


def test_a_term_of_another_unit_is_named():
    # - r (rad/s) written into an acceleration: no reading of the numbers makes it one
    with pytest.raises(dimensions.UnitError, match=r"dv_y/dt: the term -r is in s\^-1, the equation needs m s\^-2"):
        dimensions.check_units(_truck(extra_term="-r"))


def test_a_declared_parameter_unit_the_equations_contradict_is_named():
    with pytest.raises(dimensions.UnitError, match=r"the declared unit of tau is m, the equations make it s"):
        dimensions.check_units(_truck(units={"tau": "m"}))


def test_an_output_declared_at_another_scale_is_refused_unless_converted():
    # a gyro declared in deg/s that is the yaw rate in rad/s: the step would read degrees as radians
    with pytest.raises(dimensions.UnitError, match=r"output gyro = r is declared in deg/s, r is in rad/s, and the "
                                                   r"step does not convert: .*57.29577951\*r"):
        dimensions.check_units(_truck(gyro_unit="deg/s"))
    r = sp.Symbol("r")
    dimensions.check_units(_truck(gyro_unit="deg/s", gyro=180 / sp.pi * r))     # converted: accepted


def test_a_sum_of_one_dimension_at_two_scales_is_refused():
    # the steering angle declared in deg but subtracted from radians inside the tyre law: every
    # dimension agrees, the scales do not, and the step does not convert (a new user's model built,
    # validated and exported with the estimate 10^5 % off)
    with pytest.raises(dimensions.UnitError) as err:
        dimensions.check_units(_single_track({"delta": "deg"}))
    msg = str(err.value)
    assert "dbeta/dt, dr/dt: in the sum -beta + delta - l_f*r/v_x, delta (delta in deg) is 0.01745329252 " \
           "times the unit of -beta (beta in rad)" in msg, msg
    assert msg.count("in the sum") == 1                 # the sum both equations share is named once
    # a state at another scale than its equation needs: r in deg/s beside beta' in rad/s
    with pytest.raises(dimensions.UnitError, match=r"dbeta/dt: the term -r \(r in deg/s\) is 0.01745329252 "
                                                   r"times the unit the equation needs \(rad per s\)"):
        dimensions.check_units(_single_track({"r": "deg/s", "beta": "rad"}))
    # written with the conversion, or declared alike: accepted
    dimensions.check_units(_single_track({"delta": "rad"}))
    deg, rad = sp.symbols("delta beta")
    converted = _single_track({"delta": "deg"})
    converted = ModelDefinition(converted.name, converted.states, converted.known_inputs, (),
                                converted.dynamics.subs(deg, sp.pi / 180 * deg), converted.outputs,
                                converted.scheduling, converted.parameters, units=converted.units)
    dimensions.check_units(converted)


def test_a_function_reads_its_argument_in_radians():
    x, delta = sp.symbols("x delta")
    k = sp.Symbol("k", positive=True)
    model = ModelDefinition("sine_of_degrees", (x,), (delta,), (), sp.Matrix([k * sp.sin(delta) - x]),
                            (("x", x),), (), (k,), units={"x": "m", "delta": "deg"})
    with pytest.raises(dimensions.UnitError, match=r"sin reads its argument delta \(delta in deg\) in radians / SI "
                                                   r"units, 57.29577951 times its unit"):
        dimensions.check_units(model)


def test_numbers_may_carry_units_and_zero_fits_any():
    """3000 N written as a number, a time constant as a number, Min(a_x, 0): consistent readings exist."""
    x, v, a_x, F = sp.symbols("x v a_x F")
    m = sp.Symbol("m", positive=True)
    model = ModelDefinition(
        "numbers_with_units", (x, v), (a_x,), (F,),
        sp.Matrix([v, 3000 * sp.sin(sp.Rational(13, 10) * sp.atan(x / 2)) / m + sp.Min(a_x, 0) + F / m
                   + (a_x - v) / 10]),
        (("x", x),), (), (m,), units={"x": "m", "v": "m/s", "a_x": "m/s^2", "F": "N", "m": "kg"})
    dimensions.check_units(model)


def _yaw_moment(moment, torques: bool, scale=None) -> ModelDefinition:
    """A yaw rate driven by the wheels' longitudinal forces (N), or by their torques (N m) where the
    ``moment`` (a function of t_f and the two signals, and of a length parameter x_0) needs forces."""
    r, left, right, d = sp.symbols("r left right d")
    t_f, I_z, x_0 = sp.symbols("t_f I_z x_0", positive=True)
    unit = "N m" if torques else "N"
    params = (t_f, I_z) + ((x_0,) if scale else ())
    return ModelDefinition(
        "yaw_moment", (r,), (left, right), (d,), sp.Matrix([(moment(t_f, left, right, x_0) + d) / I_z]),
        (("r", r),), (), params,
        units={"r": "rad/s", "left": unit, "right": unit, "d": "N m", "t_f": "m", "I_z": "kg m^2",
               **({"x_0": scale} if scale else {})})


@pytest.mark.parametrize("moment", [lambda t, fl, fr, _: t / 2 * (fr - fl), lambda t, fl, fr, _: 0.5 * t * (fr - fl),
                                    lambda t, fl, fr, _: 3 * t / 4 * (fr - fl)],
                         ids=["t_f/2", "0.5*t_f", "3*t_f/4"])
def test_a_small_number_carries_no_unit(moment):
    """Issue 42 item 3: torques used as forces passed the check when a /2 stood in the term (the 2 read as
    a length); a small ratio (|p|, q <= 4) beside a parameter is a pure number, so the term is refused as
    it is without it, and the same moment of forces passes."""
    with pytest.raises(dimensions.UnitError, match=r"the declared unit of t_f is m, the equations make it "
                                                   r"dimensionless .*a small number such as 2, 1/2 or 3/4 beside a "
                                                   r"parameter is pure"):
        dimensions.check_units(_yaw_moment(moment, torques=True))
    with pytest.raises(dimensions.UnitError):
        dimensions.check_units(_yaw_moment(lambda t, fl, fr, _: t * (fr - fl), torques=True))   # as without /2
    dimensions.check_units(_yaw_moment(moment, torques=False))


def test_a_length_scale_written_as_a_small_number_beside_a_parameter_is_refused():
    """atan(t_f / 2) with t_f in metres (a 2 m scale written as the number 2 beside the parameter) is
    refused; the scale as a parameter with its unit passes, and so does a larger number (20 m), which
    may carry one; with signals alone (atan(x / 2), -3 r) a small number may still be a scale or a rate."""
    with pytest.raises(dimensions.UnitError, match=r"a small number such as 2, 1/2 or 3/4 beside a parameter is pure"):
        dimensions.check_units(_yaw_moment(lambda t, fl, fr, x0: t * sp.atan(t / 2) * (fr - fl), torques=False))
    dimensions.check_units(_yaw_moment(lambda t, fl, fr, x0: t * sp.atan(t / x0) * (fr - fl), torques=False,
                                       scale="m"))
    dimensions.check_units(_yaw_moment(lambda t, fl, fr, x0: t * sp.atan(t / 20) * (fr - fl), torques=False))


def test_a_small_number_is_pure_only_where_it_is_written_beside_a_parameter():
    """The rule reads the product as written, not as expanded: in C_r (1.5 r - v_y) / v_x the 1.5 is a length
    (l_r inline) inside a sum, which expanding puts beside C_r; read as pure, it made r (rad/s) and v_y (m/s)
    disagree and a correct model was refused."""
    v_y, r, delta, d = sp.symbols("v_y r delta d")
    v_x = sp.Symbol("v_x", positive=True)
    m, C_r = sp.symbols("m C_r", positive=True)
    for lever in (1.5, sp.Rational(3, 2), 1.2):
        force = C_r * (lever * r - v_y) / v_x
        model = ModelDefinition("inline_lever", (v_y,), (delta, r), (d,), sp.Matrix([force / m - v_x * r + d]),
                                (("v_y", v_y),), (SchedulingSignal(v_x, "m/s"),), (m, C_r),
                                units={"v_y": "m/s", "r": "rad/s", "delta": "rad", "d": "m/s^2", "v_x": "m/s",
                                       "m": "kg", "C_r": "N/rad"})
        dimensions.check_units(model)
    assert dimensions._mark_pure(C_r * (sp.Rational(3, 2) * r - v_y), {"C_r"}).has(dimensions.PURE) is False
    assert dimensions._mark_pure(C_r / 2 * (r - v_y), {"C_r"}).has(dimensions.PURE)


def test_pure_numbers_are_the_small_ratios():
    pure = [sp.Integer(2), sp.Rational(1, 2), sp.Float(0.5), sp.Rational(3, 4), sp.Float(1 / 3), sp.Integer(-4),
            sp.Float(2.0), sp.Rational(4, 3)]
    free = [sp.Integer(5), sp.Rational(1, 10), sp.Integer(3000), sp.Float(9.81), sp.Float(0.3), sp.Rational(13, 10),
            sp.pi]
    assert all(dimensions._pure(n) for n in pure), [n for n in pure if not dimensions._pure(n)]
    assert not any(dimensions._pure(n) for n in free), [n for n in free if dimensions._pure(n)]


def _assist_motor(torque_term=None, units=None) -> ModelDefinition:
    """A steering column with a DC assist motor: current i [A] from the voltage u [V] through
    L di/dt = u - R i - k_e w, the column's rate w driven by k_t i and the driver's torque T_d."""
    th, w, i, u, T_d = sp.symbols("th w i u T_d")
    J, c, k_t, k_e, R, L = sp.symbols("J c k_t k_e R L", positive=True)
    torque = k_t * i if torque_term is None else torque_term(i, k_t)
    return ModelDefinition(
        "assist_motor", (th, w, i), (u,), (T_d,),
        sp.Matrix([w, (torque + T_d - c * w) / J, (u - R * i - k_e * w) / L]),
        (("th", th), ("i", i)), (), (J, c, k_t, k_e, R, L),
        units={"th": "rad", "w": "rad/s", "i": "A", "u": "V", "T_d": "N m", "J": "kg m^2", "c": "N m s/rad",
               "k_t": "N m/A", "k_e": "V s/rad", "R": "Ohm", "L": "H", **(units or {})})


def test_an_electric_actuator_declares_its_units():
    dimensions.check_units(_assist_motor())
    a = dimensions.infer(_assist_motor())
    assert a.dims["k_t"] == a.dims["k_e"] == (2, 1, -2, -1)          # N m/A and V s/rad are one unit
    # the torque constant left out: a current written into a torque
    with pytest.raises(dimensions.UnitError, match=r"the units do not agree in dw/dt"):
        dimensions.check_units(_assist_motor(torque_term=lambda i, k_t: i))
    with pytest.raises(dimensions.UnitError, match=r"the declared unit of R is V, the equations make it "
                                                   r"m\^2 kg s\^-3 A\^-2"):
        dimensions.check_units(_assist_motor(units={"R": "V"}))


def test_a_unit_that_does_not_read_names_its_key():
    with pytest.raises(dimensions.DimensionError, match=r"model 'assist_motor': units\['i'\] = 'Amp': unit 'Amp': "
                                                        r"cannot read 'Amp' \(known: .*\bA\b.*\); write the unit"):
        dimensions.check_units(_assist_motor(units={"i": "Amp"}))


def test_every_builtin_model_passes_the_units_check():
    for name in observers.names():
        dimensions.check_units(observers.get(name).load_model())


def test_the_units_check_runs_before_any_design(tmp_path, capsys):
    path = _project(tmp_path, extra=', "I_e": "kg m^2"')      # T_eng / I_e is an acceleration: I_e in kg m
    assert cli.main(["design", str(path)]) == 2
    out = capsys.readouterr()
    err = out.err.strip().splitlines()[-1]
    assert err.startswith("uiogen: error: UnitError: model 'unit_slip_car'") and "the declared unit of" in err
    # said once: the analysis printed above a failed design fails on the same error and adds nothing
    assert (out.out + out.err).count("the declared unit of") == 1, out


@pytest.mark.parametrize("table, text, message", [
    ("state_bounds", "[state_bounds]\nv_yy = [-1.5, 1.5]\n", r"\[state_bounds\] v_yy = \[-1.5, 1.5\]: unknown .*did you "
                                                            r"mean 'v_y'.*allowed \(the signals of model 'unit_slip_car'\)"),
    ("inputs", "[inputs]\nT_en = { min = 0.0, max = 1.0 }\n", r"\[inputs\] T_en = .*did you mean 'T_eng'"),
    ("scheduling", "[scheduling.v_z]\nmin = 5.0\nmax = 30.0\nrate_min = -1.0\nrate_max = 1.0\n",
     r"\[scheduling\] v_z = .*unknown .*did you mean 'v_[xy]'.*allowed \(the signals of model 'unit_slip_car'\)"),
])
def test_a_table_entry_naming_no_signal_of_the_model_is_refused(tmp_path, capsys, table, text, message):
    """A misspelt [state_bounds] / [inputs] / [scheduling.NAME] entry would be silently unused."""
    path = _project(tmp_path)
    params = tmp_path / "car.toml"
    params.write_text(params.read_text().replace("[state_bounds]\n", text + "[state_bounds]\n", 1)
                      if table != "state_bounds" else params.read_text() + text.split("\n", 1)[1])
    assert cli.main(["design", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "ConfigurationError" in err and "car.toml" in err and "Traceback" not in err
    import re
    assert re.search(message, err), err


def test_a_parameter_without_a_unit_is_named_as_not_range_checked(tmp_path, capsys):
    """Units are optional, so a parameter whose unit the model does not declare gets no plausible
    range (C_f written in kN/rad passes if C_r is in kN/rad too): ``uiogen analyze`` and ``uiogen
    design`` say so, naming it and how to have it checked (a note, not an error)."""
    path = _project(tmp_path / "none", M="1.476")                # tonnes where kg is meant: passes
    model = observers.get(str(path)).load_model()
    assert dimensions.unranged_parameters(model) == ("M", "l_f", "l_r", "I_e", "I_z", "C_f", "C_r")
    assert cli.main(["analyze", str(path), "--no-design", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["unranged_parameters"] == list(dimensions.unranged_parameters(model))
    path = _project(tmp_path / "some", extra=', "M": "kg", "l_f": "m", "l_r": "m", "I_e": "kg m", "I_z": "kg m^2"')
    assert cli.main(["analyze", str(path), "--no-design"]) == 0
    out = capsys.readouterr().out
    note = [line.strip() for line in out.splitlines() if line.strip().startswith("note: model 'unit_slip_car'")]
    assert note == [f"note: model 'unit_slip_car' ({tmp_path / 'some' / 'car.py'}) declares no unit for C_f, C_r: their "
                    f"values are not checked against a plausible range (a value in kN where N is meant can pass); to "
                    f"have them checked, declare their units in the model's units={{...}} (as \"M\": \"kg\", "
                    f"\"C_f\": \"N/rad\", \"I_z\": \"kg m^2\"; units such as m, kg, s, N, rad)"], out
    assert cli.main(["design", str(path)]) == 0                     # and below the design it certified
    out = capsys.readouterr().out
    assert [line for line in out.splitlines() if line.startswith("note: ")] == note, out
    path = _project(tmp_path / "all", extra=', "M": "kg", "l_f": "m", "l_r": "m", "I_e": "kg m", "I_z": "kg m^2", '
                                           '"C_f": "N/rad", "C_r": "N/rad"')
    model = observers.get(str(path)).load_model()
    assert dimensions.unranged_parameters(model) == () and dimensions.unranged_note(model) == ""
