"""Every line of text uiogen prints about a design, in one place.

``uiogen design``, ``uiogen demo``, ``uiogen check-gains``, ``uiogen validate``, ``uiogen bench``,
``uiogen fit``, the generated C header and ``uiogen generate``'s log turn a family's
:class:`~codegen.certificate.certificate.Certificate` and its figures (plain data) into text here;
families write no prose about their designs. The tables whose layout is a paper's own (a
validation table, a printed form of the gains, a family's study) stay the family's, and are
reached through this module too.
"""
from __future__ import annotations

from .certificate import NORMS, Certificate


def number(v) -> str:
    """A figure as text: floats to six significant digits (in lists too), the rest as they are."""
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(number(x) for x in v) + "]"
    return str(v)


def region_text(cert: Certificate) -> str:
    """The set the certificate needs, as 'v_x in [5, 35], a_x in [-4, 4]'."""
    return ", ".join(f"{k} in [{number(lo)}, {number(hi)}]" for k, (lo, hi) in cert.region.items()) or "everywhere"


def bound_text(b) -> str:
    return f"{b.quantity} = {number(b.value)} {b.unit}"


def contraction_text(step) -> str:
    """'sqrt(V) contracts by 0.955060 per step', or the strict decrease without a proven rate."""
    if step.rate_proven:
        text = f"sqrt(V) of the estimation error contracts by {step.contraction:.6f} per step"
    else:
        text = "V of the estimation error decreases strictly at every step (no rate proven)"
    if step.sampled is not None:
        text += f"; sampled: {step.sampled:.6f} per step (evidence, not proof)"
    return text


def headline(cert: Certificate) -> str:
    """One line: the bound, the step's contraction, the least LMI margin (the C banner, generate's log)."""
    parts = [bound_text(b) for b in cert.bounds[:1]]
    parts.append(f"sqrt(V) contracts by {cert.step.contraction:.6f}/step" if cert.step.rate_proven
                 else "V decreases strictly")
    parts.append(f"worst LMI margin {cert.recheck.worst_min_eig:.3g}")
    return ", ".join(parts)


def stability(cert: Certificate) -> str:
    """The C header's sentence on the step's certificate."""
    return f"{cert.step.method}; certified while {region_text(cert)}: {contraction_text(cert.step)}"


def certificate_lines(cert: Certificate, indent: str = "  ") -> list:
    """The certificate in full: the claim and its conditions, the bounds, the checks."""
    out = [f"{indent}certified: {cert.claim}",
           f"{indent}  plant class: {cert.plant_class}",
           f"{indent}  noise: {cert.noise}",
           f"{indent}  while {region_text(cert)}" + (f"; {cert.region_note}" if cert.region_note else "")]
    for b in cert.bounds:
        out.append(f"{indent}bound: {bound_text(b)} ({b.norm}: {NORMS[b.norm]}; error: {b.error}; input: {b.input})")
    if not cert.bounds:
        out.append(f"{indent}bound: none from an input (a convergence certificate: the step's contraction below)")
    r = cert.recheck
    out.append(f"{indent}LMI re-check (numpy, no solver): {r.blocks} blocks, worst margin {r.worst_min_eig:.3e} "
               f"(relative {r.worst_relative_margin:.3e}) in {r.worst_block}")
    s = cert.step
    tau = f" (time constant {s.time_constant_s:.3g} s)" if s.rate_proven else ""
    out.append(f"{indent}discrete step Ts = {s.sample_time:g} s ({s.method}): {contraction_text(s)}{tau}")
    return out


def figure_lines(figures: dict, indent: str = "  ", skip=()) -> list:
    """Figures (JSON data) as 'key  value' lines; nested tables indented under their key."""
    out = []
    for key, value in figures.items():
        if key in skip:
            continue
        if isinstance(value, dict):
            if value and all(not isinstance(v, (dict, list)) for v in value.values()) and len(value) <= 4:
                out.append(f"{indent}{key:24s} " + ", ".join(f"{k} {number(v)}" for k, v in value.items()))
            else:
                out.append(f"{indent}{key}:")
                out += figure_lines(value, indent + "  ")
        elif isinstance(value, (list, tuple)) and value and all(isinstance(v, dict) for v in value):
            out.append(f"{indent}{key}:")
            for v in value:
                out.append(f"{indent}  - " + ", ".join(f"{k} {number(x)}" for k, x in v.items()))
        elif isinstance(value, (list, tuple)):
            out.append(f"{indent}{key:24s} {number(value)}")
        else:
            out.append(f"{indent}{key:24s} {number(value)}")
    return out


