#!/usr/bin/env python3
"""The generated blocks of README.md and docs/*.md: the tables that restate the code.

A block sits between ``<!-- generated: WHAT -->`` and ``<!-- end generated -->``; WHAT says what
it holds, one of

- ``methods``: the planning methods (:func:`vp_planner.methods.method_table`);
- ``params MODULE[:ATTR]``: a node's parameters, a table of name, default, allowed values,
  read-only and description, from its :class:`vp_scene.node_runtime.Param` descriptors (``ATTR``
  defaults to ``PARAMS``);
- ``param-names MODULE[:ATTR]``: the same parameters' names alone, one wrapped line;
- ``action NAME``, ``msg NAME``, ``srv NAME``: the fields of ``src/vp_interfaces/KIND/NAME.KIND``
  (an action's goal, result and feedback) with their types and comments, and its constants;
- ``action-names NAME`` (``msg-names``, ``srv-names``): the same fields' and constants' names alone.

``python tools/doc_tables.py`` rewrites every block from the code; ``--check`` rewrites nothing
and exits 1 naming the files whose blocks differ (``tests/test_docs.py`` runs the check). Needs
the ROS shell (the nodes import rclpy).
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import re
import sys
import textwrap
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
INTERFACES = ROOT / "src" / "vp_interfaces"
BLOCK = re.compile(r"(<!-- generated: (?P<what>[^>]*?) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S)
#: Lines of the name lists are wrapped to this width (the README keeps lines under 120 characters).
WIDTH = 116
#: Defaults that depend on the machine or the user, shown as what they are: (module, parameter) ->
#: (text, the value here).
MACHINE_DEFAULTS = {
    ("vp_recon.recon_node", "output_folder"): ("`~/.ros/vp_recon`", lambda: str(Path.home() / ".ros" / "vp_recon")),
    ("vp_recon.recon_node", "num_threads"): ("cores - 1", lambda: max(1, (os.cpu_count() or 2) - 1)),
    ("vp_recon.recon_node", "workers"): ("cores - 1", lambda: max(1, (os.cpu_count() or 2) - 1)),
}


def files() -> list[Path]:
    """The documents that may hold generated blocks."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


# ---------------------------------------------------------------- node parameters
def _params(spec: str) -> tuple[str, dict]:
    module, _, attr = spec.partition(":")
    return module, getattr(importlib.import_module(module), attr or "PARAMS")


def _number(v: float) -> str:
    if isinstance(v, bool) or not isinstance(v, float):
        return str(v)
    return f"{v:.4g}"


def _default(module: str, name: str, value: Any) -> str:
    if (module, name) in MACHINE_DEFAULTS:
        text, here = MACHINE_DEFAULTS[module, name]
        if value != here():
            raise ValueError(f"{module} parameter {name}: default {value!r} is not {text} ({here()}) here: "
                             f"update MACHINE_DEFAULTS")
        return text
    if isinstance(value, bool):
        return "`true`" if value else "`false`"
    if isinstance(value, str):
        return f"`{value}`" if value else "`''`"
    if isinstance(value, (list, tuple)):
        return "`[" + ", ".join(str(v) for v in value) + "]`"
    return _number(value)


def _allowed(p: Any) -> str:
    """The allowed values: the range as an interval (an end the constraints exclude is open), then
    what else the constraints say."""
    from vp_scene.node_runtime import INT_MAX

    rest = p.constraints
    if p.range is None:
        return rest
    lo, hi = p.range
    both_open = rest == "the ends are excluded"
    lo_open = both_open or (rest in ("> 0", "above 0") and lo == 0)
    if both_open or lo_open:
        rest = ""
    if hi in (math.inf, INT_MAX):
        text = f"{'>' if lo_open else '>='} {_number(lo)}"
    else:
        text = f"{'(' if lo_open else '['}{_number(lo)}, {_number(hi)}{')' if both_open else ']'}"
    return f"{text}; {rest}" if rest else text


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def params_table(spec: str) -> str:
    """A node's parameters as a markdown table (``spec``: ``MODULE[:ATTR]``)."""
    from vp_scene.node_runtime import Param

    module, params = _params(spec)
    rows = ["| parameter | default | allowed | read-only | meaning |", "|---|---|---|---|---|"]
    for name, raw in params.items():
        p = Param(*raw)
        rows.append(f"| `{name}` | {_cell(_default(module, name, p.default))} | {_cell(_allowed(p))} | "
                    f"{'yes' if p.read_only else ''} | {_cell(p.description)} |")
    return "\n".join(rows)


def _names(names: list[str], lead: str = "", item: bool = False) -> str:
    """``names`` in code spans, after ``lead``, wrapped (``item``: as a list item)."""
    return textwrap.fill(lead + ", ".join(f"`{n}`" for n in names) + ".", WIDTH, break_on_hyphens=False,
                         initial_indent="- " if item else "", subsequent_indent="  " if item else "")


