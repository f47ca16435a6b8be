"""uiogen toolchain: model -> representation -> design -> certificate -> C -> extension.

Modules, in pipeline order:

* :mod:`codegen.model`      symbolic model definitions and parameter files
* :mod:`codegen.polytope`   sector-nonlinearity / Taylor-reduced polytopes, membership rate bounds
* :mod:`codegen.lmi`        LMI layer compiled to Clarabel, with the numpy re-check
* :mod:`codegen.designs`    LMI conditions of each observer family
* :mod:`codegen.discrete`   discrete-time step and its stability certificate
* :mod:`codegen.pipeline`   runs the stages for one observer configuration
* :mod:`codegen.emit`       C emission (CasADi kernel + Jinja2 API)
* :mod:`codegen.cli`        the ``uiogen`` command
"""
__version__ = "0.1.0"
