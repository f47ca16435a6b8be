"""uiogen toolchain: model -> representation -> design -> certificate -> C -> extension.

Subpackages, in pipeline order:

* :mod:`codegen.project`         the inputs: observer files, settings tables, log column maps
* :mod:`codegen.model`           1. symbolic model definitions and parameter files
* :mod:`codegen.representation`  2. representations the families share (polytope, bounds, HOSMD)
* :mod:`codegen.design`          3. LMI layer (Clarabel + numpy re-check), the solvers (fresh or
                                 the lock replayed), the design lock, machine-independent numbers,
                                 source hashing, sweeps
* :mod:`codegen.certificate`     4. one typed Certificate for every family, the check of external
                                 gains, and every line of text about a design
* :mod:`codegen.emit`            5. C emission (CasADi kernel + Jinja2 API) and the C toolchain
* :mod:`codegen.extension`       6. the compiled step as a Python extension (:mod:`python_bindings`)
* :mod:`codegen.families`        one folder per observer family (representation, design, build,
                                 validation), the required protocol, the optional capabilities
                                 and the registry the toolchain asks
* :mod:`codegen.pipeline`        runs the stages of an observer's family with a solver (fresh, or its lock replayed)
* :mod:`codegen.cli`             the ``uiogen`` command; :mod:`codegen.errors` its typed errors

Beside the pipeline: :mod:`codegen.validation` (scenarios, real logs, plants, the demo),
:mod:`codegen.campaign` (dispersed runs on Dask), :mod:`codegen.targets` (FMU, float32,
Cortex-M, MISRA) and :mod:`codegen.tools` (maintainer tools: bench, docs, spread, QEMU).
"""
__version__ = "0.1.0"
