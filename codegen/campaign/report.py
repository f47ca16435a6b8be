"""A campaign's summary (distributions of the per-run rows) and its plots."""
from __future__ import annotations

import math

import numpy as np

from ..project import outputs

PCTS = (50, 90, 99)


def error_signals(rows) -> list:
    return [k[4:] for k in (rows[0] if rows else {}) if k.startswith("rms.")]


def _ok(rows):
    return [r for r in rows if r.get("status") == "ok"]


def worst_runs(spec, rows) -> list:
    ok = _ok(rows)
    key = f"rms.{spec.rank_by}"
    return [r["run"] for r in sorted(ok, key=lambda r: -r[key])[:spec.worst]]


def _dist(x) -> dict:
    x = np.asarray([v for v in x if not math.isnan(v)], float)
    if x.size == 0:
        return {}
    return {"mean": float(x.mean()), **{f"p{p}": float(np.percentile(x, p)) for p in PCTS}, "max": float(x.max()),
            "min": float(x.min())}


def _ranks(x):
    r = np.empty(len(x))
    r[np.argsort(x, kind="stable")] = np.arange(len(x))
    return r


def sensitivity(spec, rows) -> dict:
    """Spearman rank correlation of each signal's RMS error with each dispersed value."""
    ok = _ok(rows)
    out = {}
    if len(ok) < 3:
        return out
    for s in error_signals(ok):
        e = _ranks([r[f"rms.{s}"] for r in ok])
        row = {}
        for c in spec.dispersed():
            v = np.array([r[c] for r in ok], float)
            if np.ptp(v) == 0:
                continue
            row[c] = float(np.corrcoef(_ranks(v), e)[0, 1])
        out[s] = row
    return out


def summarize(spec, rows, wall_s: float, workers: int, scheduler: str) -> dict:
    from .runner import certified_gain_norm
    ok = _ok(rows)
    gamma = ok[0]["gamma"] if ok else None
    ratios = [r["ratio"] for r in ok]
    cert = certified_gain_norm(spec.config())
    s = {"observer": spec.observer, "spec": spec.source, "scenarios": list(spec.scenarios), "seed": spec.seed,
         **({"logs": list(spec.logs)} if spec.logs else {}),
         # what each run that produced no result raised (a log refused by its checks, say), by run
         "errors": {str(r["run"]): r["error"] for r in rows if r.get("status") == "error"},
         # every run that is not "ok" (flagged samples, a spun or diverged plant, a lost worker, an
         # error) is counted here by its status and left out of every distribution below
         "runs": len(rows), "runs_ok": len(ok), "runs_failed": {st: sum(r["status"] == st for r in rows)
                                                              for st in sorted({r["status"] for r in rows}) if st != "ok"},
         "wall_s": wall_s, "runs_per_s": len(rows) / wall_s if wall_s > 0 else None, "workers": workers,
         "scheduler": scheduler,
         "rms": {sig: _dist([r[f"rms.{sig}"] for r in ok]) for sig in error_signals(ok)},
         "max": {sig: _dist([r[f"max.{sig}"] for r in ok]) for sig in error_signals(ok)},
         "scheduling_clamped": {"fraction_of_samples": _dist([r["clamped_fraction"] for r in ok]),
                                "runs_with_any": sum(r["clamped_fraction"] > 0 for r in ok)},
         "certificate": {"kind": cert, "gamma": gamma, "ratio": _dist(ratios),
                         "runs_above_gamma": sum(x > gamma for x in ratios) if gamma is not None else None,
                         "ratio_definition": {"peak": "sup_t |x - x_hat|_2 (model states, SI) / sup_t |d| "
                                                      "(unknown input), after the settle time",
                                              "l2": "|xi - xi_hat|_2 / |phi_r|_2 (xi: the [switching] performance "
                                                    "outputs), after the settle time"}.get(cert)},
         "worst_runs": worst_runs(spec, rows), "rank_by": spec.rank_by,
         "sensitivity_spearman": sensitivity(spec, rows),
         "units": "rms/max errors: angles in degrees (deg/s for rates), others in SI"}
    return s


