"""``[design] through_sliding``: the nonlinear-tyre step certified at every slip, beyond sliding included.

The claim (docs/families/nonlinear_tyre_observer.md, "Through sliding"): with a Lyapunov matrix of its
own, V(e+) <= (1 - T_s (a phi - eps (1 - phi))) V(e), phi the mean over the axles of theta_k / theta_k,full;
every axle slope in [0, full] (the Fiala law's slope is 0 beyond sliding), so V never grows faster than
eps where both axles slide, and the step corrects by the tyre model at every slip. Checked here on the
model itself (its own forces, its own Euler step), not on the family's factorization.
"""
import dataclasses

import numpy as np
import pytest
import sympy as sp

from codegen import cli, families
from codegen.design.solver import FreshSolver, LockReplay
from codegen.errors import CertificateError, ConfigurationError, ModelDefinitionError
from codegen.families.nonlinear_tyre_observer import design as dsn
from codegen.families.nonlinear_tyre_observer.fit import _set_values
from codegen.model import load_parameters
from codegen.project import observer_file as observers

from conftest import new_starter

NAME = "stanford_sideslip_nonlinear_tyre"
FAMILY = families.get("nonlinear_tyre_observer")


def _through(config, **more):
    return dataclasses.replace(config, design={**config.design, "through_sliding": True, **more})


@pytest.fixture(scope="module")
def built():
    return FAMILY.build(_through(observers.get(NAME)), FreshSolver())


def _model_functions(config):
    """The model's own numbers: its Euler step, its a_y and its axle forces (sympy -> numpy), its slips over
    their sliding slip, in (v_y, r, delta, a_x, v_x)."""
    module = config.load_model_module()
    model = module.MODEL
    params = load_parameters(config.parameter_path).values
    syms = [*model.states, *model.known_inputs, model.scheduling[0].symbol]
    subs = {p: params[str(p)] for p in model.parameters}
    subs.update({w: 0 for w in model.unknown_inputs})
    mods = [{"Min": np.minimum, "Max": np.maximum}, "numpy"]
    f = [sp.lambdify(syms, sp.sympify(e).xreplace(subs), mods) for e in model.dynamics]
    a_y = sp.lambdify(syms, sp.sympify(dict(model.outputs)["a_y"]).xreplace(subs), mods)
    forces = [sp.lambdify(syms, sp.sympify(e).xreplace(subs), mods) for e in (module.Phi_f, module.Phi_r)]
    ratio = [sp.lambdify(syms, (sp.Abs(a.slip) / a.sliding.subs(a.peak_symbol, a.peak)).xreplace(subs), mods)
             for a in module.AXLES]
    return f, a_y, forces, ratio


def test_slope_bounds_hold_beyond_sliding(built):
    # the model's own force slope (central differences of MODEL) at random states far beyond sliding: every
    # value inside the through-sliding bounds, which hold 0 and reach the full slope
    _, _, forces, ratio = _model_functions(built.config)
    rng = np.random.default_rng(3)
    n = 4000
    args = [rng.uniform(-8, 8, n), rng.uniform(-0.6, 0.6, n), rng.uniform(-0.2, 0.2, n), rng.uniform(-15, 10, n),
            rng.uniform(15, 65, n)]
    h = 1e-6
    beyond = np.zeros(n, bool)
    for k, b in enumerate(built.rep.through_set):
        theta = args[4] * (forces[k](args[0] + h, *args[1:]) - forces[k](args[0] - h, *args[1:])) / (2 * h)
        assert b.theta[0] <= theta.min() and theta.max() <= b.theta[1]
        assert b.theta[0] < 0 <= b.theta[1] < 1.0                  # 0 inside, the positive end a rounding only
        beyond |= ratio[k](*args) > 1.0
    assert beyond.sum() > n / 2
    # the full slope is the decay set's: the same product bound at tau = 0
    for bt, bd in zip(built.rep.through_set, built.rep.decay_set):
        assert bt.theta[0] == pytest.approx(bd.theta[0], rel=5e-3)


