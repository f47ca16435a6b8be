"""LMI layer: Clarabel's cone convention, exact coefficient extraction, typed failures."""
import numpy as np
import pytest

from codegen.errors import CertificateError, InfeasibleLMIError, LMIShapeError, NonAffineLMIError
from codegen.design.lmi import BlockCheck, LMIProblem, bmat, check_blocks, svec, trace, uncertified, unsvec, worst_block


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


def _slack_problem():
    """A Lyapunov-type problem written with a redundant slack (it enters only through P + S), a
    block with a constant part (Schur-reducible) and a block that block implies."""
    A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    prob = LMIProblem("slack")
    S = prob.symmetric("S", 2)
    P = prob.symmetric("P", 2)
    Q = P + S
    t = prob.scalar("t")
    prob.require_psd("Q >= 0", Q, 1e-6)
    prob.require_psd("[[Q, I], [I, I]] >= 0", bmat([[Q, np.eye(2)], [np.eye(2), np.eye(2)]]), 1e-6)
    prob.require_nsd("A'Q + QA <= -I", A.T @ Q + Q @ A + np.eye(2), 1e-6)
    prob.require_psd("t >= trace Q", t - trace(Q), 1e-6)
    prob.minimize(t)
    return prob


def test_exact_reductions_keep_the_optimum_and_the_certificate():
    prob = _slack_problem()
    _, _, _, q, _, blocks = prob._compile()
    red = prob._reduce(q, blocks)
    labels = [con.label for con, _ in red.blocks]
    assert "Q >= 0" not in labels                       # implied by the reduced 4x4 block
    sizes = [round((np.sqrt(8 * (sl.stop - sl.start) + 1) - 1) / 2) for _, sl in red.blocks]
    assert sizes[labels.index("[[Q, I], [I, I]] >= 0")] == 2     # Schur complement of the constant I
    assert red.kept_variables.size == len(prob._names) - 3     # the slack S is fixed at 0
    full = _slack_problem().solve(tol=1e-9)
    reduced = _slack_problem().solve(tol=1e-9, reduce=True)
    assert reduced.objective == pytest.approx(full.objective, rel=1e-6)
    assert np.all(reduced["S"] == 0.0)
    np.testing.assert_allclose(reduced["P"], full["P"] + full["S"], atol=1e-6)
    assert [c.label for c in reduced.checks] == [c.label for c in full.checks]   # every original block
    assert all(c.min_eig >= 0 for c in reduced.checks)


def test_recheck_needs_a_margin_beyond_rounding():
    # a strict LMI (P > 0) holds only when the smallest eigenvalue is positive beyond what eigvalsh
    # cannot resolve (about n eps ||M||): an exactly singular block, or one positive by rounding only,
    # is not certified; a small but resolved margin is
    singular, rounding, resolved, negative = check_blocks({
        "zero": np.zeros((3, 3)),
        "rounding": np.diag([1e6, 1e-12]),
        "resolved": np.diag([1e6, 1e-6]),
        "negative": np.diag([1.0, -1e-3])})
    assert [c.certified for c in (singular, rounding, resolved, negative)] == [False, False, True, False]
    assert uncertified([resolved]) is None
    assert uncertified([resolved, rounding, negative]) is negative        # the least relative margin
    assert "must exceed the eigensolver's rounding" in rounding.failure()


def test_replay_of_a_singular_solution_fails_the_recheck():
    from codegen.design.lmi import SolveRecord
    A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    prob = LMIProblem("lyapunov")
    P = prob.symmetric("P", 2)
    prob.require_psd("P > 0", P)
    prob.require_nsd("A'P + PA < 0", A.T @ P + P @ A)
    prob.minimize(trace(P))
    rec = SolveRecord(prob.name, {"P": np.zeros((2, 2)).tolist()}, 0.0, 0, dict(prob.data))
    with pytest.raises(CertificateError, match="'P > 0' fails the numpy re-check: smallest eigenvalue 0"):
        prob.replay(rec)


def test_the_worst_block_is_named_alike_on_every_machine():
    """Mirror-image blocks have equal eigenvalues but for their last bits, which differ between CPUs: of the
    blocks within the eigensolver's rounding of the least margin, the first in order is named, whichever of
    them is smaller by a bit here (a lock written on one machine replays on another)."""
    eps = np.finfo(float).eps
    a, b = BlockCheck("(27a) l=1", 6, 1e-3, 2.0), BlockCheck("(27a) l=3", 6, 1e-3 * (1 - 4 * eps), 2.0)
    far = BlockCheck("(27b)", 6, 5e-3, 2.0)
    for by in ("relative_margin", "min_eig"):
        assert worst_block([far, a, b], by).label == "(27a) l=1"
        assert worst_block([far, b, a], by).label == "(27a) l=3"
    clearly = BlockCheck("(27c)", 6, 0.9e-3, 2.0)            # smaller beyond the rounding: named
    assert worst_block([a, b, clearly]).label == "(27c)"
