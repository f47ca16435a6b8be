"""``uiogen docs``: the tables of figures in ``docs/``, produced from ``uiogen demo --json`` and
``uiogen bench --json`` (never typed by hand).

The pages hold marked regions::

    <!-- uiogen:design linf_uio -->
    ...generated table...
    <!-- /uiogen:design linf_uio -->

and :func:`update` rewrites every region from the recorded runs (``docs/data/demo.json``,
``docs/data/bench.json``). ``--check`` fails when a page differs from what the records give,
which the tests run, so a page cannot drift from the figures it claims. A region names a table
kind and an argument:

* ``design FAMILY``: the design figures of every demo observer of the family;
* ``validation FAMILY``: the validation errors of its demo scenarios (observer and baselines);
* ``real_data -``: the shared Stanford log, every estimator's sideslip error;
* ``bench -``: the step cost and design time of every observer (``make bench``);
* ``spread -``: how far a re-solve moves (``python -m codegen.tools.spread``);
* ``record NAME``: the ``table`` ({"header", "rows"}, and a "note" line under it where there is one) of a
  study's record ``docs/data/NAME.json`` (the command that writes it is named where the region sits).
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from ..errors import ConfigurationError, UnsupportedError
from ..design.sources import ROOT

DOCS = ROOT / "docs"
DATA = DOCS / "data"
REGION = re.compile(r"(<!-- uiogen:(\w+) ([\w-]+) -->\n)(.*?)(<!-- /uiogen:\2 \3 -->)", re.S)


def _num(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _table(header: list, rows: list) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(_num(c) for c in row) + " |" for row in rows]
    return "\n".join(out) + "\n"


def _scalars(report: dict, prefix: str = "") -> dict:
    """The numbers of a family's demo report, nested dicts flattened one level ("discrete.kappa")."""
    out = {}
    for k, v in sorted(report.items()):
        if k in ("family", "scenarios"):
            continue
        if isinstance(v, dict) and not prefix:
            out.update(_scalars(v, f"{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[prefix + k] = v
        elif isinstance(v, (str, bool)) and not prefix:
            out[k] = v
    return out


def design_table(demo: dict, family: str) -> str:
    rows = [(name, e) for name, e in sorted(demo.items()) if isinstance(e, dict) and e.get("family") == family]
    if not rows:
        return "(no demo observer of this family)\n"
    out = []
    for name, e in rows:
        figures = _scalars(e)
        out.append(f"`{name}`\n\n" + _table(["figure", "value"], [[k, v] for k, v in figures.items()]))
    return "\n".join(out)


def _stats_row(label: str, s: dict) -> list:
    """A row of the one definition of every validation (codegen.validation.metrics.signal_report)."""
    unit = (s.get("unit") or "–") + (f" (from {s['converted_from']})" if s.get("converted_from") else "")
    return [label, unit, s.get("rms"), s.get("truth_rms"), s.get("rms_percent"), s.get("max"), s.get("mae"),
            s.get("nmse_percent")]


def validation_table(demo: dict, family: str) -> str:
    out = []
    for name, e in sorted(demo.items()):
        if not isinstance(e, dict) or e.get("family") != family:
            continue
        for scen, r in e["scenarios"].items():
            rows = [_stats_row(sig, s) for sig, s in r["observer"].items()]
            for base, sigs in r.get("baselines", {}).items():
                rows += [_stats_row(f"{sig} ({base})", s) for sig, s in sigs.items()]
            after = {s.get("after_s") for s in r["observer"].values()}
            window = f"after the first {after.pop():g} s; " if len(after) == 1 and None not in after else ""
            out.append(f"`{name}`, scenario `{scen}` on the {r.get('plant_model', r['plant'])} plant "
                       f"({r['samples']} samples, {r['status_flags']} flagged; {window}every figure in its row's unit)\n\n"
                       + _table(["signal", "unit", "RMS", "truth RMS", "RMS % of truth", "max", "MAE", "NMSE %"], rows))
    return "\n".join(out) or "(no demo scenario)\n"


def real_data_table(demo: dict) -> str:
    """The shared log: every estimator's sideslip RMS on the evaluation part (the headline: no number
    of any estimator was chosen on it), on the identification part and on the whole half."""
    real = demo["real_data"]
    parts = real.get("parts", {})
    entries = [("observer", "observer (`stanford_sideslip`)", real["observer"])]
    entries += [(name, name, t) for name, t in sorted(real["baselines"].items())]
    entries += [(name, f"`{name}`", t) for name, t in sorted(real.get("other_observers", {}).items())]
    entries += [(name, name, t) for name, t in sorted(real.get("other_baselines", {}).items())]
    rows = [[label, parts.get(key, {}).get("evaluation"), parts.get(key, {}).get("identification"), t["beta"]["rms"],
             t["beta"].get("rms_percent"), t["beta"]["max"], t["beta"]["mae"]] for key, label, t in entries]
    return _table(["estimator", "β RMSE evaluation part [deg]", "identification part", "whole half",
                   "whole half, % of β's RMS", "β max [deg]", "β MAE [deg]"], rows)


def bench_table(bench: dict) -> str:
    rows = []
    for name, r in sorted(bench["observers"].items()):
        d = r["design"]
        ours = d.get("ours_clarabel", {}).get("seconds")     # absent: the single solve stopped short
        peer = d.get("cvxpy_clarabel", {}).get("seconds")
        rows.append([f"`{name}`", r["batch_ns_per_sample"], r["instructions_per_step"], r["flops_per_step"]["total"],
                     r["step_python_ns"], r["casadi_function_call_ns"], r["numpy_step_ns"],
                     None if ours is None else 1e3 * ours,
                     None if peer is None else 1e3 * peer])
    return _table(["observer", "C batch [ns/sample]", "instructions/step", "flops/step", "Python step [ns]",
                   "CasADi call [ns]", "numpy step [ns]", "LMI ours [ms]", "LMI CVXPY+Clarabel [ms]"], rows)


def spread_table(spread: dict) -> str:
    rows = []
    for name, r in sorted(spread["observers"].items()):
        for how, key in ((f"re-solve on {spread['cpu']} (QEMU)", "cpu"), ("1e-13 perturbation", "perturbation")):
            for row in r[key]:
                if row.get("problem") is None:
                    rows.append([f"`{name}`", how, "–", row.get("error", "failed"), "", ""])
                else:
                    rows.append([f"`{name}`", how, row["problem"], row["objective"], row["variables"],
                                 row["worst_variable"]])
    return _table(["observer", "against the committed design", "LMI problem", "objective (relative)",
                   "decision variables (relative)", "largest in"], rows)


def family_bench_table(bench: dict, family: str) -> str:
    """A family's own study in the bench record (``Family.bench_family``): one row per point,
    every key a column (first-seen order)."""
    rows = bench.get("families", {}).get(family)
    if not rows:
        return "(no study of this family in the recorded bench run)\n"
    columns = list(dict.fromkeys(k for r in rows for k in r))
    return _table(columns, [[r.get(c) for c in columns] for r in rows])


def sweep_table(sweep: dict) -> str:
    """A recorded ``uiogen sweep --json``: one row per grid point, its settings, the outcome and
    the figures the sweep was asked to show."""
    keys = list(sweep["grid"])
    show = sweep.get("show", ["gamma"])
    rows = [[p["settings"][k] for k in keys] + [p["outcome"]] + [p.get(c, "–") for c in show]
            for p in sweep["points"]]
    return _table([f"`{k}`" for k in keys] + ["outcome"] + show, rows)


def _render(kind: str, arg: str, demo: dict | None, bench: dict | None, spread: dict | None = None) -> str | None:
    if kind == "sweep":
        record = _load(DATA / "sweeps" / f"{arg}.json")
        return None if record is None else sweep_table(record)
    if kind == "record":
        record = _load(DATA / f"{arg}.json")
        if record is None:
            return None
        note = record["table"].get("note")         # a line under the table (how and where it was measured)
        return _table(record["table"]["header"], record["table"]["rows"]) + (f"\n{note}\n" if note else "")
    if kind == "family_bench":
        return None if bench is None else family_bench_table(bench, arg)
    if kind == "spread":
        return None if spread is None else spread_table(spread)
    if kind in ("design", "validation", "real_data") and demo is None:
        return None
    if kind == "bench" and bench is None:
        return None
    if kind == "design":
        return design_table(demo, arg)
    if kind == "validation":
        return validation_table(demo, arg)
    if kind == "real_data":
        return real_data_table(demo)
    if kind == "bench":
        return bench_table(bench)
    raise ConfigurationError(f"unknown docs table kind {kind!r} (design, validation, real_data, bench, spread, "
                             f"family_bench, sweep, record)")


def _load(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f"{path}: not a JSON record of `uiogen demo/bench --json` ({exc}); re-run `make docs`",
                                 source=str(path)) from None


# pages copied into the docs from where they live beside the code
COPIES = {"adding_a_family.md": ROOT / "codegen" / "families" / "README.md"}


def _copied(source: Path) -> str:
    text = source.read_text()
    # links of the original, relative to its folder, as the docs site sees them
    text = text.replace("](../../docs/", "](")
    return (f"<!-- copied from {source.relative_to(ROOT)} by `uiogen docs`; edit it there -->\n" + text)


def update(check: bool = False, demo_path: Path | None = None, bench_path: Path | None = None,
           docs: Path | None = None) -> list:
    """Rewrite (or with ``check`` only compare) every marked region of the docs, and the pages
    copied from beside the code; returns the pages that changed (or would change)."""
    docs = Path(docs or DOCS)
    demo = _load(Path(demo_path or DATA / "demo.json"))
    bench = _load(Path(bench_path or DATA / "bench.json"))
    spread = _load(DATA / "spread.json")
    changed = []
    for name, source in COPIES.items():
        page = docs / name
        text = _copied(source)
        if not page.is_file() or page.read_text() != text:
            changed.append(page)
            if not check:
                page.write_text(text)
    for page in sorted(docs.rglob("*.md")):
        text = page.read_text()

        def fill(m):
            body = _render(m.group(2), m.group(3), demo, bench, spread)
            return m.group(0) if body is None else m.group(1) + body + m.group(5)
        new = REGION.sub(fill, text)
        if new != text:
            changed.append(page)
            if not check:
                page.write_text(new)
    return changed


def main(check: bool = False) -> int:
    if not DOCS.is_dir():        # an installed uiogen: the docs are the repository's, not the package's
        raise UnsupportedError(f"uiogen docs rewrites the docs of a source checkout, and there is none here ({DOCS} "
                               f"does not exist: this uiogen is installed); run it in a clone of the repository")
    changed = update(check=check)
    for p in changed:
        print(f"{'differs' if check else 'updated'}: {p.relative_to(ROOT)}")
    if check and changed:
        print("the docs' tables differ from docs/data/*.json: run `uiogen docs` (or `make docs` to re-record them first)")
        return 1
    return 0
