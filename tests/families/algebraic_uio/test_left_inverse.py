"""The left inverse of a non-square Gamma (more outputs than unknown inputs): the one the state error
reaches least, in the state box (representation.left_inverse), instead of the paper's Gamma^+ of
(86) in raw output units; and the solver's fallback scaling (design.design). The user's case: an
electric assist motor, angle and current measured, load torque unknown, L = 0.2 mH."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import null_space

from codegen import pipeline
from codegen.design.solver import FreshSolver, LockReplay
from codegen.errors import DesignLockError, InfeasibleLMIError
from codegen.families.algebraic_uio import build as algebraic_uio
from codegen.families.algebraic_uio import representation as rdeg
from codegen.model import ModelDefinition, SchedulingSignal, instantiate, load_parameters
from codegen.project import observer_file as observers
from codegen.validation import excitation

HERE = Path(__file__).parent / "assist_motor"

# y_th''' and y_i''' on the excitation run (measured after its first 0.1 s, about half these), per L
LIPSCHITZ = {0.0002: (1000.0, 5e4), 0.002: (1000.0, 1.5e5), 0.02: (1000.0, 3e4)}


def _motor(tmp_path, L=0.0002, current_scale=None):
    """The motor's model, parameters and observer file in tmp_path: h = 1 ms (the electric pole at
    -R/L = -500 1/s needs h a ||F||_X < 1 for the Gauss step's certificate: 10 ms cannot be
    certified at 0.2 mH, a DiscretizationError); ``current_scale``: the current output in other units
    (1000: mA)."""
    model = (HERE / "motor.py").read_text()
    if current_scale is not None:
        model = model.replace('("i", i)', f'("i_out", {current_scale} * i)').replace('"i": "A"', '"i": "A", "i_out": "mA"')
    (tmp_path / "motor.py").write_text(model)
    (tmp_path / "motor.toml").write_text((HERE / "motor.toml").read_text().replace("L = 0.0002", f"L = {L}"))
    lip_th, lip_i = LIPSCHITZ[L]
    out = "y_i" if current_scale is None else "y_i_out"
    (tmp_path / "motor_obs.toml").write_text(
        'family = "algebraic_uio"\nmodel = "motor.py"\nparameters = "motor.toml"\nsample_time = 0.001\n\n'
        '[design]\nlmi = "direct"\nalpha = 1.0\nauxiliary = "output_injection"\nauxiliary_alpha = 0.5\n\n'
        f'[design.differentiators.y_th]\norder = 2\nlipschitz = {lip_th}\n\n'
        f'[design.differentiators.{out}]\norder = 2\nlipschitz = {lip_i * (current_scale or 1)}\n')
    return observers.get(str(tmp_path / "motor_obs.toml"))


class _CasadiStep:
    """The step's CasADi graph (the C kernel's) with the runtime's interface (names, ``run``), so the
    excitation validation runs without a generated and compiled extension."""

    def __init__(self, b):
        self.b, self.input_names, self.output_names = b, tuple(b.input_names), tuple(b.output_names)

    def run(self, rows):
        rows = np.asarray(rows, float).T
        nu, ny = self.b.nu, self.b.ny
        z, excess = self.b.step_function().mapaccum(rows.shape[1])(
            np.zeros(self.b.n_state), rows[:nu], rows[nu:nu + ny], rows[nu + ny:])[:2]
        return np.array(z).T[:, -len(self.output_names):], (np.array(excess).ravel() > 0).astype(int), None


# ---- the stiff motor designs, certifies and reconstructs T_d ---------------------------------------------

@pytest.mark.parametrize("L", [0.0002, 0.002, 0.02])
def test_stiff_motor_designs_certifies_and_reconstructs_the_torque(tmp_path, L):
    """Before: 0.2 mH stopped in Clarabel (InsufficientProgress), 2 mH failed the numpy re-check,
    20 mH certified with cond X 3e4 and a T_d error of 2 % RMS. Gamma^+ in raw units took T_d from
    i'' (its Gamma entry -k_e/(J L) outweighs 1/J by 250 at 0.2 mH), which puts the 1/L^2 terms of
    i'' into the error matrix. Now T_d comes from th'' (the state error reaches it least)."""
    cfg = _motor(tmp_path, L)
    b = pipeline.build(cfg)
    G, Gam = np.array(b.dec.Gamma_inv.evalf(), float), np.array(b.dec.Gamma.evalf(), float)
    assert G[0, 0] * Gam[0, 0] > 0.9              # th'' carries T_d: G Gamma = G_th / J - G_i k_e / (J L) = 1
    assert b.recheck["worst_min_eig"] > 0 and b.dense["max_eig"] < 0
    assert np.linalg.cond(b.design.X) < 1e4
    assert b.discrete["h_a_f"] < 1 and b.discrete["contraction_bound_per_step"] < 1
    # the excitation scenario (the motor's angle is an open integrator: over 30 s the run drifts past the
    # plausible angles and is refused, so 6 s, as `uiogen validate --scenario excitation --duration 6`)
    res = excitation.run(cfg, duration=6.0, observer=_CasadiStep(b))
    assert res["status_flags"] == 0
    rows = res["observer"]
    assert rows["T_d"]["rms_percent"] < 1.0, rows["T_d"]
    assert all(rows[s]["rms_percent"] < 1.0 for s in ("th", "w", "i")), rows


def test_the_fallback_scaling_is_committed_and_replayed(tmp_path):
    """At 0.2 mH the observability scaling (unit columns of [C; C F; C F^2], whose F^2 terms the
    electric pole sets) leaves the problem AlmostPrimalInfeasible; it is solved in the matrix-balanced
    scaling with the outputs scaled to it, and a design lock replays that problem (the scalings are
    the problem's data)."""
    cfg = _motor(tmp_path)
    fresh = FreshSolver()
    b = algebraic_uio.build(cfg, fresh)
    rec = next(r for r in fresh.records if r.problem.endswith("LMI (39)"))
    assert rec.data == {"state_scaling": b.design.scaling.tolist(), "output_scaling": b.design.output_scaling.tolist()}
    replay = LockReplay(fresh.records, source="test lock")
    again = algebraic_uio.build(cfg, replay)
    replay.check_complete()
    assert np.array_equal(again.design.scaling, b.design.scaling)
    assert np.array_equal(again.design.output_scaling, b.design.output_scaling)
    assert all(np.array_equal(x, y) for x, y in zip(again.design.L, b.design.L))
    bad = dataclasses.replace(rec, data={**rec.data, "state_scaling": [0.3, 1.0, 1.0]})
    with pytest.raises(DesignLockError, match="committed state_scaling .* is not 3 power"):
        algebraic_uio.build(cfg, LockReplay([bad if r is rec else r for r in fresh.records]))


def test_an_infeasibility_verdict_at_full_tolerance_stands(tmp_path):
    """The fallback is for a solve that settled nothing; Clarabel's PrimalInfeasible (its full
    tolerances) is reported as it is, from the one solve (decay 300 1/s here)."""
    cfg = _motor(tmp_path)
    cfg = dataclasses.replace(cfg, design={**cfg.design, "alpha": 300.0})
    with pytest.raises(InfeasibleLMIError, match=r"Clarabel: PrimalInfeasible") as info:
        pipeline.build(cfg)
    assert info.value.status == "PrimalInfeasible" and "posed again" not in str(info.value)


# ---- unit-free -------------------------------------------------------------------------------------------

def test_the_torque_estimate_does_not_depend_on_the_current_unit(tmp_path):
    """The current measured in mA: Gamma, Mcal scale by 1000 in that row; the left inverse scales by
    1/1000 there (to its weight's 12 digits), so Q Mcal, F0 and T_d_hat = G (Y - Mcal x_hat) are the
    same. The paper's Gamma^+ in raw units moves further still towards i'' in mA."""
    (tmp_path / "A").mkdir()
    (tmp_path / "mA").mkdir()
    decs = []
    for sub, scale in (("A", None), ("mA", 1000)):
        cfg = _motor(tmp_path / sub, current_scale=scale)
        decs.append(rdeg.derive(instantiate(cfg.load_model(), load_parameters(cfg.parameter_path))))
    a, ma = decs
    M = np.diag([1.0, 1000.0])
    f = lambda m: np.array(m.evalf(), float)
    assert ma.Gamma == sp.diag(1, 1000) * a.Gamma and ma.Mcal == sp.diag(1, 1000) * a.Mcal
    np.testing.assert_allclose(f(ma.Gamma_inv) @ M, f(a.Gamma_inv), rtol=1e-11)
    np.testing.assert_allclose(f(ma.F0), f(a.F0), rtol=1e-11, atol=1e-11 * np.abs(f(a.F0)).max())
    np.testing.assert_allclose(f(ma.Gamma_inv * ma.Gamma), [[1.0]], rtol=0, atol=1e-15)     # exact left inverses
    rng = np.random.default_rng(0)
    (Ga, Ma, Gma), (Gm, Mm, Gmm) = ((f(d.Gamma_inv), f(d.Mcal), f(d.Gamma)) for d in decs)
    for _ in range(100):
        x, xh, d = rng.uniform(-20, 20, 3), rng.uniform(-20, 20, 3), rng.uniform(-10, 10, 1)
        Ya = Ma @ x + Gma @ d
        Ym = Mm @ x + Gmm @ d
        assert Gm @ (Ym - Mm @ xh) == pytest.approx(Ga @ (Ya - Ma @ xh), rel=1e-10, abs=1e-9)


def test_the_whole_step_estimates_the_same_torque_with_the_current_in_mA(tmp_path):
    """End to end at 0.2 mH: both designs are the fallback problem (its output scaling follows C, so
    the two problems differ only by 1000/1024 in the current's row), and the torque estimates of the
    excitation run agree to 1e-3 N m (T_d spans +-10 N m). The default problem is not unit-free (the
    observability scaling and min ||K|| read the outputs' units): where it solves, as at 20 mH, the
    gains differ and so do the estimates' transients (0.06 N m there); after convergence the decoupling
    (the left inverse) alone sets them."""
    est = []
    for sub, scale in (("A", None), ("mA", 1000)):
        (tmp_path / sub).mkdir()
        cfg = _motor(tmp_path / sub, current_scale=scale)
        b = pipeline.build(cfg)
        res = excitation.run(cfg, duration=6.0, observer=_CasadiStep(b))
        assert res["status_flags"] == 0 and res["observer"]["T_d"]["rms_percent"] < 1.0
        est.append(res["signals"]["estimate"]["T_d"][res["signals"]["t"] >= 2.0])
    assert np.abs(est[0] - est[1]).max() < 1e-3


# ---- the rule on a scheduled model: a left inverse, the least sensitive one, across the box ------------

def _mimo(tmp_path, outputs, bounds=True):
    """x1' = x2, x2' = -rho x1 - x2 + rho d1, x3' = x1 - x3 + d2, rho in [1, 5]."""
    x1, x2, x3, d1, d2 = sp.symbols("x1 x2 x3 d1 d2")
    rho = sp.Symbol("rho", positive=True)
    sig = {"x1": x1, "x2": x2, "x3": x3, "s13": x1 + x3}
    m = ModelDefinition("mimo3", (x1, x2, x3), (), (d1, d2), sp.Matrix([x2, -rho * x1 - x2 + rho * d1, x1 - x3 + d2]),
                        tuple((o, sig[o]) for o in outputs), (SchedulingSignal(rho),), ())
    box = "\n[state_bounds]\nx1 = [-1.0, 1.0]\nx2 = [-4.0, 4.0]\nx3 = [-0.5, 0.5]\n" if bounds else ""
    p = tmp_path / "mimo3.toml"
    p.write_text(f"[parameters]\n\n[scheduling.rho]\nmin = 1.0\nmax = 5.0\nrate_min = -2.0\nrate_max = 2.0\n{box}")
    return instantiate(m, load_parameters(p))


@pytest.mark.parametrize("outputs", [("x1", "x3", "s13"), ("x1", "x3", "x2")])
def test_left_inverse_across_the_box_and_least_sensitive_at_its_centre(tmp_path, outputs):
    """G Gamma = I symbolically and at samples of the box, P D = 0; at the centre of the box (rho = 3,
    where the weight is taken) every other left inverse G + Z N' (N' Gamma = 0) has G R G' at least as
    large, R = Mcal S^2 Mcal'. With x2 measured beside x1, x1'' = x2' is an output combination without
    state or UI: G ignores it (G R_B U = 0, R_B the row norms of [Mcal S, Gamma])."""
    lpv = _mimo(tmp_path, outputs)
    dec = rdeg.derive(lpv)
    rho = dec.base[0]
    assert sp.simplify(dec.Gamma_inv * dec.Gamma - sp.eye(2)) == sp.zeros(2, 2)
    assert sp.simplify(dec.P * lpv.D) == sp.zeros(3, 2)
    S = [2, 8, 1]                   # the widths of the state box
    num = lambda m, v: np.array(m.subs(rho, v).evalf(), float)
    rng = np.random.default_rng(1)
    for v in [1.0, 5.0, *rng.uniform(1.0, 5.0, 20)]:
        assert np.allclose(num(dec.Gamma_inv, v) @ num(dec.Gamma, v), np.eye(2), atol=1e-12)
    G, Gam, MS = num(dec.Gamma_inv, 3.0), num(dec.Gamma, 3.0), num(dec.Mcal * sp.diag(*S), 3.0)
    R = MS @ MS.T
    Np = null_space(Gam.T)
    for _ in range(50):
        G2 = G + rng.standard_normal((2, Np.shape[1])) @ Np.T
        assert np.linalg.eigvalsh(G2 @ R @ G2.T - G @ R @ G.T).min() > -1e-9 * np.abs(G @ R @ G.T).max()
    B = np.hstack([MS, Gam])
    N = null_space(B.T)
    assert N.shape[1] == (outputs[-1] == "x2")
    if N.shape[1]:
        assert np.abs(G @ np.diag(np.linalg.norm(B, axis=1) ** 2) @ N).max() < 1e-9
    cert = dec.certificates["left_inverse"]
    assert cert["state_scale"] == {"x1": "2.00000000000", "x2": "8.00000000000", "x3": "1.00000000000"}
    assert cert["state_scale_source"] == "the [state_bounds] widths" and cert["weight_at"] == {"rho": 3.0}
    assert ("redundant_output_combinations" in cert) == (outputs[-1] == "x2")


def test_without_a_state_box_the_states_are_measured_in_their_units(tmp_path):
    """The box is how large a state error can be; without one the model's unit is all there is, and
    the design's record says so (the outputs' units still do not enter)."""
    dec = rdeg.derive(_mimo(tmp_path, ("x1", "x3", "s13"), bounds=False))
    cert = dec.certificates["left_inverse"]
    assert cert["state_scale"] == {"x1": "1.00000000000", "x2": "1.00000000000", "x3": "1.00000000000"}
    assert cert["state_scale_source"] == "the [state_bounds] widths; the model's unit for x1, x2, x3 (no box)"
    assert sp.simplify(dec.Gamma_inv * dec.Gamma - sp.eye(2)) == sp.zeros(2, 2)