def format_summary(s: dict) -> str:
    failed = ", ".join(f"{n} {st}" for st, n in s["runs_failed"].items())
    speed = f"{s['runs_per_s']:.1f} runs/s, " if s.get("runs_per_s") else ""
    resumed = f", {s['resumed_runs']} of them from the results kept before" if s.get("resumed_runs") else ""
    lines = [f"{s['observer']}: {s['runs']} runs ({s['runs_ok']} ok{'; not ok: ' + failed if failed else ''}) "
             f"of {', '.join(s.get('logs') or s['scenarios'])} in {s['wall_s']:.1f} s ({speed}{s['scheduler']}{resumed})",
             f"{'RMS error':14s} {'mean':>10s} {'p50':>10s} {'p90':>10s} {'p99':>10s} {'max':>10s}"]
    for sig, d in s["rms"].items():
        if d:
            lines.append(f"{sig:14s} " + " ".join(f"{d[k]:10.4g}" for k in ("mean", "p50", "p90", "p99", "max")))
    c = s["certificate"]
    if c["kind"] and c["gamma"] is not None and c["ratio"]:
        r = c["ratio"]
        lines.append(f"certificate ({c['kind']}): gamma {c['gamma']:.4g}; empirical ratio p50 {r['p50']:.4g}, p99 "
                     f"{r['p99']:.4g}, max {r['max']:.4g}; {c['runs_above_gamma']} runs above gamma")
    sc = s["scheduling_clamped"]
    lines.append(f"SCHEDULING_CLAMPED: mean fraction {sc['fraction_of_samples'].get('mean', 0):.4g} of samples, "
                 f"{sc['runs_with_any']} runs with any")
    lines.append(f"worst runs by RMS {s['rank_by']}: {s['worst_runs']} (uiogen campaign SPEC --only K)")
    lines += [f"run {k}: {e}" for k, e in list(s.get("errors", {}).items())[:5]]
    sens = s["sensitivity_spearman"].get(s["rank_by"], {})
    if sens:
        top = sorted(sens.items(), key=lambda kv: -abs(kv[1]))[:4]
        lines.append(f"RMS {s['rank_by']} most sensitive to: " + ", ".join(f"{k} ({v:+.2f})" for k, v in top))
    return "\n".join(lines)


def format_row(row: dict) -> str:
    return "\n".join(f"{k:22s} {v!r}" if isinstance(v, float) else f"{k:22s} {v}" for k, v in row.items())


def _save(fig, out_dir, name: str) -> str:
    """Lay out, write ``out_dir/NAME.png`` and close a figure; its path."""
    plt = outputs.pyplot()
    fig.tight_layout()
    path = f"{out_dir}/{name}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plots(spec, rows, traces: dict, out_dir) -> list:
    """error_cdf.png (per signal, overall and by third of the most influential dispersion),
    sensitivity.png (Spearman heat map), worst_runs.png (errors over time of the worst runs)."""
    plt = outputs.pyplot()
    ok = _ok(rows)
    sigs = error_signals(ok)
    paths = []
    if not ok:
        return paths
    sens = sensitivity(spec, rows)
    fig, axes = plt.subplots(1, len(sigs), figsize=(3.2 * len(sigs), 3.2), squeeze=False)
    for ax, s in zip(axes[0], sigs):
        e = np.sort([r[f"rms.{s}"] for r in ok])
        ax.step(e, np.arange(1, e.size + 1) / e.size, "k", where="post", label="all runs")
        if sens.get(s):
            c, _ = max(sens[s].items(), key=lambda kv: abs(kv[1]))
            v = np.array([r[c] for r in ok])
            lo, hi = np.percentile(v, [100 / 3, 200 / 3])
            for mask, lab, col in ((v <= lo, f"{c} low third", "b"), (v >= hi, f"{c} high third", "r")):
                ee = np.sort(np.array([r[f"rms.{s}"] for r in ok])[mask])
                if ee.size:
                    ax.step(ee, np.arange(1, ee.size + 1) / ee.size, col, where="post", lw=0.9, label=lab)
        ax.set_xlabel(f"RMS error {s}")
        ax.set_ylabel("fraction of runs")
        ax.legend(fontsize=6, loc="lower right")
    fig.suptitle(f"{spec.observer}: error CDFs over {len(ok)} runs")
    paths.append(_save(fig, out_dir, "error_cdf"))
    cols = spec.dispersed()
    if sens and cols:
        m = np.array([[sens[s].get(c, 0.0) for c in cols] for s in sigs])
        fig, ax = plt.subplots(figsize=(1.0 + 0.7 * len(cols), 1.2 + 0.45 * len(sigs)))
        im = ax.imshow(m, cmap="RdBu_r", vmin=-1, vmax=1, aspect="auto")
        ax.set_xticks(range(len(cols)), cols, rotation=60, ha="right", fontsize=7)
        ax.set_yticks(range(len(sigs)), [f"RMS {s}" for s in sigs], fontsize=7)
        for i in range(len(sigs)):
            for j in range(len(cols)):
                ax.text(j, i, f"{m[i, j]:+.2f}", ha="center", va="center", fontsize=6)
        fig.colorbar(im, ax=ax, label="Spearman rank correlation")
        ax.set_title("sensitivity of the error to each dispersion", fontsize=9)
        paths.append(_save(fig, out_dir, "sensitivity"))
    if traces:
        fig, axes = plt.subplots(len(sigs), 1, figsize=(9, 1.8 * len(sigs)), sharex=True, squeeze=False)
        for k, tr in traces.items():
            for ax, s in zip(axes[:, 0], sigs):
                ax.plot(tr["t"], tr[f"{s}_estimate"] - tr[f"{s}_truth"], lw=0.7, label=f"run {k}")
                ax.set_ylabel(f"{s} error [SI]", fontsize=7)
        axes[0, 0].legend(fontsize=7, loc="upper right")
        axes[-1, 0].set_xlabel("t [s]")
        fig.suptitle(f"worst runs by RMS {spec.rank_by}")
        paths.append(_save(fig, out_dir, "worst_runs"))
    return paths
