"""The ``algebraic_uio`` family (Ichalal and Mammar 2015) in the pipeline: build, discrete step (CasADi and numpy), C API.

:func:`build` runs model -> relative degrees and decoupling (:mod:`codegen.families.algebraic_uio.representation`) ->
classical-UIO check -> LMI (39) -> certificates (numpy re-check, dense check, Gauss-Legendre
B-stability, auxiliary system) and returns an :class:`AlgebraicUIOBuild`, which offers the interface
:mod:`codegen.emit` needs (``step_function`` etc.).

The step's state vector (names from :attr:`AlgebraicUIOBuild.state_names`)::

    [primed, HOSMD of each output (k_i + 1) and its held sample (1), HOSMD of each scheduling
     signal (k + 1) and its held sample (1), (known inputs only:) s of (20) (n), u of the previous
     sample (n_u), z_hat (n), x_hat (n), d_hat (n_d)]

The differentiators run in error coordinates (:func:`codegen.representation.differentiators.hosmd_step_sx`):
the first entry of each is its estimate of the signal less the sample it consumed last, which is
held beside it, so that in float32 the tracking error sigma is formed from small quantities
(the estimate itself is held + that entry).

The last n + n_d entries are the outputs: the estimates at the time of the sample just consumed
(x_hat(t_j), d_hat(t_j)). The first call after init (primed = 0) starts every differentiator at
(f_0, 0, ..., 0), keeps x_hat, and is flagged WARMING_UP.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import cached_property

import casadi as ca
import numpy as np
import sympy as sp
from scipy.linalg import expm

from ...certificate.artifact import artifact_head, significant, solver_certificate
from ...certificate.certificate import Certificate, Recheck, Step
from ...contract.family import ObserverBuild, StepNotes
from ...certificate.contraction import ContractionMetric
from . import representation as rdeg
from . import design as alg
from ...representation.differentiators import HosmdSpec, hosmd_step_numpy, hosmd_step_sx
from ...emit.stepgen import solve_unpivoted
from ...design.solver import FreshSolver
from ...errors import InfeasibleLMIError, ModelDefinitionError, UiogenError
from ...model import LPVModel, instantiate, load_parameters
from ...representation.substitution import offer
from ...representation.polytope import sector_weights_product


def _entry_functions(symbols, mat, xp):
    """One compiled callable per entry (numpy or CasADi), evaluated into a matrix of that kind."""
    mat = sp.Matrix(mat)
    fns = [[alg._lambdify(symbols, mat[i, j], xp) for j in range(mat.shape[1])] for i in range(mat.shape[0])]

    def evaluate(*vals):
        if xp is ca:
            return ca.blockcat([[ca.SX(f(*vals)) for f in row] for row in fns])
        return np.array([[float(f(*vals)) for f in row] for row in fns])
    return evaluate


@dataclass(frozen=True)
class AlgebraicUIOBuild(ObserverBuild):
    """A Ichalal and Mammar 2015 algebraic UIO: derivation, design, certificates, step (interface of the pipeline)."""

    config: object
    lpv: LPVModel
    dec: rdeg.Decoupling
    settings: alg.AlgebraicSettings
    classical: dict
    design: alg.AlgebraicDesign
    recheck: dict
    dense: dict
    discrete: dict
    aux: dict | None
    compare: dict | None
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    # -- signals ------------------------------------------------------------------------------------
    @property
    def base(self) -> tuple:
        return self.dec.base

    @property
    def nu(self) -> int:
        return self.lpv.nu

    @property
    def ny(self) -> int:
        return self.lpv.ny

    @property
    def input_names(self) -> list:
        d = self.lpv.definition
        return [str(s) for s in d.known_inputs] + [f"y_{n}" for n in d.output_names] + [str(s) for s in self.base]

    @property
    def output_names(self) -> list:
        d = self.lpv.definition
        return [str(s) for s in d.states] + [str(s) for s in d.unknown_inputs]

    def spec(self, signal: str) -> HosmdSpec:
        return self.settings.differentiators[signal]

    @cached_property
    def layout(self) -> list:
        """[(name, size, doc)] of the state vector, in order."""
        d = self.lpv.definition
        out = [("primed", 1, "1 once the differentiators are started, else 0")]
        for name in [f"y_{n}" for n in d.output_names] + [str(s) for s in self.base]:
            k = self.spec(name).order
            out.append((f"hosmd_{name}", k + 1, f"Levant differentiator of {name}: estimates of its derivatives 0..{k}, "
                                                f"the 0th less held_{name}"))
            out.append((f"held_{name}", 1, f"the last sample the differentiator of {name} consumed"))
        if self.nu:
            out.append(("aux", self.lpv.nx, "auxiliary system (20) s' = A s + B u"))
            out.append(("u_prev", self.nu, "known inputs of the previous sample"))
            if self.injection is not None:
                out.append(("y_prev", self.ny, "measured outputs of the previous sample"))
            out.append(("zhat", self.lpv.nx, "observer state for z = x - s (21)"))
        out.append(("xhat", self.lpv.nx, "state estimate"))
        out.append(("dhat", self.lpv.nd, "unknown-input estimate"))
        return out

    @cached_property
    def slices(self) -> dict:
        out, k = {}, 0
        for name, size, _ in self.layout:
            out[name] = slice(k, k + size)
            k += size
        return out

    @property
    def n_state(self) -> int:
        return sum(size for _, size, _ in self.layout)

    def contraction_metrics(self) -> list:
        """V = e' X e of (39) over z_hat, the Gauss-Legendre step's B-stability bound per step."""
        d = self.lpv.definition
        return [ContractionMetric(float(self.discrete["contraction_bound_per_step"]), (self.design.X,),
                                  tuple(f"zhat_{s}" if self.nu else str(s) for s in d.states),
                                  f"(39) He(X (F - L C)) <= -2 alpha X on every vertex, alpha = {self.settings.alpha:g} "
                                  f"1/s, 2-stage Gauss-Legendre step (B-stable)", knob="[design] alpha")]

    @property
    def state_names(self) -> list:
        d = self.lpv.definition
        names = []
        for name, size, _ in self.layout:
            if name == "primed":
                names.append("primed")
            elif name.startswith("hosmd_"):
                names += [f"{name}_d{m}" for m in range(size)]
            elif name.startswith("held_"):
                names.append(name)
            elif name == "aux":
                names += [f"aux_{s}" for s in d.states]
            elif name == "u_prev":
                names += [f"u_prev_{s}" for s in d.known_inputs]
            elif name == "y_prev":
                names += [f"y_prev_{o}" for o in d.output_names]
            elif name == "zhat":
                names += [f"zhat_{s}" for s in d.states]
        return names + self.output_names

    def signal_docs(self) -> tuple:
        """(state, inputs, outputs) field docs of the C API."""
        d = self.lpv.definition
        units = d.units
        state = []
        for (name, size, doc), sl in zip(self.layout, self.slices.values()):
            for k, field_name in enumerate(self.state_names[sl]):
                if name in ("xhat", "dhat"):
                    state.append({"name": field_name, "doc": f"estimate of {field_name} [{units.get(field_name, '-')}]"})
                elif name.startswith("hosmd_"):
                    state.append({"name": field_name, "doc": f"differentiator of {name[6:]}: derivative {k} at the next "
                                                             f"sample time (Taylor state)" if k else
                                                             f"differentiator of {name[6:]}: its value at the next sample "
                                                             f"time less held_{name[6:]} (error coordinates)"})
                else:
                    state.append({"name": field_name, "doc": doc + (f" (entry {k})" if size > 1 else "")})
        inputs = ([{"name": str(s), "doc": f"known input [{units.get(str(s), '-')}]"} for s in d.known_inputs]
                  + [{"name": f"y_{n}", "doc": f"measured {n} [{units.get(n, '-')}]"} for n in d.output_names]
                  + [{"name": str(s), "doc": f"scheduling signal [{units.get(str(s), '-')}]"} for s in self.base])
        outputs = [{"name": n, "doc": f"estimate of {n} at this sample [{units.get(n, '-')}]"} for n in self.output_names]
        return state, inputs, outputs

    def scheduling_boxes(self) -> list:
        rows = [(str(s), *self.dec.boxes[s], False) for s in self.base]
        rows += [(str(s), *self.dec.boxes[s], True) for s in self.dec.symbols if s not in self.base]
        return rows

    def input_boxes(self) -> dict:
        return {str(s): list(self.dec.boxes[s]) for s in self.base}

    @property
    def injection(self):
        """K_s of the output-injected auxiliary system, or None."""
        return None if self.aux is None or self.aux["K_s"] is None else np.array(self.aux["K_s"], dtype=float)

    # -- the step ------------------------------------------------------------------------------------
    @cached_property
    def sched_orders(self) -> dict:
        """Derivative orders the step evaluates per scheduling signal (>= 0)."""
        return dict(self.dec.derivative_orders)

    def step_function(self) -> ca.Function:
        return step_casadi(self, f"{self.name}_kernel")

    def increment_function(self):
        """The step with the Gauss increment of the certified state as a fourth output, and that
        state's names (:meth:`ObserverBuild.increment_function`)."""
        return step_casadi(self, f"{self.name}_kernel", increments=True), list(self.contraction_metrics()[0].states)

    def step_numpy(self, z, u, y, rho):
        return step_numpy(self, z, u, y, rho)

    def reference_step(self, z, u, y, rho):
        return step_numpy(self, z, u, y, rho)

    def lmi_problem(self):
        """A fresh LMI (39) problem of this design, in the design's state scaling (benchmark: our path vs
        CVXPY on the same blocks)."""
        return alg.build_problem(self.dec, self.settings, self.design.scaling, self.design.output_scaling)[0]

    def figures(self) -> dict:
        return design_summary(self)

    def step_notes(self) -> StepNotes:
        return StepNotes(
            notes=("Each call takes the sample at t_j and returns x_hat(t_j) and d_hat(t_j). Output and",
                   "parameter derivatives come from Levant differentiators whose states are in the state",
                   "struct (hosmd_*); the observer ODE is integrated over [t_{j-1}, t_j] with their",
                   "Taylor polynomials at the Gauss stages."),
            clamp=("A scheduling input outside its box, or a differentiator's estimate of a parameter derivative\n"
                   " * outside its bound (converging differentiator, or Assumption 1 violated): clamped for the\n"
                   " * step, which stays certified, but the decoupling uses the clamped value."),
            warmup=("the differentiators start at (sample, 0, ..., 0); the observer state is\n"
                    " * held and the unknown-input estimate of this sample is not meaningful."))

    @property
    def certificate(self) -> Certificate:
        d, dec, r = self.design, self.dec, self.recheck
        degrees = ", ".join(str(v) for v in dec.relative_degrees)
        aux = "" if self.aux is None else f"; the known inputs' auxiliary system ({self.aux['mode']}) certified as well"
        return Certificate(
            family="algebraic_uio",
            claim=(f"LMI (39) of Ichalal and Mammar 2015 (relative degree {degrees}, {d.form} form): the estimation "
                   f"error of the decoupled states decays at rate alpha = {self.settings.alpha:g} 1/s for every "
                   f"scheduling trajectory in the box whose derivatives stay within their bounds{aux}; the unknown "
                   f"inputs are reconstructed algebraically from the output derivatives"),
            plant_class=(f"the LPV model {self.lpv.definition.name} with the parameters of {self.config.parameters}, "
                         f"its decoupled error system A - Q M - L C on the polytope of {d.gain_polytope.n_vertices} "
                         f"gain vertices"),
            noise=("noise-free outputs; their derivatives from Levant differentiators, taken as converged (the "
                   "differentiators' error is not in the certificate)"),
            region={str(k): tuple(v) for k, v in dec.boxes.items()},
            region_note=("the scheduling signals and their derivatives within these bounds; SCHEDULING_CLAMPED flags an "
                         "input or a differentiator's estimate of a derivative outside"),
            recheck=Recheck(r["blocks"], r["worst_block"], r["worst_min_eig"], r["worst_relative_margin"]),
            step=Step(self.config.sample_time, "2-stage Gauss-Legendre on the observer ODE (B-stable)",
                      self.discrete["contraction_bound_per_step"]),
            extras=solver_certificate(d.solution, recheck=self.recheck, dense_check=self.dense,
                                      fixed_modes=d.fixed_modes, compare_gain=self.compare))

    def artifact(self) -> dict:
        return {
            # parameter-derivative estimates outside their bounds are flagged too
            **artifact_head(self, self.dec.symbols, flags_from_inputs_only=False),
            "decoupling": significant(self.dec.to_json()),
            "classical_uio_11": significant(self.classical),
            **significant(self.design.gains_json(), 12),
            "differentiators": {k: {"order": s.order, "lipschitz": s.lipschitz, "gains": list(s.gains)}
                                for k, s in self.settings.differentiators.items()},
            "discrete": significant(self.discrete),
            "auxiliary_system": significant(self.aux),
        }


