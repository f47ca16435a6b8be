"""The test modules' measured durations, which ``make test`` uses to start the longest first.

``make test`` runs two pytest-xdist workers, a module per worker at a time (``--dist loadfile``).
xdist's own order (modules with most tests first) left the longest module, started late, running
alone for minutes at the end. ``tests/conftest.py`` orders the modules by the seconds recorded in
``tests/durations.json`` instead, longest first (a greedy longest-processing-time schedule); a
module without a record goes last, in collection order. The record only orders: no test reads it
as a figure, and a stale one costs time, never a result.

Refresh it from a full run's JUnit report::

    .venv/bin/python -m pytest -n auto --dist loadfile tests --junitxml=/tmp/full.xml
    .venv/bin/python -m codegen.tools.durations /tmp/full.xml
"""
from __future__ import annotations

import argparse
import json
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

RECORD = Path(__file__).resolve().parents[2] / "tests" / "durations.json"


def module_seconds(junit: Path) -> dict:
    """{test module path: seconds (setup, call and teardown of its tests)} from a JUnit report."""
    seconds = Counter()
    for case in ET.parse(junit).iter("testcase"):
        module = case.get("classname", "").replace(".", "/") + ".py"
        seconds[module] += float(case.get("time") or 0.0)
    return {m: round(s, 1) for m, s in sorted(seconds.items(), key=lambda kv: (-kv[1], kv[0]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m codegen.tools.durations", description=__doc__.split("\n")[0])
    ap.add_argument("junit", type=Path, help="the JUnit XML report of a full run (pytest --junitxml)")
    ap.add_argument("--out", type=Path, default=RECORD)
    args = ap.parse_args(argv)
    record = module_seconds(args.junit)
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"{args.out}: {len(record)} modules, {sum(record.values()) / 60:.1f} min in all")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
