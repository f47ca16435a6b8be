"""The ``uiogen`` command line.

    uiogen list [--json]
    uiogen analyze MODEL_OR_OBSERVER [--parameters FILE] [--outputs ...] [--unknown-inputs ...] [--json] [--no-design]
    uiogen design NAME [--json] [--out FILE] [--update] [--project DIR]
    uiogen generate [NAME ...] [--force] [--out DIR] [--project DIR]
    uiogen build [NAME ...] [--float32] [--project DIR]
    uiogen check-gains NAME --gains FILE [--json]
    uiogen fit NAME --data PATH|stanford|niki --samples A:B [--folds K] [--judge RUN ...] [--choose KEY=[V, ...]] [--plot FILE.png] [--write] [--json]
    uiogen validate NAME --scenario S [--plant nominal|commonroad] [--noise-free] [--fail-uninformative] [--json] [--plot FILE.png] [--report DIR] [--project DIR]
    uiogen validate NAME --data PATH|stanford|niki [--out FILE.mf4|.parquet] [--json] [--plot FILE.png] [--report DIR]
                    [--project DIR]
    uiogen demo [--json] [--report DIR]
    uiogen bench [--json]
    uiogen campaign SPEC.toml [--runs N] [--only K] [--resume] [--json] [--scheduler ADDRESS] [--workers N] [--out DIR]
                    [--project DIR]
    uiogen export NAME --format TARGET --out FILE|DIR [--project DIR]     (uiogen export --format: the targets)

``--project DIR``: the project folder whose ``generated_c/`` and ``build/`` the command reads and
writes (:mod:`python_bindings.workspace`); default: the observer file's folder, or for a built-in
observer the source checkout (installed: the current directory).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .design import lock as design_lock
from .design.solver import progress_after
from .emit import generate as emit
from . import workflow
from . import families, pipeline
from .project import observer_file as observers
from .project import outputs
from .commandline import project_option, report_errors
from .errors import (ConfigurationError, DesignLockError, MissingParameterError,
                     SchedulingBoundsError, UiogenError, UnknownObserverError, UnknownParameterError)


def _print_json(obj) -> None:
    print(json.dumps(obj, indent=1, sort_keys=True, default=_jsonable))


def _jsonable(x):
    """numpy scalars and arrays, paths: what a report may hold besides JSON's own types."""
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


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


def _objectives(records) -> list:
    return [{"problem": r.problem, "objective": r.objective} for r in records]


def _compare_with_committed(config, records) -> dict:
    """Fresh objectives beside the committed design's (same machine: identical; another one:
    within the solver's accuracy, see docs/guarantees)."""
    data, why = design_lock.read(config)
    if data is None:
        return {"committed": None, "reason": why}
    try:
        committed = design_lock.solutions(data, str(design_lock.path(config)))
    except DesignLockError as exc:          # a damaged lock: nothing to compare, --update replaces it
        return {"committed": None, "reason": str(exc)}
    rows = []
    for fresh, old in zip(records, committed):
        rel = abs(fresh.objective - old.objective) / max(abs(old.objective), 1e-300)
        spread = design_lock.variable_spread(old.variables, fresh.variables)
        worst = max(spread, key=spread.get) if spread else None
        rows.append({"problem": fresh.problem, "fresh": fresh.objective, "committed": old.objective,
                     "relative_difference": rel, "variables_relative_difference": spread,
                     "worst_variable": worst})
    try:
        status, _ = design_lock.status(config)
    except DesignLockError as exc:          # edited by hand: shown, and --update replaces it
        return {"committed": rows, "current": False, "edited": str(exc)}
    return {"committed": rows, "current": status is not None}


def cmd_analyze(args) -> int:
    from . import analysis
    progress = None if args.json else (lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True))
    result = analysis.analyze(args.target, args.parameters, args.outputs, args.unknown_inputs,
                              design=not args.no_design, progress=progress)
    if args.json:
        _print_json(result.to_json())
    else:
        print(result.text())
    return 0


# Errors that are a mistake in a file (a key, a value, a path): the analysis has nothing to add
_FILE_MISTAKES = (ConfigurationError, UnknownObserverError, MissingParameterError, UnknownParameterError,
                  SchedulingBoundsError, DesignLockError)