# ---- shared pieces of the step -------------------------------------------------------------------------

def _taylor_coeffs(order: int, offset: float, m: int) -> list:
    """Coefficients c_l with f^(m)(t + offset) = sum_l c_l z_l for a Taylor state z at t."""
    return [0.0] * m + [offset ** (l - m) / math.factorial(l - m) for l in range(m, order + 1)]


def _stage_offsets(h: float) -> tuple:
    """Offsets from t_{j+1} (where the updated differentiators sit) of the two Gauss stages of
    [t_{j-1}, t_j] and of t_j itself."""
    return tuple((c - 2.0) * h for c in alg.GL_C), -h


class _Compiled:
    """The symbolic pieces compiled for one backend (numpy or CasADi)."""

    def __init__(self, b: AlgebraicUIOBuild, xp):
        syms = b.dec.symbols
        self.F0 = _entry_functions(syms, b.dec.F0, xp)
        self.Q = _entry_functions(syms, b.dec.Q, xp)
        self.Mcal = _entry_functions(syms, b.dec.Mcal, xp)
        self.Ginv = _entry_functions(syms, b.dec.Gamma_inv, xp)
        self.premises = [alg._lambdify(syms, p.expr, xp) for p in b.design.gain_polytope.premises]
        self.A = _entry_functions(b.base, b.dec.lpv.A, xp)     # A - K_s C with output injection
        self.B = _entry_functions(b.base, b.lpv.B, xp) if b.nu else None
        self.C = np.array(b.lpv.C.evalf(), dtype=float)


