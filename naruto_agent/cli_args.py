"""Command-line flags from a typed ``@dataclass`` of arguments (the benchmark scripts' style).

Each field becomes ``--field-name``; its type hint picks the parsing (``bool`` gives
``--flag / --no-flag``, ``list[X]`` takes one or more values, ``X | None`` parses as ``X``), and
the string literal written under a field becomes its help text.

One concept has one flag across the tools (:data:`RENAMED_FLAGS`): a flag of an earlier
spelling is refused with an error naming the flag that replaced it, never taken silently.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import textwrap
from collections.abc import Iterable
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

ArgsT = TypeVar("ArgsT")

#: Earlier spellings of the tools' flags -> the flags that replaced them. Where a spelling
#: named two concepts (a folder or a file), the replacement is the one the tool has; a parser
#: that has none of them, or still defines the old flag itself, is left alone.
RENAMED_FLAGS: dict[str, tuple[str, ...]] = {
    "--out": ("--output-dir", "--output-file"),
    "--out-dir": ("--output-dir",),
    "--output": ("--output-dir", "--output-file"),
    "--results-dir": ("--output-dir",),
    "--run-dir": ("--output-dir",),
    "--steps": ("--max-episode-steps",),
    "--episode-steps": ("--max-episode-steps",),
    "--step-budget": ("--max-episode-steps",),
    "--checkpoints": ("--eval-points",),
    "--mapper": ("--mapper-kind",),
    # The reference TSDF mapper's device, in a tool whose --device would not be the agent's.
    "--device": ("--reference-device",),
}


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


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Help with each flag's default, wrapped at spaces only: names with hyphens (policy
    names such as ``goal-ranker-untrained``) stay whole on one line."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return textwrap.fill(
            " ".join(text.split()), width, initial_indent=indent, subsequent_indent=indent,
            break_on_hyphens=False,
        )  # fmt: skip


def dataclass_parser(
    cls: type, description: str | None = None, prog: str | None = None
) -> argparse.ArgumentParser:
    """An ``argparse`` parser with one flag per field of the dataclass ``cls``."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description=description,
        formatter_class=HelpFormatter,
    )
    hints = get_type_hints(cls)
    docs = field_docs(cls)
    names = {item.name for item in dataclasses.fields(cls)}
    flags_made: list[str] = []
    for item in dataclasses.fields(cls):
        flag = "--" + item.name.replace("_", "-")
        flags_made.append(flag)
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
            flags = (
                [flag]
                if singular in names or singular == item.name
                else [flag, "--" + singular.replace("_", "-")]
            )
            flags_made += flags
            parser.add_argument(
                *flags, dest=item.name, nargs="*", type=element, default=default, help=help_text
            )
        else:
            element = next((a for a in get_args(kind) if a is not type(None)), kind)
            parser.add_argument(flag, type=element, default=default, help=help_text)
    refuse_renamed_flags(parser, flags_made)
    return parser


class _RenamedFlag(argparse.Action):
    """A flag's earlier spelling: using it ends parsing with an error naming the new flag."""

    def __init__(self, option_strings: list[str], dest: str, new_flag: str, **kwargs: Any):
        self.new_flag = new_flag
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: Any,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        parser.error(f"{option_string} was renamed: use {self.new_flag}")


def refuse_renamed_flags(parser: argparse.ArgumentParser, flags: Iterable[str]) -> None:
    """Make ``parser``, whose flags are ``flags``, refuse their earlier spellings
    (:data:`RENAMED_FLAGS`).

    Without this, argparse would also read an old spelling that is a prefix of the new one
    (``--out`` of ``--output-dir``) as that flag, silently.
    """
    defined = set(flags)
    for old, replacements in RENAMED_FLAGS.items():
        new = next((flag for flag in replacements if flag in defined), None)
        if old in defined or new is None:
            continue
        parser.add_argument(
            old,
            action=_RenamedFlag,
            new_flag=new,
            nargs="*",
            default=argparse.SUPPRESS,
            help=argparse.SUPPRESS,
        )


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