def _analysis_of_failure(config, as_json: bool, error: Exception) -> None:
    """The analysis facts at the top of a failed design (stdout; the error stays one line on
    stderr): the structure and every family's verdict, without trial designs."""
    from . import analysis
    try:
        result = analysis.analyze(config.source, design=False)
    except Exception as exc:        # the design's own error is the one that matters: it follows, one line
        if (type(exc), str(exc)) != (type(error), str(error)):      # the same error once, not twice
            print(f"(no analysis of {config.source}: {type(exc).__name__}: {exc})")
        return
    if as_json:
        _print_json({"analysis": result.to_json()})
        return
    print(f"uiogen design {config.name} failed; uiogen analyze {config.source}:")
    print("\n".join("  " + line if line else "" for line in result.text().splitlines()))


def _check_sensor_noise(config) -> None:
    """The parameter file's ``[sensor_noise]`` names and units, refused at design as validate and build
    --float32 refuse them (:func:`codegen.validation.noise.declared`); read here, not by the pipeline, so the
    table stays out of the design hash."""
    from .model import load_parameters
    from .validation import noise
    noise.declared(config.load_model(), load_parameters(config.parameter_path))


def cmd_design(args) -> int:
    config = observers.get(args.name, project=args.project)
    _check_sensor_noise(config)
    try:
        progress = None if args.json else (lambda line: print(f"  ... {line}", file=sys.stderr, flush=True))
        b, records = pipeline.solve(config, progress=progress_after(progress))
    except _FILE_MISTAKES:
        raise
    except UiogenError as exc:
        _analysis_of_failure(config, args.json, exc)
        raise
    text = design_lock.dumps(design_lock.document(b, records))
    compare = _compare_with_committed(config, records)
    path = None
    if args.update:
        path = emit.commit_lock(config, text)
    if args.out:
        path = Path(args.out)
        outputs.make_folder(path.parent)
        outputs.write_atomic(path, text)
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
            print(f"design lock updated: {design_lock.path(config)}; `uiogen generate {config.command_name}` emits its C")
    return code


def _print_design(b, path, as_json: bool, compare: dict) -> int:
    """The design's certificate and figures (text, or JSON with the comparison to the committed
    design), and the parameters no plausible range checked (no unit declared: a note)."""
    from .certificate import text
    from .model import dimensions
    model = b.config.load_model()
    if as_json:
        _print_json({"observer": b.name, "artifact": str(path), **b.figures(), "certificate": b.certificate.to_json(),
                     "committed_design": compare, "unranged_parameters": list(dimensions.unranged_parameters(model))})
        return 0
    print("\n".join(text.design_lines(families.get(b.config.family), b, path)))
    note = dimensions.unranged_note(model, b.config.model_path)
    if note:
        print(note)
    return 0


def cmd_sweep(args) -> int:
    """The figure columns are checked against the first certified point's figures (a family's are
    known once it has designed): an unknown ``--show`` name is a ConfigurationError with a
    did-you-mean; without ``--show``, the default columns the family reports. Rows before the
    columns are known (refusals) wait for them, so the table has one header."""
    from .analysis import sweep
    from .settings import parse_set
    grid = [parse_set(text) for text in args.sets]
    requested = None if args.show is None else [c.strip() for c in args.show.split(",") if c.strip()]
    result = {"observer": args.name, "grid": dict(grid), "points": []}
    state = {"columns": None, "waiting": [], "printed": False}

    def flush(rows):
        if args.json:
            return
        for row in rows:            # the header with the first row: a mistake is one error line, no table
            head, line = sweep.lines({**result, "points": [row]}, state["columns"])
            print(line if state["printed"] else f"{head}\n{line}", flush=True)
            state["printed"] = True

    def show(row):
        if state["columns"] is None and row["outcome"] == "certified":
            state["columns"] = sweep.columns(args.name, row, requested)
        if state["columns"] is None:
            state["waiting"].append(row)
            return
        rows, state["waiting"] = state["waiting"] + [row], []
        flush(rows)
    done = sweep.run(args.name, grid, log=show)
    if state["columns"] is None:    # no point certified: no figures to show
        state["columns"] = []
        flush(state["waiting"])
    if args.json:
        _print_json({**done, "show": state["columns"]})
    return 0


def cmd_generate(args) -> int:
    workflow.generate(args.names or None, Path(args.out) if args.out else None, force=args.force,
                  project=args.project)
    return 0


def cmd_build(args) -> int:
    from .extension import build as extension
    from . import targets
    variant = next((t for t in targets.all_targets()
                    if isinstance(t, targets.BuildVariant) and getattr(args, t.build_flag, False)), None)
    if variant is None:
        return extension.main(args.names, project=args.project, force=args.force)
    return variant.build(args.names, project=args.project)


