"""Compile every observer in ``generated_c/`` into a CPython extension.

The observer C is compiled with the strict flags of the project
(``-std=c99 -Wall -Wextra -Werror -pedantic``, no fast-math, ``-ffp-contract=off``
so results do not depend on FMA availability) plus the speed flags below. The Python
glue is rendered from ``templates/pymodule.c.j2`` into ``python_bindings/_build/`` and
linked with it.
"""
from __future__ import annotations

import os
import shlex
import subprocess
import sys
import sysconfig
from pathlib import Path

import jinja2

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
GENERATED_DIR = ROOT / "generated_c"
EXT_DIR = HERE / "_ext"
BUILD_DIR = HERE / "_build"

from codegen.emit import STRICT_CFLAGS
from codegen.errors import ToolchainError

STRICT_FLAGS = list(STRICT_CFLAGS)
# Python.h is not -pedantic/-Wconversion clean; the glue gets the same flags minus those two.
GLUE_FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off", "-O2"]
# Speed flags of the extension (after the strict ones, so -O3 wins over -O2). Link-time
# optimization makes the batch loop, the step and the CasADi kernel one function: no call, no
# argument arrays, no null-pointer tests on them; hidden visibility lets it (only PyInit is
# exported). Neither changes a result: -ffp-contract=off stays and nothing implies fast-math.
SPEED_FLAGS = ["-O3"]
LTO_FLAGS = ["-flto", "-fvisibility=hidden"]


def compiler() -> str:
    return os.environ.get("CC", "cc")


def lto_supported() -> bool:
    """Whether the compiler and linker build a shared object with -flto (clang with a linker
    lacking its LTO plugin does not); checked once per process."""
    global _LTO
    if _LTO is None:
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp, "probe.c")
            src.write_text("int uiogen_probe(int x) { return x + 1; }\n")
            cmd = [compiler(), *SPEED_FLAGS, *LTO_FLAGS, "-fPIC", "-shared", str(src), "-o", str(Path(tmp, "probe.so"))]
            _LTO = subprocess.run(cmd, capture_output=True).returncode == 0
    return _LTO


_LTO = None


def observer_sources(name: str) -> list:
    d = GENERATED_DIR / name
    return [d / f"{name}_kernel.c", d / f"{name}.c"]


def _run(cmd: list) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise ToolchainError(f"compiler failed:\n$ {shlex.join(map(str, cmd))}\n{proc.stdout}{proc.stderr}")


def build_extension(name: str, extra_flags: list | None = None, ext_dir: Path = EXT_DIR,
                    suffix: str = "") -> Path:
    """Compile observer ``name``; returns the path of the extension module."""
    extra = SPEED_FLAGS + (LTO_FLAGS if lto_supported() else []) + list(extra_flags or [])
    BUILD_DIR.mkdir(exist_ok=True)
    ext_dir.mkdir(parents=True, exist_ok=True)
    (ext_dir / "__init__.py").touch()
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE / "templates")),
                             undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
    glue = BUILD_DIR / f"{name}_pymodule.c"
    glue.write_text(env.get_template("pymodule.c.j2").render(name=name, NAME=name.upper()))
    inc = ["-I", str(GENERATED_DIR / name)]
    objs = []
    for src in observer_sources(name):
        obj = BUILD_DIR / (src.stem + suffix + ".o")
        _run([compiler(), *STRICT_FLAGS, *extra, "-fPIC", *inc, "-c", str(src), "-o", str(obj)])
        objs.append(obj)
    glue_obj = BUILD_DIR / (glue.stem + suffix + ".o")
    import numpy
    _run([compiler(), *GLUE_FLAGS, *extra, "-fPIC", *inc, "-I", sysconfig.get_paths()["include"],
          "-I", numpy.get_include(),
          "-c", str(glue), "-o", str(glue_obj)])
    target = ext_dir / f"_{name}{sysconfig.get_config_var('EXT_SUFFIX')}"
    _run([compiler(), "-shared", *extra, *map(str, objs), str(glue_obj), "-o", str(target), "-lm"])
    return target


def generated_names() -> list:
    return sorted(p.name for p in GENERATED_DIR.iterdir() if (p / f"{p.name}.h").is_file()) \
        if GENERATED_DIR.is_dir() else []


def main(argv=None) -> int:
    names = (argv if argv is not None else sys.argv[1:]) or generated_names()
    for name in names:
        path = build_extension(name)
        print(f"{name}: built {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
