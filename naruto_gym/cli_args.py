"""Command-line flags from a typed ``@dataclass`` of arguments (the benchmark scripts' style).

Each field becomes ``--field-name``; its type hint picks the parsing (``bool`` gives
``--flag / --no-flag``, ``list[X]`` takes one or more values, ``X | None`` parses as ``X``), and
the string literal written under a field becomes its help text.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

ArgsT = TypeVar("ArgsT")


def field_docs(cls: type) -> dict[str, str]:
    """The string literal under each field of a dataclass (empty when no source is found)."""
    try:
        tree = ast.parse(inspect.getsource(cls))
    except (OSError, TypeError):  # no source available (frozen app, interactive class)
        return {}
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for node, following in zip(body, body[1:], strict=False):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(following, ast.Expr)
            and isinstance(following.value, ast.Constant)
        ):
            docs[node.target.id] = str(following.value.value)
    return docs


def dataclass_parser(
    cls: type, description: str | None = None, prog: str | None = None
) -> argparse.ArgumentParser:
    """An ``argparse`` parser with one flag per field of the dataclass ``cls``."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description=description,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    hints = get_type_hints(cls)
    docs = field_docs(cls)
    names = {item.name for item in dataclasses.fields(cls)}
    for item in dataclasses.fields(cls):
        flag = "--" + item.name.replace("_", "-")
        kind = hints[item.name]
        default: Any = (
            item.default if item.default is not dataclasses.MISSING else item.default_factory()
        )
        # argparse expands %-formats in help strings: a doc's "10 %" must stay text.
        help_text = docs.get(item.name, "").replace("%", "%%")
        if kind is bool:
            parser.add_argument(
                flag, action=argparse.BooleanOptionalAction, default=default, help=help_text
            )
        elif get_origin(kind) in (list, tuple):
            element = get_args(kind)[0]
            # A list flag also answers to its singular ("--policy" for "--policies"), as users
            # type it; otherwise argparse would read "--policy" as a prefix of another flag.
            singular = _singular(item.name)
            flags = [flag] if singular in names or singular == item.name else [
                flag, "--" + singular.replace("_", "-")]
            parser.add_argument(*flags, dest=item.name, nargs="*", type=element,
                                default=default, help=help_text)
        else:
            element = next((a for a in get_args(kind) if a is not type(None)), kind)
            parser.add_argument(flag, type=element, default=default, help=help_text)
    return parser


def _singular(name: str) -> str:
    """``policies`` -> ``policy``, ``classes`` -> ``class``, ``seeds`` -> ``seed``."""
    if name.endswith("ies"):
        return name[:-3] + "y"
    if name.endswith(("sses", "shes", "ches", "xes")):
        return name[:-2]
    if name.endswith("s") and not name.endswith("ss"):
        return name[:-1]
    return name


def parse_dataclass_args(
    cls: type[ArgsT], argv: list[str] | None = None, description: str | None = None
) -> ArgsT:
    """Parse ``argv`` (default: the command line) into an instance of ``cls``."""
    namespace = dataclass_parser(cls, description).parse_args(argv)
    return cls(**vars(namespace))