def _load_gains(path: Path) -> dict:
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigurationError(f"gains file not found: {path}", source=str(path)) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f"gains file {path} is not JSON: {exc}", source=str(path)) from None
    except OSError as exc:      # a folder, no permission, an unreadable device: the cause, not a traceback
        raise ConfigurationError(f"gains file {path} cannot be read ({exc.strerror or exc}); allowed: a readable "
                                 f"JSON file", source=str(path)) from None
    if not isinstance(data, dict):
        raise ConfigurationError(f"gains file {path}: expected a JSON object of named matrices", source=str(path))
    return data


def check_gains(name: str, gains: dict, source: str = "gains"):
    """Check externally supplied gains against the observer family's LMIs (no solver): a
    :class:`~codegen.certificate.gains.GainsCheck`."""
    from .certificate import gains as gains_check
    cfg = observers.get(name)
    return gains_check.check(families.get(cfg.family), cfg, gains, source)


def cmd_check_gains(args) -> int:
    from .certificate import text
    cfg = observers.get(args.name)
    res = check_gains(args.name, _load_gains(args.gains), args.gains)
    if args.json:
        _print_json(res.to_json())
    else:
        print("\n".join(text.check_gains_lines(families.get(cfg.family), res)))
    return 0 if res.feasible else 1


def _shown(path: Path) -> str:
    """A path as a record shows it: relative to the working directory when inside it."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def cmd_fit(args) -> int:
    """Identify an observer's numbers on samples A..B-1 of a log (the family's ``fit``); print them,
    say whether the committed files hold them, and with --write put them there."""
    from .certificate import text
    from .contract.capabilities import Identification, require
    cfg = observers.get(args.name)
    family = require(families.get(cfg.family), Identification)
    if args.plot and not args.judge:
        raise ConfigurationError("--plot draws the fit run beside the runs --judge names; name at least one --judge RUN",
                                 source="--plot", key="--plot", value=args.plot)
    if args.plot and not Path(args.plot).suffix:        # matplotlib adds .png: say the file it writes
        args.plot = f"{args.plot}.png"
    from .settings import parse_set
    choose = [parse_set(text, "--choose") for text in args.choose or ()]
    result = family.fit(cfg, args.data, args.samples, folds=args.folds, judge=tuple(args.judge or ()),
                        choose=choose, jobs=args.jobs)
    if args.plot:
        with outputs.writing(args.plot):
            family.fit_plot(result, args.plot)
    texts = family.fit_files(cfg, result)
    changed = {path: path.read_text() != body for path, body in texts.items()}
    if args.write and any(changed.values()):     # all the old files or all the new ones, never a mixture
        outputs.write_together({path: body for path, body in texts.items() if changed[path]}, cfg.source)
    files = {_shown(p): ("written" if args.write and c else "differs" if c else "equal") for p, c in changed.items()}
    lines = text.fit_lines(family, result, files)
    if args.report:
        from .validation import report
        with outputs.writing(args.report):
            report.write_fit(args.name, result, lines, args.report,
                             plot=family.fit_plot if result.get("runs") else None)
    for row in result.get("runs", ()):
        row.pop("series")                                  # arrays: the plot's, not the printed result's
    if args.json:
        _print_json({**result, "files": files})
    else:
        print("\n".join(lines))
    return 0


def _print_remark_and_files(remark: str, args, page) -> None:
    """Below a validation's table: the no-information remark, then where the plot, the report and the
    outputs (``--data ... --out``) were written."""
    if remark:
        print(remark)
    if args.plot:
        print(f"plot: {args.plot}")
    if args.report:
        print(f"report: {page.resolve()}")
    if getattr(args, "out", None):
        print(f"outputs: {Path(args.out).resolve()}")


def cmd_validate(args) -> int:
    from .validation import logs, noise, run as validate
    config = observers.get(args.name, project=args.project)
    page = None                                         # the report's page, where --report writes one
    if args.plot and not Path(args.plot).suffix:        # matplotlib adds .png: say the file it writes
        args.plot = f"{args.plot}.png"
    if args.out and not args.data:
        raise ConfigurationError("--out FILE writes the outputs of a logged run: it goes with --data PATH")
    if args.data:
        if args.out:
            from .validation import logout
            logout.check_path(args.out)             # a suffix it cannot write is refused before the run
        result = logs.run(config, args.data, out=args.out)
        if args.plot:
            with outputs.writing(args.plot):
                logs.plot(result, args.plot)
        if args.report:
            from .validation import report
            with outputs.writing(args.report):
                page = report.write_validation(args.name, result, args.report, data=True)
        remark = noise.remark(result.get("observer", {}), noisy=None)
        if args.json:
            from .validation.metrics import DEFINITIONS
            keys = ("observer", "baselines", "estimates", "status_flags", "samples", "splits", "peaks", "warnings",
                    "log_checks", "baselines_skipped", "unchecked_columns", "format", "resampling", "out",
                    "noise", "log_checks_overridden")
            print(json.dumps({**{k: result[k] for k in keys if k in result}, "definitions": DEFINITIONS,
                              "uninformative": sorted(noise.uninformative(result.get("observer", {})))},
                             indent=1, sort_keys=True))
        else:
            warned = f", {len(result['warnings'])} warning(s) below" if result.get("warnings") else ""
            print(f"{args.name} on {result['data']}: {result['samples']} samples, {result['status_flags']} "
                  f"flagged{warned}")
            print(logs.format_table(result))
            _print_remark_and_files(remark, args, page)
        return _uninformative_exit(remark, args)
    if not args.scenario:
        raise ConfigurationError("validate needs --scenario S (simulated plant) or --data PATH (logged run)")
    result = validate.run_scenario(config, args.scenario, args.plant, duration=args.duration,
                                   progress=validate.progress_bar(f"{args.scenario} on {args.plant}"),
                                   noise=not args.noise_free)
    if args.plot:
        with outputs.writing(args.plot):
            validate.plot(result, args.plot)
    if args.report:
        from .validation import report
        with outputs.writing(args.report):
            page = report.write_validation(args.name, result, args.report, data=False)
    # a run whose step failed numerically or diverged is a failed validation: exit 1, the reason on stderr
    why = validate.failure(result)
    record = result.get("noise")
    remark = noise.remark(result.get("observer", {}),
                          noisy=bool(record["levels"]) if isinstance(record, dict) and "mode" in record else None)
    if args.json:
        print(validate.to_json(result))
    else:
        print(validate.header(args.name, result))
        print(validate.format_table(result))
        _print_remark_and_files(remark, args, page)
    if why:
        print(f"uiogen: validation failed: {why}; the estimates above are not the observer's (an initial estimate "
              f"outside the certified set, a set the run leaves, or a step that is not certified there)", file=sys.stderr)
        return 1
    return _uninformative_exit(remark, args)


def _uninformative_exit(remark: str, args) -> int:
    """The exit code of a validation that ran: 3 with --fail-uninformative when an estimate carries no
    information (the remark, also on stderr), else 0."""
    if not remark:
        return 0
    print(f"uiogen: warning: {remark}", file=sys.stderr)
    if args.fail_uninformative:
        print("uiogen: validation failed (--fail-uninformative): an estimate carries no information", file=sys.stderr)
        return 3
    return 0


def cmd_demo(args) -> int:
    from .validation import demo
    return demo.main(json_output=args.json, report_dir=args.report)


def cmd_new(args) -> int:
    """A starter project: the family's example observer, its model and its parameters, copied
    into DIR and wired to each other by paths, ready to design, generate, build and validate as
    written (:mod:`codegen.project.starter`). With ``--from-model FILE`` instead: the observer file
    of the family ``uiogen analyze`` ranks first for that model, with the settings the analysis
    chose and comments that say why; with ``--from-model FILE --family F``, the observer file of
    family F for that model (the settings the analysis measured for F, else its proposal, else
    the family's defaults), refused with the analysis's reason when F does not apply."""
    from .project import starter
    if args.family is None and args.from_model is None:
        raise ConfigurationError("uiogen new DIR: give --family F (a starter copied from the family's example), "
                                 "--from-model FILE [--parameters FILE] (the observer the analysis chooses), or both "
                                 "(the observer file of family F for your model)", key="--family")
    if args.from_model is not None:
        return _new_from_model(args)
    for given, flag in ((args.parameters, "--parameters"), (args.outputs, "--outputs"),
                        (args.unknown_inputs, "--unknown-inputs")):
        if given is not None:
            raise ConfigurationError(f"uiogen new {flag} goes with --from-model", key=flag)
    target = starter.write(Path(args.dir), families.get(args.family), args.name)
    print(f"wrote {target}, {target.parent / 'model.py'}, {target.parent / 'parameters.toml'}")
    print("next: " + "; ".join(starter.next_steps(target)))
    return 0


def _new_from_model(args) -> int:
    from . import analysis
    from .project import starter
    from .analysis.ranking import starter_text
    folder = Path(args.dir)
    wanted = families.get(args.family).name if args.family is not None else None    # an unknown name: refused first
    if args.name is not None:
        starter.check_name(args.name)
    result = analysis.analyze(args.from_model, args.parameters, outputs=args.outputs,
                              unknown_inputs=args.unknown_inputs, design=True,
                              progress=lambda msg: print(f"  ... {msg}", file=sys.stderr, flush=True))
    if wanted is None:
        best = result.ranking.best
        if best is None:
            print(result.text())
            raise ConfigurationError(f"uiogen new --from-model {args.from_model}: no observer family applies to these "
                                     f"sensors (the report above gives each family's condition and fix)",
                                     key="--from-model")
        if best.observer is None:
            raise ConfigurationError(f"uiogen new --from-model {args.from_model}: {best.family} ranks first but "
                                     f"proposes no settings for this model; start from uiogen new DIR --family "
                                     f"{best.family}, or write the family's defaults with --from-model "
                                     f"{args.from_model} --family {best.family}", key="--from-model")
        chosen, tried, rank_note = best, result.ranking.entries[0][1], "ranked first"
    else:
        position = result.ranking.position(wanted)
        chosen, tried = result.ranking.entries[position]
        if not chosen.applies:
            print(result.text())
            raise ConfigurationError(f"uiogen new --from-model {args.from_model} --family {wanted}: {wanted} does not "
                                     f"apply to this model with these sensors: {chosen.condition}"
                                     + (f" (fix: {chosen.fix})" if chosen.fix else ""), key="--family", value=wanted)
        rank_note = (f"ranked {'first' if position == 0 else position + 1} by the analysis, chosen with --family")
    name = args.name or f"{result.subject.name}_{chosen.family}"
    starter.check_name(name)
    target = folder / f"{name}.toml"
    if target.exists():
        raise ConfigurationError(f"uiogen new {folder}: would overwrite {target}; choose an empty folder or --name",
                                 key="dir")
    wrapper = folder / f"{name}_model.py" if result.subject.restricted else None
    if wrapper is not None and wrapper.exists():
        raise ConfigurationError(f"uiogen new {folder}: would overwrite {wrapper}; choose an empty folder or --name",
                                 key="dir")
    outputs.make_folder(folder)
    if wrapper is not None:     # the sensors chosen with --outputs/--unknown-inputs, as the analysis had them
        from .analysis.ranking import wrapper_model
        outputs.write_atomic(wrapper, wrapper_model(result.subject, beside=folder))
    text = starter_text(result.subject, chosen, folder.resolve(), trial=tried,
                        chosen_by=None if wanted is None else rank_note,
                        model_file=None if wrapper is None else wrapper.resolve()).replace("THIS_FILE", str(target))
    outputs.write_atomic(target, text)
    print(result.text())
    print(f"wrote {target} ({chosen.family}, {rank_note})")
    if tried.status == "failed":        # the file is written as proposed, but say plainly it does not design
        print(f"warning: the analysis's trial design of these settings failed ({tried.reason}); "
              f"uiogen design {target} fails the same way until you change what it names", file=sys.stderr)
    print("next: " + "; ".join(starter.next_steps(target)))
    return 0


def cmd_docs(args) -> int:
    from .tools import docs
    return docs.main(check=args.check)


def cmd_export(args) -> int:
    from . import targets
    if args.format is None:         # `uiogen export --format`: what is registered
        for t in targets.all_targets():
            print(f"{t.name:8s} --out {t.out:9s} {t.title}")
        return 0
    targets.get(args.format).export(observers.get(args.name, project=args.project), args.out)
    return 0


def cmd_bench(args) -> int:
    from .tools import bench
    return bench.main(json_output=args.json)


def cmd_campaign(args) -> int:
    from .campaign import engine, memory, report, runner, spec as campaign_spec
    spec = campaign_spec.load(args.spec, project=args.project)
    if args.runs is not None:
        spec = spec.with_runs(args.runs)
    if args.only is not None:
        if not 0 <= args.only < spec.runs:
            raise ConfigurationError(f"--only {args.only}: {args.spec} has runs 0 to {spec.runs - 1} (runs = "
                                     f"{spec.runs}{', --runs' if args.runs is not None else ''})", source=args.spec,
                                     key="--only", value=args.only, allowed=f"0 <= K < {spec.runs}")
        runner.design_hash(spec)                # the current design, its extension built from it
        memory.check(spec, 0)                   # the run, here: refused before it starts if it cannot fit
        row = runner.run_one(spec, args.only)
        if args.json:
            print(json.dumps(row, indent=1))
        else:
            print(report.format_row(row))
        return 1 if row.get("status") == "error" else 0        # a log refused by its checks: no result
    out = Path(args.out) if args.out else spec.config().workspace.campaigns / Path(args.spec).stem
    import signal
    previous = signal.signal(signal.SIGTERM, _terminate)       # SIGTERM: as Ctrl-C, with the --resume hint
    previous_int = signal.signal(signal.SIGINT, _interrupt)
    try:
        summary = engine.run(spec, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                             progress=None if args.json else engine.progress_bar())
    except KeyboardInterrupt as exc:
        print(f"uiogen: {'terminated' if isinstance(exc, _Terminated) else 'interrupted'}: the finished runs are "
              f"kept in {out / engine.JOURNAL}; `uiogen campaign {args.spec} --resume --out {out}` continues the "
              f"campaign", file=sys.stderr)
        return 143 if isinstance(exc, _Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
    if args.json:
        _print_json(summary)
    else:
        print(report.format_summary(summary))
        print(f"wrote {summary['files']['runs']}, {summary['files']['summary']}, "
              f"{', '.join(summary['files']['plots'])}")
    # runs without a result (their worker died, or they raised) make the campaign incomplete: a script
    # that checks the exit code must see it, and --resume runs the lost ones again
    failed = {k: v for k, v in summary.get("runs_failed", {}).items() if k in engine.NO_RESULT}
    if failed:
        print(f"uiogen: campaign {args.spec}: {sum(failed.values())} of {summary['runs']} runs produced no result "
              f"({', '.join(f'{k}: {v}' for k, v in sorted(failed.items()))}); the reports hold the others"
              + (f"; `uiogen campaign {args.spec} --resume --out {out}` runs the lost ones again"
                 if "worker_lost" in failed else ""), file=sys.stderr)
        return 1
    return 0


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the process is (a campaign stops as on Ctrl-C, its runs kept)."""


def _quiet_dask_shutdown() -> None:
    """Interrupted inside a Dask call (``distributed.utils.sync``) before its coroutine has started, Dask's
    own clean-up callback reads a variable it has not set yet and tornado logs that NameError with its
    traceback (``sync.<locals>.cancel`` of distributed 2026.8.0): the user stopped the campaign, and what they
    get is the line that says where the runs are kept, not a library's shutdown noise."""
    import logging
    logging.getLogger("tornado.application").disabled = True


def _terminate(signum, frame):
    _quiet_dask_shutdown()          # before the raise: Dask schedules its clean-up while the exception unwinds
    raise _Terminated()


def _interrupt(signum, frame):
    _quiet_dask_shutdown()
    raise KeyboardInterrupt()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="uiogen", description="Certified unknown-input observers, "
                                     "from symbolic vehicle equations to embeddable C.")
    sub = parser.add_subparsers(dest="command", required=True)
    # The commands that read or write an observer's generated files take its project folder.
    project = project_option()
    from . import targets          # the export targets and build variants registered (codegen/targets/)
    p = sub.add_parser("list", help="list observer configurations")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("analyze", help="what a model's sensors allow and which observer family to use (families "
                                       "ranked, cheap designs tried)")
    p.add_argument("target", help="a built-in observer, an observer file (.toml) or a model file (.py)")
    p.add_argument("--parameters", help="the parameter file (required for a model file; for an observer file it "
                                        "replaces the one the file names)")
    p.add_argument("--outputs", nargs="+", metavar="OUTPUT",
                   help="the measured outputs, among those the model declares (default: all of them)")
    p.add_argument("--unknown-inputs", nargs="+", metavar="INPUT",
                   help="the unknown inputs, among the model's known and unknown inputs (default: as declared)")
    p.add_argument("--no-design", action="store_true", help="no trial designs (the structure and the conditions only)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_analyze)
    p = sub.add_parser("design", parents=[project],
                       help="solve and certify one observer's design (writes nothing unless --update/--out)")
    p.add_argument("name")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", help="also write the design (lock format) to this file")
    p.add_argument("--update", action="store_true",
                   help="commit the fresh design as the design lock generated_c/NAME/NAME_design.json")
    p.set_defaults(func=cmd_design)
    p = sub.add_parser("sweep", help="design one observer over a grid of its settings (writes nothing)")
    p.add_argument("name")
    p.add_argument("--set", dest="sets", action="append", required=True, metavar="KEY=[V, ...]",
                   help="a dotted key of the observer file and a TOML array of values to try, e.g. "
                        "design.pole_radius=[50,100,300]; repeat for a grid (every combination)")
    p.add_argument("--show", default=None,
                   help="comma-separated figures of the design summary in the text table (default gamma where the "
                        "family reports it, else certified_contraction_per_step); a name the family does not "
                        "report is an error that lists those it does")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("generate", parents=[project], help="emit C for observers whose inputs changed")
    p.add_argument("names", nargs="*")
    p.add_argument("--force", action="store_true", help="regenerate even if the inputs hash is unchanged")
    p.add_argument("--out", help="output directory (default generated_c/)")
    p.set_defaults(func=cmd_generate)
    p = sub.add_parser("build", parents=[project], help="compile the generated C into Python extensions")
    p.add_argument("names", nargs="*")
    p.add_argument("--force", action="store_true", help="compile and check again an extension whose generated C "
                                                         "and files are unchanged since it was built (skipped "
                                                         "otherwise)")
    for t in targets.all_targets():         # the build variants the registered targets offer (--float32)
        if isinstance(t, targets.BuildVariant):
            p.add_argument(f"--{t.build_flag}", action="store_true", help=t.build_help)
    p.set_defaults(func=cmd_build)
    p = sub.add_parser("check-gains", help="verify external gains against an observer's LMIs")
    p.add_argument("name")
    p.add_argument("--gains", required=True,
                   help="JSON: a design lock (or its lmi_solutions), or the family's printed form: "
                        "P1..PN, L1..LN [, X, alpha] (linf_uio), L (nonlinear_tyre_observer)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_check_gains)
    p = sub.add_parser("fit", help="identify an observer's numbers (tyre, noise levels) on a sample range of a log")
    p.add_argument("name")
    p.add_argument("--data", required=True, help="a logged run with a sideslip reference, read as validate --data "
                                                 "reads it: through the observer file's [data] map (CSV, Parquet, MDF4, "
                                                 "ROS 2 bag, CAN log), else the shared format; 'stanford', 'niki' = the "
                                                 "shared logs (Ferrari, GTI)")
    p.add_argument("--samples", required=True, metavar="A:B", help="the samples A..B-1 the fit may read (e.g. 0:13750)")
    p.add_argument("--folds", type=int, default=None, help="cross-validate inside the range with K contiguous folds: "
                                                           "each tyre set (fitted; the parameter file's [prior] "
                                                           "stiffnesses) judged on held-out folds, the better written "
                                                           "(default: 5 with a [prior], else 0, no cross-validation)")
    p.add_argument("--judge", action="append", metavar="RUN", help="another run of the same car (a log in the shared "
                                                                     "format, or a shorthand): the observer designed "
                                                                     "with the fitted numbers and its same-tyre EKF and "
                                                                     "UKF run on it and are printed beside the fit run; "
                                                                     "repeat for more runs")
    p.add_argument("--choose", action="append", metavar="KEY=[V, ...]",
                   help="a [design] setting and the values to judge on the held-out folds with the tyre sets, e.g. "
                        "design.decay_fraction=[0.1, 0.2]; repeat for a grid; the best is written")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="processes for the folds' designs and the peers' grid (default: every CPU); the same result "
                        "with any number")
    p.add_argument("--plot", metavar="FILE.png", help="with --judge: the sideslip of every run, truth and estimates")
    p.add_argument("--report", metavar="DIR", help="an HTML page DIR/index.html: the runs (with --judge) and their "
                                                   "figure, the held-out folds, the output")
    p.add_argument("--write", action="store_true", help="write the fitted values into the parameter and observer files")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_fit)
    p = sub.add_parser("validate", parents=[project],
                       help="errors on an independent plant, beside the KF/EKF baselines")
    p.add_argument("name")
    p.add_argument("--scenario", help="excitation (any model: its own equations, swept and excited) or one of codegen.validation.scenarios.names()")
    p.add_argument("--data", help="a logged run (CSV, plain or .gz; Parquet; MDF4; a ROS 2 bag folder; a CAN log, "
                                  "BLF or ASC, decoded with the DBC of [data] dbc; told by the content): the columns "
                                  "or channels mapped by the observer file's [data] table, or "
                                  "else the shared CSV format; 'stanford', 'niki' = the shared logs (Ferrari, GTI)")
    p.add_argument("--out", metavar="FILE", help="with --data: write the observer's outputs and "
                                                 "status, with their units, on the log's time base to FILE.mf4 (MDF4) "
                                                 "or FILE.parquet (whole or not at all)")
    p.add_argument("--plant", choices=("nominal", "model", "commonroad"), default="nominal",
                   help="nominal: our symbolic truth plant (Pacejka); model: the observer's exact model")
    p.add_argument("--duration", type=float, default=None, help="truncate the scenario [s]")
    p.add_argument("--noise-free", action="store_true",
                   help="excitation: without the sensor noise the parameter file's [sensor_noise] declares (added by "
                        "default)")
    p.add_argument("--fail-uninformative", action="store_true",
                   help="exit 3 when an estimate carries no information (error RMS >= its truth's RMS about its mean); "
                        "without it the run names such estimates and exits 0")
    p.add_argument("--json", action="store_true")
    p.add_argument("--plot", help="write estimates vs truth to this PNG")
    p.add_argument("--report", metavar="DIR", help="write an HTML page (DIR/index.html) with the figures and the tables")
    p.set_defaults(func=cmd_validate)
    p = sub.add_parser("demo", help="simulate every observer on its nonlinear model and summarize")
    p.add_argument("--json", action="store_true")
    p.add_argument("--report", metavar="DIR", help="write an HTML page (DIR/index.html) of every observer, the best "
                                                   "real-data observer first, and print a summary pointing at it")
    p.set_defaults(func=cmd_demo)
    p = sub.add_parser("new", help="a starter project (model, parameters, observer file) in DIR, or the observer "
                                   "file of the family the analysis ranks first for your model (--from-model), or "
                                   "of the family you name (--from-model with --family)")
    p.add_argument("dir")
    p.add_argument("--family", help="an observer family (uiogen list shows them in use): alone, a starter copied "
                                    "from its example; with --from-model, the observer file of this family for "
                                    "your model (the settings the analysis measured for it; refused, with the "
                                    "analysis's reason, where it does not apply)")
    p.add_argument("--from-model", help="your model file (.py): the observer file of the best-ranked family "
                                        "(or of --family)")
    p.add_argument("--parameters", help="the model's parameter file (with --from-model)")
    p.add_argument("--outputs", nargs="+", metavar="OUTPUT",
                   help="with --from-model: the measured outputs, among those the model declares (default: all); "
                        "the observer file's model is then DIR/NAME_model.py, your model with these sensors")
    p.add_argument("--unknown-inputs", nargs="+", metavar="INPUT",
                   help="with --from-model: the unknown inputs, among the model's known and unknown inputs "
                        "(default: as declared)")
    p.add_argument("--name", help="the observer's name, the file's stem (default: my_FAMILY, or MODEL_FAMILY with "
                                  "--from-model; never a built-in's)")
    p.set_defaults(func=cmd_new)
    p = sub.add_parser("docs", help="the docs' tables of figures from docs/data/{demo,bench}.json")
    p.add_argument("--check", action="store_true", help="only compare; exit 1 if a page differs")
    p.set_defaults(func=cmd_docs)
    p = sub.add_parser("bench", help="benchmarks (C step, Python call, design time)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_bench)
    p = sub.add_parser("campaign", parents=[project],
                       help="dispersed runs of an observer on its compiled truth plant or its logs, on Dask")
    p.add_argument("spec", help="a campaign file (TOML), e.g. docs/campaigns/lpv_linf_driver_torque.toml")
    p.add_argument("--runs", type=int, help="number of runs (default: the file's runs)")
    p.add_argument("--only", type=int, metavar="K", help="re-run run K alone (no cluster) and print its row")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted campaign: the runs kept in OUT/runs.jsonl are not run again "
                        "(refused if the campaign file or the observer's design changed since)")
    p.add_argument("--json", action="store_true", help="print the summary (or the row) as JSON")
    p.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local cluster size (default: the cores)")
    p.add_argument("--out", help="directory for runs.csv, summary.json, traces and plots "
                                 "(default: build/campaigns/SPEC_STEM of the observer's project)")
    p.set_defaults(func=cmd_campaign)
    p = export = sub.add_parser("export", parents=[project],
                                help="package a generated observer for another tool (" + ", ".join(targets.names())
                                + "; uiogen export --format lists them)")
    p.add_argument("name", nargs="?")
    p.add_argument("--format", choices=targets.names(), required=True, nargs="?", const=None,
                   help="the export target (--format alone lists them with what each writes)")
    p.add_argument("--out", help="what to write: " + "; ".join(f"{t.out} ({t.name})" for t in targets.all_targets()))
    p.set_defaults(func=cmd_export)
    args = parser.parse_args(argv)
    if getattr(args, "runs", None) is not None and args.runs < 1:
        parser.error("--runs must be >= 1")
    if getattr(args, "workers", None) is not None and args.workers < 1:
        parser.error("--workers must be >= 1")
    if args.command == "export" and args.format is not None and None in (args.name, args.out):
        export.error("the following arguments are required: "
                     + ", ".join(n for n, v in (("name", args.name), ("--out", args.out)) if v is None))
    return report_errors(f"uiogen {args.command}", lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
