"""Thin Python API over the compiled observer steps.

>>> from python_bindings import load
>>> obs = load("lpv_linf_driver_torque")        # a built-in observer, or the path of an observer file
>>> state = obs.initial_state()
>>> out = np.empty(obs.n_output)
>>> status = obs.step(state, inputs, out)       # one sample, in place, C speed
>>> outputs, status, final = obs.run(inputs_2d)  # whole array, loop in C

``step`` is the C function itself (no Python wrapper on the hot path); it checks shapes,
dtypes, byte order and alignment and raises TypeError/ValueError on bad arrays. The extensions
are built by ``make build`` (:mod:`codegen.extension.build`, with its C glue template
``codegen/emit/templates/pymodule.c.j2``) into the observer's project's ``build/extensions/``
(:mod:`codegen.project.workspace`).
"""
from codegen.extension.build import CompiledObserver, load

__all__ = ["CompiledObserver", "load"]
