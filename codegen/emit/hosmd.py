"""The Levant differentiator (:mod:`codegen.representation.differentiators`) as stand-alone C with a driver
(tests and ``uiogen bench``): the CasADi C of its step and ``templates/hosmd_driver.c.j2``, compiled with
the project's strict flags, run over a stream of samples."""
from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from ..errors import ToolchainError
from ..representation.differentiators import HosmdSpec, hosmd_function
from .toolchain import casadi_sources, compile_and_link, render_template


def c_sources(spec: HosmdSpec) -> dict:
    """CasADi C of the step (function ``hosmd_step``) plus the driver
    (``templates/hosmd_driver.c.j2``), as {file name: text}."""
    code, header = casadi_sources(hosmd_function(spec, "hosmd_step"))
    return {"hosmd_kernel.c": code, "hosmd_kernel.h": header,
            "hosmd_driver.c": render_template("hosmd_driver.c.j2", n_state=spec.n_state)}


def build_c_driver(spec: HosmdSpec, out_dir: Path, cc: str = "gcc", extra_flags=()) -> Path:
    """Compile the step and its driver with the project's strict flags; returns the executable."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for fname, text in c_sources(spec).items():
        (out_dir / fname).write_text(text)
    return compile_and_link([out_dir / "hosmd_kernel.c", out_dir / "hosmd_driver.c"], out_dir / "hosmd_driver",
                            include=[out_dir], extra_flags=extra_flags, cc=cc)


def run_c_driver(exe: Path, spec: HosmdSpec, samples, z0) -> np.ndarray:
    """Stream ``samples`` through a compiled driver; row j is the state before the update with f_j."""
    data = (np.asarray(z0, dtype=np.float64).tobytes()
            + np.ascontiguousarray(samples, dtype=np.float64).tobytes())
    proc = subprocess.run([str(exe)], input=data, capture_output=True)
    if proc.returncode != 0:
        raise ToolchainError(f"{exe} exited with {proc.returncode}: {proc.stderr.decode(errors='replace')}")
    return np.frombuffer(proc.stdout, dtype=np.float64).reshape(-1, spec.n_state)
