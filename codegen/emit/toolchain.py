"""The C toolchain, in one place: the flags every C file compiles
with, CasADi's code-generation options and the fix-ups its output needs, templates, and one
compile-and-link function used by the extension, the benchmark/check driver and the
differentiator driver.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import jinja2

from ..errors import ToolchainError

TEMPLATES = Path(__file__).resolve().parent / "templates"

# Every emitted file must compile cleanly with these (gcc and clang); never -ffast-math, and
# no FMA contraction, so results do not depend on the target's FMA support.
STRICT_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wshadow", "-Wconversion",
                 "-Wdouble-promotion", "-Wvla", "-ffp-contract=off", "-fno-fast-math", "-O2")

# CasADi's C: a plain function of arrays, no memory objects, ints as int (the API's types).
CASADI_OPTIONS = {"with_header": True, "casadi_real": "double", "casadi_int": "int", "with_mem": False,
                  "verbose": False, "cpp": False, "main": False, "mex": False, "indent": 2}


def environment(folder: Path = TEMPLATES) -> jinja2.Environment:
    """Jinja2 for C: every variable must be given (StrictUndefined), nothing is escaped."""
    return jinja2.Environment(loader=jinja2.FileSystemLoader(str(folder)), undefined=jinja2.StrictUndefined,
                              keep_trailing_newline=True, autoescape=False)


def render_template(template: str, folder: Path = TEMPLATES, /, **context) -> str:
    """``template`` (a file in ``folder``) rendered with ``context`` (positional-only parameters,
    so a context key may be called ``name``)."""
    return environment(folder).get_template(template).render(**context)


def _fix_unused_parameters(code: str, kernel: str) -> str:
    """CasADi's kernel ignores some of its standard arguments; mark them used for -Wextra -Werror."""
    fixes = [
        (r"(static int casadi_f0\(const casadi_real\*\* arg, casadi_real\*\* res, casadi_int\* iw, "
         r"casadi_real\* w, int mem\) \{\n)", r"\1  (void)iw; (void)w; (void)mem;\n"),
        (rf"(CASADI_SYMBOL_EXPORT void {kernel}_release\(int mem\) \{{\n)", r"\1  (void)mem;\n"),
    ]
    for pattern, repl in fixes:
        code, count = re.subn(pattern, repl, code)
        if count != 1:
            raise ToolchainError(f"CasADi {ca.__version__} output changed shape: pattern {pattern!r} "
                                 f"matched {count} times; update codegen/emit/toolchain.py")
    return code


def _fix_float_conditions(code: str) -> str:
    """CasADi's selects (``if_else``) test a double as a condition, ``(a?x:0)`` and ``(!a)``,
    which clang's -Wconversion refuses; the same tests written out: ``a != 0`` (true for NaN,
    like the implicit test) and ``a == 0``."""
    code = re.sub(r"=\((a\d+)\?", r"=(\1!=0?", code)
    return re.sub(r"=\(!(a\d+)\);", r"=(\1==0);", code)


def casadi_sources(f: ca.Function) -> tuple:
    """(C, header) of CasADi's code for ``f`` (file stem: the function's name), fixed up for the
    project's strict flags."""
    kernel = f.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{kernel}.c", CASADI_OPTIONS)
        cg.add(f)
        cg.generate(tmp + "/")
        c_code = Path(tmp, f"{kernel}.c").read_text()
        h_code = Path(tmp, f"{kernel}.h").read_text()
    return _fix_float_conditions(_fix_unused_parameters(c_code, kernel)), h_code


def compiler() -> str:
    return os.environ.get("CC", "cc")


def run(cmd: list, cwd: Path | None = None) -> None:
    """Run a compiler command; a failure is a :class:`ToolchainError` with the command and its output."""
    try:
        proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, cwd=cwd)
    except FileNotFoundError:
        raise ToolchainError(f"no C compiler {cmd[0]!r}: install one (e.g. gcc) or set CC") from None
    if proc.returncode != 0:
        raise ToolchainError(f"compiler failed:\n$ {shlex.join(map(str, cmd))}\n{proc.stdout}{proc.stderr}")


def compile_and_link(sources: list, target: Path, *, include: list = (), flags=STRICT_CFLAGS, extra_flags=(),
                     source_flags: dict | None = None, shared: bool = False, cc: str | None = None,
                     object_dir: Path | None = None, suffix: str = "") -> Path:
    """Compile ``sources`` (each with ``flags`` + ``extra_flags``, or ``source_flags[source]``) into
    objects in ``object_dir`` (default: beside ``target``) and link them into ``target``
    (an executable, or a shared object with ``shared``). Returns ``target``."""
    cc = cc or compiler()
    target = Path(target)
    object_dir = Path(object_dir or target.parent)
    object_dir.mkdir(parents=True, exist_ok=True)
    inc = [a for d in include for a in ("-I", str(d))]
    objs = []
    for src in map(Path, sources):
        obj = object_dir / (src.stem + suffix + ".o")
        own = (source_flags or {}).get(src, flags)
        run([cc, *own, *extra_flags, *(["-fPIC"] if shared else []), *inc, "-c", src, "-o", obj], cwd=object_dir)
        objs.append(obj)
    run([cc, *(["-shared"] if shared else []), *extra_flags, *objs, "-o", target, "-lm"])
    return target
