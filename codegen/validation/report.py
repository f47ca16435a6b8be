"""The HTML report of ``uiogen validate --report DIR`` and ``uiogen demo --report DIR``: one page
(``DIR/index.html``) with the figures beside it as PNG files and the tables of the text output.

Each figure shows, per estimated signal, the truth (or the log's reference) and the compiled
observer's estimate with its peers (the baselines run on the same measurements, where the run
keeps their traces), the error of each below, and the samples the C step flagged (a status bit
set: clamped scheduling, non-finite input, numerical failure, warming up) as shaded spans.
Angles are drawn in degrees. The page is static HTML: no script, no network, opens from disk.
"""
from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from ..project import outputs
from . import metrics
from . import logs, run as validate

PAGE = "index.html"
COLORS = ("tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:cyan", "tab:brown")
FLAG_COLOR = "#f4c7c3"

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1150px; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; margin-top: 2em; }
h3 { margin-top: 1.5em; }
pre { background: #f6f6f6; padding: .6em; overflow-x: auto; font-size: .85em; }
table { border-collapse: collapse; margin: .6em 0; font-size: .9em; }
td, th { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
td:first-child, th:first-child { text-align: left; }
tr.best td { font-weight: bold; background: #eef6ee; }
img { max-width: 100%; border: 1px solid #ddd; margin: .4em 0; }
.note { color: #555; font-size: .9em; }
nav ul { columns: 2; }
"""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "figure"


def _page(title: str, body: list) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def _pre(text: str) -> str:
    return f"<pre>{html.escape(text)}</pre>"


def _img(path: Path, alt: str) -> str:
    return f'<img src="{html.escape(path.name)}" alt="{html.escape(alt)}">'


def _flag_spans(axes, t, status) -> None:
    """Shade the samples whose status word is non-zero (one artist per axis, however many spans)."""
    if status is None:
        return
    flagged = np.asarray(status) != 0
    if not flagged.any():
        return
    for ax in axes:
        ax.fill_between(t, 0, 1, where=flagged, step="mid", color=FLAG_COLOR, linewidth=0,
                        transform=ax.get_xaxis_transform(), zorder=0)


def scenario_figure(result: dict, path: Path) -> Path:
    """Truth and estimates (and the peers' traces a family keeps in ``signals["baselines"]``),
    the errors below, flagged samples shaded; one row per signal that has a truth."""
    plt = outputs.pyplot()
    sig = result["signals"]
    units = result.get("units", {})
    t = np.asarray(sig["t"])
    names = [n for n in sig["estimate"] if n in sig["truth"]]
    peers = sig.get("baselines", {})
    fig, axes = plt.subplots(len(names), 2, figsize=(12, 2.1 * len(names) + 0.8), sharex=True, squeeze=False)
    for row, n in zip(axes, names):
        unit, scale, _ = metrics.reported_unit(units.get(n))      # the unit of the tables' rows
        truth, est = np.asarray(sig["truth"][n]) * scale, np.asarray(sig["estimate"][n]) * scale
        row[0].plot(t, truth, "k", lw=1.0, label="truth")
        row[0].plot(t, est, "r--", lw=1.0, label="observer (C step)", zorder=3)
        row[1].plot(t, est - truth, "r", lw=0.8, label="observer", zorder=3)
        for color, (peer, traces) in zip(COLORS, peers.items()):
            if n in traces:
                p = np.asarray(traces[n]) * scale
                row[0].plot(t, p, color=color, lw=0.7, alpha=0.8, label=peer)
                row[1].plot(t, p - truth, color=color, lw=0.7, alpha=0.8, label=peer)
        row[0].set_ylabel(f"{n} [{unit}]" if unit else n)
        row[1].set_ylabel(f"error [{unit}]" if unit else "error")
        _flag_spans(row, t, sig.get("status"))
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[0, 1].legend(loc="upper right", fontsize=7)
    axes[0, 0].set_title("truth and estimates")
    axes[0, 1].set_title("error (estimate - truth)")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    flagged = int(np.count_nonzero(np.asarray(sig["status"]))) if "status" in sig else None
    fig.suptitle(f"{result['scenario']} on the {result['plant']} plant"
                 + (f"; {flagged} flagged samples shaded" if flagged else ""))
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def data_figure(result: dict, path: Path) -> Path:
    """A logged run: sideslip reference, the observer and every peer run on the same log, their
    errors below; the large-sideslip windows and the evaluation split marked, flagged samples
    shaded. A user's column-mapped log: its own plot (:func:`codegen.validation.logs.plot`)."""
    if "estimates" in result:
        logs.plot(result, str(path))
        return path
    plt = outputs.pyplot()
    sig = result["signals"]
    t = np.asarray(sig["t"])
    deg = 180 / np.pi
    truth = np.asarray(sig["beta_true"]) * deg
    fig, ax = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    ax[0].plot(t, truth, "k", lw=0.9, label="reference atan2(vy, vx) of the log")
    traces = [("observer (C step)", "beta", "r")] + [(k, k, c) for k, c in zip(result["baselines"], COLORS)]
    for label, key, color in traces:
        b = np.asarray(sig[key]) * deg
        ours = key == "beta"          # the observer drawn above its peers
        style = {"color": color, "lw": 0.9 if ours else 0.6, "alpha": 1.0 if ours else 0.7, "zorder": 3 if ours else 2}
        ax[0].plot(t, b, label=label, **style)
        ax[1].plot(t, b - truth, label=label, **style)
    for pk in result.get("peaks", ()):
        for a in ax:
            a.axvspan(pk["t"] - logs.PEAK_HALF_WIDTH, pk["t"] + logs.PEAK_HALF_WIDTH, color="0.9", zorder=0)
    if "splits" in result:
        for a in ax:
            a.axvline(result["splits"]["t_split"], color="k", ls=":", lw=0.8)
    _flag_spans(ax, t, sig.get("status"))
    ax[0].set_ylabel("beta [deg]")
    ax[1].set_ylabel("beta error [deg]")
    ax[1].set_xlabel("t [s]")
    ax[0].legend(loc="upper right", fontsize=7)
    title = f"{result.get('name', 'observer')} on {Path(str(result['data'])).name}"
    if "splits" in result:
        title += f"; evaluation part from t = {result['splits']['t_split']:g} s (dotted)"
    if result.get("peaks"):
        title += "; grey: large-sideslip windows"
    if result["status_flags"]:
        title += f"; {result['status_flags']} flagged samples shaded"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def scenario_section(name: str, result: dict, out_dir: Path, level: int = 3) -> list:
    """The header line, the paper-format table and the figure of one simulated run."""
    fig = scenario_figure(result, out_dir / f"{_slug(name)}__{_slug(str(result['scenario']))}.png")
    return [f"<h{level}>{html.escape(str(result['scenario']))} on the {html.escape(str(result['plant']))} plant</h{level}>",
            _pre(validate.header(name, result) + "\n" + validate.format_table(result)),
            _img(fig, f"{name}: truth, estimates and errors on {result['scenario']}")]


def data_section(name: str, result: dict, out_dir: Path, level: int = 3) -> list:
    """The real-data table and figure of one logged run."""
    fig = data_figure({**result, "name": name}, out_dir / f"{_slug(name)}__data.png")
    return [f"<h{level}>{html.escape(name)} on {html.escape(Path(str(result['data'])).name)}</h{level}>",
            f'<p class="note">{result["samples"]} samples, {result["status_flags"]} flagged</p>',
            _pre(logs.format_table(result)),
            _img(fig, f"{name}: sideslip against the log's reference, peers and errors")]


def write_validation(name: str, result: dict, out_dir, data: bool) -> Path:
    """``uiogen validate ... --report DIR``: the page of one run (simulated when ``data`` is
    False, logged otherwise); returns the page's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    section = data_section(name, result, out_dir, 2) if data else scenario_section(name, result, out_dir, 2)
    page = out_dir / PAGE
    page.write_text(_page(f"uiogen validate {name}", [f"<h1>uiogen validate {html.escape(name)}</h1>", *section]))
    return page


def _table(header: list, rows: list) -> str:
    def cell(v):
        return "–" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)
    return ("<table><tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>"
            + "".join("<tr>" + "".join(f"<td>{html.escape(cell(v))}</td>" for v in r) + "</tr>" for r in rows)
            + "</table>")


def write_fit(name: str, result: dict, text: list, out_dir, plot=None) -> Path:
    """``uiogen fit ... --report DIR``: the identification's page: the fit run and every judged run
    (sideslip RMS and largest error per estimator, the figure ``plot(result, path)`` draws), the
    held-out folds' table, and the text output; returns the page's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    body = [f"<h1>uiogen fit {html.escape(name)}</h1>"]
    runs = result.get("runs") or []
    if runs:
        names = list(runs[0]["estimators"])
        body += ["<h2>The fitted numbers on the fit run and on the other runs</h2>",
                 '<p class="note">β RMS and largest error [deg], each estimator from its initial state; the '
                 'judged runs are never read by the fit.</p>',
                 _table(["run", *(f"{n} RMS" for n in names), *(f"{n} max" for n in names)],
                        [[r["data"], *(r["estimators"][n]["rms_deg"] for n in names),
                          *(r["estimators"][n]["max_abs_deg"] for n in names)] for r in runs])]
        if plot is not None:
            fig = out_dir / "runs.png"
            plot(result, fig)
            body.append(_img(fig, "sideslip of every run, truth and estimates"))
    if "table" in result:
        body += ["<h2>Held-out folds</h2>", _table(result["table"]["header"], result["table"]["rows"])]
    body += ["<h2>Output</h2>", _pre("\n".join(text))]
    page = out_dir / PAGE
    page.write_text(_page(f"uiogen fit {name}", body))
    return page


def rank_real_data(runs: dict) -> list:
    """Every estimator run on a log, best first: (label, observer name or None for a peer, sideslip
    RMS [deg] it is ranked by, what that RMS is of). ``runs``: {observer: its run on the log}, the
    main one first; the peers of the first run keep their names, a peer only a later run has is
    'PEER (peer of OBSERVER)', and a peer a later run repeats (the same KF on the same log) is
    listed once, as in :func:`codegen.validation.demo.real_data_json`. Ranked by the evaluation
    part where the run has one (no number of any estimator was chosen on it), else by the whole log."""
    rows = []
    first = next(iter(runs.values()))
    for i, (obs_name, run) in enumerate(runs.items()):
        keys = ["observer", *[b for b in run["baselines"] if i == 0 or b not in first["baselines"]]]
        for key in keys:
            label = obs_name if key == "observer" else (key if i == 0 else f"{key} (peer of {obs_name})")
            if run.get("splits"):
                rms, what = run["splits"]["evaluation"][key], f"evaluation part, t >= {run['splits']['t_split']:g} s"
            else:
                rms, what = (run["observer"] if key == "observer" else run["baselines"][key])["beta"]["rms"], "whole log"
            rows.append((label, obs_name if key == "observer" else None, rms, what))
    return sorted(rows, key=lambda r: r[2])


def write_demo(report: dict, runs: dict, out_dir) -> Path:
    """``uiogen demo --report DIR``: every observer on one page, the real-data observers first,
    best first (sideslip RMS on the log's evaluation part), then each simulated observer with its
    design figures, tables and figures. ``report``: {name: demo entry} as built by
    :func:`codegen.validation.demo.run_all`; ``runs``: {observer: its run on the shared log}, the
    demo's main real-data observer first."""
    from ..contract import registry
    from ..certificate import text
    from ..certificate.certificate import Certificate

    def entry_lines(entry):        # the design part of a demo entry, from its typed certificate
        return text.demo_lines(registry.get(entry["family"]), Certificate.from_json(entry["certificate"]))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ranking = rank_real_data(runs)
    order = [r[1] for r in ranking if r[1] is not None]
    best = order[0]
    basis = ranking[0][3]
    body = ["<h1>uiogen demo</h1>",
            f'<p>{len(set(report) | set(runs))} observers. On the shared real log the best is <b>{html.escape(best)}</b> '
            f"(sideslip RMS {ranking[[r[1] for r in ranking].index(best)][2]:.4f} deg, {html.escape(basis)}); "
            "the simulated runs follow, one section per observer.</p>",
            "<nav><ul>" + "".join(f'<li><a href="#{_slug(n)}">{html.escape(n)}</a></li>'
                                  for n in [*order, *[n for n in report if n not in order]]) + "</ul></nav>",
            "<h2>Real data: the shared Stanford log</h2>",
            "<table><tr><th>estimator</th><th>beta RMS [deg]</th><th>of</th></tr>"
            + "".join(f'<tr{" class=best" if i == 0 else ""}><td>{html.escape(label)}</td><td>{rms:.4f}</td>'
                      f"<td>{html.escape(what)}</td></tr>" for i, (label, _, rms, what) in enumerate(ranking))
            + "</table>"]
    for n in order:
        body.append(f'<h2 id="{_slug(n)}">{html.escape(n)} (real data)</h2>')
        body += data_section(n, runs[n], out_dir)
        if n in report:
            body.append(_pre("\n".join(entry_lines(report[n]))))
    for n, e in report.items():
        if n in order:
            continue
        family = registry.get(e["family"])
        body.append(f'<h2 id="{_slug(n)}">{html.escape(n)}</h2>')
        body.append(f'<p class="note">{html.escape(family.title)}</p>')
        body.append(_pre("\n".join(entry_lines(e))))
        for r in e["scenarios"].values():
            body += scenario_section(n, r, out_dir)
    page = out_dir / PAGE
    page.write_text(_page("uiogen demo", body))
    return page
