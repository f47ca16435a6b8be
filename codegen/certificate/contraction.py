"""A certified contraction of an observer's step in a Lyapunov norm, over part of its state.

A family's build offers, through :meth:`ObserverBuild.contraction_metrics`, the norms in which
its certificate proves the step contracting: for two runs of the step on the same inputs, the
difference ``e`` of the covered state entries obeys ``|e+|_P <= c |e|_P`` (``|v|_P = sqrt(v' P v)``),
the other entries acting as inputs. :mod:`codegen.targets.float32` bounds the single-precision
step's deviation from the double step with it.

A parameter-dependent Lyapunov matrix ``P(h) = sum_i h_i P_i`` (memberships ``h`` in the simplex)
is given by its vertices; every figure drawn from it is then the worst vertex's, which bounds
every ``h``: ``v' P(h) v <= max_i v' P_i v``, the generalized eigenvalues of ``(A, P(h))`` are at
most the largest of ``(A, P_i)``, and ``(P(h)^-1)_jj <= max_i (P_i^-1)_jj`` (the matrix inverse is
convex).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ContractionMetric:
    """``|e+|_P <= contraction |e|_P`` for the step-state entries ``states``.

    Attributes
    ----------
    contraction : float
        The certified factor ``c < 1`` per step.
    P : tuple of ndarray
        The Lyapunov matrix over ``states`` (in their units and order), or the vertices of a
        parameter-dependent one.
    states : tuple of str
        The step-state entries the norm covers (names of :attr:`ObserverBuild.state_names`).
    source : str
        Which certificate proves it, with its conditions (for reports).
    knob : str
        The design setting that would make it contract faster (for refusals).
    """

    contraction: float
    P: tuple
    states: tuple
    source: str
    knob: str = ""
    _factors: dict = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        mats = tuple(np.array(p, dtype=float) for p in self.P)
        n = len(self.states)
        if not mats or any(p.shape != (n, n) for p in mats):
            raise ValueError(f"P must be {n} x {n} matrices over {list(self.states)}")
        if not 0.0 <= self.contraction < 1.0:
            raise ValueError(f"the certified contraction must be in [0, 1), got {self.contraction}")
        roots, inv_roots = [], []
        for p in mats:
            w, v = np.linalg.eigh(0.5 * (p + p.T))
            if w.min() <= 0:
                raise ValueError("P is not positive definite")
            roots.append((v * np.sqrt(w)) @ v.T)
            inv_roots.append((v / np.sqrt(w)) @ v.T)
        object.__setattr__(self, "P", mats)
        object.__setattr__(self, "_factors", {"root": roots, "inv_root": inv_roots})

    @property
    def margin(self) -> float:
        return 1.0 - self.contraction

    def norm(self, v: np.ndarray) -> np.ndarray:
        """``max_i |v|_{P_i}`` of each column of ``v`` (m x n_samples), or of a vector."""
        v = np.asarray(v, dtype=float)
        return np.max([np.linalg.norm(r @ v, axis=0) for r in self._factors["root"]], axis=0)

    def extraction(self) -> np.ndarray:
        """``max_i sqrt((P_i^-1)_jj)`` per covered entry: ``|e_j| <= extraction_j |e|_P``."""
        return np.max([np.sqrt(np.diag(np.linalg.inv(p))) for p in self.P], axis=0)

    def row_gain(self, rows: np.ndarray) -> np.ndarray:
        """``max_i |r P_i^(-1/2)|`` of each row ``r`` (..., m): ``|r e| <= row_gain |e|_P``."""
        rows = np.asarray(rows, dtype=float)
        return np.max([np.linalg.norm(rows @ ir, axis=-1) for ir in self._factors["inv_root"]], axis=0)

    def gain_from(self, other: "ContractionMetric", J: np.ndarray) -> np.ndarray:
        """``max_ij |P_i^(1/2) J Q_j^(-1/2)|_2`` for (..., m, m_other) blocks ``J``: ``|J e'|_P <= gain |e'|_Q``."""
        J = np.asarray(J, dtype=float)
        best = None
        for r in self._factors["root"]:
            for ir in other._factors["inv_root"]:
                g = np.linalg.norm(r @ J @ ir, ord=2, axis=(-2, -1))
                best = g if best is None else np.maximum(best, g)
        return best

    def self_gain(self, J: np.ndarray) -> np.ndarray:
        """``|P^(1/2) J P^(-1/2)|_2`` of the step's own Jacobian blocks (common P only: for a
        parameter-dependent P the norm at one sample needs the memberships; None)."""
        if len(self.P) != 1:
            return None
        return self.gain_from(self, J)
