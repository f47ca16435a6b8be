"""``uiogen demo``: the README's main job, after design + generate + build.

For every built-in observer: its design figures (from the design lock, ``Family.demo_report``),
then the compiled C step on its family's demo scenarios (``Family.demo_scenarios``) against the
plant its family names for it (an optional ``demo_plant(config)`` of the family, else the nominal
one), beside the baselines, in the table format of its paper; then the real-data table
(the shared Stanford log).
"""
from __future__ import annotations

import json

from . import design_lock, families, observers, validate
from .toolchain import GENERATED_DIR

REAL_DATA_OBSERVER = "stanford_sideslip"
REAL_DATA_OTHERS = ("ts_fuzzy_uio_stanford",)     # same log, other families
REAL_DATA_PLOT = GENERATED_DIR.parent / "build" / "stanford_sideslip_real_data.png"


def main(json_output: bool = False) -> int:
    report = {}
    for name in [n for n in observers.names() if n != REAL_DATA_OBSERVER and n not in REAL_DATA_OTHERS]:
        config = observers.get(name)
        family = families.get(config.family)
        art = json.loads(design_lock.path(config).read_text())
        plant = getattr(family, "demo_plant", lambda _config: "nominal")(config)
        scen = {s: validate.run_scenario(config, s, plant) for s in family.demo_scenarios}
        report[name] = {"family": config.family, **family.demo_report(art), "scenarios": scen}
    real = validate.run_data(REAL_DATA_OBSERVER, "stanford")
    others = {n: validate.run_data(n, "stanford") for n in REAL_DATA_OTHERS if n in observers.names()}
    REAL_DATA_PLOT.parent.mkdir(exist_ok=True)
    validate.plot_data(real, str(REAL_DATA_PLOT))
    if json_output:
        print(json.dumps({"real_data": {**{k: real[k] for k in ("observer", "baselines")},
                                        "other_observers": {n: r["observer"] for n, r in others.items()}}, **{n: {**{k: v for k, v in e.items() if k != "scenarios"},
                              "scenarios": {s: json.loads(validate.to_json(r)) for s, r in e["scenarios"].items()}}
                          for n, e in report.items()}}, indent=1, sort_keys=True))
        return 0
    for name, e in report.items():
        print(f"== {name}")
        for line in families.get(e["family"]).demo_lines(e):
            print("   " + line)
        for r in e["scenarios"].values():
            print("   " + validate.header(name, r))
            print("     " + validate.format_table(r).replace("\n", "\n     "))
    print(f"== real data: {REAL_DATA_OBSERVER} on {real['data']} ({real['samples']} samples at 100 Hz, "
          f"optical-sensor sideslip truth; {real['status_flags']} flagged)")
    print("   " + validate.format_data_table(real).replace("\n", "\n   "))
    for n, r in others.items():
        t = r["observer"]
        print(f"   {n} (same log; linear tyres, delta estimated as an unknown input): beta RMSE "
              f"{t['beta']['rms']:.4f} deg, max {t['beta']['max']:.4f} deg; delta RMSE {t['delta']['rms']:.4f} deg")
    print(f"   plot: {REAL_DATA_PLOT}")
    return 0
