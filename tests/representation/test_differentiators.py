"""HOSMD (Levant's differentiator, matching discretization): exactness, noise asymptotics, C == Python."""
import math
import re
import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest

from codegen.emit import hosmd as H
from codegen.representation import differentiators as D
from codegen.errors import ModelDefinitionError, SampleError, UiogenError

ORDERS = range(1, D.MAX_ORDER + 1)
EPS = np.finfo(float).eps


# ---- gains and spec -------------------------------------------------------------------------------

def test_levant_gains_are_the_published_non_recursive_values():
    # Levant's non-recursive gains as tabulated for lambda = (1.1, 1.5, 2, 3, 5, ...)
    np.testing.assert_allclose(D.levant_gains(1), (1.1, 1.5))
    np.testing.assert_allclose(D.levant_gains(2), (1.1, 2.12, 2.0), atol=5e-3)
    np.testing.assert_allclose(D.levant_gains(3), (1.1, 3.06, 4.16, 3.0), atol=5e-3)
    np.testing.assert_allclose(D.levant_gains(4), (1.1, 4.57, 9.30, 10.03, 5.0), atol=5e-3)


@pytest.mark.parametrize("k", ORDERS)
def test_non_recursive_form_equals_levants_recursive_form(k):
    """The continuous-time right-hand sides agree for random states (the gain identity is exact)."""
    lam = D.LEVANT_RECURSIVE_GAINS
    lt = D.levant_gains(k)
    rng = np.random.default_rng(k)
    for _ in range(20):
        L = 10 ** rng.uniform(-2, 2)
        z = rng.standard_normal(k + 1)
        f = rng.standard_normal()
        sig = z[0] - f
        nonrec = [-lt[k - i] * L ** ((i + 1) / (k + 1)) * abs(sig) ** ((k - i) / (k + 1)) * np.sign(sig)
                  + (z[i + 1] if i < k else 0.0) for i in range(k + 1)]
        rec, v_prev = [], None
        for i in range(k + 1):
            e = sig if i == 0 else z[i] - v_prev
            n = k - i
            v = -lam[n] * L ** (1 / (n + 1)) * abs(e) ** (n / (n + 1)) * np.sign(e) + (z[i + 1] if i < k else 0.0)
            rec.append(v)
            v_prev = v
        np.testing.assert_allclose(rec, nonrec, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("bad, match", [
    (dict(order=0), "order must be in 1..5"),
    (dict(order=6), "order must be in 1..5"),
    (dict(order=2.0), "integer"),
    (dict(order=True), "integer"),
    (dict(lipschitz=0.0), "Lipschitz constant must be finite and > 0"),
    (dict(lipschitz=-1.0), "Lipschitz"),
    (dict(lipschitz=float("nan")), "Lipschitz"),
    (dict(lipschitz=float("inf")), "Lipschitz"),
    (dict(lipschitz="fast"), "must be a number"),
    (dict(sample_time=0.0), "sample time"),
    (dict(sample_time=float("nan")), "sample time"),
    (dict(gains=(1.1, 2.0)), "needs 3 gains, got 2"),
    (dict(gains=2.0), "sequence of numbers"),
    (dict(gains=(1.1, -2.0, 2.0)), "gain must be finite and > 0"),
    (dict(gains=(1.0, 0.1, 5.0)), "not make the gain polynomial Hurwitz"),   # 5 * 0.1 < 1
])
def test_bad_specs_raise_typed_errors(bad, match):
    args = dict(order=2, lipschitz=1.0, sample_time=0.01) | bad
    with pytest.raises(ModelDefinitionError, match=match) as info:
        D.HosmdSpec(**args)
    assert isinstance(info.value, (UiogenError, ValueError))


def test_spec_is_frozen_and_hashable():
    s = D.HosmdSpec(2, 1.0, 0.01)
    assert s.gains == D.levant_gains(2) and s.n_state == 3
    with pytest.raises(Exception):
        s.order = 3
    assert s == D.HosmdSpec(2, 1, 0.01) and hash(s) == hash(D.HosmdSpec(2, 1, 0.01))


def test_state_shape_is_checked():
    s = D.HosmdSpec(2, 1.0, 0.01)
    with pytest.raises(SampleError, match=r"shape \(3,\)"):
        D.hosmd_step_numpy(s, np.zeros(2), 0.0)
    with pytest.raises(SampleError, match=r"shape \(3, 1\)"):
        D.hosmd_step_sx(s, ca.SX.sym("z", 4), ca.SX.sym("f"))


# ---- the discrete step ----------------------------------------------------------------------------

@pytest.mark.parametrize("k", ORDERS)
def test_large_errors_give_levants_explicit_euler_step(k):
    """tau*rho -> 0: the matched gain tends to tau times Levant's continuous-time gain."""
    L, tau = 2.0, 1e-3
    s = D.HosmdSpec(k, L, tau)
    z = np.zeros(k + 1)
    for sigma in (1e2, 1e6, 1e10):
        rho = (L / sigma) ** (1 / (k + 1))
        nxt = D.hosmd_step_numpy(s, z, -sigma)            # z0 - f = sigma
        euler = np.array([-tau * s.gains[k - i] * rho ** (i + 1) * sigma for i in range(k + 1)])
        # first-order agreement in q = tau * rho (the next term of exp(q nu) = 1 + q nu + ...)
        np.testing.assert_allclose(nxt, euler, rtol=10 * tau * rho)


@pytest.mark.parametrize("k", ORDERS)
def test_step_is_finite_and_continuous_at_zero_error(k):
    """No pow(0, p<0), no division by |sigma|: sigma = 0 (and subnormal) give the dead-beat step."""
    s = D.HosmdSpec(k, 1.0, 0.01)
    rng = np.random.default_rng(k)
    z = rng.standard_normal(k + 1)
    phi_z = D._constants(s).Phi @ z
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        at_zero = D.hosmd_step_numpy(s, z, z[0])
        np.testing.assert_allclose(at_zero, phi_z, rtol=1e-15, atol=1e-15)
        for tiny in (5e-324, 1e-310, 1e-300, 1e-200):
            for sign in (1, -1):
                nxt = D.hosmd_step_numpy(s, z, z[0] - sign * tiny)
                assert np.all(np.isfinite(nxt))
                np.testing.assert_allclose(nxt, phi_z, rtol=1e-12, atol=1e-12)
    f = D.hosmd_function(s)
    for tiny in (0.0, 5e-324, -1e-300):
        np.testing.assert_allclose(np.array(f(z, z[0] - tiny)).ravel(), phi_z, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("k", ORDERS)
def test_generated_c_is_safe_at_zero_error(k):
    """Read the CasADi C: pow only with a literal exponent in (0, 1), sqrt only of |.| or sqrt, and
    the one division is by fmax(., positive literal) -- nothing can be 0^-p, x/0 or sqrt(<0)."""
    code = H.c_sources(D.HosmdSpec(k, 1.0, 0.01))["hosmd_kernel.c"]
    body = code[code.index("static int casadi_f0"):].split("\n")
    last = {}
    literal = re.compile(r"^-?[0-9.]+(e[+-]?[0-9]+)?$")
    n_pow = n_div = 0
    for line in body:
        m = re.match(r"\s*(a\d+)=(.*);$", line)
        if not m:
            continue
        var, rhs = m.groups()
        if (p := re.fullmatch(r"pow\((a\d+),(a\d+)\)", rhs)):
            n_pow += 1
            assert literal.match(last[p.group(2)]) and 0 < float(last[p.group(2)]) < 1
        if (q := re.fullmatch(r"sqrt\((a\d+)\)", rhs)):
            assert last[q.group(1)].startswith(("casadi_fabs(", "sqrt("))
        if (d := re.fullmatch(r"\((a\d+)/(a\d+)\)", rhs)):
            n_div += 1
            fm = re.fullmatch(r"casadi_fmax\((a\d+),(a\d+)\)", last[d.group(2)])
            assert fm and literal.match(last[fm.group(2)]) and float(last[fm.group(2)]) > 0
        last[var] = rhs
    assert n_pow == (0 if k in (1, 3) else 1) and n_div == 1
    assert "sign" not in "\n".join(body)


# ---- exactness on polynomials ---------------------------------------------------------------------

def _deadbeat_noise_gain(spec):
    """l1 gain from a sample error to each estimate error of the dead-beat limit of the step."""
    K = D._constants(spec)
    k = spec.order
    ell = K.V @ np.array([math.comb(k + 1, j) for j in range(k + 1)], float)
    M = K.Phi - np.outer(ell, np.eye(k + 1)[0])
    gain, v = np.zeros(k + 1), ell
    for _ in range(k + 1):
        gain += np.abs(v)
        v = M @ v
    return gain


@pytest.mark.parametrize("k", ORDERS)
@pytest.mark.parametrize("L", [0.1, 10.0])
def test_polynomials_of_degree_up_to_k_are_differentiated_exactly(k, L):
    """Noise free, from z = (f0, 0, ..): after convergence the errors are the round-off of the samples
    (eps * max|f|) amplified by the dead-beat differentiator, nothing more (no chattering).

    That floor grows like N^i for the i-th derivative of a polynomial spanning N samples (double
    precision, not the method: any sample-local differentiator has it), so the window is kept short.
    """
    tau, n, settle = 0.01, 1600, 800
    s = D.HosmdSpec(k, L, tau)
    t = np.arange(n) * tau
    x = t - t[-1] / 2
    for deg in range(k + 1):
        rng = np.random.default_rng(100 * k + deg)
        P = np.polynomial.Polynomial(rng.uniform(-1, 1, deg + 1) / (t[-1] / 2) ** np.arange(deg + 1))
        f = P(x)
        truth = np.column_stack([P.deriv(i)(x) for i in range(k + 1)])
        err = np.abs(D.hosmd_run(s, f) - truth)
        bound = _deadbeat_noise_gain(s) * EPS * np.abs(f).max()
        assert np.all(err[settle:] <= 4 * bound), (deg, (err[settle:] / bound).max(axis=0))
        # in plain numbers: value, slope and curvature to 1e-7 of their natural scale max|f| / (T/2)^i
        scale = np.abs(f).max() / (t[-1] / 2) ** np.arange(k + 1)
        assert np.all(err[settle:, :3].max(axis=0) <= 1e-7 * scale[:3]), err[settle:].max(axis=0) / scale
        assert err[0].max() > 1e3 * err[settle:].max() or deg == 0    # it did have to converge


def test_levant_explicit_euler_would_chatter_on_the_same_polynomial():
    """Contrast (why the matching scheme): explicit Euler of the same differentiator on a parabola
    keeps an O(lt_0 L tau) jitter in z_k; the matching step is at round-off."""
    k, L, tau, n = 2, 1.0, 0.01, 3000
    s = D.HosmdSpec(k, L, tau)
    t = np.arange(n) * tau
    f = 0.5 * 0.01 * t ** 2
    z = s.initial_state(f[0])
    out = np.empty((n, k + 1))
    lt = s.gains
    for j in range(n):
        out[j] = z
        sig = z[0] - f[j]
        corr = [lt[k - i] * L ** ((i + 1) / (k + 1)) * abs(sig) ** ((k - i) / (k + 1)) * np.sign(sig)
                for i in range(k + 1)]
        z = z + tau * (np.append(z[1:], 0.0) - np.array(corr))
    euler_err = np.abs(out[1000:, 2] - 0.01).max()
    ours_err = np.abs(D.hosmd_run(s, f)[1000:, 2] - 0.01).max()
    assert euler_err > 0.1 * lt[0] * L * tau
    assert ours_err < 1e-6 * euler_err


# ---- noisy sines: accuracy asymptotics --------------------------------------------------------------

# eps windows (tau = 1e-3, f = sin t, L = 1) between the sampling-error floor and saturation
NOISE_WINDOWS = {1: (1e-3, 1e-1), 2: (1e-5, 1e-2), 3: (1e-6, 1e-3), 4: (1e-7, 1e-4), 5: (1e-8, 1e-5)}


@pytest.mark.parametrize("k", ORDERS)
def test_noise_error_exponents_match_levants_asymptotics(k):
    """max |z_i - f^(i)| ~ eps^((k+1-i)/(k+1)): fit the exponent over the eps window, per derivative."""
    tau = 1e-3
    s = D.HosmdSpec(k, 1.0, tau)
    n = int(8 * np.pi / tau)
    t = np.arange(n) * tau
    truth = np.column_stack([np.sin(t + i * np.pi / 2) for i in range(k + 1)])
    lo, hi = NOISE_WINDOWS[k]
    epss = np.geomspace(lo, hi, 4)
    log_err = np.zeros((epss.size, k + 1))
    for a, eps in enumerate(epss):
        for seed in range(2):
            f = truth[:, 0] + eps * np.random.default_rng(seed).uniform(-1, 1, n)
            err = np.abs(D.hosmd_run(s, f, truth[0]) - truth)[n // 4:].max(axis=0)
            log_err[a] += np.log(err) / 2
    for i in range(k + 1):
        slope = np.polyfit(np.log(epss), log_err[:, i], 1)[0]
        assert abs(slope - (k + 1 - i) / (k + 1)) <= 0.1, (i, slope)


# ---- C == Python ---------------------------------------------------------------------------------

def _signal(n, tau, seed):
    """Noisy sine with outliers, a constant stretch (sigma -> 0 exactly) and a jump."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * tau
    f = np.sin(2 * t) + 1e-3 * rng.uniform(-1, 1, n)
    f[rng.integers(0, n, 10)] += rng.standard_normal(10)
    f[n // 2: n // 2 + 300] = 0.25
    f[3 * n // 4:] += 3.0
    return f


@pytest.fixture(scope="module", params=["gcc", "clang"])
def cc(request):
    if shutil.which(request.param) is None:
        pytest.skip(f"{request.param} not installed")
    return request.param


@pytest.mark.parametrize("k", ORDERS)
def test_compiled_c_agrees_with_numpy_and_casadi(tmp_path, cc, k):
    s = D.HosmdSpec(k, 4.0 ** (k + 1), 0.005)
    exe = H.build_c_driver(s, tmp_path, cc=cc)
    f = _signal(2000, s.sample_time, seed=k)
    z0 = s.initial_state(f[0])
    zc = H.run_c_driver(exe, s, f, z0)
    assert zc.shape == (f.size, k + 1) and np.all(np.isfinite(zc))
    # every step on its own: C's z_{j+1} against numpy's step from C's z_j (relative 1e-12)
    ref = np.array([D.hosmd_step_numpy(s, zc[j], f[j]) for j in range(f.size - 1)])
    rel = np.max(np.abs(zc[1:] - ref), axis=1) / np.maximum(np.max(np.abs(ref), axis=1), 1e-300)
    assert rel.max() <= 1e-12
    # the whole run against the CasADi evaluation of the same graph
    za = D.hosmd_run(s, f, z0)
    rel = np.max(np.abs(zc - za), axis=1) / np.maximum(np.max(np.abs(za), axis=1), 1e-300)
    assert rel.max() <= 1e-10
    assert np.max(rel[:10]) <= 1e-12
    # wild samples: |sigma| from 1e-12 to 1e6 in every step.  Far out (q = tau*rho small) the step's
    # exp(x) - 1 carries a relative error ~2.2e-16/|x| that the reference's expm1 does not
    rng = np.random.default_rng(7 + k)
    wild = rng.choice([-1.0, 1.0], 3000) * 10.0 ** rng.uniform(-12, 6, 3000)
    zc = H.run_c_driver(exe, s, wild, np.zeros(k + 1))
    ref = np.array([D.hosmd_step_numpy(s, zc[j], wild[j]) for j in range(wild.size - 1)])
    rel = np.max(np.abs(zc[1:] - ref), axis=1) / np.maximum(np.max(np.abs(ref), axis=1), 1e-300)
    K = D._constants(s)
    q = K.c / np.maximum(np.abs(zc[:-1, 0] - wild[:-1]) ** (1 / (k + 1)), K.q_floor)
    slowest = -max(np.real(s._roots))
    assert np.all(np.isfinite(zc))
    assert np.all(rel <= 1e-12 + (k + 1) * 2.2e-16 / (q * slowest)), (rel / (1e-12 + 2.2e-16 / q)).max()
    assert np.all(rel[q * slowest > 1e-3] <= 1e-12)


def test_c_step_is_heap_free_and_strict_clean(tmp_path):
    s = D.HosmdSpec(3, 1.0, 0.01)
    H.build_c_driver(s, tmp_path)
    syms = subprocess.run(["nm", "-u", str(tmp_path / "hosmd_kernel.o")], capture_output=True, text=True).stdout
    assert not {"malloc", "calloc", "realloc", "free"} & set(syms.split())


def test_sx_step_embeds_in_a_larger_function():
    """Observers put the differentiator state inside their own state vector."""
    s = D.HosmdSpec(2, 1.0, 0.01)
    x = ca.SX.sym("x", 5)                    # [observer states (2), differentiator state (3)]
    y = ca.SX.sym("y")
    nxt = ca.vertcat(x[0] + x[2], x[1], D.hosmd_step_sx(s, x[2:5], y))
    F = ca.Function("obs", [x, y], [nxt])
    xv = np.array([1.0, 2.0, 0.3, -0.2, 0.1])
    out = np.array(F(xv, 0.7)).ravel()
    np.testing.assert_allclose(out[2:], D.hosmd_step_numpy(s, xv[2:], 0.7), rtol=1e-14)


@pytest.mark.parametrize("k", ORDERS)
def test_error_coordinates_are_the_same_step_with_the_first_entry_less_the_held_sample(k):
    """hosmd_step_sx/numpy with ``held``: first entry = estimate - held sample, the rest the Taylor
    state; run side by side with the Taylor form on a sampled signal, the estimates agree to the
    rounding of the Taylor form's z_0 (which is what error coordinates avoid), the reference step
    agrees with the SX step, and a wrong held sample (the one before) does not."""
    s = D.HosmdSpec(k, 4.0 ** (k + 1), 0.005)
    z = ca.SX.sym("z", k + 1)
    f, held = ca.SX.sym("f"), ca.SX.sym("held")
    step = ca.Function("e", [z, f, held], [D.hosmd_step_sx(s, z, f, held)])
    sig = 3.0 + _signal(800, s.sample_time, seed=10 + k)
    zt = s.initial_state(sig[0])
    ze, h = np.zeros(k + 1), sig[0]
    worst = np.zeros(k + 1)
    scale = s.sample_time ** -np.arange(k + 1)         # a unit change of f moves entry i by ~tau^-i
    for j in range(sig.size):
        nxt_e = np.array(step(ze, sig[j], h)).ravel()
        ref = D.hosmd_step_numpy(s, ze, sig[j], h)
        assert np.all(np.abs(nxt_e - ref) <= 1e-12 * (np.abs(ref) + scale)), (j, nxt_e, ref)
        zt = D.hosmd_step_numpy(s, zt, sig[j])
        ze, h = nxt_e, sig[j]
        est = ze.copy()
        est[0] += h
        worst = np.maximum(worst, np.abs(est - zt) / scale)
    # z_0's rounding in the Taylor form (|f| ~ 3: 4.4e-16 a step) amplified by the gains, ~tau^-i in entry i
    assert np.all(worst <= 1e-11), worst
    stale = D.hosmd_step_numpy(s, ze, sig[-1], sig[-2])
    assert abs(stale[0] - D.hosmd_step_numpy(s, ze, sig[-1], sig[-1])[0]) > 1e-6
