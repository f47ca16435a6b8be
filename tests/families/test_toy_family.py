"""A new family is one folder and one line: a toy family defined and registered here, in the
test itself, goes through design -> certificate -> C -> extension without touching any other file.
It implements the required protocol only (codegen.contract.family): build(config, solver) and an
ObserverBuild with its signals, step, reference step, certificate and artifact; no optional
capability (codegen.contract.capabilities), and uiogen refuses what needs one, by name.

The toy is a Luenberger observer of an LTI model (x' = A x + B u, y = C x) with a decay-rate
LMI: find P > 0, Y with He(P A - Y C) + 2 alpha P < 0, gain L = P^-1 Y; the step is backward
Euler. Its model, parameters and observer file live in a temporary folder (a user's project).
"""
import dataclasses
import json
import textwrap

import casadi as ca
import numpy as np
import pytest

from codegen import cli, families, pipeline
from codegen.design import lock as design_lock, lmi
from codegen import workflow
from codegen.project import observer_file as observers
from codegen.certificate.artifact import artifact_head, significant, solver_certificate
from codegen.certificate.certificate import Certificate, Recheck, Step
from codegen.representation.canonical import decimal_round, matmul, solve
from codegen.errors import CertificateError, UnsupportedError
from codegen.families import Family, ObserverBuild
from codegen.model import instantiate, load_parameters
from codegen.settings import parse_settings, setting


@dataclasses.dataclass(frozen=True)
class ToySettings:
    alpha: float = setting(2.0, gt=0, doc="decay rate, 1/s")
    tol: float = setting(1e-8, gt=0, doc="solver tolerance")


def _problem(A, C, alpha):
    prob = lmi.LMIProblem("toy decay-rate LMI")
    n, m = A.shape[0], C.shape[0]
    P = prob.symmetric("P", n)
    Y = prob.matrix("Y", n, m)
    prob.require_psd("P >= I", P, margin=1.0)
    blk = P @ A - Y @ C
    prob.require_nsd("He(P A - Y C) + 2 alpha P < 0", blk + blk.T + 2 * alpha * P, margin=1e-6)
    prob.minimize(lmi.trace(P))
    return prob


@dataclasses.dataclass(frozen=True)
class ToyBuild(ObserverBuild):
    config: object
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    P: np.ndarray
    L: np.ndarray
    settings: ToySettings
    slowest_pole: float
    contraction: float
    solution: object
    names: tuple
    timings: dict

    state_names = property(lambda self: list(self.names[0]))
    output_names = property(lambda self: list(self.names[0]))
    input_names = property(lambda self: list(self.names[1]) + [f"y_{n}" for n in self.names[2]])
    nu = property(lambda self: self.B.shape[1])
    ny = property(lambda self: self.C.shape[0])

    def _matrices(self):
        Ts = self.config.sample_time
        G = np.eye(self.A.shape[0]) - Ts * (self.A - matmul(self.L, self.C))
        return solve(G, np.eye(G.shape[0])), Ts

    def step_function(self):
        Gi, Ts = self._matrices()
        z, u, y = ca.SX.sym("z", self.A.shape[0]), ca.SX.sym("u", self.nu), ca.SX.sym("y", self.ny)
        rho = ca.SX.sym("rho", 0)
        z_next = ca.DM(Gi) @ (z + ca.DM(Ts * self.B) @ u + ca.DM(Ts * self.L) @ y)
        return ca.Function(f"{self.name}_kernel", [z, u, y, rho], [z_next, 0.0],
                           ["z", "u", "y", "rho"], ["z_next", "excess"])

    def reference_step(self, z, u, y, rho):
        Ts = self.config.sample_time
        G = np.eye(self.A.shape[0]) - Ts * (self.A - self.L @ self.C)
        return np.linalg.solve(G, z + Ts * (self.B @ u + self.L @ y)), 0.0

    def input_boxes(self):
        return {}

    def scheduling_boxes(self):
        return []

    @property
    def certificate(self):
        return Certificate(
            family="toy_luenberger",
            claim=f"He(P (A - L C)) + 2 alpha P < 0: the estimation error decays at alpha = {self.settings.alpha:g} 1/s",
            plant_class="the LTI model of the observer file", noise="noise-free measurements, no unknown input",
            region={}, region_note="", recheck=Recheck.of(self.solution.checks),
            step=Step(self.config.sample_time, "backward Euler", self.contraction),
            extras=solver_certificate(self.solution, slowest_pole=self.slowest_pole))

    def artifact(self):
        return {**artifact_head(self, []), "P": self.P.tolist(), "L": self.L.tolist()}


