"""Scheduling signals derived from the outputs, written in the states.

A ``SchedulingSignal(..., derived=EXPR)`` is a function of the measured outputs (symbols ``y_NAME``). Where
a family evaluates the model at an estimated state (the TS fuzzy UIO's measured premises, the DMVT
observer's f and h), the signal is the same function of the outputs' expressions in the states: replaced
by it, it is part of the model's equations, and whatever the family bounds or evaluates covers it.
"""
from __future__ import annotations

import dataclasses

import sympy as sp

from ..model import ModelDefinition


def derived_in_states(model: ModelDefinition) -> ModelDefinition:
    """``model`` with every scheduling signal derived from the outputs replaced, in its dynamics and
    outputs, by its expression in the states (``y_NAME`` is output NAME's expression); the scheduling
    signals that are inputs of their own are kept."""
    derived = [g for g in model.scheduling if g.derived is not None]
    if not derived:
        return model
    outputs = {sp.Symbol(f"y_{n}"): sp.sympify(e) for n, e in model.outputs}
    on_states = {g.symbol: sp.sympify(g.derived).subs(outputs) for g in derived}
    return dataclasses.replace(model, dynamics=sp.Matrix(model.dynamics).subs(on_states),
                               outputs=tuple((n, sp.sympify(e).subs(on_states)) for n, e in model.outputs),
                               scheduling=tuple(g for g in model.scheduling if g.derived is None))