def _gl2(x, F, g, h, xp, unpivoted=False):
    return x + _gl2_increment(x, F, g, h, xp, unpivoted)


def _gl2_increment(x, F, g, h, xp, unpivoted=False):
    """h (b1 K1 + b2 K2) of the Gauss step x+ = x + h (b1 K1 + b2 K2): the increment at its own
    scale (the compensated float32 update adds it to x by TwoSum)."""
    n = x.shape[0]
    a = alg.GL_A
    if xp is ca:
        I = ca.DM.eye(n)
        big = ca.vertcat(ca.horzcat(I - h * a[0][0] * F[0], -h * a[0][1] * F[0]),
                         ca.horzcat(-h * a[1][0] * F[1], I - h * a[1][1] * F[1]))
        rhs = ca.vertcat(F[0] @ x + g[0], F[1] @ x + g[1])
        K = solve_unpivoted(big, rhs) if unpivoted else ca.solve(big, rhs)
    else:
        I = np.eye(n)
        big = np.block([[I - h * a[0][0] * F[0], -h * a[0][1] * F[0]], [-h * a[1][0] * F[1], I - h * a[1][1] * F[1]]])
        K = np.linalg.solve(big, np.concatenate([F[0] @ x + g[0], F[1] @ x + g[1]]))
    return h * (alg.GL_B[0] * K[:n] + alg.GL_B[1] * K[n:])


