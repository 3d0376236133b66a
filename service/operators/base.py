"""What an operator is: its parameter model, the context a run passes it, its registry entry.

:func:`register` adds an operator to :data:`REGISTRY`; the modules of :mod:`service.operators`
call it for the built-in ones. :mod:`service.registry` is the catalogue the rest of the service
reads (it imports the built-in operators first).
"""

from __future__ import annotations

import functools
import re
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import ConfigDict, Field, ValidationError, field_validator, model_validator

from gbuffer.frame import Frame
from ops.numerics import clip_new_negatives, new_values
from service.errors import PipelineError
from service.masks import MASK_SYNTAX, blend_layers, matte, shown
from service.masks import parse as parse_mask
from service.memo import Memo
from service.numbers import NumbersModel


class Params(NumbersModel):
    """Base of every operator's parameters: unknown keys are refused, values validated.

    An operator may name sets of parameter values in ``PRESETS`` (e.g. ``"paper"``: the values
    that reproduce its paper's figures) and declare a ``preset`` field listing them: a step's
    ``preset`` fills in every parameter the step does not give itself.
    """

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)
    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {}

    mask: str | None = Field(
        None,
        max_length=4096,
        description=f"restrict the step to a matte (pixels of m = 0 stay bit-exact): {MASK_SYNTAX}",
    )
    mask_feather: float = Field(
        0.0, ge=0.0, le=0.5, description="σ of a Gaussian softening the mask, per image height"
    )
    mask_amount: float = Field(1.0, ge=0.0, le=1.0, description="the mask times this")
    mask_stats: bool = Field(
        False,
        description="measure the step's statistics inside the mask only (the automatic white "
        "level of radiance_scaling and unsharp_masking, the congruence score and its "
        "normalisation), so a small object is not normalised by the rest of the frame",
    )

    @field_validator("mask", mode="before")
    @classmethod
    def _mask_list(cls, value: Any) -> Any:
        """A list (what ``--set mask=cryptomatte:a,b`` parses to) is the comma list it was."""
        if isinstance(value, list):
            return ",".join(str(v) for v in value)
        return value

    @field_validator("mask")
    @classmethod
    def _mask(cls, value: str | None) -> str | None:
        if value is not None:
            parse_mask(value)  # raises ValueError naming what is wrong
        return value

    @model_validator(mode="before")
    @classmethod
    def _fill_preset(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        data = {k: [v] if k in _list_fields(cls) and _scalar(v) else v for k, v in data.items()}
        if isinstance(data.get("preset"), str):
            values = cls.PRESETS.get(data["preset"])
            if values is not None:  # an unknown name is refused by the field's own choices
                return {**values, **data}
        return data


@functools.cache
def _list_fields(model: type[Params]) -> frozenset[str]:
    """The parameters of ``model`` that hold lists: one value given alone (``--set
    lobes=transmission``, ``"sigmas": 0.5``) is that one item."""
    return frozenset(
        name
        for name, info in model.model_fields.items()
        if any(
            typing.get_origin(t) is list
            for t in (info.annotation, *typing.get_args(info.annotation))
        )
    )


def _scalar(value: Any) -> bool:
    return isinstance(value, str | int | float) and not isinstance(value, bool)


@dataclass
class Context:
    """What a pipeline run passes to every operator besides its parameters.

    ``debug_layers``: also write intermediate layers (curvature, σ, multi-scale normals, ...).
    ``pinned``: statistics pinned for a whole sequence (white levels, normalisations), keyed by
    ``"<op>.<name>"``; an operator whose parameter is ``auto`` reads it from here when present
    and records what it measured in ``measured`` so a batch can pin it for later frames.
    ``files``: whether parameters may name image files on this machine (matcaps, environment
    maps, gain maps, ARMs); the HTTP service runs with ``files=False``.
    ``region``: where a step with ``mask_stats`` measures its statistics (:mod:`service.masks`).
    ``memo``: results computed from the frame's arrays, kept for the next run on the same
    arrays (:mod:`service.memo`: the viewer's previews); by default one that keeps nothing.
    ``warnings``: what the steps tell the user besides their result (a mask that selects no
    pixel), said as the reader's warnings are.
    """

    debug_layers: bool = False
    files: bool = True
    pinned: dict[str, float] = field(default_factory=dict)
    measured: dict[str, float] = field(default_factory=dict)
    region: np.ndarray | None = None
    memo: Memo = field(default_factory=lambda: Memo(0))
    warnings: list[str] = field(default_factory=list)

    def counted(self, covered: np.ndarray) -> np.ndarray:
        """``covered`` (H, W) bool, within the step's mask when it restricts statistics."""
        return covered if self.region is None else covered & self.region

    def statistic(self, key: str, compute: Callable[[], float]) -> float:
        """The pinned value of ``key``, else ``compute()`` (recorded in ``measured``)."""
        if key in self.pinned:
            return self.pinned[key]
        value = float(compute())
        self.measured[key] = value
        return value


Apply = Callable[[Frame, Any, Context], None]


@dataclass(frozen=True)
class Operator:
    """A registered operator. ``apply(frame, params, context)`` edits ``frame`` in place:
    it may replace ``frame.buffers["beauty"]`` and add output layers with ``frame.set_layer``."""

    name: str
    summary: str
    params: type[Params]
    needs: tuple[str, ...]
    writes: tuple[str, ...]
    apply: Apply
    needs_camera: bool = False

    def run(self, frame: Frame, params: Params, context: Context) -> None:
        """``apply``, restricted to the step's ``mask`` when it has one (:mod:`service.masks`):
        every array the step replaced, added or dropped is blended with the one before.
        Operators do not change arrays in place, so an array the step kept is the same object.
        A beauty the step made has the values it made negative set to 0
        (:func:`ops.numerics.clip_new_negatives`): radiance is never negative, and Σ scaled
        lobes + (beauty − Σ lobes) goes below 0 where that rest does. One it made NaN or
        infinite where the input was finite (parameters that take float32 past its range, as
        γ = 100 on radiance of 1e5) is a :class:`PipelineError`: the run stops there, and no file
        is written."""
        before = frame.buffers.get("beauty")
        self._run_masked(frame, params, context)
        after = frame.buffers.get("beauty")
        if after is None or before is None or after is before:
            return
        negatives, not_finite = new_values(after, before)
        if not_finite:
            raise PipelineError(
                f"{self.name}: the result is NaN or infinite at {not_finite} value"
                f"{'s' * (not_finite != 1)} of the beauty where the input is finite (past "
                "float32's range): lower the parameters that scale it"
            )
        if negatives:
            frame.buffers["beauty"] = clip_new_negatives(after, before, counted=True)

    def _run_masked(self, frame: Frame, params: Params, context: Context) -> None:
        if params.mask is None:
            self.apply(frame, params, context)
            return
        said: list[str] = []
        m = matte(frame, params.mask, params.mask_feather, params.mask_amount, context.files, said)
        if not m.any():  # (an index no pixel holds, a name of nothing in view)
            said.append(f"mask {shown(params.mask)} selects no pixel: the step changed nothing")
        context.warnings += [f"{self.name}: {line}" for line in said]
        buffers, outputs = dict(frame.buffers), dict(frame.outputs)
        region = context.region
        if params.mask_stats:
            context.region = m > 0 if region is None else region & (m > 0)
        try:
            self.apply(frame, params, context)
        finally:
            context.region = region
        blend_layers(frame.buffers, buffers, m)
        blend_layers(frame.outputs, outputs, m)

    def parse(self, values: dict[str, Any]) -> Params:
        """Validate ``values`` into the parameter model, or raise :class:`PipelineError`."""
        try:
            return self.params.model_validate(values)
        except ValidationError as exc:
            raise PipelineError(describe_validation(self, exc)) from None

    def schema(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "summary": self.summary,
            "needs": list(self.needs),
            "writes": list(self.writes),
            "params": self.params.model_json_schema(),
        }


REGISTRY: dict[str, Operator] = {}


def register(
    name: str,
    *,
    summary: str,
    params: type[Params],
    needs: tuple[str, ...],
    writes: tuple[str, ...],
    needs_camera: bool = False,
) -> Callable[[Apply], Apply]:
    """Decorator registering ``apply`` as operator ``name``."""

    def wrap(apply: Apply) -> Apply:
        if name in REGISTRY:
            raise RuntimeError(f"operator {name!r} registered twice")
        REGISTRY[name] = Operator(name, summary, params, needs, writes, apply, needs_camera)
        return apply

    return wrap


def get(name: str) -> Operator:
    """The registered operator ``name``, or a :class:`PipelineError` listing the valid names."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise PipelineError(
            f"unknown operator {name!r}; valid operators: {', '.join(sorted(REGISTRY))}"
        ) from None


def describe_validation(op: Operator, exc: ValidationError) -> str:
    """One line per problem: ``op: param=value: what is wrong (valid parameters: ...)``. A value
    a union refused (``1e-40`` or ``'abc'`` for a number or ``'auto'``) is one problem, said for
    what it was meant as."""
    fields = op.params.model_fields
    problems = []
    for loc, value, errs in _by_value(exc.errors()):
        if errs[0]["type"] == "extra_forbidden":
            problems.append(
                f"{op.name}: unknown parameter {loc!r}; valid parameters: {', '.join(fields)}"
            )
            continue
        name = loc.split(".")[0]
        desc = fields[name].description if name in fields else ""
        hint = f" ({desc})" if desc else ""
        problems.append(f"{op.name}: {loc}={value!r}: {_what_is_wrong(errs, value)}{hint}")
    return "; ".join(problems)


#: The parts of an error's location that name a member of a union ("constrained-float",
#: "literal['auto']", "float"), not a parameter or an index.
_MEMBER = re.compile(
    r"^(?:constrained-|literal\[|function-|list\[|dict\[|(?:float|int|str|bool|none)$)"
)


def _by_value(errors: list[Any]) -> list[tuple[str, Any, list[Any]]]:
    """The errors grouped by the value they are about (a union's members each give one): its
    location without the members' names, the value, and its errors."""
    groups: dict[tuple[str, str], tuple[str, Any, list[Any]]] = {}
    for err in errors:
        parts = [  # (a union's member is named right after its parameter)
            p
            for i, p in enumerate(err["loc"])
            if i != 1 or isinstance(p, int) or not _MEMBER.match(str(p))
        ]
        loc = ".".join(str(p) for p in parts) or "params"
        value = err.get("input")
        groups.setdefault((loc, repr(value)), (loc, value, []))[2].append(err)
    return list(groups.values())


_BOUNDS = {
    "greater_than": ("gt", "greater than"),
    "greater_than_equal": ("ge", "greater than or equal to"),
    "less_than": ("lt", "less than"),
    "less_than_equal": ("le", "less than or equal to"),
}


def _what_is_wrong(errs: list[Any], value: Any) -> str:
    """The words for one value's errors: a number's (its bound written as 1e-30, not
    0.000…001), else what the union takes ("a number or 'auto'"), else the validator's own."""
    number = isinstance(value, int | float) and not isinstance(value, bool)
    literals = [e["ctx"]["expected"] for e in errs if e["type"] == "literal_error"]
    others = [e for e in errs if e["type"] != "literal_error"]
    if len(errs) > 1 and literals and (not number or not others):
        return f"Input should be {' or '.join((['a number'] if others else []) + literals)}"
    err = (others or errs)[0]
    if err["type"] in _BOUNDS:
        key, words = _BOUNDS[err["type"]]
        return f"Input should be {words} {err['ctx'][key]:g}"
    # a validator's own words, without pydantic's "Value error, " before them
    return str(err["ctx"]["error"]) if err["type"] == "value_error" else str(err["msg"])
