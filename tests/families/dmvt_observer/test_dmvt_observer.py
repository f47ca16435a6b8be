"""The DMVT observer (family dmvt_observer): a nonlinear model with a nonlinear output (the rolling sedan's
a_y through two tanh tyre laws), certified by one Lyapunov matrix over the corners of the Jacobian box.

The claims are checked on the model itself (its own equations lambdified here from the model file, not the
family's representation): the step contracts the error as certified at random pairs of states in the box, the
RMS bound holds on a noisy run, and the gains follow the declared noise levels. Then what is refused.
"""
import dataclasses

import numpy as np
import pytest
import sympy as sp

from codegen import families
from codegen.design.solver import FreshSolver
from codegen.errors import CertificateError, ConfigurationError, ModelDefinitionError, SchedulingBoundsError
from codegen.families.dmvt_observer import representation
from codegen.model import ModelDefinition, load_parameters, parameter_substitution
from codegen.project import observer_file as observers

NAME = "roll_sedan_tanh_dmvt"
FAMILY = families.get("dmvt_observer")


@pytest.fixture(scope="module")
def sedan(built):
    b = built(NAME)
    model = b.config.load_model()
    params = load_parameters(b.config.parameter_path)
    subs = parameter_substitution(model, params)
    args = (*model.states, *model.known_inputs, *(g.symbol for g in model.scheduling))
    f = sp.lambdify(args, sp.Matrix(model.dynamics).subs(subs), "numpy")
    h = sp.lambdify(args, sp.Matrix([e for _, e in model.outputs]).subs(subs), "numpy")
    return b, params, (lambda *a: np.asarray(f(*a), float).ravel()), (lambda *a: np.asarray(h(*a), float).ravel())


def _physical_P(b):
    S = b.scaled.S
    return b.synthesis.P / S[:, None] / S[None, :]


def test_the_step_contracts_the_error_as_certified_at_random_pairs_in_the_box(sedan):
    b, params, f, h = sedan
    c = b.certificate.step.contraction
    assert c < 1 and b.certificate.recheck.blocks == 2 + 2 ** len(b.rep.free_entries)
    P, Ts = _physical_P(b), b.config.sample_time
    box = np.array([params.state_bounds[n] for n in b.output_names])
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(2000):
        x, xh = (rng.uniform(box[:, 0], box[:, 1]) for _ in range(2))
        w = [rng.uniform(-0.015, 0.015), rng.uniform(15.0, 35.0)]       # delta, v_x in their boxes
        z, excess = b.reference_step(np.r_[xh, xh], w[:1], h(*x, *w), w[1:])
        assert excess == 0.0
        e, e_next = x - xh, x + Ts * f(*x, *w) - z[:4]
        ratio = np.sqrt(float(e_next @ P @ e_next) / float(e @ P @ e))
        assert ratio <= c * (1 + 1e-9)
        worst = max(worst, ratio)
    assert worst > 0.9                 # the certified rate is not a vacuous statement about this model


