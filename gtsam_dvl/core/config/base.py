"""The base of every configuration model: pydantic checks, one-line errors, TOML text.

Every section is a pydantic model (ConfigModel): unknown keys are refused (extra="forbid"), numbers are finite
(allow_inf_nan=False) and strict (a string or a boolean is no number; an integer is a float where a float belongs,
a float is no integer), enumerations are Literal fields, ranges are the fields' constraints (Gt, Ge, Le, ...).
A pydantic ValidationError becomes one GtsamDvlError line naming the source, the section, the key, the value and
what is allowed, built from the error's location and the field's declared type and constraints, e.g.
"cfg.toml: [dvl] noise_m_s must be a number >= 0, got -0.1".

Construction checks (ConfigModel(...), model_validate); assignment does not: a configuration changed in Python
is checked by validate(), which every estimator calls when it starts. An optional field (`X | None`) takes None
(JSON null) or, in a TOML file, which has no null, the string "none".
"""

from __future__ import annotations

import json
import math
import numbers
import types
import typing
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, Literal, Self

import numpy as np
from annotated_types import Ge, Gt
from pydantic import BaseModel, ConfigDict, Strict, ValidationError, model_validator
from pydantic.fields import FieldInfo

from gtsam_dvl.core.errors import GtsamDvlError

# Field types. Strict: "5" or true is not taken for a number; an int is taken for a float (and made float).
Number = Annotated[float, Strict()]  # any finite number
Positive = Annotated[float, Strict(), Gt(0.0)]
NonNegative = Annotated[float, Strict(), Ge(0.0)]
Integer = Annotated[int, Strict()]
Flag = Annotated[bool, Strict()]


