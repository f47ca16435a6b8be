"""The nonlinear-tyre observer across the parameter range its certificate covers, on a log.

``stiffness_range`` and ``friction_range`` of the observer file declare factors on each axle's
cornering stiffness and friction coefficient; the vertex LMIs hold for every law in that range, so
the committed gains need no redesign when the tyre is re-identified within it. This study runs the
observer with the committed gains and the model's stiffnesses and friction moved to the corners
and the middle of the range (both axles together), and reports the sideslip RMS on the
identification part, the evaluation part and the whole log::

    python -m codegen.families.nonlinear_tyre_observer.study [OBSERVER] > docs/data/nonlinear_tyre_range.json

Each point is certified again (the gains given, :func:`.build.build`) before it runs.
"""
from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np

from ...design import lock as design_lock
from ...project import observer_file as observers
from ...model import load_parameters
from ...validation import stanford


def parameter_range(name: str = "stanford_sideslip_nonlinear_tyre", path="stanford") -> dict:
    from .fit import observer_beta
    config = observers.get(name)
    art = json.loads(design_lock.path(config).read_text())
    L = art["L"]
    gains = dict(zip(("gain_vy_ay", "gain_vy_r", "gain_r_ay", "gain_r_r"), [L[0][0], L[0][1], L[1][0], L[1][1]]))
    params = load_parameters(config.parameter_path)
    axles = config.load_model_module().AXLES
    s_rng, f_rng = config.design.get("stiffness_range", [1.0, 1.0]), config.design.get("friction_range", [1.0, 1.0])
    run = stanford.load(path, sample_time=config.sample_time)
    t = run.t - run.t[0]
    split = float(params.meta.get("identification_t_end", stanford.EVALUATION_T_START))
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
            rows.append({"stiffness_factor": cs, "friction_factor": fs,
                         "evaluation": float(np.sqrt(np.mean(err[t >= split] ** 2))),
                         "identification": float(np.sqrt(np.mean(err[t < split] ** 2))),
                         "whole": float(np.sqrt(np.mean(err ** 2)))})
    table = {"header": ["stiffness factor", "friction factor", "β RMSE evaluation part [deg]", "identification part",
                        "whole half"],
             "rows": [[r["stiffness_factor"], r["friction_factor"], r["evaluation"], r["identification"], r["whole"]]
                      for r in rows]}
    return {"observer": name, "data": str(path), "L": L, "stiffness_range": s_rng, "friction_range": f_rng,
            "t_split": split, "points": rows, "table": table}


if __name__ == "__main__":
    print(json.dumps(parameter_range(*sys.argv[1:2]), indent=1, sort_keys=True))
