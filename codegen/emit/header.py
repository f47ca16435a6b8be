"""What an emitted header declares, read back from it: the fields of its state, input and output
structs with their documentation (``templates/observer.h.j2`` writes one field per line,
``double NAME; /* DOC */``, DOC ending in ``[UNIT]``). The extension compiles these in, so the
names a user sees are those of the C it runs, in the C's order."""
from __future__ import annotations

import re

from ..errors import GenerationError


def unit_of(doc: str) -> str:
    """The unit in a signal's doc, ``estimate of beta [rad]`` -> ``rad``; '' for none or ``[-]``."""
    m = re.search(r"\[([^\]]+)\]", doc)
    return "" if m is None or m.group(1).strip() in ("-", "") else m.group(1).strip()


def struct_fields(header: str, name: str) -> dict:
    """{"state"|"input"|"output": [(field, doc, unit), ...], or None for a struct the header of
    observer ``name`` does not declare}."""
    out = {}
    for part in ("state", "input", "output"):
        m = re.search(r"typedef struct \{\n([^{}]*)\n\} " + re.escape(f"{name}_{part}") + ";", header)
        if m is None and part == "output" and f"typedef {name}_state {name}_output;" in header:
            out[part] = out["state"]
        elif m is None:
            out[part] = None
        else:
            fields = re.findall(r"^\s*\w+ (\w+);(?: /\* (.*?) \*/)?$", m.group(1), re.M)
            out[part] = [(field, doc, unit_of(doc)) for field, doc in fields]
    return out


def signals(header: str, name: str) -> dict:
    """:func:`struct_fields`, every struct required (a :class:`GenerationError` names the one missing)."""
    out = struct_fields(header, name)
    for part, fields in out.items():
        if fields is None:
            raise GenerationError(f"the header of {name} declares no struct {name}_{part}; regenerate it "
                                  f"(`uiogen generate {name} --force`)")
    return out
