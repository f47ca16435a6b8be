"""Stand-alone C driver of a generated observer, for benchmarks and reliability checks.

:func:`build_harness` compiles ``templates/harness.c.j2`` with the observer's C under
the project's strict flags plus any extra flags (sanitizers, ``-fstack-usage``,
``-fcallgraph-info``); :func:`run_stream` feeds it rows of inputs and reads back the
outputs and status codes.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

import jinja2
import numpy as np

from .emit import GENERATED_DIR, STRICT_CFLAGS, TEMPLATES
from .errors import ToolchainError


def render(name: str) -> str:
    import json
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
    art = json.loads((GENERATED_DIR / name / f"{name}_design.json").read_text())
    # the last input schedules the step: the benchmark sweeps it over its box
    last = art["signals"]["input"][-1]
    lo, hi = art["signals"]["input_boxes"][last]
    return env.get_template("harness.c.j2").render(
        name=name, NAME=name.upper(), banner=f"/* Benchmark/check driver of {name} (uiogen). */",
        first_min=repr(float(lo)), first_max=repr(float(hi)))


def build_harness(name: str, out_dir: Path, extra_flags=(), cc: str = "gcc") -> Path:
    """Compile the driver + observer into ``out_dir``; objects stay there (for .su/.ci files)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    src_dir = GENERATED_DIR / name
    main = out_dir / f"{name}_harness.c"
    main.write_text(render(name))
    objs = []
    for src in (src_dir / f"{name}_kernel.c", src_dir / f"{name}.c", main):
        obj = out_dir / (src.stem + ".o")
        cmd = [cc, *STRICT_CFLAGS, *extra_flags, "-I", str(src_dir), "-c", str(src), "-o", str(obj)]
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=out_dir)
        if proc.returncode != 0:
            raise ToolchainError(f"{' '.join(cmd)}\n{proc.stderr}")
        objs.append(obj)
    exe = out_dir / f"{name}_harness"
    proc = subprocess.run([cc, *extra_flags, *map(str, objs), "-o", str(exe), "-lm"], capture_output=True, text=True)
    if proc.returncode != 0:
        raise ToolchainError(proc.stderr)
    return exe


def run_stream(exe: Path, inputs: np.ndarray, n_output: int, env=None):
    """Run the driver on ``inputs`` (n, n_input); returns (outputs, status, completed process)."""
    data = np.ascontiguousarray(inputs, dtype=np.float64).tobytes()
    proc = subprocess.run([str(exe)], input=data, capture_output=True, env=env)
    row = np.dtype([("out", np.float64, (n_output,)), ("status", np.int32)])
    rec = np.frombuffer(proc.stdout, dtype=row) if proc.returncode == 0 else np.zeros(0, dtype=row)
    return rec["out"], rec["status"], proc