def test_the_rms_bound_holds_on_a_noisy_run_of_the_model(sedan):
    b, params, f, h = sedan
    Ts, n = b.config.sample_time, 20000
    sigma = b.scaled.sigma
    rng = np.random.default_rng(5)
    t = np.arange(n) * Ts
    delta = 0.012 * np.sin(0.9 * t) * np.sin(0.13 * t)
    v_x = 25.0 + 8.0 * np.sin(0.05 * t)
    x = np.zeros(4)
    z = np.r_[[0.3, 0.1, 0.02, 0.0], [0.3, 0.1, 0.02, 0.0]]
    err = np.empty((n, 4))
    for k in range(n):
        y = h(*x, delta[k], v_x[k]) + sigma * rng.standard_normal(sigma.size)
        z, excess = b.reference_step(z, [delta[k]], y, [v_x[k]])
        assert excess == 0.0
        x = x + Ts * f(*x, delta[k], v_x[k])
        err[k] = x - z[:4]
    rms = np.sqrt(np.mean(err[n // 4:] ** 2, axis=0))
    bound = np.array([bd.value for bd in b.certificate.bounds if bd.norm == "rms"])
    assert np.all(rms <= bound), (rms, bound)
    assert rms[0] > 0.1 * bound[0]     # the bound is of the error's size, not orders above it


def test_the_gains_follow_the_noise_levels():
    config = observers.get(NAME)
    louder = dataclasses.replace(config, design={**config.design, "noise": {**config.design["noise"], "a_y": 0.5},
                                                 "decay": 1.0})
    b = FAMILY.build(louder, FreshSolver())
    ref = FAMILY.build(dataclasses.replace(config, design={**config.design, "decay": 1.0}), FreshSolver())
    a_y = 2
    assert np.abs(b.L[:, a_y]).max() < 0.5 * np.abs(ref.L[:, a_y]).max()      # a noisier a_y is trusted less

    def objective(x):              # what the gains minimise: the variance bound of every scaled error
        d, c = x.synthesis, x.synthesis.contraction
        return np.trace(d.L_s.T @ d.P @ d.L_s) / (1 - c * c)
    assert objective(b) > objective(ref)


def test_the_committed_rate_minimises_the_bound_among_its_neighbours(built):
    from codegen.families.dmvt_observer import design as dsn
    b = built(NAME)
    rate, sc = b.synthesis.rate, b.scaled
    values = {}
    for r in (rate / 2, rate, rate * 2):
        sol = dsn.problem(sc, r, design=False, margin=b.settings.margin).solve(tol=1e-8)
        values[r] = dsn.rms_objective(sol.objective, r, sc.sample_time)
    assert values[rate] <= min(values.values()) * (1 + 1e-6)


# --- what is refused ---------------------------------------------------------------------------------------

x1, x2, u, d = sp.symbols("x1 x2 u d")


def _params(tmp_path, bounds="x1 = [-1, 1]\nx2 = [-1, 1]\n", extra=""):
    p = tmp_path / "p.toml"
    p.write_text(f"[parameters]\n\n[state_bounds]\n{bounds}\n[inputs]\nu = {{ min = -1.0, max = 1.0 }}\n{extra}")
    return load_parameters(p)


def _model(outputs=(("y", sp.tanh(x1)),), unknown=(), dynamics=None):
    dyn = dynamics if dynamics is not None else sp.Matrix([x2, -x1 - x2 + u + (d if unknown else 0)])
    return ModelDefinition(name="toy", states=(x1, x2), known_inputs=(u,), unknown_inputs=unknown, dynamics=dyn,
                           outputs=outputs, scheduling=(), parameters=())


def test_a_nonlinear_output_gives_a_box_of_jacobians(tmp_path):
    rep = representation.build(_model(), _params(tmp_path))
    assert rep.H_box[0, 0, 0] == pytest.approx(1 - np.tanh(1) ** 2, rel=1e-3) and rep.H_box[0, 0, 1] == 1.0
    assert rep.free_entries == (("H", 0, 0),) and len(rep.corners()) == 2


def test_unknown_inputs_are_refused_with_the_families_that_take_them(tmp_path):
    with pytest.raises(ModelDefinitionError, match="unknown inputs d: .*linf_uio"):
        representation.build(_model(unknown=(d,)), _params(tmp_path))


def test_a_state_without_a_box_is_refused_by_its_key(tmp_path):
    with pytest.raises(SchedulingBoundsError, match=r"lacks: x2 = \[min, max\] under \[state_bounds\]"):
        representation.build(_model(), _params(tmp_path, bounds="x1 = [-1, 1]\n"))


def test_an_output_that_reads_no_state_is_refused(tmp_path):
    with pytest.raises(ModelDefinitionError, match="output 'y' = u reads no state"):
        representation.build(_model(outputs=(("y", u),)), _params(tmp_path))


def test_too_many_corners_are_refused_naming_the_entries(tmp_path):
    dyn = sp.Matrix([sp.sin(x1) * x2, sp.cos(x2) * x1 + u])
    with pytest.raises(SchedulingBoundsError, match=r"d\(x1'\)/dx1.*above \[design\] max_corners = 8"):
        representation.build(_model(dynamics=dyn), _params(tmp_path), max_corners=8)


def test_the_noise_levels_name_every_output(tmp_path):
    from codegen.families.dmvt_observer.build import noise_levels, parse
    config = observers.get(NAME)
    model = config.load_model()
    with pytest.raises(ConfigurationError, match=r"\[design\] noise lacks a_y: .*a_y = SIGMA \(m/s\^2\)"):
        noise_levels(config, dataclasses.replace(parse(config), noise={"r": 1e-3, "phi_dot": 1e-3}), model)
    with pytest.raises(ConfigurationError, match="a_x is no output of model 'roll_sedan_tanh'; its outputs: r, "):
        noise_levels(config, dataclasses.replace(parse(config), noise={"a_x": 1.0}), model)


def test_an_unobservable_state_is_refused_before_any_gain(tmp_path):
    # x2 is an integrator nobody measures: no rate is certifiable at any corner
    dyn = sp.Matrix([-x1 + u, u])
    (tmp_path / "toy.py").write_text(
        "import sympy as sp\nfrom codegen.model import ModelDefinition\n"
        "x1, x2, u = sp.symbols('x1 x2 u')\n"
        f"MODEL = ModelDefinition(name='toy', states=(x1, x2), known_inputs=(u,), unknown_inputs=(), "
        f"dynamics=sp.Matrix({[str(e) for e in dyn]}), outputs=(('y', sp.tanh(x1)),), scheduling=(), parameters=())\n")
    _params(tmp_path)
    (tmp_path / "toy_dmvt.toml").write_text('family = "dmvt_observer"\nmodel = "toy.py"\nparameters = "p.toml"\n'
                                            'sample_time = 0.01\n[design]\nnoise = { y = 0.01 }\n')
    with pytest.raises(CertificateError, match="no decay rate .* is certifiable"):
        FAMILY.build(observers.get(str(tmp_path / "toy_dmvt.toml")), FreshSolver())