def test_the_claim_holds_on_the_model_step_at_any_slip(built):
    # true state and estimate anywhere (both axles sliding, one, none), no noise: one step of the model (its
    # Euler step) and one of the observer's reference step; V of the error with the certificate's own matrix
    c = built.recheck
    assert c["through_rate"] == pytest.approx(3.05, abs=0.02) and c["sliding_growth"] == 1e-3
    assert built.recheck["blocks"] == 1 + 8 + 16 + 1 + 16 + 1 + 8
    f, a_y, forces, ratio = _model_functions(built.config)
    full = [b.theta[0] for b in built.rep.through_set]
    Ts = built.config.sample_time
    D = built.plant.D
    P = D.T @ built.through.P @ D
    rng = np.random.default_rng(5)
    worst, sliding_pairs = -np.inf, 0
    for _ in range(3000):
        u = [rng.uniform(-0.2, 0.2), rng.uniform(-15, 10)]
        v = rng.uniform(15, 65)
        x = np.array([rng.uniform(-6, 6), rng.uniform(-0.6, 0.6)])
        xh = x + np.array([rng.uniform(-3, 3), rng.uniform(-0.05, 0.05)])
        x_next = x + Ts * np.array([fn(*x, *u, v) for fn in f])
        z, excess = built.reference_step(np.array([*xh, 0.0, 0.0]), u, [a_y(*x, *u, v), x[1]], [v])
        assert excess == 0                                       # inside the boxes: never flagged, at any slip
        e, e_next = x - xh, x_next - z[:2]
        # r_hat is corrected by the measured r, which stands in for the state inside the forces: the claim is
        # about the error of the prediction, e = x - x_hat with r_hat the previous prediction
        ratio_v = float(e_next @ P @ e_next) / float(e @ P @ e)
        # the mean-value slopes of this pair: the secant of each axle force along v_y (r measured, the same)
        theta = [v * (F(*x, *u, v) - F(xh[0], x[1], *u, v)) / (x[0] - xh[0]) for F in forces]
        phi = float(np.mean([th / fl for th, fl in zip(theta, full)]))
        claimed = 1.0 - Ts * dsn.through_rate(phi, c["through_rate"], c["sliding_growth"])
        assert ratio_v <= claimed * (1 + 1e-9)
        worst = max(worst, ratio_v)
        sliding_pairs += all(q(*x, *u, v) > 1.0 and q(*xh, *u, v) > 1.0 for q in ratio)
    assert sliding_pairs > 50
    assert worst <= 1.0 + Ts * c["sliding_growth"] * 1.001


def test_without_it_a_slip_beyond_the_set_is_flagged_and_falls_back():
    plain = FAMILY.build(observers.get(NAME), FreshSolver())
    solver = FreshSolver()
    through = FAMILY.build(_through(observers.get(NAME)), solver)
    z0 = np.array([-3.0, 0.2, 0.0, 0.0])                           # far beyond sliding at the rear
    u, y, v = [0.02, 0.0], [9.0, 0.3], [20.0]
    z_plain, ex_plain = plain.reference_step(z0, u, y, v)
    z_through, ex_through = through.reference_step(z0, u, y, v)
    assert ex_plain > 0 and z_plain[0] == pytest.approx(-3.0 + 0.01 * (9.0 - 0.3 * 20.0), abs=1e-15)
    assert ex_through == 0 and z_through[0] != pytest.approx(z_plain[0], abs=1e-6)
    # a measured signal outside its box still flags, and falls back, in both
    assert through.reference_step(z0, [0.5, 0.0], y, v)[1] > 0
    # the replayed design reproduces the through-sliding rate and matrix from the lock records
    replay_solver = LockReplay(solver.records, source="test")
    replay = FAMILY.build(_through(observers.get(NAME)), replay_solver)
    replay_solver.check_complete()
    assert replay.recheck["through_rate"] == through.recheck["through_rate"]
    assert np.array_equal(replay.through.P, through.through.P)


def test_no_growth_at_full_sliding_is_refused_naming_the_setting():
    # at full sliding of both axles the error along v_y cannot decay (unobservable): V is held at best, and a
    # growth eps below what the LMI margin resolves is refused, naming the settings, not reported as certified
    cfg = observers.get(NAME)
    with pytest.raises(CertificateError, match="through_sliding: no Lyapunov matrix keeps V from growing faster than "
                                               "sliding_growth = 1e-09"):
        FAMILY.build(_through(cfg, sliding_growth=1e-9), FreshSolver())
    # read with through_sliding only: set alone, it would be silently unused
    with pytest.raises(ConfigurationError, match="sliding_growth = 0.01 is read with through_sliding = true only"):
        FAMILY.build(dataclasses.replace(cfg, design={**cfg.design, "sliding_growth": 0.01}), FreshSolver())