# figures that the certificate's lines already give
_IN_CERTIFICATE = ("observer", "artifact", "worst_block", "worst_min_eig", "worst_relative_margin", "lmi_blocks",
                   "sample_time")


def design_lines(family, build, path) -> list:
    """What ``uiogen design`` prints: the certificate, the family's figures, where the lock went."""
    return [f"observer {build.name}: {family.title} ({family.short_citation})",
            *certificate_lines(build.certificate),
            "  figures:",
            *figure_lines(build.figures(), "    ", skip=_IN_CERTIFICATE),
            f"artifact: {path}"]


def demo_lines(family, cert: Certificate) -> list:
    """The design part of an observer's entry in ``uiogen demo``."""
    tau = f"; time constant {cert.step.time_constant_s:.3g} s" if cert.step.rate_proven else ""
    return [f"{family.title} ({family.short_citation}): {cert.claim}",
            f"{headline(cert)}{tau} at Ts = {cert.step.sample_time:g} s"]


def check_gains_lines(family, check) -> list:
    """What ``uiogen check-gains`` prints for a :class:`~codegen.certificate.gains.GainsCheck`."""
    out = [f"{family.title} ({family.short_citation}): check of {check.source} on observer {check.observer} "
           f"(form {check.form})"]
    for case, c in check.cases.items():
        out.append(f"  {case}:")
        for blk in c.get("blocks", ()):
            rest = ", ".join(f"{k} {number(v)}" for k, v in blk.items() if k != "label")
            out.append(f"    {blk['label']:45s} {rest}")
        out += figure_lines({k: v for k, v in c.items() if k != "blocks"}, "    ")
    out += figure_lines(check.figures, "  ")
    if check.certificate is not None:
        out += certificate_lines(check.certificate)
    if not check.feasible:
        out.append(f"  FAIL: {check.reason}")
    elif check.certificate is not None:
        out.append("  PASS: every block re-checked with numpy, and the discrete step certified (the certificate above)")
    else:
        out.append("  PASS: every block re-checked with numpy")
    return out


def validation_header(family, name: str, result: dict, settle_time: float) -> str:
    """The line ``uiogen validate`` prints above a scenario's table."""
    model = result.get("plant_model", result.get("plant"))
    parts = [f"{name}: scenario {result['scenario']} on the {result['plant']} plant ({model}), "
             f"{result['samples']} samples"]
    if result.get("max_abs_ay") is not None:      # None: a model without a lateral acceleration
        parts.append(f"max |a_y| {result['max_abs_ay']:.2f} m/s^2")
    if "relative_degrees" in result:
        parts.append(f"relative degree {result['relative_degrees']}")
    record = result.get("noise")
    if isinstance(record, dict) and "mode" in record:     # the excitation run's: its levels are the line below
        parts.append({"declared": "sensor noise as declared", "off": "noise free (--noise-free)",
                      "none declared": "noise free (none declared)"}[record["mode"]])
    elif "noise" in result:
        parts.append(f"white output noise {result['noise']}" if result["noise"] else "noise free")
    parts.append(f"{result['status_flags']} flagged samples")
    note = getattr(family, "table_note", "") if result.get("table_format") != "generic" else ""
    return ", ".join(parts) + f"; errors after {settle_time:g} s" + (f" ({note})" if note else "")


def bench_lines(figures: dict) -> list:
    """A family's bench figures (``BenchFigures.bench_figures``)."""
    return figure_lines(figures, "")


def bench_study_lines(family, rows: list) -> list:
    """A family-wide bench study (``BenchStudy``), in the family's table format."""
    return [f"{family.title}: family study", *family.bench_family_table(rows)]


def fit_lines(family, result: dict, files: dict) -> list:
    """``uiogen fit``'s result, in the family's table format (``Identification.fit_table``), then each
    file's state ({path: "written" | "differs" | "equal"})."""
    said = {"written": "written", "differs": "differs from the fit (--write puts it there)", "equal": "equals the fit"}
    return [*family.fit_table(result), *(f"  {path}: {said[state]}" for path, state in files.items())]
