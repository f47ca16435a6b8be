"""LMI layer: Clarabel's cone convention, exact coefficient extraction, typed failures."""
import numpy as np
import pytest

from codegen.errors import CertificateError, InfeasibleLMIError, LMIShapeError, NonAffineLMIError
from codegen.lmi import LMIProblem, svec, trace, unsvec


def test_svec_roundtrip_and_order():
    rng = np.random.default_rng(0)
    m = rng.standard_normal((4, 4))
    m = m + m.T
    np.testing.assert_allclose(unsvec(svec(m), 4), m)
    # column-major upper triangle with sqrt(2) off-diagonals: <svec(A), svec(B)> = trace(A B)
    b = rng.standard_normal((4, 4))
    b = b + b.T
    assert svec(m) @ svec(b) == pytest.approx(np.trace(m @ b))
    assert svec(np.array([[1.0, 2.0], [2.0, 3.0]])).tolist() == pytest.approx([1.0, 2 * np.sqrt(2), 3.0])


def test_lyapunov_solution_matches_scipy():
    from scipy.linalg import solve_continuous_lyapunov
    A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    prob = LMIProblem("lyapunov")
    P = prob.symmetric("P", 2)
    prob.require_psd("P >= I", P - np.eye(2), 1e-6)
    prob.require_nsd("A'P + PA <= -I", A.T @ P + P @ A + np.eye(2), 0.0)
    prob.minimize(trace(P))
    sol = prob.solve()
    # minimal-trace P with A'P+PA <= -I, P >= I; the solution must satisfy both with numpy
    Pv = sol["P"]
    assert np.linalg.eigvalsh(Pv).min() >= 1.0 - 1e-9
    assert np.linalg.eigvalsh(A.T @ Pv + Pv @ A + np.eye(2)).max() <= 1e-7
    P_lyap = solve_continuous_lyapunov(A.T, -np.eye(2))
    assert np.trace(Pv) <= np.trace(np.maximum(P_lyap, 0) + np.eye(2)) + 1e-6
    assert all(c.min_eig >= 0 for c in sol.checks)


def test_infeasible_names_the_blocks():
    prob = LMIProblem("unstable")
    P = prob.symmetric("P", 2)
    A = np.array([[1.0, 0.0], [0.0, -1.0]])
    prob.require_psd("P >= I", P - np.eye(2), hint="Lyapunov matrix")
    prob.require_nsd("Lyapunov decrease", A.T @ P + P @ A, 1e-3, hint="A must be Hurwitz")
    with pytest.raises(InfeasibleLMIError, match="Lyapunov decrease.*A must be Hurwitz|A must be Hurwitz"):
        prob.solve()


def test_non_affine_and_asymmetric_refused():
    prob = LMIProblem("bad")
    P = prob.symmetric("P", 2)
    prob.require_psd("square", P @ P)
    with pytest.raises(NonAffineLMIError, match="square"):
        prob.solve()
    prob = LMIProblem("asym")
    L = prob.matrix("L", 2, 2)
    prob.require_psd("not symmetric", L)
    with pytest.raises(LMIShapeError, match="not symmetric"):
        prob.solve()
    with pytest.raises(LMIShapeError, match="not square"):
        LMIProblem("x").require_psd("rect", np.zeros((2, 3)))


def test_certificate_rejects_a_wrong_solution():
    prob = LMIProblem("cert")
    P = prob.symmetric("P", 2)
    prob.require_psd("P >= I", P - np.eye(2), 1e-6)
    _, _, _, _, _, blocks = prob._compile()
    with pytest.raises(CertificateError, match="P >= I"):
        LMIProblem.certify_values(np.array([0.5, 0.0, 2.0]), blocks, prob._evaluate)
