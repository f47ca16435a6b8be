"""``uiogen demo``: the README's main job, after design + generate + build.

For every built-in observer: its certificate and design figures (from the design lock: the typed
certificate, and the family's ``DemoFigures``), then the compiled C step on its family's demo
scenarios (``Scenarios.demo_scenarios``) against the plant its family names for it (``DemoPlant``,
else the nominal one), beside the baselines, in the table format of its paper; then the real-data
table (the shared Stanford log). Capabilities: :mod:`codegen.contract.capabilities`.
"""
from __future__ import annotations

import json

from ..certificate import text
from ..certificate.certificate import Certificate, of_lock
from ..design import lock as design_lock
from ..contract import registry
from ..contract.capabilities import DemoFigures, DemoPlant, Scenarios
from ..project import observer_file as observers
from ..errors import UnsupportedError
from . import logs, run as validate, stanford

REAL_DATA_OBSERVER = "stanford_sideslip"
REAL_DATA_OTHERS = ("ts_fuzzy_uio_stanford", "stanford_sideslip_nonlinear_tyre")     # same log, other families
# of these, the ones whose family's demo scenarios are not theirs (shown on the real data only);
# stanford_sideslip_nonlinear_tyre has no scenarios but its design figures are reported
REAL_DATA_ONLY = ("ts_fuzzy_uio_stanford",)


def run_all(names=None) -> dict:
    """{observer: its demo entry}: the certificate (JSON) and design figures from its lock (the
    family's ``DemoFigures``) and its runs on its family's demo scenarios (``"scenarios"``), for
    every built-in observer but the real-data ones (or for ``names``)."""
    report = {}
    for name in [n for n in observers.names() if n not in (REAL_DATA_OBSERVER, *REAL_DATA_ONLY)]:
        if names is not None and name not in names:
            continue
        config = observers.get(name)
        family = config.observer_family
        art = json.loads(design_lock.path(config).read_text())
        certificate = of_lock(art, str(design_lock.path(config)))
        plant = family.demo_plant(config) if isinstance(family, DemoPlant) else "nominal"
        scenarios = family.demo_scenarios if isinstance(family, Scenarios) else ()
        scen = {s: validate.run_scenario(config, s, plant) for s in scenarios}
        figures = family.demo_report(art) if isinstance(family, DemoFigures) else {}
        report[name] = {"family": config.family, **figures, "certificate": certificate.to_json(), "scenarios": scen}
    return report


def entry_lines(entry: dict) -> list:
    """The design part of an observer's demo entry as text (:func:`codegen.certificate.text.demo_lines`)."""
    return text.demo_lines(registry.get(entry["family"]), Certificate.from_json(entry["certificate"]))


def main(json_output: bool = False, report_dir=None) -> int:
    """``uiogen demo``: the text tables (or ``--json``); with ``report_dir`` the HTML page
    (:mod:`codegen.validation.report`) and a summary of a few lines pointing at it."""
    from ..extension.build import require_built
    require_built("demo", "demo")                 # said once, before minutes of simulation
    if not stanford.STANFORD_PATH.is_file():
        raise UnsupportedError(f"uiogen demo ends on the shared Stanford log ({stanford.STANFORD_PATH}), which is "
                               f"not there: run it in a source checkout beside ../shared (make demo); an observer "
                               f"of your own runs on a log with uiogen validate NAME --data PATH")
    report = run_all()
    real, others = run_real_data()
    if json_output:
        from .metrics import DEFINITIONS

        def scenario_json(r):       # the metrics' definitions once, at the top
            return {k: v for k, v in json.loads(validate.to_json(r)).items() if k != "definitions"}
        print(json.dumps({"definitions": DEFINITIONS, "real_data": real_data_json(real, others),
                          **{n: {**{k: v for k, v in e.items() if k != "scenarios"},
                                 "scenarios": {s: scenario_json(r) for s, r in e["scenarios"].items()}}
                             for n, e in report.items()}}, indent=1, sort_keys=True))
        return 0
    if report_dir is not None:
        from . import report as html_report
        page = html_report.write_demo(report, {REAL_DATA_OBSERVER: real, **others}, report_dir)
        for line in summary_lines(report, real, others):
            print(line)
        print(f"report: {page.resolve()}")
        return 0
    plot = observers.get(REAL_DATA_OBSERVER).workspace.plots / f"{REAL_DATA_OBSERVER}_real_data.png"
    plot.parent.mkdir(parents=True, exist_ok=True)
    logs.plot(real, str(plot))
    for name, e in report.items():
        print(f"== {name}")
        for line in entry_lines(e):
            print("   " + line)
        for r in e["scenarios"].values():
            print("   " + validate.header(name, r))
            print("     " + validate.format_table(r).replace("\n", "\n     "))
    for line in real_data_lines(real, others):
        print(line)
    print(f"   plot: {plot}")
    return 0


