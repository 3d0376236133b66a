"""Parameter models whose number fields refuse true and false.

Pydantic reads ``true`` as 1 and ``false`` as 0 where a number is expected, so ``--set gamma=true``
or ``{"width": true}`` would silently run with γ = 1 or a one-pixel render. :class:`NumbersModel`
refuses them, naming the field, in every model it is the base of (operators' parameters, the HTTP
service's ``scene``, ``options`` and viewer requests).
"""

from __future__ import annotations

import typing
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationInfo, field_validator

from ops.checks import holds_truth_value

__all__ = ["NumbersModel"]


class NumbersModel(BaseModel):
    """A model whose int and float fields (and lists of them) refuse true and false, and NaN
    and infinities ("Input should be a finite number", not the bound a NaN fails)."""

    model_config = ConfigDict(allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _no_truth_values_as_numbers(cls, value: Any, info: ValidationInfo) -> Any:
        field = cls.model_fields.get(info.field_name or "")
        if field is not None and holds_truth_value(value):
            kinds = _scalar_kinds(field.annotation)
            if kinds & {int, float} and bool not in kinds:
                raise ValueError("expected a number, not true or false")
        return value


def _scalar_kinds(annotation: Any) -> set[Any]:
    """The scalar types a field's annotation takes, through unions, lists, ``Annotated`` and
    aliases (``Literal`` choices and classes are left out: pydantic refuses a bool for them)."""
    if annotation in (bool, int, float):
        return {annotation}
    if typing.get_origin(annotation) is typing.Literal:
        return set()
    kinds: set[Any] = set()
    for arg in typing.get_args(annotation):
        kinds |= _scalar_kinds(arg)
    return kinds