# ---- CasADi step (becomes the C) -----------------------------------------------------------------------

def step_casadi(b: AlgebraicUIOBuild, name: str, increments: bool = False) -> ca.Function:
    """(z, u, y, rho) -> (z_next, excess, warmup); see the module docstring for z. ``increments``:
    a fourth output ``dz``, the Gauss step's increment of the certified state (z_hat, or x_hat
    without known inputs) as the step forms it, h (b1 K1 + b2 K2), before it is added to the state
    (0 while the observer is held)."""
    dec, lpv, sl = b.dec, b.lpv, b.slices
    n, nd, ny, nu, nr = lpv.nx, lpv.nd, lpv.ny, lpv.nu, len(b.base)
    h = b.config.sample_time
    comp = _Compiled(b, ca)
    z = ca.SX.sym("z", b.n_state)
    u = ca.SX.sym("u", nu)
    y = ca.SX.sym("y", ny)
    rho = ca.SX.sym("rho", nr)
    primed = z[0]
    # primed is exactly 0 or 1 and everything finite (the C wrapper rejects non-finite inputs), so these
    # blends select exactly (an if_else would emit a double-as-bool test that -Wfloat-conversion rejects)
    pick = lambda a_, b_: primed * a_ + (1.0 - primed) * b_
    excess = ca.SX(0)

    def clamp(v, box):
        c = ca.fmin(ca.fmax(v, box[0]), box[1])
        return c, ca.fabs(v - c)

    zr = []
    for k, sym in enumerate(b.base):
        spec = b.spec(str(sym))
        # started at (rho, 0, ..., 0): error coordinates 0 from the held sample rho
        zr.append(hosmd_step_sx(spec, primed * z[sl[f"hosmd_{sym}"]], rho[k], pick(z[sl[f"held_{sym}"]], rho[k])))
        _, e = clamp(rho[k], dec.boxes[sym])
        excess += e
    stages, now = _stage_offsets(h)

    est_excess = ca.SX(0)

    def taylor(zn, spec, offset, m, held):
        """f^(m)(t + offset) of a differentiator in error coordinates: the held sample enters f itself
        only, added last to the small sum."""
        small = sum(c * zn[l] for l, c in enumerate(_taylor_coeffs(spec.order, offset, m)) if c != 0.0)
        return held + small if m == 0 else small

    def sched(offset):
        nonlocal est_excess
        vals = []
        for k, sym in enumerate(b.base):
            spec = b.spec(str(sym))
            for m in range(b.sched_orders[sym] + 1):
                v = taylor(zr[k], spec, offset, m, rho[k])
                c_, e = clamp(v, dec.boxes[rdeg.derivative_symbol(sym, m)])
                est_excess += e
                vals.append(c_)
        return vals

    stage_vals = [sched(o) for o in stages]
    vals_now = sched(now)
    C = ca.DM(comp.C)
    if nu:
        s = z[sl["aux"]]
        u_prev = pick(z[sl["u_prev"]], u)
        Ks = b.injection
        y_prev = pick(z[sl["y_prev"]], y) if Ks is not None else None
        F, g = [], []
        for c, vals in zip(alg.GL_C, stage_vals):
            base_vals = [vals[sum(b.sched_orders[bb] + 1 for bb in b.base[:k])] for k in range(nr)]
            F.append(comp.A(*base_vals))
            g.append(comp.B(*base_vals) @ (u_prev + c * (u - u_prev))
                     + (ca.DM(Ks) @ (y_prev + c * (y - y_prev)) if Ks is not None else 0))
        s_new = pick(_gl2(s, F, g, h, ca, b.aux["stage_system_diagonal_dominance"] > 0), s)
    else:
        s_new = ca.SX.zeros(n)
    y_t = y - C @ s_new
    zy, ynames = [], [f"y_{o}" for o in lpv.definition.output_names]
    for i, nm in enumerate(ynames):
        spec = b.spec(nm)
        zy.append(hosmd_step_sx(spec, primed * z[sl[f"hosmd_{nm}"]], y_t[i], pick(z[sl[f"held_{nm}"]], y_t[i])))
    r = dec.relative_degrees

    def outputs_at(offset):
        Y = ca.vertcat(*[taylor(zy[i], b.spec(ynames[i]), offset, r[i], y_t[i]) for i in range(ny)])
        yv = ca.vertcat(*[taylor(zy[i], b.spec(ynames[i]), offset, 0, y_t[i]) for i in range(ny)])
        return Y, yv

    def gain(vals):
        th = [p(*vals) for p in comp.premises]
        mu = sector_weights_product(th, b.design.gain_polytope.premises, xp=ca)
        return sum((w * ca.DM(L) for w, L in zip(mu[1:], b.design.L[1:])), mu[0] * ca.DM(b.design.L[0]))

    xs = z[sl["zhat"]] if nu else z[sl["xhat"]]
    F, g = [], []
    for vals, off in zip(stage_vals, stages):
        L = gain(vals)
        Y, yv = outputs_at(off)
        F.append(comp.F0(*vals) - L @ C)
        g.append(comp.Q(*vals) @ Y + L @ yv)
    dx = _gl2_increment(xs, F, g, h, ca, b.discrete["stage_system_diagonal_dominance"] > 0)
    x_new = pick(xs + dx, xs)
    Y_now, _ = outputs_at(now)
    d_hat = comp.Ginv(*vals_now) @ (Y_now - comp.Mcal(*vals_now) @ x_new)
    x_hat = x_new + s_new
    parts = [ca.SX(1.0)]
    for zn, held in [*zip(zy, ca.vertsplit(y_t)), *zip(zr, ca.vertsplit(rho))]:
        parts += [zn, held]
    if nu:
        parts += [s_new, u] + ([y] if b.injection is not None else []) + [x_new]
    z_next = ca.vertcat(*parts, x_hat, d_hat)
    # the inputs' own excess stays finite for any finite input; the estimates' may be NaN after an overflow
    # (that sample is a NUMERICAL_FAILURE), and fmax(NaN, 0) = 0 keeps it from masking the inputs' flag
    excess = excess + ca.fmax(est_excess, 0.0)
    if increments:
        return ca.Function(name, [z, u, y, rho], [z_next, excess, 1.0 - primed, primed * dx],
                           ["z", "u", "y", "rho"], ["z_next", "excess", "warmup", "dz"])
    return ca.Function(name, [z, u, y, rho], [z_next, excess, 1.0 - primed],
                       ["z", "u", "y", "rho"], ["z_next", "excess", "warmup"])


