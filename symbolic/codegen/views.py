"""The typed views every model template receives (backend views extend :class:`ModelView`)."""

from __future__ import annotations

from dataclasses import dataclass

from gearsym.symbolic.codegen.printing import comment_text, float_repr
from gearsym.symbolic.codegen.table import FunctionTable, file_names
from gearsym.symbolic.model import Variable

__all__ = ["ModelView", "VariableView", "model_view"]


@dataclass(frozen=True)
class VariableView:
    """A state, input, parameter or output: its name, index and the comment beside it."""

    name: str
    index: int
    comment: str  # unit, meaning, default, range, source; safe in a C comment


@dataclass(frozen=True)
class ModelView:
    """What every template of a model shows: names, sizes, variables and provenance."""

    model_name: str
    prefix: str  # gearsym_<model>_
    macro: str  # GEARSYM_<MODEL>_
    header_name: str
    source_name: str
    casadi_name: str
    nx: int
    nu: int
    np: int
    ny: int
    states: tuple[VariableView, ...]
    inputs: tuple[VariableView, ...]
    parameters: tuple[VariableView, ...]
    outputs_meta: tuple[VariableView, ...]
    metadata: tuple[str, ...]  # "key: value" lines of the model's provenance


def _variable_view(
    v: Variable, index: int, bounds: tuple[float | None, float | None] = (None, None)
) -> VariableView:
    parts = [f"[{v.unit}]"]
    if v.description:
        parts.append(v.description)
    if v.default is not None:
        parts.append(f"default {float_repr(float(v.default))}")
    if bounds != (None, None):
        lo = "-inf" if bounds[0] is None else float_repr(bounds[0])
        hi = "inf" if bounds[1] is None else float_repr(bounds[1])
        parts.append(f"range [{lo}, {hi}]")
    if v.source:
        parts.append(f"source: {v.source}")
    return VariableView(v.name, index, comment_text("; ".join(parts)))


def model_view(table: FunctionTable) -> ModelView:
    """The :class:`ModelView` of a function table's model."""
    model = table.model
    names = file_names(model)
    return ModelView(
        model_name=model.name,
        prefix=table.prefix,
        macro=table.macro_prefix,
        header_name=names["header"],
        source_name=names["source"],
        casadi_name=names["casadi"],
        nx=len(model.states),
        nu=len(model.inputs),
        np=len(model.parameters),
        ny=len(model.outputs),
        states=tuple(_variable_view(v, i) for i, v in enumerate(model.states)),
        inputs=tuple(_variable_view(v, i) for i, v in enumerate(model.inputs)),
        parameters=tuple(
            _variable_view(v, i, table.bounds[i]) for i, v in enumerate(model.parameters)
        ),
        outputs_meta=tuple(_variable_view(v, i) for i, v in enumerate(model.outputs)),
        metadata=tuple(comment_text(f"{k}: {model.metadata[k]}") for k in sorted(model.metadata)),
    )