def param_names(spec: str) -> str:
    """A node's parameter names, one wrapped line."""
    return _names(list(_params(spec)[1]), "Parameters: ")


# ---------------------------------------------------------------- interfaces
#: The parts of an interface file, by its kind.
PART_NAMES = {"action": ("goal", "result", "feedback"), "msg": ("message",), "srv": ("request", "response")}


def interface_parts(kind: str, name: str) -> list[dict]:
    """The parts of ``src/vp_interfaces/KIND/NAME.KIND`` (an action's goal, result and feedback; a
    message's one part): per part, ``fields`` [(type, name, comment)] and ``constants`` [(type,
    name, value, comment)], each comment joined across its continuation lines."""
    parts = []
    for chunk in (INTERFACES / kind / f"{name}.{kind}").read_text().split("\n---\n"):
        part: dict = {"fields": [], "constants": []}
        last = None
        for line in chunk.splitlines():
            code, _, comment = line.partition("#")
            comment = comment.strip()
            if not code.strip():
                if comment and last is not None and line.startswith(" "):
                    last[-1] = f"{last[-1]} {comment}".strip()
                elif not line.startswith(" "):
                    last = None  # a comment of its own ends the entry above
                continue
            type_, rest = code.split(None, 1)
            rest = rest.strip()
            if "=" in rest:
                cname, value = (s.strip() for s in rest.split("=", 1))
                last = [type_, cname, value, comment]
                part["constants"].append(last)
            else:
                last = [type_, rest.split()[0], comment]
                part["fields"].append(last)
        parts.append(part)
    if len(parts) != len(PART_NAMES[kind]):
        raise ValueError(f"{name}.{kind}: {len(parts)} parts, expected {', '.join(PART_NAMES[kind])}")
    return parts


def interface_table(kind: str, name: str) -> str:
    """An interface's fields (part, field, type, meaning) and its constants, as markdown tables."""
    parts = interface_parts(kind, name)
    several = len(parts) > 1
    lead = "| part " if several else ""
    rows = [lead + "| field | type | meaning |", ("|---" if several else "") + "|---|---|---|"]
    for title, part in zip(PART_NAMES[kind], parts):
        lead = f"| {title} " if several else ""
        rows += [f"{lead}| `{f}` | `{t}` | {_cell(c)} |" for t, f, c in part["fields"]]
    constants = [c for part in parts for c in part["constants"]]
    if constants:
        rows += ["", "| constant | value | meaning |", "|---|---|---|"]
        rows += [f"| `{n}` | {v} | {_cell(c)} |" for _t, n, v, c in constants]
    return "\n".join(rows)


def interface_names(kind: str, name: str) -> str:
    """An interface's field names by part, each part's constants after it."""
    out = []
    for title, part in zip(PART_NAMES[kind], interface_parts(kind, name)):
        out.append(_names([f for _t, f, _c in part["fields"]], f"{title.capitalize()}: ", item=True))
        if part["constants"]:
            out.append(_names([n for _t, n, _v, _c in part["constants"]], f"{title.capitalize()} constants: ",
                              item=True))
    return "\n".join(out)


# ---------------------------------------------------------------- blocks
def render_block(what: str) -> str:
    """The text of the block ``what`` (without its markers), ending with a newline."""
    kind, _, arg = what.strip().partition(" ")
    arg = arg.strip()
    if kind == "methods":
        from vp_planner.methods import method_table

        text = method_table()
    elif kind == "params":
        text = params_table(arg)
    elif kind == "param-names":
        text = param_names(arg)
    elif kind in PART_NAMES:
        text = interface_table(kind, arg)
    elif kind.endswith("-names") and kind[:-6] in PART_NAMES:
        text = interface_names(kind[:-6], arg)
    else:
        raise ValueError(f"unknown generated block {what!r}")
    return text + "\n"


def render(text: str) -> str:
    """``text`` with every generated block rewritten from the code."""
    return BLOCK.sub(lambda m: m.group(1) + render_block(m.group("what")) + m.group(4), text)


def stale() -> list[Path]:
    """The documents whose generated blocks differ from the code."""
    return [p for p in files() if render(p.read_text()) != p.read_text()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 when a block differs")
    args = ap.parse_args(argv)
    if args.check:
        bad = stale()
        for p in bad:
            print(f"{p.relative_to(ROOT)}: generated blocks differ from the code: run python tools/doc_tables.py",
                  file=sys.stderr)
        return 1 if bad else 0
    for p in files():
        text = p.read_text()
        new = render(text)
        if new != text:
            p.write_text(new)
            print(f"wrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
