"""``uiogen export NAME --format c --out DIR``: the C package of a generated observer.

What ``uiogen generate`` wrote into ``generated_c/NAME/`` (``NAME.h``, ``NAME.c``, the CasADi
kernel, ``NAME_example.c``, the example main that runs the step on a CSV log, ``CMakeLists.txt``
building both with the strict flags, the design lock ``NAME_design.json`` and ``INPUTS.sha256``),
copied byte for byte into ``DIR`` once checked current (:func:`codegen.targets.base.generated_c`):
``cmake -S DIR -B build && cmake --build build`` builds it (docs/embedding.md).
"""
from __future__ import annotations

from pathlib import Path

from ..base import Target, generated_c, write_folder


class CPackage(Target):
    name = "c"
    title = "the C package: NAME.h/.c, its kernel, CMakeLists.txt and the example main"
    out = "DIR"

    def export(self, config, out, log=print) -> Path:
        _, files = generated_c(config)
        out = write_folder(out, files)
        log(f"{config.name}: wrote {out} (the C package: {len(files)} files, CMakeLists.txt and "
            f"{config.name}_example.c; cmake -S {out} -B build builds it)")
        return out


TARGET = CPackage()
