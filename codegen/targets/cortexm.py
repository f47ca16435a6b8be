"""Cortex-M4F cross build of the observer step (Debian's arm-none-eabi-gcc): code size
(arm-none-eabi-size) and worst-case stack (-fstack-usage, summed along the step's call chain),
double and float32 variants. ``python -m codegen.targets.cortexm [NAME ...]`` prints the table.
Executed under QEMU against the host build: codegen/tools/qemu.py."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from ..errors import UnsupportedError
from ..emit.toolchain import STRICT_CFLAGS, run

CC = "arm-none-eabi-gcc"
SIZE = "arm-none-eabi-size"
CPU_FLAGS = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]
# The strict flags, for size: -Os; -ffunction-sections so the table counts the step only.
FLAGS = [f for f in STRICT_CFLAGS if f != "-O2"] + ["-Os", "-ffunction-sections", "-fdata-sections",
                                                    "-fstack-usage"] + CPU_FLAGS


def available() -> bool:
    return shutil.which(CC) is not None and shutil.which(SIZE) is not None


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
        raise UnsupportedError(f"{CC} is not installed: run scripts/install_embedded_tools.sh")
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


def table(names=None) -> list:
    from . import float32 as prec
    from ..extension.build import generated_dir, generated_names
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names or generated_names():
            for p in ("double", "float32"):
                src = generated_dir(name) if p == "double" else prec.emit_float(name, Path(tmp) / "src")
                out = Path(tmp) / f"{name}_{p}"
                out.mkdir()
                rows.append(measure(name, src, out, p))
    return rows


def main(argv=None) -> int:
    rows = table((argv if argv is not None else sys.argv[1:]) or None)
    print(f"{'observer':32s} {'precision':9s} {'code [B]':>9s} {'rodata [B]':>10s} {'stack [B]':>9s}")
    for r in rows:
        print(f"{r['observer']:32s} {r['precision']:9s} {r['code_bytes']:9d} {r['rodata_bytes']:10d} {r['stack_bytes']:9d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
