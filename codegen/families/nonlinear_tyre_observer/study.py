"""Two studies of the nonlinear-tyre observer on a log: across its parameter range, and against its peers.

**The parameter range.**

``stiffness_range`` and ``friction_range`` of the observer file declare factors on each axle's
cornering stiffness and friction coefficient; the vertex LMIs hold for every law in that range, so
the committed gains need no redesign when the tyre is re-identified within it. This study runs the
observer with the committed gains and the model's stiffnesses and friction moved to the corners
and the middle of the range (both axles together), and reports the sideslip RMS on the
identification part, the evaluation part and the whole log::

    python -m codegen.families.nonlinear_tyre_observer.study [OBSERVER] > docs/data/nonlinear_tyre_range.json

Each point is certified again (the gains given, :func:`.build.build`) before it runs.

**The peers** (``--peers``): the sideslip RMS of the committed observer against the same-tyre EKF
and UKF (:func:`codegen.validation.peers.nonlinear_tyre_peers`) on the evaluation part, with
the paired moving-block bootstrap interval of the difference
(:func:`codegen.validation.metrics.rms_difference_interval`) for blocks of 5, 10 and 20 s::

    python -m codegen.families.nonlinear_tyre_observer.study --peers > docs/data/nonlinear_tyre_peers.json
"""
from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np

from ...design import lock as design_lock
from ...project import observer_file as observers
from ...model import load_parameters
from ...validation import metrics, peers, stanford

BLOCKS_S = (5.0, 10.0, 20.0)
"""Bootstrap block lengths [s]: a cornering manoeuvre of the log lasts a few seconds."""


@dataclasses.dataclass(frozen=True)
class _Setup:
    """The committed observer and the log both studies run it on."""

    config: object
    L: list                  # the committed gains (rows v_y, r; columns a_y, r)
    gains: dict              # the same as the observer file's given-gain keys
    params: object
    run: object
    t: np.ndarray            # t - t_0 [s]
    split: float             # start of the evaluation part [s]


def _setup(name: str, path) -> _Setup:
    config = observers.get(name)
    L = json.loads(design_lock.path(config).read_text())["L"]
    gains = dict(zip(("gain_vy_ay", "gain_vy_r", "gain_r_ay", "gain_r_r"), [L[0][0], L[0][1], L[1][0], L[1][1]]))
    params = load_parameters(config.parameter_path)
    run = stanford.load(path, sample_time=config.sample_time)
    split = float(params.meta.get("identification_t_end", stanford.EVALUATION_T_START))
    return _Setup(config, L, gains, params, run, run.t - run.t[0], split)


def _has_evaluation_part(su: _Setup) -> bool:
    """Whether the log reaches past the parameter file's identification end (a part no choice was made on)."""
    return bool(np.any(su.t >= su.split))


def parameter_range(name: str = "stanford_sideslip_nonlinear_tyre", path="stanford") -> dict:
    from .fit import observer_beta
    su = _setup(name, path)
    config, L, gains, params, run, t, split = su.config, su.L, su.gains, su.params, su.run, su.t, su.split
    axles = config.load_model_module().AXLES
    s_rng, f_rng = config.design.get("stiffness_range", [1.0, 1.0]), config.design.get("friction_range", [1.0, 1.0])
    rows = []
    for cs in (s_rng[0], 1.0, s_rng[1]):
        for fs in (f_rng[0], 1.0, f_rng[1]):
            values = dict(params.values)
            for ax in axles:
                values[str(ax.stiffness)] = params.values[str(ax.stiffness)] * cs
                values[str(ax.friction)] = params.values[str(ax.friction)] * fs
            p = dataclasses.replace(params, values=values)
            # the certified set's ranges stay around the committed numbers: the range factors of this
            # point are the committed range divided by its own factors
            design = {**gains, "stiffness_range": [s_rng[0] / cs, s_rng[1] / cs],
                      "friction_range": [f_rng[0] / fs, f_rng[1] / fs]}
            beta = observer_beta(config, p, design, run, 0, run.n)
            err = np.degrees(beta - run.beta_true)
            row = {"stiffness_factor": cs, "friction_factor": fs, "whole": float(np.sqrt(np.mean(err ** 2)))}
            if _has_evaluation_part(su):
                row.update({"evaluation": float(np.sqrt(np.mean(err[t >= split] ** 2))),
                            "identification": float(np.sqrt(np.mean(err[t < split] ** 2)))})
            rows.append(row)
    if _has_evaluation_part(su):
        table = {"header": ["stiffness factor", "friction factor", "β RMSE evaluation part [deg]",
                            "identification part", "whole half"],
                 "rows": [[r["stiffness_factor"], r["friction_factor"], r["evaluation"], r["identification"],
                           r["whole"]] for r in rows]}
    else:           # every sample identified the numbers: one column
        table = {"header": ["stiffness factor", "friction factor", "β RMSE whole log [deg]"],
                 "rows": [[r["stiffness_factor"], r["friction_factor"], r["whole"]] for r in rows]}
    return {"observer": name, "data": str(path), "L": L, "stiffness_range": s_rng, "friction_range": f_rng,
            "t_split": split, "points": rows, "table": table}


def peer_comparison(name: str = "stanford_sideslip_nonlinear_tyre", path="stanford") -> dict:
    """The committed observer against the same-tyre EKF and UKF on the evaluation part (the whole log when
    every sample identified the numbers): each RMS and the bootstrap interval of observer minus peer for
    each block length of :data:`BLOCKS_S`."""
    from .fit import observer_beta
    su = _setup(name, path)
    run = su.run
    part = su.t >= su.split if _has_evaluation_part(su) else np.ones(run.n, bool)
    where = "evaluation part" if _has_evaluation_part(su) else "whole log"
    beta = observer_beta(su.config, su.params, su.gains, run, 0, run.n)
    errors = {"observer": np.degrees(beta - run.beta_true)[part]}
    for peer, res in peers.nonlinear_tyre_peers(run, su.config.parameter_path).items():
        errors[peer] = np.degrees(res.beta - run.beta_true)[part]
    rms = {k: float(np.sqrt(np.mean(e ** 2))) for k, e in errors.items()}
    rows = []
    for peer in (k for k in errors if k != "observer"):
        for block_s in BLOCKS_S:
            r = metrics.rms_difference_interval(errors["observer"], errors[peer], block=int(round(block_s / run.dt)))
            rows.append({"peer": peer, "block_s": block_s, **r})
    table = {"header": ["peer", "block [s]", f"observer − peer, β RMSE {where} [deg]", "95 % interval low",
                        "high", "share of draws where the observer is lower"],
             "rows": [[r["peer"], r["block_s"], r["difference"], r["low"], r["high"], r["share_below_zero"]]
                      for r in rows]}
    return {"observer": name, "data": str(path), "L": su.L, "t_split": su.split, "samples": int(part.sum()), "rms": rms,
            "comparisons": rows, "table": table}


def main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m codegen.families.nonlinear_tyre_observer.study",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("observer", nargs="?", default="stanford_sideslip_nonlinear_tyre")
    ap.add_argument("--peers", action="store_true", help="the comparison with the same-tyre EKF and UKF instead of "
                                                         "the parameter range")
    args = ap.parse_args(argv)
    study = peer_comparison if args.peers else parameter_range
    print(json.dumps(study(args.observer), indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
