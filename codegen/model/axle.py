"""The axle contract of a single-track model with saturating tyres, as a typed class a model builds.

A model for the nonlinear-tyre observer (:mod:`codegen.families.nonlinear_tyre_observer`) lists its
axles in a module-level ``AXLES``, each an :class:`Axle`: how that axle's body-frame lateral force
depends on the unmeasured lateral speed. The class checks its fields when it is built, so a model
that gives a field of the wrong kind (a number where a parameter symbol is meant, a missing capacity
symbol) is one :class:`~codegen.errors.ModelDefinitionError` naming the axle and the field at the
model's import, not an error inside the design. ``model_defs/single_track_nonlinear_tyre.py`` builds
its two axles with it; a model of one's own does the same::

    from codegen.model import Axle
    AXLES = (Axle("front", law_f, sp.cos(delta), t_f, inverse_f, t_sl_f, F_peak_f, F_max_f, C_f, mu_f), ...)
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import sympy as sp

from ..errors import ModelDefinitionError
from .real import real_valued


@dataclass(frozen=True)
class Axle:
    """How one body-frame axle force Phi = law(t) projection depends on the unmeasured state.

    Parameters
    ----------
    name : str
        The axle's name in messages ("front", "rear").
    law : sympy.Expr
        The tyre law in the slip symbol ``t`` of ``inverse``, *without* its sliding clamp (equal to
        the model's on |t| <= t_sl), written in the capacity symbol ``peak_symbol``.
    projection : sympy.Expr
        The factor from the wheel to the body frame (``cos(delta)`` for a steered axle, 1 else).
    slip : sympy.Expr
        The slip t = tan(alpha) in the model's states and measured signals.
    inverse : sympy.Expr
        The lateral speed as a function of the slip symbol and the measured signals (so the slip's
        derivative along v_y becomes a function of t and delta).
    sliding : sympy.Expr
        The full-sliding slip t_sl, in ``peak_symbol``.
    peak_symbol : sympy.Symbol
        The capacity symbol ``law`` and ``sliding`` are written in.
    peak : sympy.Expr
        That capacity in the parameters and the measured inputs (mu F_z, less under a_x).
    stiffness, friction : sympy.Symbol
        The parameters whose declared ranges the certificate covers (``[design] stiffness_range``,
        ``friction_range``).

    Raises
    ------
    ModelDefinitionError
        a field of the wrong kind, naming the axle and the field.
    """

    name: str
    law: sp.Expr
    projection: sp.Expr
    slip: sp.Expr
    inverse: sp.Expr
    sliding: sp.Expr
    peak_symbol: sp.Symbol
    peak: sp.Expr
    stiffness: sp.Symbol
    friction: sp.Symbol

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ModelDefinitionError(f"Axle(name={self.name!r}): the name is a non-empty string "
                                       f"(\"front\", \"rear\")")
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            symbol = f.name in ("peak_symbol", "stiffness", "friction")
            try:
                expr = sp.sympify(value, strict=True)
            except (sp.SympifyError, TypeError):
                expr = None
            if symbol and not isinstance(expr, sp.Symbol):
                raise ModelDefinitionError(f"Axle {self.name!r}: {f.name} = {value!r} must be a sympy Symbol (a "
                                           f"{'capacity symbol' if f.name == 'peak_symbol' else 'parameter'} of "
                                           f"the model), got {type(value).__name__}")
            if expr is None:
                raise ModelDefinitionError(f"Axle {self.name!r}: {f.name} = {value!r} must be a sympy expression, got "
                                           f"{type(value).__name__}")
            object.__setattr__(self, f.name, real_valued(expr))
        if self.peak_symbol not in sp.sympify(self.law).free_symbols:
            raise ModelDefinitionError(f"Axle {self.name!r}: the law does not use its peak_symbol {self.peak_symbol} "
                                       f"(the law is written in the capacity symbol; peak gives its value)")
