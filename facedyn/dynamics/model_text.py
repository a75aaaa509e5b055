"""`usdfacedyn inspect MODEL` as text: one line per field, long lists summarized.

`describe_model` (facedyn.dynamics.modelfile) keeps everything, for `--json`; a person reading
the terminal needs what the model is and fits, not the 200 corpus takes it was trained on,
so lists longer than LIST_SHOWN are counted and their first items named, and a blend's members
are indented under it.
"""
from __future__ import annotations

LIST_SHOWN = 4  # items of a longer list that the text names


def format_model_description(description: dict, indent: str = "") -> str:
    """The text of a describe_model result (a blend's members indented below it)."""
    lines = []
    for key, value in description.items():
        if key == "members":
            for number, member in enumerate(value, start=1):
                lines.append(f"{indent}member {number}:")
                lines.append(format_model_description(member, indent + "  "))
        elif key == "bands":
            shares = ", ".join(f"{row[0]:.2f}" for row in value["weights"])
            edges = ", ".join(f"{e:g}" for e in value["edges_hz"])
            lines.append(f"{indent}bands: edges {edges} Hz; member 1's share per band, lowest first: {shares} (member 2 the rest)")
        else:
            lines.append(f"{indent}{key}: {_compact(value)}")
    return "\n".join(lines)


def _compact(value):
    """`value` with every list longer than LIST_SHOWN replaced by its count and first items."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_compact(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        if len(value) <= LIST_SHOWN:
            return "[" + ", ".join(str(_compact(v)) for v in value) + "]"
        named = [v.get("name") if isinstance(v, dict) else v for v in value[:LIST_SHOWN]]
        extra = ""
        if all(isinstance(v, dict) for v in value) and any("validation" in v for v in value):
            extra = f", {sum(bool(v.get('validation')) for v in value)} for validation"
        return f"{len(value)} items ({', '.join(map(str, named))}, ...{extra})"
    return value
