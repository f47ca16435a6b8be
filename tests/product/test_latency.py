"""The latency table of ``make bench`` (:mod:`codegen.tools.latency`): its form, never its speed.

The figures are for the bench to report (ratios against floors measured in the same run); these tests
check that the table runs on one tiny case and comes out well formed (every column, a floor beside
every verb, finite ratios), and that the committed record ``docs/data/latency.json`` is well formed.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from codegen import families as registry
from codegen.project import observer_file as observers
from codegen.tools import latency

ROOT = Path(__file__).resolve().parents[2]


def _smallest_family():
    """The family whose example observer has the fewest states (its starter designs fastest)."""
    def states(name):
        config = observers.get(registry.get(name).example)
        return len(json.loads(config.workspace.design_lock(config.name).read_text())["signals"]["state"])
    return min((n for n in registry.names() if registry.get(n).example), key=lambda n: (states(n), n))


@pytest.mark.slow       # three fresh interpreters (uiogen new, design twice) and a design in this process
def test_a_starter_case_gives_a_well_formed_table():
    family = _smallest_family()
    record = latency.measure([family], cases=("starter",), verbs=("design",), repeats=1)
    assert latency.check_record(record) == []
    table = record["table"]
    assert table["header"] == latency.HEADER
    assert [row[2] for row in table["rows"]] == ["new", "design --update"]      # new: the prerequisite
    new, design = record["rows"]
    assert new["again_s"] is None and new["floor"] == "start-up"
    assert design["floor"].endswith("LMI solve(s)") and design["floors"]["lmi_solves"] >= 1
    assert design["floor_s"] == pytest.approx(record["startup_s"] + design["floors"]["lmi_s"])
    for key in ("first_ratio", "again_ratio"):
        assert math.isfinite(design[key]) and design[key] > 0
    assert design["first_ratio"] == pytest.approx(design["first_s"] / design["floor_s"])
    assert "DIR" in " ".join(design["command"]) and design["rc"] == [0, 0]
    assert record["load_before"]["loadavg"] and record["load_after"]["uptime"]
    json.loads(json.dumps(record, allow_nan=False))                     # a JSON record, no NaN in it
    text = latency.markdown(record)
    assert text.startswith("| " + " | ".join(latency.HEADER) + " |") and "Load average" in text


def test_the_form_check_catches_a_missing_floor_and_a_failed_command():
    row = {"observer": "x", "verb": "design", "first_s": 1.0, "again_s": 1.0, "floor_s": 0.5, "first_ratio": 2.0,
           "again_ratio": 2.0, "rc": [0, 0], "errors": []}
    good = {"startup_s": 0.5, "rows": [row], "table": {"header": latency.HEADER, "rows": [["c"] * len(latency.HEADER)]}}
    assert latency.check_record(good) == []
    for change, words in (({"floor_s": None, "first_ratio": None}, "floor_s None"),
                          ({"again_ratio": float("nan")}, "again_ratio nan"),
                          ({"rc": [0, 2], "errors": ["ConfigurationError: x"]}, "exit [0, 2]"),
                          ({"floor_s": 0.1}, "below the start-up")):
        bad = dict(good, rows=[dict(row, **change)])
        assert any(words in p for p in latency.check_record(bad)), (change, latency.check_record(bad))
    short = dict(good, table={"header": latency.HEADER, "rows": [["c"]]})
    assert any("1 cells" in p for p in latency.check_record(short))


def test_the_recorded_table_is_well_formed():
    record = json.loads((ROOT / "docs" / "data" / f"{latency.RECORD}.json").read_text())
    assert latency.check_record(record) == []
    assert record["repeats"] >= 1 and record["load_before"]["uptime"]
    # the committed record is a full run: every family with a built-in, its built-in and its starter
    families = [n for n in registry.names() if latency._choice(registry.get(n)) is not None]
    assert sorted(record["families"]) == sorted(families)
    assert {(row["family"], row["case"]) for row in record["rows"]} == {(f, c) for f in families for c in latency.CASES}