def test_a_force_that_changes_beyond_sliding_is_refused(tmp_path, capsys):
    folder = new_starter(tmp_path / "p", "nonlinear_tyre_observer", "tyre1")
    model = folder / "model.py"
    text = model.read_text()
    rear = "tyres.fiala_slip_force(t_r, C_r, F_maxr)"
    assert rear in text
    model.write_text(text.replace(rear, "tyres.fiala_slip_force(t_r, C_r, F_maxr, clamp=False)"))
    obs = folder / "tyre1.toml"
    said = obs.read_text()
    assert "through_sliding = false" in said                        # the starter's copy says the built-in's choice
    obs.write_text(said.replace("through_sliding = false", "through_sliding = true"))
    assert cli.main(["design", str(obs)]) == 2
    err = capsys.readouterr().err
    assert "ModelDefinitionError" in err and "axle rear" in err and "not constant beyond the sliding slip" in err
    assert "Traceback" not in err
    with pytest.raises(ModelDefinitionError):
        FAMILY.build(observers.get(str(obs)), FreshSolver())
    # without through_sliding the same model designs (its force is the law's on the certified set)
    obs.write_text(said)
    assert cli.main(["design", str(obs)]) == 0


def test_fit_writes_a_chosen_bool_as_toml():
    text = "[design]\nsliding_fraction = 0.95   # x\nthrough_sliding = true\n"
    out = _set_values(text, "design", {"through_sliding": False, "decay_fraction": 0.1})
    assert "through_sliding = false" in out and "decay_fraction = 0.1" in out and "sliding_fraction = 0.95" in out


def test_the_float32_norm_is_the_through_certificate_at_every_slip(built):
    # beyond the decay set the through-sliding step is not flagged, so the decay set's P (which says nothing
    # there) must not bound a float32 deviation: the metric is P_t, c its rate at full slope, and the step's own
    # gain in that norm (the float32 recursion's per-sample factor) stays within the claim at the local slope
    (m,) = built.contraction_metrics()
    D = built.plant.D
    assert np.array_equal(m.P[0], D.T @ built.through.P @ D)
    c = built.recheck
    Ts = built.config.sample_time
    assert m.contraction == pytest.approx(np.sqrt(1 - Ts * c["through_rate"]), rel=1e-12) and m.contraction < 0.99
    _, _, forces, ratio = _model_functions(built.config)
    full = [b.theta[0] for b in built.rep.through_set]
    rng = np.random.default_rng(11)
    h, sliding, gains = 1e-6, 0, []
    for _ in range(400):
        u, v = [rng.uniform(-0.2, 0.2), rng.uniform(-15, 10)], rng.uniform(15, 65)
        xh = np.array([rng.uniform(-6, 6), rng.uniform(-0.6, 0.6)])
        y = [rng.uniform(-10, 10), xh[1] + rng.uniform(-0.05, 0.05)]
        J = np.zeros((2, 2))
        for j in range(2):
            dz = np.zeros(4)
            dz[j] = h
            hi = built.reference_step(np.array([*xh, 0, 0]) + dz, u, y, [v])[0][:2]
            lo = built.reference_step(np.array([*xh, 0, 0]) - dz, u, y, [v])[0][:2]
            J[:, j] = (hi - lo) / (2 * h)
        # the local slope of each axle force along v_y at the estimate (r measured inside the forces)
        theta = [v * (F(xh[0] + h, y[1], *u, v) - F(xh[0] - h, y[1], *u, v)) / (2 * h) for F in forces]
        phi = float(np.mean([th / fl for th, fl in zip(theta, full)]))
        claimed = np.sqrt(1.0 - Ts * dsn.through_rate(phi, c["through_rate"], c["sliding_growth"]))
        g = float(m.self_gain(J[None])[0])
        assert g <= max(m.contraction, claimed) * (1 + 1e-6)
        gains.append(g)
        sliding += all(q(xh[0], y[1], *u, v) > 1.0 for q in ratio)
    assert sliding > 20 and max(gains) > m.contraction             # the per-sample gain is what carries sliding


def test_float32_accepts_the_through_sliding_step_on_the_log(tmp_path):
    # the Ferrari's starter with every slip certified: no sample of the shared log outside the certified set,
    # and the float32 deviation bounded in the through-sliding norm within 0.1 x the noise response
    from codegen.targets import float32
    folder = new_starter(tmp_path / "p", "nonlinear_tyre_observer", "tyre_f32")
    obs = folder / "tyre_f32.toml"
    obs.write_text(obs.read_text().replace("through_sliding = false", "through_sliding = true"))
    for verb in ("design", "generate", "build"):
        assert cli.main([verb, str(obs)]) == 0
    r = float32.compare(str(obs), scenarios=["stanford log"])
    row = r["scenarios"]["stanford log"]
    assert r["passes"] and row["outside_certified_set"] == 0 and row["bound_covers_deviation"]
    assert "through-sliding" in r["metrics"][0]["source"]
    assert row["signals"]["v_y"]["bound"] < 0.2 * row["signals"]["v_y"]["tolerance"]