# ---- numpy reference step ------------------------------------------------------------------------------

def _shift_matrix(order: int, offset: float) -> np.ndarray:
    """expm of the integrator chain over ``offset``: Taylor state at t -> Taylor state at t + offset."""
    return expm(offset * np.eye(order + 1, k=1))


def step_numpy(b: AlgebraicUIOBuild, z, u, y, rho):
    """Independent numpy implementation of the same step: (z_next, excess, warmup).

    Differentiators by :func:`codegen.representation.differentiators.hosmd_step_numpy` (complex eigenvalues, expm),
    Taylor evaluation by expm of the integrator chain, linear solves by LAPACK.
    """
    comp = b.__dict__.get("_numpy_compiled")
    if comp is None:
        comp = _Compiled(b, np)
        object.__setattr__(b, "_numpy_compiled", comp)
    dec, lpv, sl = b.dec, b.lpv, b.slices
    z, u, y, rho = (np.asarray(a, float) for a in (z, u, y, rho))
    n, ny, nu = lpv.nx, lpv.ny, lpv.nu
    h = b.config.sample_time
    primed = z[0] > 0.5
    excess = 0.0
    zr = []
    for k, sym in enumerate(b.base):
        spec = b.spec(str(sym))
        zc, held = (z[sl[f"hosmd_{sym}"]], z[sl[f"held_{sym}"]][0]) if primed else (np.zeros(spec.n_state), rho[k])
        zr.append(hosmd_step_numpy(spec, zc, rho[k], held))
        lo, hi = dec.boxes[sym]
        excess += abs(rho[k] - min(max(rho[k], lo), hi))
    stages, now = _stage_offsets(h)

    def derivatives_at(zn, name, offset, held):
        """(f, f', ..., f^(k)) at t + offset of a differentiator in error coordinates: the value is
        the held sample plus the first entry."""
        w = _shift_matrix(b.spec(name).order, offset) @ zn
        w[0] += held
        return w

    def sched(offset):
        nonlocal excess
        vals = []
        for k, sym in enumerate(b.base):
            w = derivatives_at(zr[k], str(sym), offset, rho[k])
            for m in range(b.sched_orders[sym] + 1):
                lo, hi = dec.boxes[rdeg.derivative_symbol(sym, m)]
                c = min(max(w[m], lo), hi)
                excess += abs(w[m] - c)
                vals.append(c)
        return vals

    stage_vals = [sched(o) for o in stages]
    vals_now = sched(now)
    C = comp.C
    if nu:
        s = z[sl["aux"]]
        u_prev = z[sl["u_prev"]] if primed else u
        Ks = b.injection
        y_prev = (z[sl["y_prev"]] if primed else y) if Ks is not None else None
        F, g = [], []
        for c, vals in zip(alg.GL_C, stage_vals):
            base_vals = [vals[sum(b.sched_orders[bb] + 1 for bb in b.base[:k])] for k in range(len(b.base))]
            F.append(comp.A(*base_vals))
            g.append(comp.B(*base_vals) @ (u_prev + c * (u - u_prev))
                     + (Ks @ (y_prev + c * (y - y_prev)) if Ks is not None else 0.0))
        s_new = _gl2(s, F, g, h, np) if primed else s.copy()
    else:
        s_new = np.zeros(n)
    y_t = y - C @ s_new
    ynames = [f"y_{o}" for o in lpv.definition.output_names]
    zy = []
    for i, nm in enumerate(ynames):
        spec = b.spec(nm)
        zc, held = (z[sl[f"hosmd_{nm}"]], z[sl[f"held_{nm}"]][0]) if primed else (np.zeros(spec.n_state), y_t[i])
        zy.append(hosmd_step_numpy(spec, zc, y_t[i], held))
    r = dec.relative_degrees

    def outputs_at(offset):
        ws = [derivatives_at(zy[i], nm, offset, y_t[i]) for i, nm in enumerate(ynames)]
        return np.array([w[r[i]] for i, w in enumerate(ws)]), np.array([w[0] for w in ws])

    def gain(vals):
        th = np.array([p(*vals) for p in comp.premises], dtype=float)
        mu = sector_weights_product(th, b.design.gain_polytope.premises)
        return sum(w * L for w, L in zip(mu, b.design.L))

    xs = z[sl["zhat"]] if nu else z[sl["xhat"]]
    F, g = [], []
    for vals, off in zip(stage_vals, stages):
        L = gain(vals)
        Y, yv = outputs_at(off)
        F.append(comp.F0(*vals) - L @ C)
        g.append(comp.Q(*vals) @ Y + L @ yv)
    x_new = _gl2(xs, F, g, h, np) if primed else xs.copy()
    Y_now, _ = outputs_at(now)
    d_hat = comp.Ginv(*vals_now) @ (Y_now - comp.Mcal(*vals_now) @ x_new)
    parts = [[1.0]] + [p for zn, held in [*zip(zy, y_t), *zip(zr, rho)] for p in (zn, [held])] + ([s_new, u] + ([y] if b.injection is not None else []) + [x_new] if nu else [])
    return np.concatenate([*parts, x_new + s_new, d_hat]), float(excess), 0.0 if primed else 1.0


