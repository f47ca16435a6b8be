"""The ``uiogen`` command line.

    uiogen list [--json]
    uiogen design NAME [--json] [--out FILE] [--update]
    uiogen generate [NAME ...] [--force] [--out DIR]
    uiogen build [NAME ...]
    uiogen check-gains NAME --gains FILE [--json]
    uiogen validate NAME --scenario S [--plant nominal|commonroad] [--json] [--plot FILE.png]
    uiogen validate NAME --data PATH|stanford [--json] [--plot FILE.png]
    uiogen demo [--json]
    uiogen bench [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from . import design_lock, emit, observers, pipeline
from .designs import linf_uio
from .errors import UiogenError


def _print_json(obj) -> None:
    print(json.dumps(obj, indent=1, sort_keys=True))


def cmd_list(args) -> int:
    rows = []
    for name in observers.names():
        cfg = observers.get(name)
        rows.append({"name": name, "family": cfg.family, "model": cfg.model,
                     "parameters": cfg.parameters, "sample_time": cfg.sample_time, "doc": cfg.doc})
    if args.json:
        _print_json(rows)
    else:
        for r in rows:
            print(f"{r['name']:28s} {r['family']:10s} model={r['model']} params={r['parameters']} "
                  f"Ts={r['sample_time']:g}s\n    {r['doc']}")
    return 0


def _design_summary(b: pipeline.ObserverBuild, path: Path) -> dict:
    sol = b.design.solution
    return {
        "observer": b.name, "artifact": str(path),
        "gamma": b.design.gamma, "gamma_quadratic": b.quadratic.gamma,
        "vertices": b.poly.n_vertices, "polytope": b.poly.kind,
        "solve_time_s": sol.solve_time_s, "build_time_s": sol.build_time_s,
        "total_design_time_s": sum(b.timings.values()),
        "solver_iterations": sol.iterations,
        "worst_block": sol.worst.label, "worst_min_eig": sol.worst.min_eig,
        "worst_relative_margin": sol.worst.relative_margin,
        "recheck_gamma": b.certificate["gamma"],
        "discrete_kappa": b.discrete_certificate.kappa,
        "discrete_contraction_per_step": b.discrete_certificate.contraction,
        "discrete_spectral_radius_max": b.discrete_certificate.augmented_radius_max,
        "sample_time": b.config.sample_time,
        "taylor_error": b.taylor_error,
    }


def _ts_summary(b: pipeline.TSFuzzyBuild, path: Path) -> dict:
    sol = b.design.solution
    ts = b.ts
    return {
        "observer": b.name, "artifact": str(path), "rules": ts.n_rules,
        "premises": [f"{p.expr} in [{p.lower:.6g}, {p.upper:.6g}]" for p in ts.premises],
        "unmeasured_consequents": [str(p) for p in ts.phi],
        "jacobian_bounds": {f"d({phi})/d{s}": [b_.lower, b_.upper]
                            for phi, row in zip(ts.phi, ts.jacobian_bounds)
                            for s, b_ in zip(ts.definition.states, row)},
        "dmvt_vertices": int(ts.theta_vertices.shape[0]), "lmi_blocks": len(sol.checks),
        "solve_time_s": sol.solve_time_s, "build_time_s": sol.build_time_s,
        "total_design_time_s": b.timings["representation_s"] + b.timings["design_s"],
        "worst_block": b.certificate["worst_block"], "worst_min_eig": b.certificate["worst_min_eig"],
        "worst_relative_margin": b.certificate["worst_relative_margin"],
        "lyapunov_decrease_max_ratio": b.decrease["max_ratio"], "sample_time": b.config.sample_time,
    }


def _switched_summary(b, path: Path) -> dict:
    sm, d = b.model, b.design
    return {
        "observer": b.name, "artifact": str(path), "modes": sm.n_modes,
        "operating_points": [dict(p) for p in sm.points], "rule": sm.rule.to_json()["axes"],
        "gamma": d.gamma, "seed_gamma": 2.1, "hinf": b.hinf, "worst_block": b.certificate["worst_block"],
        "worst_min_eig": b.certificate["worst_min_eig"], "max_pole_real_part": b.certificate["max_pole_real_part"],
        "max_pole_modulus": b.certificate["max_pole_modulus"], "assumptions": b.assumptions,
        "solve_time_s": d.solution.solve_time_s, "build_time_s": d.solution.build_time_s,
        "total_design_time_s": b.timings["representation_s"] + b.timings["design_s"],
        "discrete_spectral_radius_max": b.discrete_certificate["spectral_radius_max"],
        "discrete_contraction_per_step": b.discrete_certificate["contraction_per_step"],
        "sample_time": b.config.sample_time,
    }


def _print_switched(s: dict) -> None:
    print(f"observer {s['observer']}: seed-001 switched H-inf PI observer, {s['modes']} modes")
    for a in s["rule"]:
        print(f"  rule axis {a['name']}: premise {a['premise']}, thresholds {a['thresholds']}, range {a['range']}")
    ranks = s["assumptions"]["modes"]
    print(f"  A1/A2                   hold in every mode (rank F_i = {min(m['rank_F'] for m in ranks)}, rank C_i = "
          f"{min(m['rank_C'] for m in ranks)}, (A_ai, C_ai) detectable)")
    print(f"  gamma (LMIs (20))       {s['gamma']:.6g}   (seed: gamma* = {s['seed_gamma']})")
    print(f"  LMI re-check            {s['worst_min_eig']:.3e} worst margin in {s['worst_block']} (numpy, no solver)")
    for m in s["hinf"]["modes"]:
        print(f"  mode {m['mode']} H-inf norm      {m['hinf_bisection']:.6g} (Hamiltonian bisection, peak at "
              f"{m['peak_rad_s']:.3g} rad/s), {m['hinf_sweep']:.6g} (frequency sweep)  <= gamma")
    print(f"  error poles             Re <= {s['max_pole_real_part']:.4g}, |s| <= {s['max_pole_modulus']:.4g} rad/s")
    print(f"  discrete step Ts={s['sample_time']:g}s  spectral radius {s['discrete_spectral_radius_max']:.6f}; common P: "
          f"sqrt(V) contracts by {s['discrete_contraction_per_step']:.6f}/step in every mode")
    print(f"  design time             {s['total_design_time_s']:.2f} s (solve {1e3 * s['solve_time_s']:.0f} ms)")
    print(f"artifact: {s['artifact']}")


def _objectives(records) -> list:
    return [{"problem": r.problem, "objective": r.objective} for r in records]


def _compare_with_committed(config, records) -> dict:
    """Fresh objectives beside the committed design's (same machine: identical; another one:
    within the solver's accuracy, see docs/guarantees)."""
    data, why = design_lock.read(config)
    if data is None:
        return {"committed": None, "reason": why}
    committed = design_lock.solutions(data, str(design_lock.path(config)))
    rows = []
    for fresh, old in zip(records, committed):
        rel = abs(fresh.objective - old.objective) / max(abs(old.objective), 1e-300)
        spread = {}
        for key, value in old.variables.items():
            if key in fresh.variables:
                a, b = np.asarray(fresh.variables[key], float), np.asarray(value, float)
                if a.shape == b.shape:
                    spread[key] = float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), 1e-300))
        worst = max(spread, key=spread.get) if spread else None
        rows.append({"problem": fresh.problem, "fresh": fresh.objective, "committed": old.objective,
                     "relative_difference": rel, "variables_relative_difference": spread,
                     "worst_variable": worst})
    status, _ = design_lock.status(config)
    return {"committed": rows, "current": status is not None}


