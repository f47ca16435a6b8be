"""The runtime: a compiled observer step, loaded and run with numpy and the extension only.

>>> from python_bindings import load
>>> obs = load("lpv_linf_driver_torque")        # a built-in observer, or the path of an observer file
>>> state = obs.initial_state()
>>> out = np.empty(obs.n_output)
>>> status = obs.step(state, inputs, out)       # one sample, in place, C speed
>>> outputs, status, final = obs.run(inputs_2d)  # whole array, loop in C

``step`` is the C function itself (no Python wrapper on the hot path); it checks shapes,
dtypes, byte order and alignment and raises TypeError/ValueError on bad arrays. Nothing of the
toolchain (:mod:`codegen`: sympy, CasADi, Clarabel, SciPy, Jinja2) is imported. The extensions
are built by ``uiogen build`` (:mod:`codegen.extension.build`, C glue
``codegen/emit/templates/pymodule.c.j2``) into the observer's project's ``build/extensions/``
(:mod:`python_bindings.workspace`); errors are :mod:`python_bindings.errors`.
"""
from .errors import (ChangedSourceError, DamagedExtensionError, SampleError, SourceFileError, StaleExtensionError,
                     UiogenError, UnknownObserverError)
from .runtime import CompiledObserver, Recorder, load

__all__ = ["ChangedSourceError", "CompiledObserver", "DamagedExtensionError", "Recorder", "SampleError",
           "SourceFileError", "StaleExtensionError", "UiogenError", "UnknownObserverError", "load"]
