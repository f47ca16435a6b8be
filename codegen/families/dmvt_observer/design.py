"""The gains of the DMVT observer: one Lyapunov matrix over every corner of the Jacobian box, and the
gain that minimises the certified RMS bound of the error at the sensors' noise levels.

The step is x_hat+ = x_hat + Ts f(x_hat, w) + L (y - h(x_hat, w)). With y = h(x, w) + n and x+ = x + Ts
f(x, w), the DMVT (:mod:`.representation`) gives the error e = x - x_hat

    e+ = (I + Ts A - L H) e - L n,     (A, H) in the box of Jacobians over X x W

The design works in scaled coordinates, e = S e_s with S the half-widths of the state box and
n = Sigma n_s with Sigma the noise levels, so every number is of order one: A_s = S^-1 A S,
H_s = Sigma^-1 H S, L_s = S^-1 L Sigma. For a contraction c < 1 it solves

    minimise trace(W)  over P, Y = P L_s, W
    [[c^2 P, (P + Ts P A_s - Y H_s)'], [P + Ts P A_s - Y H_s, P]] >= 0   at every corner (A_s, H_s)
    [[W, Y'], [Y, P]] >= 0,   P >= I

The corner blocks are Phi' P Phi <= c^2 P (Schur), affine in the corners, so they hold on the whole
box: V(e) = e' P e contracts by c^2 per step wherever both states stay in X. With white noise n_s of
unit variance, independent of the past, E V+ <= c^2 E V + trace(L_s' P L_s) <= c^2 E V + trace(W), so in
steady state E V <= trace(W) / (1 - c^2), and each error entry e_j^2 <= (P^-1)_jj V: the RMS bound of
every state in its unit is S_j sqrt((P^-1)_jj trace(L_s' P L_s) / (1 - c^2)). The rate alpha (c = 1 -
alpha Ts) is chosen to minimise trace(W) / (1 - c^2), the bound the gains are designed for (a Kalman
gain minimises the error variance in the same way, for the linear part); the certificate restates the
bound from the emitted (rounded) gains, not from the solver's numbers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ...design import lmi
from ...design.precision import margin_field, precision_field, required_margin
from ...design.rates import committable_rates, round_down
from ...errors import CertificateError, SolverError
from ...representation.canonical import decimal_round, solve
from ...settings import Rule, setting

PROBLEM = "dmvt gains"
#: the rates the search tries: one significant digit, from RESOLUTION / Ts to 1 / Ts
DIGITS = 1
RESOLUTION = 1e-4


@dataclass(frozen=True)
class DMVTSettings:
    """``[design]`` of a DMVT observer."""

    noise: dict = setting(default_factory=dict, items=Rule(float, gt=0),
                          doc="{output: standard deviation of its sensor's white noise, in the output's unit}: the "
                              "levels the gains minimise the error bound at; one for every output")
    decay: float | None = setting(None, gt=0, doc="alpha [1/s]: the decay rate required, the contraction c = 1 - "
                                                 "alpha Ts per step; absent: the rate that minimises the RMS bound")
    max_corners: int = setting(4096, gt=0, doc="the most corners of the Jacobian box the design takes (2^entries that "
                                               "vary over the box)")
    margin: float = setting(1e-6, gt=0, doc="smallest eigenvalue imposed on every LMI block (the numpy re-check then "
                                            "holds with room)")
    tol: float = setting(1e-8, gt=0, doc="solver tolerance")
    bounds_rel_tol: float = setting(1e-3, gt=0, doc="tightness of the Jacobian bounds")
    bounds_max_boxes: int = setting(20000, gt=0, doc="box budget of each Jacobian bound (a bound short of its "
                                                     "tolerance is a sound enclosure, stated in the artifact)")
    precision: str = precision_field()
    float32_margin: float = margin_field()


@dataclass(frozen=True)
class Scaled:
    """The corners and scales of the design (scaled coordinates, see the module docstring)."""

    corners: tuple          # ((A_s, H_s), ...)
    S: np.ndarray           # state half-widths
    sigma: np.ndarray       # output noise levels
    sample_time: float

    @classmethod
    def of(cls, rep, sigma: np.ndarray, sample_time: float) -> "Scaled":
        S = np.array([(hi - lo) / 2.0 for lo, hi in rep.state_box], float)
        corners = tuple((A * S[None, :] / S[:, None], H * S[None, :] / sigma[:, None]) for A, H in rep.corners())
        return cls(corners, S, np.asarray(sigma, float), float(sample_time))

    @property
    def nx(self) -> int:
        return self.S.size

    @property
    def ny(self) -> int:
        return self.sigma.size


def problem(sc: Scaled, rate: float, design: bool = True, margin: float = 1e-6) -> lmi.LMIProblem:
    """The LMIs of the module docstring at the contraction c = 1 - rate Ts."""
    c = 1.0 - rate * sc.sample_time
    prob = lmi.LMIProblem(PROBLEM if design else f"{PROBLEM} at {rate:g} 1/s", design=design,
                          data={"decay": rate} if design else {})
    n, m = sc.nx, sc.ny
    P = prob.symmetric("P", n)
    Y = prob.matrix("Y", n, m)
    W = prob.symmetric("W", m)
    prob.require_psd("P >= I", P - np.eye(n), margin=margin)
    for k, (A, H) in enumerate(sc.corners):
        M = P + sc.sample_time * (P @ A) - Y @ H
        prob.require_psd(f"corner {k}: Phi' P Phi <= c^2 P", lmi.bmat([[c * c * P, M.T], [M, P]]), margin=margin,
                         hint="the decay rate is too fast for the corners of the Jacobian box: a smaller [design] "
                              "decay, or a narrower box")
    prob.require_psd("W >= Y' P^-1 Y (noise)", lmi.bmat([[W, Y.T], [Y, P]]), margin=margin)
    prob.minimize(lmi.trace(W))
    return prob


def rms_objective(objective: float, rate: float, sample_time: float) -> float:
    c = 1.0 - rate * sample_time
    return objective / (1.0 - c * c)


def search_rate(sc: Scaled, solver, tol: float, margin: float, floor: float = 0.0) -> float:
    """The rate of one significant digit in [max(floor, RESOLUTION / Ts), 1 / Ts) that minimises the RMS
    objective trace(W) / (1 - c^2), by a ternary search over the candidates (an infeasible rate counts as
    infinite; the search assumes one minimum, and the certificate holds for whichever rate it commits).

    Raises
    ------
    CertificateError
        no candidate rate is feasible.
    """
    top = round_down((1.0 - 1e-9) / sc.sample_time, DIGITS)
    low = max(floor, RESOLUTION / sc.sample_time)
    cands = [r for r in committable_rates(top, DIGITS, RESOLUTION) if r >= low * (1 - 1e-12)]
    cache = {}

    def J(i):
        if i not in cache:
            try:
                sol = solver.solve(problem(sc, cands[i], design=False, margin=margin), tol=tol)
                cache[i] = rms_objective(sol.objective, cands[i], sc.sample_time)
            except SolverError:
                cache[i] = np.inf
        return cache[i]

    lo, hi = 0, len(cands) - 1
    while hi - lo > 2:
        m1, m2 = lo + (hi - lo) // 3, hi - (hi - lo) // 3
        if J(m1) <= J(m2):
            hi = m2
        else:
            lo = m1
    best = min(range(lo, hi + 1), key=lambda i: (J(i), i))
    if not np.isfinite(J(best)):
        # every probed rate failed: the smallest tells whether any can hold
        if not np.isfinite(J(0)):
            raise CertificateError(
                f"no decay rate from {cands[0]:g} 1/s up is certifiable over the corners of the Jacobian box (one "
                f"Lyapunov matrix for every corner): the outputs do not make the state observable at some corner; "
                f"narrow [state_bounds] (the box where an output's slope can reach 0), or measure another signal")
        best = 0
    return cands[best]


@dataclass(frozen=True)
class Design:
    """The emitted gains and their certificate figures (from the rounded numbers)."""

    rate: float             # the decay rate the LMIs imposed [1/s]
    P: np.ndarray           # scaled Lyapunov matrix (rounded)
    L_s: np.ndarray         # scaled gain
    L: np.ndarray           # the emitted gain, physical units: x_hat+ = ... + L (y - h)
    contraction: float      # the largest c over the corners, from the rounded P and L
    slowest_corner: int
    rms: np.ndarray         # RMS bound of every state's error at the noise levels [state unit]
    peak: np.ndarray        # steady-state peak bound per unit of noise peak (each channel in units of its sigma)
    solution: object


def design(sc: Scaled, settings: DMVTSettings, solver) -> Design:
    """Solve (or replay) the gains, round them, and re-check the contraction at every corner with numpy.

    Raises
    ------
    CertificateError
        the rounded gains do not contract at some corner.
    """
    committed = solver.committed_data(PROBLEM)
    floor = required_margin(settings) / sc.sample_time
    if committed is not None:
        rate = float(committed["decay"])
    elif settings.decay is not None:
        rate = float(settings.decay)
    else:
        rate = search_rate(sc, solver, settings.tol, settings.margin, floor)
    if rate * sc.sample_time >= 1.0:
        raise CertificateError(f"[design] decay = {rate:g} 1/s asks for a contraction 1 - alpha Ts <= 0 at Ts = "
                               f"{sc.sample_time:g} s; the largest meaningful rate is below {1 / sc.sample_time:g} 1/s")
    sol = solver.solve(problem(sc, rate, margin=settings.margin), tol=settings.tol)
    P = decimal_round(0.5 * (sol["P"] + sol["P"].T))
    Y = decimal_round(np.atleast_2d(sol["Y"]).reshape(sc.nx, sc.ny))
    L_s = solve(P, Y)
    L = decimal_round(L_s * sc.S[:, None] / sc.sigma[None, :])
    L_s = L / sc.S[:, None] * sc.sigma[None, :]          # what the step emits, back in scaled units
    c, worst = contraction(sc, P, L_s)
    if not c < 1.0:
        raise CertificateError(f"the rounded gains do not contract at corner {worst} of the Jacobian box (c = {c:.8f} "
                               f"per step): re-solve with a tighter [design] tol")
    return Design(rate, P, L_s, L, c, worst, *noise_bounds(sc, P, L_s, c), sol)


def contraction(sc: Scaled, P: np.ndarray, L_s: np.ndarray) -> tuple:
    """(max over the corners of sqrt(lambda_max(Phi' P Phi, P)), its corner): numpy, independent of the solver."""
    worst, at = 0.0, 0
    for k, (A, H) in enumerate(sc.corners):
        Phi = np.eye(sc.nx) + sc.sample_time * A - L_s @ H
        lam = float(scipy.linalg.eigh(Phi.T @ P @ Phi, P, eigvals_only=True).max())
        if lam > worst:
            worst, at = lam, k
    return float(np.sqrt(worst)), at


def noise_bounds(sc: Scaled, P: np.ndarray, L_s: np.ndarray, c: float) -> tuple:
    """(RMS bound per state at the noise levels, steady peak bound per unit noise peak) in the states' units."""
    Pinv_diag = np.diag(np.linalg.inv(P))
    variance = float(np.trace(L_s.T @ P @ L_s)) / (1.0 - c * c)
    rms = sc.S * np.sqrt(Pinv_diag * variance)
    # sup over the unit box of |L_s n|_P: a convex function of n, so at a corner of the box
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * sc.ny)).reshape(sc.ny, -1)
    Ln = L_s @ corners
    sup = float(np.sqrt(np.max(np.einsum("ik,ij,jk->k", Ln, P, Ln))))
    peak = sc.S * np.sqrt(Pinv_diag) * sup / (1.0 - c)
    return rms, peak