# ---- build -----------------------------------------------------------------------------------------------

def _check_differentiators(lpv: LPVModel, dec: rdeg.Decoupling, settings: alg.AlgebraicSettings, config):
    """Every differentiator the observer needs is declared, of a high enough order, and none is
    declared for another signal: all the mistakes in one error."""
    need = {f"y_{o}": r for o, r in zip(lpv.definition.output_names, dec.relative_degrees)}
    need.update({str(s): max(dec.derivative_orders[s], 1) for s in dec.base})
    problems = []
    for name, order in need.items():
        spec = settings.differentiators.get(name)
        if spec is None:
            problems.append(f"[design.differentiators.{name}] is missing (the observer needs derivatives of {name} up "
                            f"to order {order}: {name} = {{ order = {order}, lipschitz = ... }}, the bound of its "
                            f"derivative {order + 1})")
        elif spec.order < order:
            problems.append(f"[design.differentiators.{name}] order = {spec.order}, but the observer needs derivative "
                            f"{order} (relative degree / parameter derivatives)")
    extra = sorted(set(settings.differentiators) - set(need))
    if extra:
        problems.append(f"differentiators for signals the observer does not differentiate: "
                        f"{', '.join(f'[design.differentiators.{k}]' for k in extra)} (it needs {', '.join(need)})")
    if problems:
        raise ModelDefinitionError(f"{config.source}: {len(problems)} differentiator setting(s) to fix: "
                                   + "; ".join(problems))


