"""``make misra`` / ``python -m codegen.targets.misra``: cppcheck's MISRA C:2012 addon on the generated C.

Per observer, cppcheck analyses ``NAME.c`` and ``NAME_kernel.c`` (and the headers they include)
together with a small integration file that uses every declaration of the API once, as a program
embedding the observer does (MISRA's whole-program rules 2.5 and 8.7 see the API from outside its
file; that file's own findings are not counted). Findings are split by where they are:

* the code our templates write (``NAME.c``, ``NAME.h``): must be none;
* CasADi's kernel (``NAME_kernel.c``, ``NAME_kernel.h``): compared, rule by rule, with the
  deviations file ``misra/kernel_deviations.toml`` (rule, count over every observer, reason);
  a count above the listed one, or a rule not listed, fails (and so does a count below it: the
  file is then stale and must be updated to what the kernel now does).
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from collections import Counter
from pathlib import Path

from ...errors import ToolchainError, UnsupportedError
from ...design.sources import ROOT
from ..base import Target

DEVIATIONS = ROOT / "misra" / "kernel_deviations.toml"
_LINE = re.compile(r"^(?P<file>[^:]+):(?P<line>\d+):(?P<id>[\w.-]+)$")


def cppcheck() -> str:
    exe = shutil.which("cppcheck")
    if exe is None:
        raise UnsupportedError("cppcheck is not installed: run scripts/install_embedded_tools.sh "
                               "(apt-get install cppcheck)")
    return exe


def api_use(name: str, header: str) -> str:
    """A translation unit that calls every function of the API and uses its macros."""
    macros = [m for m in re.findall(rf"^#define ({name.upper()}_\w+)", header, flags=re.M)
              if m != f"{name.upper()}_DESIGN_HASH"]
    bits = re.findall(rf"^    ({name.upper()}_\w+) = \d+,?$", header, flags=re.M)
    uses = "\n".join([f"    sink += (double)({m});" for m in macros] + [f"    bit = {b};" for b in bits])
    return f"""#include <stddef.h>
#include "{name}.h"

int main(void);

