"""Cortex-M4F cross build of the observer step (Debian's arm-none-eabi-gcc): code size
(arm-none-eabi-size) and worst-case stack (-fstack-usage, summed along the step's call chain),
double and float32 variants. ``python -m codegen.targets.cortexm [NAME ...]`` prints the table
(NAME: a built-in observer or an observer file, as the ``uiogen`` verbs take it). Executed under
QEMU against the host build: codegen/tools/qemu.py."""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from ...errors import UnknownObserverError, UnsupportedError
from ...emit.toolchain import STRICT_CFLAGS, run
from ..base import Target

CC = "arm-none-eabi-gcc"
SIZE = "arm-none-eabi-size"
# the Debian/Ubuntu packages of the tools (scripts/install_embedded_tools.sh installs them: make embedded-tools)
PACKAGES = "gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm"
CPU_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]
# The strict flags, for size: -Os; -ffunction-sections so the table counts the step only.
FLAGS = [f for f in STRICT_CFLAGS if f != "-O2"] + ["-Os", "-ffunction-sections", "-fdata-sections",
                                                    "-fstack-usage"] + CPU_FLAGS


def available() -> bool:
    return shutil.which(CC) is not None and shutil.which(SIZE) is not None


def install_hint(tools: str) -> str:
    """The message of an embedded tool that is not installed: which, and how to install it."""
    return f"{tools} not installed: sudo apt-get install {PACKAGES} (in a checkout: make embedded-tools)"


def command_line(prog: str, description: str) -> argparse.ArgumentParser:
    """The command line of the embedded tools (this module's, :mod:`codegen.tools.m4cycles`'s,
    :mod:`codegen.tools.qemu`'s): NAME ... and ``--project``, as the ``uiogen`` verbs take them."""
    from ...commandline import project_option
    parser = argparse.ArgumentParser(prog=prog, description=description, parents=[project_option()])
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help="a built-in observer (uiogen list) or the path of an observer file (.toml), as every "
                             "uiogen verb takes it; default: every built-in observer generated in the project")
    return parser


def resolve(names=None, project=None) -> list:
    """The observers' configurations: each name (a built-in name, an observer-file path or a
    configuration) as the ``uiogen`` verbs resolve it (:func:`codegen.project.observer_file.get`),
    default every built-in observer generated in ``project``; an unknown one is an
    UnknownObserverError before any work, with a did-you-mean: the observer file ``NAME.toml`` in
    the working directory, else the closest built-in name."""
    from ...extension.build import generated_names
    from ...project import observer_file as observers
    from ...settings import suggest
    configs = []
    for name in names or generated_names(project):
        try:
            configs.append(observers.get(name, project=project))
        except UnknownObserverError as exc:
            if not isinstance(name, str) or observers.is_path(name):
                raise
            near = f"{name}.toml" if Path(f"{name}.toml").is_file() else suggest(name, observers.names())
            if near is None:
                raise
            head, text = f"no observer named {name!r}", str(exc)
            text = f"{head} (did you mean {near!r}?){text[len(head):]}" if text.startswith(head) else \
                f"{text}; did you mean {near!r}?"
            raise UnknownObserverError(text) from None
    return configs


def _stack(su_files) -> dict:
    frames = {}
    for su in su_files:
        for line in Path(su).read_text().splitlines():
            loc, size, kind = line.rsplit("\t", 2)
            frames[loc.rsplit(":", 1)[-1]] = (int(size), kind)
    return frames