class ConfigModel(BaseModel):
    """A table of the configuration (a TOML section, or the whole configuration): checked on construction
    and by validate(); SECTION is its TOML table name ("" for the whole configuration)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    SECTION: ClassVar[str] = ""

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise GtsamDvlError(one_line(exc, data, type(self), "config")) from None

    # Marked as pydantic's own __init__ (as pydantic's RootModel does): tables inside a validated dict are then
    # validated by pydantic directly, so that their errors keep their location and source, not through this.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    @model_validator(mode="before")
    @classmethod
    def _none_from_toml(cls, data: Any) -> Any:
        """TOML has no null: "none" is None in an optional field."""
        if not isinstance(data, Mapping):
            return data
        optional = {
            name
            for name, f in cls.model_fields.items()
            if type(None) in typing.get_args(f.annotation)
        }
        return {
            k: None if k in optional and isinstance(v, str) and v == "none" else v
            for k, v in data.items()
        }

    @classmethod
    def checked(cls, data: Any, source: str = "config") -> Self:
        """The model validated from a dict (or another model's fields), else GtsamDvlError (one line)."""
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise GtsamDvlError(one_line(exc, data, cls, source)) from None

    def validate(self, source: str = "config") -> Self:  # type: ignore[override]  # BaseModel.validate: deprecated
        """Check every value as on load (GtsamDvlError, one line), for a configuration built or changed in
        Python; the values are normalised in place (ints made float where a float belongs, sequences tuples).
        Returns self."""
        self._take(type(self).checked(_raw(self), source))
        return self

    def _take(self, checked: ConfigModel) -> None:
        """Set every field from checked, a section in place (a caller's reference to it stays valid); the fields
        counted as set are checked's (those set on construction or by assignment, not those a preset filled)."""
        for name in type(self).model_fields:
            new, current = getattr(checked, name), getattr(self, name)
            if isinstance(new, ConfigModel) and type(current) is type(new):
                current._take(new)
            else:
                setattr(self, name, new)
        object.__setattr__(self, "__pydantic_fields_set__", set(checked.model_fields_set))


def _raw(model: ConfigModel) -> dict[str, Any]:
    """The fields set on construction or by assignment as they are (unchecked values included), and every section
    as a dict. The others hold their defaults, or a preset's values, which the check fills again (from the preset
    the configuration names now: a sensor model changed in Python takes effect on validate())."""
    return {
        name: _raw(v) if isinstance(v, ConfigModel) else v
        for name, v in model.__dict__.items()
        if isinstance(v, ConfigModel) or name in model.model_fields_set
    }


def _sub_model(f: FieldInfo) -> type[ConfigModel] | None:
    tp = f.annotation
    return tp if isinstance(tp, type) and issubclass(tp, ConfigModel) else None


def _item(data: Any, key: Any) -> Any:
    if isinstance(data, Mapping):
        return data.get(key)
    return getattr(data, key, None) if isinstance(key, str) else None


# ----- one-line errors ----------------------------------------------------------------------------------------


def one_line(exc: ValidationError, data: Any, model: type[ConfigModel], source: str) -> str:
    """The first error of exc (an unknown key first, as a typo explains the rest) as one line:
    "{source}: [section] key {what is allowed}, got {value}". data is what was validated, for the value as given
    (the whole list, where pydantic names one element)."""
    err = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")[0]
    path = [p for p in model.SECTION.split(".") if p]
    for depth, part in enumerate(err["loc"]):
        fields = model.model_fields
        where = f"[{'.'.join(path)}]"
        if part not in fields:
            if not path:
                return f"{source}: unknown section [{part}] (known: {', '.join(sorted(fields))})"
            return f"{source}: unknown key '{part}' in {where} (known: {', '.join(fields)})"
        data = _item(data, part)
        sub = _sub_model(fields[str(part)])
        if sub is None:
            return f"{source}: {where} {part} {allowed_text(fields[str(part)], data)}"
        if depth == len(err["loc"]) - 1:  # the section itself is not a table
            if not path:
                return f"{source}: [{part}] must be a table of keys, got {data!r}"
            return f"{source}: {where} {part} must be a table [{'.'.join([*path, str(part)])}], got {data!r}"
        model, path = sub, [*path, str(part)]
    return f"{source}: {err['msg']}"


def _unannotated(tp: Any, constraints: list[Any]) -> Any:
    """tp without Annotated, its metadata appended to constraints."""
    if typing.get_origin(tp) is Annotated:
        tp, *meta = typing.get_args(tp)
        constraints.extend(meta)
    return tp


def allowed_text(f: FieldInfo, value: Any) -> str:
    """What field f allows, as the end of "[section] key ...", with the value given."""
    constraints = list(f.metadata)
    tp, or_none = f.annotation, ""
    if typing.get_origin(tp) in (types.UnionType, typing.Union) and type(None) in typing.get_args(
        tp
    ):
        (tp,) = [a for a in typing.get_args(tp) if a is not type(None)]
        or_none = " or 'none'"
    tp = _unannotated(tp, constraints)
    if typing.get_origin(tp) is Literal:
        return f"= {value!r} is not one of {', '.join(repr(a) for a in typing.get_args(tp))}"
    if tp is bool:
        what = "true or false"
    elif tp is int:
        what = f"an integer{_range_text(constraints)}"
    elif tp is float:
        what = f"a number{_range_text(constraints)}"
    elif typing.get_origin(tp) is tuple:
        elements = typing.get_args(tp)
        _unannotated(elements[0], constraints)
        what = f"a list of {len(elements)} numbers{_range_text(constraints)}"
    else:
        what = f"a {getattr(tp, '__name__', tp)}"
    return f"must be {what}{or_none}, got {value!r}"


def _range_text(constraints: list[Any]) -> str:
    """ " > 0", " in [-90, 90]", ... from the Gt/Ge/Lt/Le constraints."""
    bound = {
        k: getattr(c, k) for c in constraints for k in ("gt", "ge", "lt", "le") if hasattr(c, k)
    }
    lo = ("[", bound["ge"]) if "ge" in bound else ("(", bound["gt"]) if "gt" in bound else None
    hi = ("]", bound["le"]) if "le" in bound else (")", bound["lt"]) if "lt" in bound else None
    if lo and hi:
        return f" in {lo[0]}{lo[1]:g}, {hi[1]:g}{hi[0]}"
    if lo:
        return f" {'>=' if lo[0] == '[' else '>'} {lo[1]:g}"
    if hi:
        return f" {'<=' if hi[0] == ']' else '<'} {hi[1]:g}"
    return ""


# ----- TOML writing ---------------------------------------------------------------------------------------------
# Hand-written: tomllib only reads, and no TOML writer (tomli-w, tomlkit) is among the dependencies; the
# configuration needs tables, sub-tables, numbers, booleans, strings and flat lists only.


def toml_text(tables: ConfigModel) -> str:
    """TOML text of a model whose fields are tables (sections). TOML has no null: None is written "none", or
    left out where it is the default."""
    lines: list[str] = []
    for name in type(tables).model_fields:
        _toml_table(getattr(tables, name), name, lines)
    return "\n".join(lines)


def _toml_table(section: ConfigModel, name: str, lines: list[str]) -> None:
    lines.append(f"[{name}]")
    nested = []
    for key, f in type(section).model_fields.items():
        value = getattr(section, key)
        if isinstance(value, ConfigModel):
            nested.append((f"{name}.{key}", value))
        elif value is not None:
            lines.append(f"{key} = {_toml_value(value)}")
        # TOML has no null: "none" (a field whose default is None is left out)
        elif f.default is not None:
            lines.append(f'{key} = "none"')
    lines.append("")
    for sub_name, sub in nested:
        _toml_table(sub, sub_name, lines)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        x = float(value)
        return (
            repr(x)
            if math.isfinite(x)
            else ("nan" if math.isnan(x) else "inf" if x > 0 else "-inf")
        )
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to TOML")