int main(void)
{{
    static {name}_state s;
    static {name}_input in;
    static {name}_output out;
    static double state[{name.upper()}_N_STATE];
    static double input[{name.upper()}_N_INPUT];
    static double output[{name.upper()}_N_OUTPUT];
    static {name}_status status[1];
    const char *hash = {name.upper()}_DESIGN_HASH;
    {name}_status_bit bit = {name.upper()}_OK;
    double sink = 0.0;
    {name}_status flags;
    {name}_init(&s);
    flags = {name}_step(&s, &in, &out);
    flags += {name}_step_flat(state, input, output);
    {name}_run_flat(state, input, 1u, output, status);
    flags += status[0] + {name}_check_work();
{uses}
    flags += (hash[0] == '\\0') ? 1 : 0;
    flags += (bit == {name.upper()}_OK) ? 1 : 0;
    return (sink > 0.0) ? flags : 0;
}}
"""


def analyse(name: str, src_dir: Path | None = None) -> list:
    """cppcheck's MISRA findings for one observer: [(file name, line, rule)]."""
    if src_dir is None:
        from ...extension.build import generated_dir
        src_dir = generated_dir(name)
    src_dir = Path(src_dir)
    with tempfile.TemporaryDirectory() as tmp:
        use = Path(tmp, f"{name}_api_use.c")
        use.write_text(api_use(name, (src_dir / f"{name}.h").read_text()))
        cmd = [cppcheck(), "--addon=misra", "--std=c99", "--quiet", "--template={file}:{line}:{id}",
               f"--cppcheck-build-dir={tmp}", "-I", str(src_dir),
               str(src_dir / f"{name}.c"), str(src_dir / f"{name}_kernel.c"), str(use)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise ToolchainError(f"cppcheck failed on {name}:\n{proc.stdout}{proc.stderr}")
    out = []
    for line in (proc.stdout + proc.stderr).splitlines():
        m = _LINE.match(line.strip())
        if m and m["id"].startswith("misra-c2012-"):
            out.append((Path(m["file"]).name, int(m["line"]), m["id"][len("misra-c2012-"):]))
    return out


def classify(name: str, findings: list) -> dict:
    ours = {f"{name}.c", f"{name}.h"}
    kernel = {f"{name}_kernel.c", f"{name}_kernel.h"}
    return {"template": [f for f in findings if f[0] in ours],
            "kernel": [f for f in findings if f[0] in kernel]}


def deviations(path: Path = DEVIATIONS) -> dict:
    """{rule: (count, reason)} of the deviations file."""
    data = tomllib.loads(path.read_text())
    return {d["rule"]: (int(d["count"]), d["reason"]) for d in data.get("deviation", [])}


def findings(names=None, log=print) -> dict:
    """cppcheck's MISRA findings of the generated C of ``names`` (default: every generated
    observer): {"observers", "template": [(name, file, line, rule)], "kernel": Counter of rules}."""
    from ...extension.build import generated_names
    names = list(names or generated_names())
    template, kernel = [], Counter()
    for name in names:
        c = classify(name, analyse(name))
        template += [(name, *f) for f in c["template"]]
        kernel.update(rule for _, _, rule in c["kernel"])
        log(f"{name}: {len(c['template'])} findings in the template code, {len(c['kernel'])} in the CasADi kernel")
    return {"observers": names, "template": template, "kernel": kernel}


def judge(found: dict, deviations_path: Path = DEVIATIONS) -> dict:
    """The findings of :func:`findings` against the deviations file: no finding in template code, and
    the kernel's count of each rule exactly the one listed."""
    template, kernel = found["template"], found["kernel"]
    listed = deviations(deviations_path)
    problems = [f"{n}: {f}:{line}: MISRA C:2012 rule {rule} in code our templates write"
                for n, f, line, rule in template]
    for rule in sorted(set(kernel) | set(listed), key=lambda r: [int(x) for x in r.split(".")]):
        count, (allowed, _) = kernel.get(rule, 0), listed.get(rule, (0, ""))
        if count != allowed:
            problems.append(f"kernel rule {rule}: {count} findings, deviations file lists {allowed}"
                            + (" (new finding)" if count > allowed else " (stale entry: lower the count)"))
    return {"observers": found["observers"], "template_findings": len(template), "kernel_findings": dict(kernel),
            "deviations": {r: c for r, (c, _) in listed.items()}, "problems": problems}


def run(names=None, log=print, deviations_path: Path = DEVIATIONS) -> dict:
    return judge(findings(names, log), deviations_path)


def main(argv=None) -> int:
    args = argv if argv is not None else sys.argv[1:]
    try:
        r = run(args or None)
    except (UnsupportedError, ToolchainError) as exc:
        print(f"misra: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    print(f"MISRA C:2012 (cppcheck addon): {r['template_findings']} findings in the code our templates write; "
          f"kernel: {sum(r['kernel_findings'].values())} findings in {len(r['kernel_findings'])} rules, "
          f"against {DEVIATIONS.relative_to(ROOT)}")
    for p in r["problems"]:
        print(f"  FAIL {p}")
    return 1 if r["problems"] else 0


def report(name: str, found: list, deviations_path: Path = DEVIATIONS) -> str:
    """One observer's MISRA report: its findings in the template code (none, or it is refused) and
    the kernel's, rule by rule, with the reason the deviations file gives."""
    c = classify(name, found)
    listed = deviations(deviations_path)
    kernel = Counter(rule for _, _, rule in c["kernel"])
    lines = [f"MISRA C:2012 (cppcheck {cppcheck_version()} addon) of {name}: {len(c['template'])} findings in the "
             f"code our templates write ({name}.c, {name}.h); {sum(kernel.values())} in CasADi's kernel",
             f"deviations: {DEVIATIONS.relative_to(ROOT)}"]
    for rule in sorted(kernel, key=lambda r: [int(x) for x in r.split(".")]):
        reason = listed.get(rule, (0, "NOT LISTED"))[1]
        lines.append(f"  rule {rule}: {kernel[rule]} in {name}_kernel.c: {reason}")
    return "\n".join(lines) + "\n"


def cppcheck_version() -> str:
    proc = subprocess.run([cppcheck(), "--version"], capture_output=True, text=True)
    return proc.stdout.strip().rpartition(" ")[2] or "?"


class Misra(Target):
    name = "misra"
    title = "the C package with its MISRA C:2012 report (cppcheck); refused on a template finding"
    out = "DIR"

    def export(self, config, out, log=print) -> Path:
        from ..base import generated_c, write_folder
        folder, files = generated_c(config)
        found = analyse(config.name, folder)
        template = classify(config.name, found)["template"]
        if template:
            raise ToolchainError(f"{config.name}: MISRA C:2012 findings in code our templates write: "
                                 + "; ".join(f"{f}:{line}: rule {rule}" for f, line, rule in template))
        text = report(config.name, found)
        out = write_folder(out, {**files, f"{config.name}_misra.txt": text})
        log(text.rstrip())
        log(f"{config.name}: wrote {out} (the C package and {config.name}_misra.txt)")
        return out


TARGET = Misra()
