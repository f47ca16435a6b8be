"""Stand-alone C driver of a generated observer, for benchmarks and reliability checks.

:func:`build_harness` compiles ``templates/harness.c.j2`` with the observer's C under
the project's strict flags plus any extra flags (sanitizers, ``-fstack-usage``,
``-fcallgraph-info``); :func:`run_stream` feeds it rows of inputs and reads back the
outputs and status codes.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np

from ..design import lock as design_lock
from ..project import observer_file as observers
from ..emit.toolchain import compile_and_link, render_template


def render(name: str) -> str:
    config = observers.get(name)
    art = json.loads(design_lock.path(config).read_text())
    # the last input schedules the step: the benchmark sweeps it over its box
    last = art["signals"]["input"][-1]
    lo, hi = art["signals"]["input_boxes"][last]
    return render_template("harness.c.j2", name=name, NAME=name.upper(),
                           banner=f"/* Benchmark/check driver of {name} (uiogen). */",
                           first_min=repr(float(lo)), first_max=repr(float(hi)))


def build_harness(name: str, out_dir: Path, extra_flags=(), cc: str = "gcc") -> Path:
    """Compile the driver + observer into ``out_dir``; objects stay there (for .su/.ci files)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    src_dir = design_lock.path(observers.get(name)).parent
    main = out_dir / f"{name}_harness.c"
    main.write_text(render(name))
    return compile_and_link([src_dir / f"{name}_kernel.c", src_dir / f"{name}.c", main], out_dir / f"{name}_harness",
                            include=[src_dir], extra_flags=extra_flags, cc=cc)


def run_stream(exe: Path, inputs: np.ndarray, n_output: int, env=None):
    """Run the driver on ``inputs`` (n, n_input); returns (outputs, status, completed process)."""
    data = np.ascontiguousarray(inputs, dtype=np.float64).tobytes()
    proc = subprocess.run([str(exe)], input=data, capture_output=True, env=env)
    row = np.dtype([("out", np.float64, (n_output,)), ("status", np.int32)])
    rec = np.frombuffer(proc.stdout, dtype=row) if proc.returncode == 0 else np.zeros(0, dtype=row)
    return rec["out"], rec["status"], proc