class ToyLuenberger(Family):
    name = "toy_luenberger"
    title = "toy Luenberger observer"
    citation = "a test of the family protocol"
    short_citation = "toy"

    def build(self, config, solver):
        settings = parse_settings(ToySettings, config.design, source=config.source, section="design",
                                  **({"tol": solver.tol} if solver.tol is not None else {}))
        lpv = instantiate(config.load_model(), load_parameters(config.parameter_path))
        A, B, C = (np.array(m.evalf(), dtype=float) for m in (lpv.A, lpv.B, lpv.C))
        sol = solver.solve(_problem(A, C, settings.alpha), tol=settings.tol)
        P = decimal_round(0.5 * (sol["P"] + sol["P"].T))
        Y = decimal_round(np.atleast_2d(sol["Y"]).reshape(A.shape[0], C.shape[0]))
        L = solve(P, Y)
        Acl = A - L @ C
        worst = float(np.linalg.eigvals(Acl).real.max())
        if worst >= -settings.alpha + 1e-9:
            raise CertificateError(f"closed loop decays at {-worst:.4g} < alpha")
        # backward Euler: e+ = G^-1 e with G = I - Ts Acl; in the P norm |G^-1|_P <= 1/sqrt(1 + 2 alpha Ts)
        Ts = config.sample_time
        Gi = np.linalg.inv(np.eye(A.shape[0]) - Ts * Acl)
        Lc = np.linalg.cholesky(P)
        ratio = float(np.linalg.eigvalsh(np.linalg.solve(Lc, Gi.T @ P @ Gi) @ np.linalg.inv(Lc).T).max())
        if ratio >= 1.0:
            raise CertificateError(f"the backward-Euler step does not contract in the P norm ({ratio:.6f})")
        d = lpv.definition
        names = ([str(s) for s in d.states], [str(s) for s in d.known_inputs], list(d.output_names))
        return ToyBuild(config, A, B, C, P, L, settings, significant(worst), float(np.sqrt(ratio)), sol, tuple(names),
                        {"total_s": sol.solve_time_s})


MODEL = '''
import sympy as sp
from codegen.model import ModelDefinition

x, v, F = sp.symbols("x v F")
k, c, m = sp.symbols("k c m", positive=True)
MODEL = ModelDefinition(
    name="mass_spring_damper", states=(x, v), known_inputs=(F,), unknown_inputs=(),
    dynamics=sp.Matrix([v, (F - k * x - c * v) / m]), outputs=(("x", x),), scheduling=(),
    parameters=(k, c, m), units={"x": "m", "v": "m/s", "F": "N"})
'''


@pytest.fixture
def toy(tmp_path):
    family = families.register(ToyLuenberger())
    (tmp_path / "msd.py").write_text(MODEL)
    (tmp_path / "msd.toml").write_text("[parameters]\nk = 4.0\nc = 0.4\nm = 1.0\n")
    (tmp_path / "toy_msd.toml").write_text(textwrap.dedent('''\
        # A toy observer of a mass-spring-damper, from its position.
        family = "toy_luenberger"
        model = "msd.py"
        parameters = "msd.toml"
        sample_time = 0.01

        [design]
        alpha = 2.0
        '''))
    yield tmp_path / "toy_msd.toml", family
    families.unregister(family.name)


@pytest.mark.slow          # builds
def test_a_family_registered_from_outside_goes_to_a_compiled_step(toy, capsys):
    path, family = toy
    assert family.capabilities() == ()
    config = observers.get(str(path))
    assert config.family == "toy_luenberger" and not config.builtin
    assert cli.main(["design", str(path), "--update"]) == 0
    out = capsys.readouterr().out
    assert "toy Luenberger observer" in out and "certified: He(P (A - L C))" in out
    lock = design_lock.path(config)
    assert lock.is_file() and lock.parent == path.parent / "generated_c" / "toy_msd"
    workflow.generate([str(path)], log=lambda *_: None)
    assert cli.main(["build", str(path)]) == 0
    from python_bindings import load
    obs = load(str(path))
    assert obs.input_names == ("F", "y_x")
    # the compiled step against the numpy reference, on a simulated run
    b = pipeline.build(config)
    rng = np.random.default_rng(0)
    inputs = np.column_stack([rng.standard_normal(300), np.sin(np.linspace(0, 6, 300))])
    out, status, _ = obs.run(inputs)
    z = np.zeros(2)
    for k, row in enumerate(inputs):
        z, _ = b.reference_step(z, row[:1], row[1:], np.zeros(0))
        np.testing.assert_allclose(out[k], z, rtol=1e-12, atol=1e-12)
    assert not status.any()
    # the committed design replays without a solver, and its banner names the family
    header = (lock.parent / "toy_msd.h").read_text()
    assert "toy Luenberger observer: a test of the family protocol" in header
    data = json.loads(lock.read_text())
    assert data["lock"]["lmi_solutions"][0]["problem"] == "toy decay-rate LMI"
    assert Certificate.from_json(data["certificate"]) == b.certificate and b.certificate.step.contraction < 1
    # what needs a capability the family does not have is refused by name
    with pytest.raises(UnsupportedError, match="toy_luenberger.*no simulated validation scenarios"):
        from codegen.validation import run as validate
        validate.run_scenario(config, "track_varying_speed")
    assert cli.main(["fit", str(path), "--data", "stanford", "--samples", "0:10"]) == 2
    assert "'toy_luenberger' has no identification (uiogen fit)" in capsys.readouterr().err


def test_the_registry_refuses_what_is_not_a_family():
    with pytest.raises(TypeError):
        families.register(object())
    with pytest.raises(ValueError, match="registered already"):
        families.register(ToyLuenberger.__new__(type("Other", (ToyLuenberger,), {"name": "linf_uio"})))
