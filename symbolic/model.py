"""The one intermediate representation every analysis and emitter consumes.

A :class:`Model` is an explicit ODE ``dx/dt = f(x, u, p)`` with outputs ``y = h(x, u, p)``,
every symbol named (the names become C identifiers) and every parameter carrying its default
value, unit and source. Stages downstream (sensitivities, Fisher information, observability,
code generation, validation) take a ``Model`` and never look back at the gearbox description.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp


@dataclass(frozen=True)
class Variable:
    """A named scalar of a model: a state, an input, a parameter or an output."""

    name: str
    symbol: sp.Symbol
    unit: str = "1"
    description: str = ""
    default: float | None = None
    source: str = ""


@dataclass(frozen=True)
class Model:
    """``dx/dt = rhs(x, u, p)``, ``y = output_expressions(x, u, p)``.

    ``rhs`` and ``output_expressions`` are column matrices of SymPy expressions whose free
    symbols are drawn from the symbols of ``states``, ``inputs`` and ``parameters``.
    ``metadata`` holds provenance (gearbox name, shift, thesis equations) as plain strings.
    """

    name: str
    states: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    parameters: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    rhs: sp.Matrix
    output_expressions: sp.Matrix
    metadata: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.rhs.shape != (len(self.states), 1):
            raise ValueError(f"rhs has shape {self.rhs.shape}, expected ({len(self.states)}, 1)")
        if self.output_expressions.shape != (len(self.outputs), 1):
            raise ValueError(
                f"output_expressions has shape {self.output_expressions.shape}, "
                f"expected ({len(self.outputs)}, 1)"
            )
        names = [v.name for v in (*self.states, *self.inputs, *self.parameters)]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"names used twice in model {self.name!r}: {duplicates}")
        known = set(self.state_symbols + self.input_symbols + self.parameter_symbols)
        stray = (self.rhs.free_symbols | self.output_expressions.free_symbols) - known
        if stray:
            raise ValueError(
                f"model {self.name!r} uses symbols that are neither states, inputs nor "
                f"parameters: {sorted(map(str, stray))}"
            )

    @property
    def state_symbols(self) -> list[sp.Symbol]:
        return [v.symbol for v in self.states]

    @property
    def input_symbols(self) -> list[sp.Symbol]:
        return [v.symbol for v in self.inputs]

    @property
    def parameter_symbols(self) -> list[sp.Symbol]:
        return [v.symbol for v in self.parameters]

    def parameter_defaults(self) -> dict[sp.Symbol, float]:
        """Default value of every parameter that has one."""
        return {v.symbol: v.default for v in self.parameters if v.default is not None}

    def variable(self, name: str) -> Variable:
        """Look up a state, input, parameter or output by name."""
        for v in (*self.states, *self.inputs, *self.parameters, *self.outputs):
            if v.name == name:
                return v
        raise KeyError(name)


def with_input_gain(model: Model, input_name: str, gain: Variable) -> Model:
    """``model`` with its input ``input_name`` acting through ``gain`` times itself: every
    occurrence of u in f and h becomes g u, and g joins the parameters (its default the
    nominal gain, 1 for a calibrated input). A TCU is told an input torque through its
    engine's torque model; the true one is g times it, and an estimator or an observability
    analysis that takes g as an unknown parameter needs this model. ``model`` is unchanged."""
    told = model.variable(input_name)
    if told not in model.inputs:
        raise KeyError(f"{input_name!r} is not an input of model {model.name!r}")
    scaled = {told.symbol: gain.symbol * told.symbol}
    return Model(
        name=model.name,
        states=model.states,
        inputs=model.inputs,
        parameters=(*model.parameters, gain),
        outputs=model.outputs,
        rhs=model.rhs.xreplace(scaled),
        output_expressions=model.output_expressions.xreplace(scaled),
        metadata={**model.metadata, "input_gain": f"{gain.name} on {input_name}"},
    )