def summary_lines(report: dict, real: dict, others: dict) -> list:
    """What ``uiogen demo --report`` prints beside the page: the real-data ranking and, per
    simulated observer, its scenarios and flagged samples (the tables are on the page)."""
    from .report import rank_real_data
    lines = ["real data (shared Stanford log), sideslip RMS, best first:"]
    for label, _, rms, what in rank_real_data({REAL_DATA_OBSERVER: real, **others}):
        lines.append(f"   {label:44s} {rms:8.4f} deg ({what})")
    lines.append(f"simulated ({len(report)} observers): scenario [samples, flagged]")
    for name, e in report.items():
        runs = ", ".join(f"{s} [{r['samples']}, {r['status_flags']}]" for s, r in e["scenarios"].items())
        lines.append(f"   {name:44s} {runs or 'design figures only'}")
    return lines


def run_real_data() -> tuple:
    """The real-data part of the demo: (run of REAL_DATA_OBSERVER, {other observer: its run}) on the
    shared log, each run with its own baselines (an observer of the nonlinear-tyre model brings its
    same-tyre EKF and UKF peers, :func:`codegen.validation.logs.run`)."""
    real = logs.run(REAL_DATA_OBSERVER, "stanford")
    others = {n: logs.run(n, "stanford") for n in REAL_DATA_OTHERS if n in observers.names()}
    return real, others


def real_data_json(real: dict, others: dict) -> dict:
    """The demo JSON's ``real_data``: the main run's observer and baselines, every other observer,
    the baselines only another observer's run has (``other_baselines``, named 'PEER (OBSERVER)'), and
    each estimator's sideslip RMS on the evaluation and identification parts of the log (``parts``,
    the same keys: "observer", a baseline, an other observer's name, 'PEER (OBSERVER)')."""
    extra = {f"{peer} ({n})": t for n, r in others.items() for peer, t in r["baselines"].items()
             if peer not in real["baselines"]}
    parts = {}
    for key, run, row in [("observer", real, "observer"), *[(b, real, b) for b in real["baselines"]],
                          *[(n, r, "observer") for n, r in others.items()],
                          *[(f"{peer} ({n})", r, peer) for n, r in others.items() for peer in r["baselines"]
                            if peer not in real["baselines"]]]:
        sp_ = run.get("splits")
        if sp_:
            parts[key] = {"evaluation": sp_["evaluation"][row], "identification": sp_["identification"][row]}
    out = {**{k: real[k] for k in ("observer", "baselines")},
           "other_observers": {n: r["observer"] for n, r in others.items()}, "other_baselines": extra}
    if parts:
        out["parts"] = parts
        out["t_split"] = real["splits"]["t_split"]
    return out


def _note(name: str) -> str:
    config = observers.get(name)
    return config.observer_family.title


def real_data_lines(real: dict, others: dict) -> list:
    """The real-data table of ``uiogen demo`` as text: the main observer with the source repository's
    baselines, then each other observer on the same log with the peers only its run has."""
    lines = [f"== real data: {REAL_DATA_OBSERVER} on {real['data']} ({real['samples']} samples at 100 Hz, "
             f"sideslip reference atan2(vy, vx) of the log's velocities; {real['status_flags']} flagged)",
             "   " + logs.format_table(real).replace("\n", "\n   ")]
    for n, r in others.items():
        t = r["observer"]
        line = (f"   {n} (same log; {_note(n)}; {r['status_flags']} flagged): beta RMSE {t['beta']['rms']:.4f} deg, "
                f"max {t['beta']['max']:.4f} deg, MAE {t['beta']['mae']:.4f} deg")
        if "delta" in t:
            line += f"; delta (an unknown input) RMSE {t['delta']['rms']:.4f} deg"
        lines.append(line)
        for peer, b in r["baselines"].items():
            if peer not in real["baselines"]:
                lines.append(f"     {peer} (peer of {n}, same model and parameter file): beta RMSE "
                             f"{b['beta']['rms']:.4f} deg, max {b['beta']['max']:.4f} deg, MAE {b['beta']['mae']:.4f} deg")
    return lines
