"""Cycles per step of an observer on the Cortex-M4F: the instructions QEMU executes, each
weighted by its Cortex-M4 timing.

Method. The bare-metal harness of :mod:`codegen.tools.qemu` (the same cross build: strict flags, hard
float, newlib, libgcc's soft double) is built to run the first ``N`` samples of the
observer's recorded validation inputs through ``NAME_step_flat``, printing nothing, built for speed
(``-O2 -flto``: the kernel inlined into the step; the size table of :mod:`codegen.targets.cortexm`
is the ``-Os`` build). QEMU
(``-singlestep -d exec,nochain``) logs the address of every instruction it executes; the run for
``N2`` samples less the run for ``N1`` samples, over ``N2 - N1``, is the cost of one step (the
start-up cancels; the harness loop adds 4 instructions per step). Every address is matched to its
instruction in the ELF (``arm-none-eabi-objdump``) and weighted by the Cortex-M4 Technical
Reference Manual's timings (r0p1, tables 3-1 and 7-1): one cycle for data processing, VADD, VSUB,
VMUL, VABS, VNEG, VMOV, VCMP, VCVT; 2 for a single load or store (LDR, STR, VLDR, VSTR); 3 for
LDRD/STRD and for the multiply-accumulates (VMLA, VMLS, VNMLA, VNMLS, VFMA); 1 + N for a load or
store of N registers (LDM, STM, PUSH, POP, VLDM, VSTM, VPUSH, VPOP); 14 for VDIV and VSQRT; 2 to
12 for SDIV/UDIV (counted 12); a branch costs 1 when not taken and 1 + P when taken (whether it
was is read off the trace: the next address), P = 1..3 the pipeline refill, reported as the two
ends of the range. Zero wait states are assumed (code and data in SRAM, as on the MPS2 board);
flash wait states add to every figure. Double arithmetic has no unit on the M4F: it runs in
libgcc's soft-float routines, whose instructions are counted the same way.

``python -m codegen.tools.m4cycles [NAME ...]`` prints the table (NAME: a built-in observer or an
observer file, as the ``uiogen`` verbs take it); ``uiogen bench`` includes it.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from ..errors import UnsupportedError
from ..targets import cortexm
from . import qemu

OBJDUMP = "arm-none-eabi-objdump"
# samples of the two runs per precision: the difference is what one step costs
RUNS = {"float32": (100, 300), "double": (4, 12)}
# the speed build (the size table of codegen.targets.cortexm is -Os): the kernel inlined into the
# step by link-time optimization, which drops its argument checks and its call
OPTIMIZE = ("-O2", "-flto")
REFILL = (1, 3)                # P, the pipeline refill of a taken branch (TRM: 1 to 3)
TIMEOUT_S = 300

CONDITIONS = ("eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le", "al")
ONE = {"vadd", "vsub", "vmul", "vnmul", "vabs", "vneg", "vmov", "vcmp", "vcmpe", "vcvt", "vcvtr", "vmrs", "vmsr"}
MAC = {"vmla", "vmls", "vnmla", "vnmls", "vfma", "vfms", "vfnma", "vfnms"}
SLOW_FP = {"vdiv", "vsqrt"}
LOAD_STORE = {"ldr", "ldrb", "ldrh", "ldrsb", "ldrsh", "ldrex", "str", "strb", "strh", "strex", "vldr", "vstr"}
PAIR = {"ldrd", "strd"}
MULTIPLE = {"ldm", "ldmia", "ldmdb", "ldmfd", "stm", "stmia", "stmdb", "stmfd", "push", "pop", "vldm", "vldmia",
            "vldmdb", "vstm", "vstmia", "vstmdb", "vpush", "vpop"}
MULTIPLY = {"mul": 1, "muls": 1, "mla": 2, "mls": 2, "umull": 1, "smull": 1, "umlal": 1, "smlal": 1,
            "sdiv": 12, "udiv": 12}
BRANCH = {"b", "bl", "bx", "blx", "cbz", "cbnz", "tbb", "tbh"}
FLOAT_OPS = ONE | MAC | SLOW_FP
KINDS = ("float", "load/store", "branch", "other")
METHOD = ("QEMU mps2-an386 instruction trace, steps N2 - N1, weighted by the Cortex-M4 TRM timings; "
          "zero wait states; taken branch 1 + P, P = 1 and 3")


def available() -> bool:
    return qemu.available() and shutil.which(OBJDUMP) is not None


def _base(mnemonic: str) -> str:
    """``vaddgt.f32`` -> ``vadd``, ``beq.n`` -> ``b``, ``adds`` -> ``adds`` (table lookups below)."""
    m = mnemonic.split(".")[0]
    known = ONE | MAC | SLOW_FP | LOAD_STORE | PAIR | MULTIPLE | set(MULTIPLY) | BRANCH
    if m in known:
        return m
    if len(m) > 2 and m[-2:] in CONDITIONS and m[:-2] in known | {"mov", "add", "sub"}:
        return m[:-2]
    return m


def _registers(operands: str) -> int:
    """The number of registers in a list ``{r4, r5, lr}`` or ``{d8-d15}`` (a D register is two words)."""
    m = re.search(r"\{([^}]*)\}", operands)
    if not m:
        return 1
    n = 0
    for part in m.group(1).split(","):
        part = part.strip()
        r = re.fullmatch(r"([rsd])(\d+)-[rsd](\d+)", part)
        words = 2 if part.startswith("d") else 1
        n += (int(r.group(3)) - int(r.group(2)) + 1) * words if r else words
    return n


def instruction_table(elf: Path) -> dict:
    """{address: (mnemonic, base cycles, size in bytes, kind, is branch, function)} from the disassembly."""
    out = subprocess.run([OBJDUMP, "-d", "--no-show-raw-insn", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    rows, function = [], ""
    for line in out.splitlines():
        head = re.match(r"^[0-9a-f]+ <(.+)>:$", line)
        if head:
            function = head.group(1)
            continue
        m = re.match(r"^\s+([0-9a-f]+):\t(\S+)\s*(.*)$", line)
        if m and not m.group(2).startswith("."):
            rows.append((int(m.group(1), 16), m.group(2), m.group(3), function))
    table = {}
    for i, (addr, mnem, ops, fn) in enumerate(rows):
        size = (rows[i + 1][0] - addr) if i + 1 < len(rows) and rows[i + 1][0] - addr in (2, 4) else 4
        base = _base(mnem)
        pops_pc = base in ("pop", "ldm", "ldmia", "ldmfd") and re.search(r"\bpc\b", ops) is not None
        branch = base in BRANCH or pops_pc or (base in ("ldr", "mov", "add") and ops.startswith("pc"))
        if base in FLOAT_OPS:
            kind, cycles = "float", 14 if base in SLOW_FP else 3 if base in MAC else 1
        elif base in LOAD_STORE:
            kind, cycles = "load/store", 2
        elif base in PAIR:
            kind, cycles = "load/store", 3
        elif base in MULTIPLE:
            kind, cycles = "load/store", 1 + _registers(ops)
        elif branch:
            kind, cycles = "branch", 1
        else:
            kind, cycles = "other", MULTIPLY.get(base, 1)
        if pops_pc:
            kind = "branch"
        table[addr] = (mnem, cycles, size, kind, branch, fn)
    return table


def trace_pcs(log: Path) -> np.ndarray:
    """The program counter of every executed instruction in a ``-d exec`` log (one per line with
    ``-singlestep``)."""
    pcs = []
    pattern = re.compile(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/")
    with open(log) as fh:
        for line in fh:
            m = pattern.match(line)
            if m:
                pcs.append(int(m.group(1), 16))
    return np.array(pcs, dtype=np.int64)


def count(elf: Path, work: Path) -> dict:
    """Instructions and cycles (at each P of :data:`REFILL`) of one run of ``elf``, by kind."""
    log = work / (elf.stem + ".trace")
    cmd = [qemu.QEMU, "-M", qemu.MACHINE, "-nographic", "-monitor", "none", "-serial", "none",
           "-semihosting-config", "enable=on,target=native", "-singlestep", "-d", "exec,nochain",
           "-D", str(log), "-kernel", str(elf)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
    text = proc.stdout + proc.stderr
    if proc.returncode != 0 or "END" not in text.splitlines():
        raise UnsupportedError(f"QEMU run of {elf.name} failed (exit {proc.returncode}): {text[-400:]}")
    pcs = trace_pcs(log)
    log.unlink()
    table = instruction_table(elf)
    unknown = {int(p) for p in np.unique(pcs) if int(p) not in table}
    if unknown:
        raise UnsupportedError(f"{elf.name}: executed addresses outside the disassembly: "
                               f"{', '.join(hex(p) for p in sorted(unknown)[:5])}")
    uniq, inverse = np.unique(pcs, return_inverse=True)
    info = [table[int(p)] for p in uniq]
    base = np.array([i[1] for i in info])[inverse]
    size = np.array([i[2] for i in info])[inverse]
    is_branch = np.array([i[4] for i in info])[inverse]
    taken = np.zeros(pcs.size, bool)
    taken[:-1] = is_branch[:-1] & (pcs[1:] != pcs[:-1] + size[:-1])
    kinds = np.array([KINDS.index(i[3]) for i in info])[inverse]
    soft = np.array([i[5].startswith("__") for i in info])[inverse]
    out = {"instructions": int(pcs.size), "taken_branches": int(taken.sum()),
           "by_kind": {k: int(np.count_nonzero(kinds == j)) for j, k in enumerate(KINDS)},
           "soft_float_instructions": int(soft.sum())}
    for p in REFILL:
        out[f"cycles_p{p}"] = int(base.sum() + p * taken.sum())
    out["mnemonics"] = dict(Counter(table[int(p)][0].split(".")[0] for p in pcs).most_common())
    return out


def measure(observer, precision: str, inputs: np.ndarray, work: Path, src_dir: Path | None = None) -> dict:
    """Per step of ``observer`` (a name, an observer-file path or a configuration) in ``precision``
    on the M4F: instructions, cycles (P = 1 and 3), by kind."""
    from ..extension.build import generated_dir
    from ..project import observer_file as observers
    from ..targets import float32 as prec
    if not available():
        raise UnsupportedError(cortexm.install_hint(qemu.missing() or OBJDUMP))
    config = observers.get(observer)
    name = config.name
    n1, n2 = RUNS[precision]
    if inputs.shape[0] < n2:
        raise UnsupportedError(f"{name}: {inputs.shape[0]} recorded samples, {n2} needed")
    src = src_dir or (generated_dir(config) if precision == "double" else prec.emit_float(config, work / "src"))
    runs = []
    for n in (n1, n2):
        target = work / f"{precision}_{n}"
        target.mkdir(parents=True, exist_ok=True)
        elf = qemu.build_elf(name, src, inputs[:n2], target, precision, defines=[f"UIOGEN_COUNT_STEPS={n}"],
                             optimize=OPTIMIZE)
        runs.append(count(elf, target))
    a, b = runs
    steps = n2 - n1

    def per(x, y):
        return (y - x) / steps
    row = {"observer": name, "precision": precision, "steps": steps,
           "instructions": per(a["instructions"], b["instructions"]),
           "taken_branches": per(a["taken_branches"], b["taken_branches"]),
           "soft_float_instructions": per(a["soft_float_instructions"], b["soft_float_instructions"]),
           "by_kind": {k: per(a["by_kind"][k], b["by_kind"][k]) for k in KINDS}}
    for p in REFILL:
        row[f"cycles_p{p}"] = per(a[f"cycles_p{p}"], b[f"cycles_p{p}"])
    row["mnemonics"] = {m: per(a["mnemonics"].get(m, 0), b["mnemonics"].get(m, 0))
                        for m in set(a["mnemonics"]) | set(b["mnemonics"])}
    row["mnemonics"] = {m: v for m, v in sorted(row["mnemonics"].items(), key=lambda kv: -kv[1]) if v > 0}
    return row


def flops(name) -> int:
    """The step's floating-point operations (the CasADi graph's arithmetic nodes), the floor
    (``name``: a name, an observer-file path or a configuration)."""
    from .. import pipeline
    from ..project import observer_file as observers
    from ..emit.flops import flop_count
    return int(flop_count(pipeline.build(observers.get(name)).step_function())["total"])


def table(names=None, progress=None, project=None) -> list:
    """Per observer (names or configurations, :func:`codegen.targets.cortexm.resolve`) and precision:
    cycles and instructions per step, and the step's flop count (``progress``: called with each row
    as it is measured). The generated C is checked against its stamp first."""
    from ..extension.build import check_generated
    rows = []
    for config in cortexm.resolve(names, project):
        check_generated(config)
        scenario, inputs = qemu.record_inputs(config)
        f = flops(config)
        with tempfile.TemporaryDirectory() as tmp:
            for p in ("float32", "double"):
                r = measure(config, p, inputs, Path(tmp) / p)
                r.update(scenario=scenario, flops=f, cycles_per_flop=r[f"cycles_p{REFILL[-1]}"] / f)
                rows.append(r)
                if progress is not None:
                    progress(r)
    return rows


def format_row(r: dict) -> str:
    lo, hi = (r[f"cycles_p{p}"] for p in REFILL)
    return (f"{r['observer']:32s} {r['precision']:8s} {r['instructions']:10.0f} {lo:10.0f} {hi:10.0f} "
            f"{r['flops']:6d} {r['cycles_per_flop']:8.2f}")


HEADER = (f"{'observer':32s} {'precision':8s} {'instr':>10s} {'cycles P=1':>10s} {'cycles P=3':>10s} "
          f"{'flops':>6s} {'cyc/flop':>8s}")


PROG = "python -m codegen.tools.m4cycles"
DESCRIPTION = ("Cycles per step of each observer on the Cortex-M4F, float32 and double: the step built for speed "
               "(-O2 -flto) runs the observer's recorded validation inputs under QEMU (mps2-an386), every executed "
               "instruction weighted by its Cortex-M4 timing (zero wait states; a taken branch 1 + P, P = 1 and 3); "
               "beside the step's flop count. The observer must have been generated and built (uiogen generate NAME; "
               "uiogen build NAME). Needs arm-none-eabi-gcc, arm-none-eabi-objdump and qemu-system-arm: sudo apt-get "
               f"install {cortexm.PACKAGES} (in a checkout: make embedded-tools).")


def main(argv=None) -> int:
    from ..commandline import report_errors
    args = cortexm.command_line(PROG, DESCRIPTION).parse_args(argv)
    return report_errors(PROG, lambda: _main(args))


def _main(args) -> int:
    from ..extension.build import check_generated, load
    configs = cortexm.resolve(args.names, args.project)
    if not available():
        raise UnsupportedError(cortexm.install_hint(qemu.missing() or OBJDUMP))
    for config in configs:      # generated and built, before the table starts (else how to do it)
        check_generated(config)
        load(config)
    print(HEADER, flush=True)
    table(configs, progress=lambda r: print(format_row(r), flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
