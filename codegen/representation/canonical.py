"""Machine-independent numbers for everything that is emitted.

Two machines compute the same double differently as soon as a BLAS kernel (matrix products,
solves, eigen- and singular-value decompositions) or a vectorized transcendental function is
involved: the kernel is chosen per CPU, and its summation order and use of FMA differ. The
numbers that reach the generated C are therefore

* rounded through the decimal string (:func:`decimal_round`: Python's correctly rounded
  float-to-string conversion, the same on every platform), never by scaling with ``10.0**k``
  (numpy's ``power`` is itself CPU-dispatched); and
* derived from committed numbers with the exact arithmetic of this module (:func:`matmul`,
  :func:`solve`, :func:`inv`, :func:`pinv`, :func:`eigh`, :func:`expm`): evaluated by mpmath at
  40 significant digits and rounded once to the nearest double. mpmath is pure Python, so the
  result is the correctly rounded value of the exact operation on any machine.

Elementwise IEEE arithmetic (+, -, *, /, sqrt) is reproducible as it is; numpy may be used for it.
"""
from __future__ import annotations

import mpmath
import numpy as np

DIGITS = 40          # working precision of the exact operations
_CTX = mpmath.MPContext()
_CTX.dps = DIGITS


def decimal_round(a, digits: int = 12):
    """``a`` rounded to ``digits`` significant digits through its decimal string (same shape).

    The result is the double nearest to the rounded decimal, identical on every machine.
    """
    arr = np.asarray(a, dtype=float)
    fmt = f".{digits - 1}e"
    out = np.array([float(format(float(x), fmt)) if np.isfinite(x) else float(x) for x in arr.ravel()],
                   dtype=float)
    return out.reshape(arr.shape) if arr.ndim else float(out[0])


def _mp(a):
    a = np.atleast_2d(np.asarray(a, dtype=float))
    return _CTX.matrix([[_CTX.mpf(float(x)) for x in row] for row in a])


def _np(m, shape=None) -> np.ndarray:
    out = np.array([[float(m[i, j]) for j in range(m.cols)] for i in range(m.rows)], dtype=float)
    return out.reshape(shape) if shape is not None else out


def matmul(*mats) -> np.ndarray:
    """Product of 2-D matrices, exact then rounded once (vectors are treated as columns)."""
    shapes = [np.shape(m) for m in mats]
    if any(0 in sh for sh in shapes):       # an empty factor: numpy's (exact) zeros of the right shape
        out = np.asarray(mats[0], float)
        for m in mats[1:]:
            out = out @ np.asarray(m, float)
        return np.zeros(out.shape)
    out = _mp(mats[0] if len(shapes[0]) == 2 else np.reshape(mats[0], (1, -1)))
    for m, sh in zip(mats[1:], shapes[1:]):
        out = out * _mp(m if len(sh) == 2 else np.reshape(m, (-1, 1)))
    res = _np(out)
    if len(shapes[-1]) == 1:
        res = res[:, 0]
    if len(shapes[0]) == 1:
        res = res[0]
    return res


def solve(A, B) -> np.ndarray:
    """A^-1 B (B a matrix or a vector), exact then rounded once."""
    vec = np.ndim(B) == 1
    Bm = np.reshape(B, (-1, 1)) if vec else B
    x = _np(_CTX.inverse(_mp(A)) * _mp(Bm))   # 40 digits: the inverse loses nothing that shows
    return x[:, 0] if vec else x


def inv(A) -> np.ndarray:
    return _np(_CTX.inverse(_mp(A)))


def pinv(A) -> np.ndarray:
    """Moore-Penrose pseudo-inverse of a matrix of full column or full row rank:
    (A'A)^-1 A' or A'(AA')^-1, exact then rounded once."""
    m = _mp(A)
    if m.rows >= m.cols:
        return _np(_CTX.inverse(m.T * m) * m.T)
    return _np(m.T * _CTX.inverse(m * m.T))


def eigh(A, B=None) -> tuple:
    """Eigenvalues (ascending) and eigenvectors of a symmetric A, or of the pencil (A, B) with B
    symmetric positive definite (V' B V = I). Eigenvectors are normalized with their largest
    entry positive, so the result is unique for simple eigenvalues."""
    a = _mp(0.5 * (np.asarray(A, float) + np.asarray(A, float).T))
    if B is None:
        lam, V = _CTX.eigsy(a)
    else:
        Lc = _CTX.cholesky(_mp(0.5 * (np.asarray(B, float) + np.asarray(B, float).T)))
        Li = _CTX.inverse(Lc)
        lam, W = _CTX.eigsy(Li * a * Li.T)
        V = Li.T * W
    n = len(lam)
    order = sorted(range(n), key=lambda k: lam[k])
    cols = []
    for k in order:
        col = [V[i, k] for i in range(n)]
        big = max(range(n), key=lambda i: abs(col[i]))
        sign = -1 if col[big] < 0 else 1
        cols.append([sign * c for c in col])
    lam_out = np.array([float(lam[k]) for k in order])
    V_out = np.array([[float(cols[k][i]) for k in range(n)] for i in range(n)])
    return lam_out, V_out


def expm(A) -> np.ndarray:
    """Matrix exponential, exact (mpmath's Taylor/Pade at 40 digits) then rounded once."""
    return _np(_CTX.expm(_mp(A)))


def polyroots(coeffs) -> list:
    """Roots (complex) of the polynomial with ``coeffs`` (highest power first), by mpmath's
    Durand-Kerner iteration at 40 digits, each rounded once; sorted by (real, imag)."""
    roots = _CTX.polyroots([_CTX.mpf(float(c)) for c in coeffs], maxsteps=400, extraprec=80)
    out = [complex(float(_CTX.re(r)), float(_CTX.im(r))) for r in roots]
    return sorted(out, key=lambda z: (z.real, z.imag))