def cmd_design(args) -> int:
    config = observers.get(args.name)
    b, records = pipeline.solve(config)
    text = design_lock.dumps(design_lock.document(b, records))
    compare = _compare_with_committed(config, records)
    path = None
    if args.update:
        path = design_lock.path(config)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    if args.out:
        path = Path(args.out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    shown = path if path is not None else "not written (--update commits it as the design lock, --out FILE writes a copy)"
    code = _print_design(b, shown, args.json, compare)
    if not args.json:
        if compare["committed"] is None:
            print(f"committed design: none ({compare['reason']})")
        else:
            for row in compare["committed"]:
                worst = row["worst_variable"]
                var = (f"; decision variables within {row['variables_relative_difference'][worst]:.2e} of their "
                       f"size (largest: {worst})") if worst else ""
                print(f"committed design: {row['problem']}: objective {row['committed']:.8g}, fresh "
                      f"{row['fresh']:.8g} (relative difference {row['relative_difference']:.2e}){var}")
        if args.update:
            print(f"design lock updated: {design_lock.path(config)}; `uiogen generate {b.name}` emits its C")
    return code


def _print_design(b, path, as_json: bool, compare: dict) -> int:
    """The family's design summary (text, or JSON with the comparison to the committed design)."""
    args = argparse.Namespace(json=as_json)
    if as_json:
        import contextlib
        import io
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            code = _family_summary(b, path, args)
        data = json.loads(buf.getvalue())
        data["committed_design"] = compare
        _print_json(data)
        return code
    return _family_summary(b, path, args)


def _family_summary(b, path, args) -> int:
    if hasattr(b, "summary_lines"):        # families that summarize themselves
        s = b.summary(path)
        if args.json:
            _print_json(s)
            return 0
        print("\n".join(b.summary_lines(s)))
        return 0
    if b.config.family == "switched_pi":
        s = _switched_summary(b, path)
        if args.json:
            _print_json(s)
        else:
            _print_switched(s)
        return 0
    if b.config.family == "algebraic_uio":
        from . import algebraic_uio
        return algebraic_uio.print_design(b, path, args.json)
    if isinstance(b, pipeline.TSFuzzyBuild):
        s = _ts_summary(b, path)
        if args.json:
            _print_json(s)
            return 0
        print(f"observer {b.name}: TS fuzzy UIO, {s['rules']} rules, premises {'; '.join(s['premises'])}")
        print(f"  unmeasured consequents  {', '.join(s['unmeasured_consequents'])}; DMVT vertices {s['dmvt_vertices']}")
        for k, v in s["jacobian_bounds"].items():
            print(f"  {k:22s}  [{v[0]:.6g}, {v[1]:.6g}]  (sound, interval arithmetic)")
        print(f"  LMIs (27)               {s['lmi_blocks']} blocks; worst margin {s['worst_min_eig']:.3e} "
              f"(relative {s['worst_relative_margin']:.3e}) in {s['worst_block']} (numpy re-check)")
        print(f"  design time             {s['total_design_time_s']:.2f} s (bounds + LMIs; solve "
              f"{1e3 * s['solve_time_s']:.0f} ms)")
        print(f"  (33) on random samples  max V(e+)/V(e) = {s['lyapunov_decrease_max_ratio']:.6f}")
        print(f"artifact: {path}")
        return 0
    s = _design_summary(b, path)
    if args.json:
        _print_json(s)
        return 0
    print(f"observer {b.name}: {s['polytope']} polytope, {s['vertices']} vertices")
    kind = b.design.settings.lyapunov
    print(f"  gamma ({kind:9s})      {s['gamma']:.6g}   (quadratic: {s['gamma_quadratic']:.6g})")
    print(f"  re-checked gamma        {s['recheck_gamma']:.6g}   (numpy, no solver)")
    print(f"  solve / build time      {1e3 * s['solve_time_s']:.1f} ms / {1e3 * s['build_time_s']:.1f} ms "
          f"({s['solver_iterations']} Clarabel iterations); whole design {s['total_design_time_s']:.2f} s")
    print(f"  worst LMI margin        {s['worst_min_eig']:.3e} (relative {s['worst_relative_margin']:.3e}) "
          f"in {s['worst_block']}")
    print(f"  discrete step Ts={s['sample_time']:g}s  kappa {s['discrete_kappa']:.6f} -> sqrt(V) contracts by "
          f"{s['discrete_contraction_per_step']:.6f}/step; dense-grid spectral radius "
          f"{s['discrete_spectral_radius_max']:.6f}")
    if s["taylor_error"]:
        te = s["taylor_error"]
        print(f"  Taylor-reduction error  {te['max_abs_error']:.4g} on A{tuple(te['entry'])} at "
              f"{b.poly.signal}={te['at']:g} ({100 * te['relative_error_there']:.1f}% of the entry)")
    print(f"artifact: {path}")
    return 0


def cmd_generate(args) -> int:
    emit.generate(args.names or None, Path(args.out) if args.out else emit.GENERATED_DIR, force=args.force)
    return 0


def cmd_build(args) -> int:
    from python_bindings import build
    return build.main(args.names)


def _load_gains(path: Path) -> dict:
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise UiogenError(f"gains file not found: {path}") from None
    except json.JSONDecodeError as exc:
        raise UiogenError(f"gains file {path} is not JSON: {exc}") from None
    return data


def check_gains(name: str, gains: dict) -> dict:
    """Verify externally supplied P_i, X, L_i against the observer's Theorem-1 LMIs."""
    cfg = observers.get(name)
    lpv, poly, _ = pipeline.representation(cfg)
    alpha = float(gains.get("alpha", cfg.design.get("alpha", 5.0)))
    N = poly.n_vertices
    missing = [k for k in [*(f"P{i + 1}" for i in range(N)), *(f"L{i + 1}" for i in range(N))] if k not in gains]
    if missing:
        raise UiogenError(f"gains lack {', '.join(missing)} (this observer has {N} vertices)")
    P = [np.array(gains[f"P{i + 1}"], float) for i in range(N)]
    L = [np.array(gains[f"L{i + 1}"], float) for i in range(N)]
    X = np.array(gains.get("X", np.zeros_like(P[0])), float)
    for label, m, shape in [("X", X, P[0].shape)] + [(f"L{i + 1}", l, (lpv.nx, lpv.ny)) for i, l in enumerate(L)]:
        if m.shape != shape:
            raise UiogenError(f"{label} has shape {m.shape}, expected {shape}")
    from .polytope import taylor_reduced_polytope, sector_polytope
    make = taylor_reduced_polytope if poly.kind == "taylor_reduced" else sector_polytope
    out = {"observer": name, "alpha": alpha, "results": {}}
    for mode in ("exact", "at_expansion_point") if poly.kind == "taylor_reduced" else ("exact",):
        p = make(lpv, mode)
        res = linf_uio.certify(p, P, X, L, alpha)
        res["rate_bounds"] = p.rate_bounds.tolist()
        out["results"][mode] = res
    M = [np.linalg.solve(P[i] + X, L[i]) for i in range(N)]
    out["gain_norm_max"] = max(float(np.linalg.norm(m, 2)) for m in M)
    for key in ("gamma", "gamma_stated"):
        if key in gains:
            out[f"{key}_in_file"] = gains[key]
    return out


def cmd_check_gains(args) -> int:
    res = check_gains(args.name, _load_gains(args.gains))
    if args.json:
        _print_json(res)
        return 0 if all(r["feasible"] for r in res["results"].values()) else 1
    print(f"Theorem 1 check of {args.gains} on observer {args.name} (alpha = {res['alpha']:g})")
    for mode, r in res["results"].items():
        label = {"exact": "sound rate bounds over the whole box",
                 "at_expansion_point": "rate bounds of the seed's eq. (11)"}[mode]
        print(f"  [{label}: phi = {r['rate_bounds'][0]}]")
        for blk in r["blocks"]:
            if "min_eig" in blk:
                print(f"    {blk['label']:45s} min eig {blk['min_eig']:.6g}")
            else:
                print(f"    {blk['label']:45s} max eig (state block) {blk['max_eig_state_block']:.6g}, "
                      f"needs nu >= {blk['nu_needed']:.6g}")
        verdict = "PASS" if r["feasible"] else "FAIL"
        print(f"    {verdict}: certified gamma = sqrt(mu nu) = sqrt({r['mu']:.6g} * {r['nu']:.6g}) = {r['gamma']:.6g}")
    print(f"  max ||M_i|| = {res['gain_norm_max']:.4g} 1/s")
    for key in ("gamma_in_file", "gamma_stated_in_file"):
        if key in res:
            print(f"  {key.replace('_in_file', '')} stated in the file: {res[key]}")
    return 0 if all(r["feasible"] for r in res["results"].values()) else 1


def cmd_validate(args) -> int:
    from . import validate
    if args.data:
        result = validate.run_data(args.name, args.data)
        if args.plot:
            validate.plot_data(result, args.plot)
        if args.json:
            print(json.dumps({k: result[k] for k in ("observer", "baselines")}, indent=1, sort_keys=True))
            return 0
        print(f"{args.name} on {result['data']}: {result['samples']} samples, {result['status_flags']} flagged")
        print(validate.format_data_table(result))
        if args.plot:
            print(f"plot: {args.plot}")
        return 0
    if not args.scenario:
        raise UiogenError("validate needs --scenario S (simulated plant) or --data PATH (logged run)")
    result = validate.run_scenario(args.name, args.scenario, args.plant, duration=args.duration,
                                   progress=validate.progress_bar(f"{args.scenario} on {args.plant}"))
    if args.plot:
        validate.plot(result, args.plot)
    if args.json:
        print(validate.to_json(result))
        return 0
    if result.get("family") == "algebraic_uio":
        from .validation import algebraic
        print(algebraic.header(args.name, result))
        print(validate.format_table(result))
        if args.plot:
            print(f"plot: {args.plot}")
        return 0
    print(f"{args.name}: scenario {args.scenario} on the {args.plant} plant ({result['plant_model']}), {result['samples']} samples, "
          f"max |a_y| {result['max_abs_ay']:.2f} m/s^2, {result['status_flags']} flagged samples; "
          f"errors after {validate.SETTLE_TIME:g} s" + (" (SI units, seed 004 Table II format)"
                                                          if "seed_table" in result else " (seed 003 Table 1 format)"
                                                          if "seed003" in result else " (angles in degrees)"))
    print(validate.format_table(result))
    if args.plot:
        print(f"plot: {args.plot}")
    return 0


def cmd_demo(args) -> int:
    from . import demo
    return demo.main(json_output=args.json)


def cmd_bench(args) -> int:
    from . import bench
    return bench.main(json_output=args.json)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="uiogen", description="Certified unknown-input observers, "
                                     "from symbolic vehicle equations to embeddable C.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("list", help="list observer configurations")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("design", help="solve and certify one observer's design (writes nothing unless --update/--out)")
    p.add_argument("name")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", help="also write the design (lock format) to this file")
    p.add_argument("--update", action="store_true",
                   help="commit the fresh design as the design lock generated_c/NAME/NAME_design.json")
    p.set_defaults(func=cmd_design)
    p = sub.add_parser("generate", help="emit C for observers whose inputs changed")
    p.add_argument("names", nargs="*")
    p.add_argument("--force", action="store_true", help="regenerate even if the inputs hash is unchanged")
    p.add_argument("--out", help="output directory (default generated_c/)")
    p.set_defaults(func=cmd_generate)
    p = sub.add_parser("build", help="compile the generated C into Python extensions")
    p.add_argument("names", nargs="*")
    p.set_defaults(func=cmd_build)
    p = sub.add_parser("check-gains", help="verify external gains against an observer's LMIs")
    p.add_argument("name")
    p.add_argument("--gains", required=True, help="JSON with P1, P2, X, L1, L2 (nested lists)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_check_gains)
    p = sub.add_parser("validate", help="errors on an independent plant, beside the KF/EKF baselines")
    p.add_argument("name")
    p.add_argument("--scenario", help="one of codegen.validation.scenarios.names()")
    p.add_argument("--data", help="a logged run in the shared CSV format (plain or .gz); 'stanford' = the shared log")
    p.add_argument("--plant", choices=("nominal", "model", "commonroad"), default="nominal",
                   help="nominal: our symbolic truth plant (Pacejka); model: the observer's exact model")
    p.add_argument("--duration", type=float, default=None, help="truncate the scenario [s]")
    p.add_argument("--json", action="store_true")
    p.add_argument("--plot", help="write estimates vs truth to this PNG")
    p.set_defaults(func=cmd_validate)
    p = sub.add_parser("demo", help="simulate every observer on its nonlinear model and summarize")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_demo)
    p = sub.add_parser("bench", help="benchmarks (C step, Python call, design time)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_bench)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except UiogenError as exc:
        print(f"uiogen: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
