"""uiogen toolchain: model -> representation -> design -> certificate -> C -> extension.

Modules, in pipeline order:

* :mod:`codegen.model`        symbolic model definitions and parameter files
* :mod:`codegen.observers`    observer files (built-in or a user's, anywhere on disk)
* :mod:`codegen.families`     one folder per observer family (representation, design, build,
                              validation) and the registry the toolchain asks
* :mod:`codegen.polytope`, :mod:`codegen.bounds`, :mod:`codegen.differentiators`
                              representations and building blocks the families share
* :mod:`codegen.lmi`          LMI layer compiled to Clarabel, with the numpy re-check
* :mod:`codegen.design_lock`  the certified design, committed like a lock file
* :mod:`codegen.pipeline`     runs the stages of an observer's family (replaying its lock)
* :mod:`codegen.canonical`    machine-independent numbers for everything emitted
* :mod:`codegen.emit`         C emission (CasADi kernel + Jinja2 API), :mod:`codegen.toolchain`
* :mod:`codegen.extension`    the compiled step as a Python extension (:mod:`python_bindings`)
* :mod:`codegen.cli`          the ``uiogen`` command
"""
__version__ = "0.1.0"
