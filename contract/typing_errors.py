"""Turns pydantic validation errors into readable text: `error_path`/`error_line` for any
error, and located diagnostics (RC101-RC103) for a YAML document."""

from __future__ import annotations

import types
from collections.abc import Sequence
from typing import Any, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from robotconf.contract.diagnostics import Diagnostic, Severity, describe_value, did_you_mean
from robotconf.contract.yamlio import YamlDocument

_EXPECTED = {
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "int_type": "a whole number",
    "int_parsing": "a whole number",
    "int_from_float": "a whole number",
    "float_type": "a number",
    "float_parsing": "a number",
    "string_type": "text",
    "dict_type": "a mapping (key: value)",
    "model_type": "a mapping (key: value)",
    "model_attributes_type": "a mapping (key: value)",
    "list_type": "a list",
}


def type_error_text(error: ErrorDetails) -> str | None:
    """`must be a number, got 'fast' (text)` for a value of the wrong type, else None."""
    expected = _EXPECTED.get(error["type"])
    if expected is None:
        return None
    return f"must be {expected}, got {describe_value(error.get('input'))}"


def _unwrap(annotation: Any) -> Any:
    """The structured member of an Optional/Union annotation, else the annotation itself."""
    origin = get_origin(annotation)
    if origin is Union or origin is types.UnionType:
        for arg in get_args(annotation):
            if arg is type(None):
                continue
            if (isinstance(arg, type) and issubclass(arg, BaseModel)) or get_origin(arg) in (
                dict,
                list,
            ):
                return arg
        return annotation
    return annotation


def _model_at(model: type[BaseModel], loc: Sequence[str | int]) -> type[BaseModel] | None:
    """The model class that a data path points into, for listing its allowed fields."""
    current: Any = model
    for part in loc:
        current = _unwrap(current)
        if isinstance(current, type) and issubclass(current, BaseModel):
            info = current.model_fields.get(str(part))
            if info is None:
                return None
            current = info.annotation
        elif get_origin(current) is dict:
            current = get_args(current)[1]
        elif get_origin(current) is list:
            current = get_args(current)[0]
        else:
            return None
    current = _unwrap(current)
    if isinstance(current, type) and issubclass(current, BaseModel):
        return current
    return None


def _data_loc(data: Any, loc: Sequence[str | int]) -> tuple[str | int, ...]:
    """The part of pydantic's loc that exists in the data (drops union member tags)."""
    out: list[str | int] = []
    current = data
    for part in loc:
        indexable = isinstance(current, dict) or (
            isinstance(current, list) and isinstance(part, int) and part >= 0
        )
        if not indexable:
            continue
        try:
            current = current[part]
        except (KeyError, IndexError):
            continue
        out.append(part)
    return tuple(out)


def error_path(loc: Sequence[str | int], top: str = "(top level)") -> str:
    """pydantic's loc as a person reads it, `scenario.goals[0].task`; `top` for the whole
    input."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or top


def error_text(error: ErrorDetails) -> str:
    """pydantic's message; for our own validators' ValueError, their words alone."""
    return str(error["msg"]).removeprefix("Value error, ")


def error_line(error: ErrorDetails) -> str:
    """One error as one readable line: `where: what`, or `where must be X, got V (kind)`."""
    natural = type_error_text(error)
    if natural is not None:
        return f"{error_path(error['loc'])} {natural}"
    return f"{error_path(error['loc'])}: {error_text(error)}"


def _dotted(loc: Sequence[str | int]) -> str:
    return error_path(loc, "the file")


def _another_member_went_deeper(
    loc: tuple[str | int, ...],
    errs: list[ErrorDetails],
    grouped: dict[tuple[str | int, ...], list[ErrorDetails]],
) -> bool:
    """Whether the errors at `loc` are only union members the value is not (`text` for a
    list) while a member it is failed inside it: `[1]` for `str | list[str]` is "item 0 must
    be text", not also "must be text"."""
    tagged = all(len(err["loc"]) > len(loc) for err in errs)
    return tagged and any(len(other) > len(loc) and other[: len(loc)] == loc for other in grouped)


def typing_diagnostics(
    doc: YamlDocument, model: type[BaseModel], error: ValidationError, what: str
) -> list[Diagnostic]:
    """One diagnostic per wrong place, pointing at the offending key or value."""
    grouped: dict[tuple[str | int, ...], list[ErrorDetails]] = {}
    found: list[Diagnostic] = []

    def report(loc: Sequence[str | int], code: str, message: str, *, key: bool = False) -> None:
        line, col = doc.locate(loc, key=key)
        found.append(Diagnostic(doc.path, line, col, Severity.ERROR, code, message))

    for err in error.errors(include_url=False):
        kind = err["type"]
        loc = tuple(err["loc"])
        if kind == "extra_forbidden":
            parent = _model_at(model, loc[:-1])
            allowed = sorted(parent.model_fields) if parent else []
            name = str(loc[-1])
            where = f" in {_dotted(loc[:-1])}" if loc[:-1] else ""
            hint = did_you_mean(name, allowed) if allowed else ""
            if hint.startswith("; known:"):
                hint = "; allowed: " + ", ".join(allowed)
            report(loc, "RC101", f"unknown field '{name}'{where} of {what}{hint}", key=True)
        elif kind == "missing":
            parent = _model_at(model, loc[:-1])
            info = parent.model_fields.get(str(loc[-1])) if parent else None
            about = f" ({info.description})" if info is not None and info.description else ""
            where = f" in {_dotted(loc[:-1])}" if loc[:-1] else ""
            report(loc[:-1], "RC102", f"missing required field '{loc[-1]}'{where}{about}")
        else:
            grouped.setdefault(_data_loc(doc.data, loc), []).append(err)

    for loc, errs in grouped.items():
        if _another_member_went_deeper(loc, errs, grouped):
            continue
        expected: list[str] = []
        for err in errs:
            text = _EXPECTED.get(err["type"])
            context = err.get("ctx") or {}
            if err["type"] == "too_short" and "min_length" in context:
                least = context["min_length"]
                text = f"a list of at least {least} item{'s' if least != 1 else ''}"
            if text is None:
                text = error_text(err)
                text = (text[:1].lower() + text[1:]).removeprefix("input should be ")
            if text not in expected:
                expected.append(text)
        value = errs[0].get("input")
        given = describe_value(value, kind=any(err["type"] in _EXPECTED for err in errs))
        report(
            loc,
            "RC103",
            f"{_dotted(loc)} must be {' or '.join(expected)}, got {given}",
        )
    return found