def build(config, solver, lpv: LPVModel | None = None) -> AlgebraicUIOBuild:
    """Ichalal and Mammar 2015: model -> relative degree, M, Q, P, Gamma -> classical check -> LMI (39) -> certificates;
    the LMIs answered by ``solver`` (:mod:`codegen.design.solver`).

    ``lpv`` overrides the configuration's model and parameter file (tests build models in memory)."""
    settings = alg.settings_from_config(config)
    if solver.tol is not None:
        settings = replace(settings, tol=solver.tol)
    t0 = time.perf_counter()
    if lpv is None:
        lpv = instantiate(config.design_model(), load_parameters(config.parameter_path), unknown_input_hint=offer)
    if any(s.derived is not None for s in lpv.definition.scheduling):
        derived = [str(s.symbol) for s in lpv.definition.scheduling if s.derived is not None]
        raise ModelDefinitionError(f"{config.source}: derived scheduling signal(s) {', '.join(derived)}: the algebraic "
                                   f"UIO differentiates its scheduling signals as measured inputs (HOSMD of each); "
                                   f"make each an input of the step (SchedulingSignal without derived=). The "
                                   f"L-infinity UIO (family linf_uio) and the TS fuzzy UIO (ts_fuzzy_uio) take "
                                   f"scheduling derived from the outputs")
    rdeg.check_structure(lpv)          # before anything evaluates the model's matrices
    boxes = rdeg.derivative_boxes(lpv)
    aux = alg.aux_design(lpv, boxes, settings.auxiliary, settings.auxiliary_alpha, solver, settings.tol)
    lpv_obs = lpv
    if aux is not None and aux["K_s"] is not None:
        # z = x - s obeys z' = (A - K_s C) z + D d: the observer is derived for that system
        Ks = sp.Matrix(aux["K_s"]).applyfunc(lambda e: sp.nsimplify(e, rational=True))
        lpv_obs = replace(lpv, A=lpv.A - Ks * lpv.C)
    dec = rdeg.derive(lpv_obs)
    _check_differentiators(lpv, dec, settings, config)
    classical = alg.classical_uio(lpv, dec.boxes)
    t1 = time.perf_counter()
    try:
        design = alg.design(dec, settings, solver)
    except InfeasibleLMIError as exc:
        # the solver's verdict on LMI (39) (status set: not a fixed mode, refused before any solve): the
        # error names a lower alpha measured to design and certify, when one of a few does
        if exc.status is None or time.perf_counter() - t1 > RETRY_WITHIN_S:
            raise
        exc.args = (f"{config.source}: {exc}{_lower_alpha_that_works(dec, settings, config.sample_time)}",)
        raise exc from None
    t2 = time.perf_counter()
    cert = alg.certify(design)
    dense = alg.dense_check(dec, design)
    disc = alg.discrete_certificate(design, config.sample_time)
    if aux is not None:
        aux["stage_system_diagonal_dominance"] = 1.0 - config.sample_time * aux["gl_a"] * aux["abs_max_row_sum"]
    compare = None
    if settings.compare_gain is not None:
        L = np.array(settings.compare_gain, dtype=float).reshape(lpv.nx, lpv.ny)
        compare = {"L": L.tolist(), **alg.check_fixed_gain(design, L, np.array(lpv.C.evalf(), dtype=float))}
    t3 = time.perf_counter()
    timings = {"derivation_s": t1 - t0, "design_s": t2 - t1, "solve_s": design.solution.solve_time_s,
               "build_s": design.solution.build_time_s, "certificates_s": t3 - t2}
    return AlgebraicUIOBuild(config, lpv, dec, settings, classical, design, cert, dense, disc, aux, compare, timings)