def measure(name: str, src_dir: Path, out_dir: Path, precision: str = "double") -> dict:
    """Compile one observer (the files in ``src_dir``) for the M4F; code size of the step and
    the worst-case stack of NAME_step (its frame + step_flat + run_flat + kernel + casadi_f0 and
    the largest helper). Double arithmetic on the M4F calls libgcc's soft-float routines, whose
    code and stack are not in these figures."""
    if not available():
        raise UnsupportedError(install_hint(CC))
    stem = name + ("_f32" if precision == "float32" else "")
    objs, sus = [], []
    for src in (src_dir / f"{stem}_kernel.c", src_dir / f"{stem}.c"):
        obj = out_dir / (src.stem + ".o")
        run([CC, *FLAGS, "-I", src_dir, "-c", src, "-o", obj], cwd=out_dir)
        objs.append(obj)
        sus.append(obj.with_suffix(".su"))
    proc = subprocess.run([SIZE, "-A", *map(str, objs)], capture_output=True, text=True, check=True)
    text = sum(int(m.group(2)) for m in re.finditer(r"^\.text\.?(\S*)\s+(\d+)", proc.stdout, flags=re.M))
    rodata = sum(int(m.group(1)) for m in re.finditer(r"^\.rodata\S*\s+(\d+)", proc.stdout, flags=re.M))
    frames = _stack(sus)
    chain = [f"{stem}_step", f"{stem}_step_flat", f"{stem}_run_flat", f"{stem}_kernel", "casadi_f0"]
    # CasADi's helpers (NAME_kernel_fmax, ...) and queries: the largest frame, called from the kernel
    helpers = [s for f, (s, _) in frames.items() if f.startswith(f"{stem}_kernel_")]
    stack = sum(frames.get(f, (0, ""))[0] for f in chain) + max(helpers, default=0)
    dynamic = [f for f, (_, k) in frames.items() if "dynamic" in k and "bounded" not in k]
    return {"observer": name, "precision": precision, "code_bytes": text, "rodata_bytes": rodata,
            "stack_bytes": stack, "unbounded": dynamic}


def measure_both(config, out: Path, scratch: Path) -> list:
    """:func:`measure` of one observer (its generated C checked against its stamp first, as ``uiogen
    build`` does), double and float32: the objects in ``out/NAME_PRECISION/``, the float32 C
    emitted into ``scratch``."""
    from .. import float32 as prec
    from ...extension.build import check_generated, generated_dir
    check_generated(config)
    rows = []
    for p in ("double", "float32"):
        src = generated_dir(config) if p == "double" else prec.emit_float(config, Path(scratch) / "src")
        folder = Path(out) / f"{config.name}_{p}"
        folder.mkdir()
        rows.append(measure(config.name, src, folder, p))
    return rows


def table(names=None, project=None) -> list:
    """Code, rodata and stack per observer (names or configurations, :func:`resolve`) and precision;
    the generated C is checked against its stamp first (``uiogen build`` does the same)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for config in resolve(names, project):
            rows += measure_both(config, Path(tmp), Path(tmp))
    return rows


def table_lines(rows) -> list:
    lines = [f"{'observer':32s} {'precision':9s} {'code [B]':>9s} {'rodata [B]':>10s} {'stack [B]':>9s}"]
    lines += [f"{r['observer']:32s} {r['precision']:9s} {r['code_bytes']:9d} {r['rodata_bytes']:10d} "
              f"{r['stack_bytes']:9d}" for r in rows]
    return lines


PROG = "python -m codegen.targets.cortexm"
DESCRIPTION = ("Cross-compile each observer's step for the Cortex-M4F (arm-none-eabi-gcc, hard float, the strict "
               "flags, -Os), double and float32, and print its code and rodata (arm-none-eabi-size) and the "
               "worst-case stack of NAME_step (-fstack-usage). The observer must have been generated (uiogen "
               f"generate NAME). Needs arm-none-eabi-gcc: sudo apt-get install {PACKAGES} (in a checkout: make "
               "embedded-tools).")


def main(argv=None) -> int:
    from ...commandline import report_errors
    args = command_line(PROG, DESCRIPTION).parse_args(argv)
    return report_errors(PROG, lambda: _main(args))


def _main(args) -> int:
    configs = resolve(args.names, args.project)
    if not available():
        raise UnsupportedError(install_hint(CC if shutil.which(CC) is None else SIZE))
    rows = table(configs)
    for line in table_lines(rows):
        print(line)
    return 0


class CortexM(Target):
    name = "cortexm"
    title = "Cortex-M4F objects, double and float32, with code, rodata and stack (cortexm.json)"
    out = "DIR"

    def export(self, config, out, log=print) -> Path:
        import json
        from ...project import outputs
        if not available():
            raise UnsupportedError(install_hint(CC if shutil.which(CC) is None else SIZE))
        out = outputs.make_folder(out)
        for p in ("double", "float32"):
            if (out / f"{config.name}_{p}").exists():
                shutil.rmtree(out / f"{config.name}_{p}")
        with tempfile.TemporaryDirectory() as tmp:
            rows = measure_both(config, out, Path(tmp))
        outputs.write_atomic(out / "cortexm.json", json.dumps(rows, indent=1) + "\n")
        for line in table_lines(rows):
            log(line)
        log(f"{config.name}: wrote {out} (Cortex-M4F objects, double and float32, and cortexm.json)")
        return out


TARGET = CortexM()