#: a solve of LMI (39) found infeasible in less than this many seconds is tried again at lower alphas
#: (:func:`_lower_alpha_that_works`): a few designs of about its cost, so the error names a measured fix
RETRY_WITHIN_S = 30.0


def _lower_alpha_that_works(dec, settings, h: float) -> str:
    """After LMI (39) is infeasible at [design] alpha: the design again at alpha / 2, / 10, / 100 (each a
    measurement with its own solver; nothing is committed); the first that solves, re-checks and passes
    the Gauss step's certificate at sample time ``h`` is named, else the text says none does."""
    tried = []
    for factor in (2, 10, 100):
        alpha = float(f"{settings.alpha / factor:.3g}")
        tried.append(f"{alpha:g}")
        trial = replace(settings, alpha=alpha)
        try:
            alg.discrete_certificate(alg.design(dec, trial, FreshSolver()), h)
        except UiogenError:
            continue
        return (f"; measured: with [design] alpha = {alpha:g} the design is solved and certified (a lower alpha "
                f"certifies a slower decay)")
    return f"; measured: [design] alpha = {', '.join(tried)} do not solve either"


# ---- `uiogen design` report -------------------------------------------------------------------------------

def _show(m) -> str:
    m = sp.Matrix(m).applyfunc(lambda e: sp.N(sp.expand(e), 6))
    return str(m.tolist()) if m.shape[0] > 1 else str(m.row(0).tolist()[0])


def design_summary(b: AlgebraicUIOBuild) -> dict:
    d, dec = b.design, b.dec
    return {
        "relative_degrees": list(dec.relative_degrees),
        "uniformity": dec.certificates,
        "M": {f"y_{o}": [_show(m) for m in dec.M[i]] for i, o in enumerate(b.lpv.definition.output_names)},
        "Gamma": _show(dec.Gamma), "Q": _show(dec.Q), "P": _show(dec.P), "F0": _show(dec.F0),
        "classical_uio_11": {"exists": b.classical["exists"], "reason": b.classical["reason"]},
        "lmi_form": d.form, "gain_vertices": d.gain_polytope.n_vertices,
        "premises": [f"{p.expr} in [{p.lower:.6g}, {p.upper:.6g}]" for p in d.gain_polytope.premises]
        + ([f"(P) {p.expr} in [{p.lower:.6g}, {p.upper:.6g}]" for p in d.factor_polytope.premises]
           if d.factor_polytope is not None else []),
        "lmi_blocks": b.recheck["blocks"], "worst_block": b.recheck["worst_block"],
        "worst_min_eig": b.recheck["worst_min_eig"], "alpha": b.settings.alpha,
        "dense_check_max_eig": b.dense["max_eig"], "fixed_modes": d.fixed_modes,
        "gains": [l.ravel().tolist() for l in d.L],
        "compare_gain": b.compare, "discrete": b.discrete, "auxiliary": b.aux,
        "differentiators": {k: f"order {s.order}, L = {s.lipschitz:g}" for k, s in b.settings.differentiators.items()},
        "design_time_s": b.timings["derivation_s"] + b.timings["design_s"],
        "sample_time": b.config.sample_time,
    }
