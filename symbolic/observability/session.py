"""The session: the state every follow-up question about one augmented system (4.1) needs.

A verdict (:func:`.rank.analyze_observability`) is rarely the last question: the drop search
(:mod:`.drops`) re-ranks ``Q`` (4.7) on sets given by point restrictions and input models, and
follows drops to higher derivative orders (4.13). Those questions need the model, the
estimated parameters, the input models and — the expensive part — the Lie derivatives (4.4).
A session holds them, with one cached :class:`.lie.LieEngine` per set of input models, and
every result points to its session.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import symengine as se
import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.observability.exact import exact_rational, rationalize
from gearsym.symbolic.observability.lie import LieEngine, SymbolTable
from gearsym.symbolic.observability.system import AugmentedSystem, InputModel, normalize_trig

DEFAULT_MAX_ERROR = 1e-9


@dataclass(frozen=True)
class RankSettings:
    """Target of the probability bound of a rank-deficient verdict, and the trial cap."""

    max_error_probability: float = DEFAULT_MAX_ERROR
    max_trials: int = 8


@dataclass(frozen=True)
class RankedMatrix:
    """The ``Q`` (4.7) a verdict was decided on.

    ``rows`` are SymEngine expressions with the point restrictions ``conditions`` applied;
    ``input_models`` are the excitation models its Lie derivatives (4.4) were built with.
    """

    rows: tuple[tuple[se.Basic, ...], ...]
    labels: tuple[str, ...]
    input_models: Mapping[str, InputModel]
    conditions: Mapping[sp.Symbol, sp.Expr]


class ObservabilitySession:
    """Model, augmented system (4.1), baseline input models, settings and cached engines."""

    def __init__(
        self,
        model: Model,
        system: AugmentedSystem,
        input_models: Mapping[str, InputModel],
        settings: RankSettings | None = None,
    ) -> None:
        self.model = model
        self.system = system
        self.input_models = dict(input_models)
        self.settings = RankSettings() if settings is None else settings
        self.symbols = SymbolTable(system)
        self._engines: dict[tuple[tuple[str, str], ...], LieEngine] = {}

    @property
    def estimated_parameters(self) -> tuple[str, ...]:
        return self.system.parameter_names

    def engine(self, input_models: Mapping[str, InputModel] | None = None) -> LieEngine:
        """The Lie engine of ``input_models`` (default: the session's), created once."""
        models = self.input_models if input_models is None else dict(input_models)
        key = tuple(sorted((name, str(m)) for name, m in models.items()))
        if key not in self._engines:
            self._engines[key] = LieEngine(self.system, models, self.symbols)
        return self._engines[key]

    def with_overrides(
        self, base: Mapping[str, InputModel], overrides: Mapping[str, str | InputModel] | None
    ) -> dict[str, InputModel]:
        """``base`` with some inputs' models replaced (``{"u": "constant"}``)."""
        models = dict(base)
        for name, spec in (overrides or {}).items():
            if name not in models:
                raise KeyError(f"{name!r} is not an input")
            models[name] = InputModel.parse(spec)
        return models

    def parse_conditions(self, conditions: Mapping[str, Any] | None) -> dict[sp.Symbol, sp.Expr]:
        """Names -> symbols; values (numbers, strings, expressions) -> exact expressions."""
        if not conditions:
            return {}
        local = {name: self.symbols.sympy[s] for name, s in self.symbols.by_variable.items()}
        parsed: dict[sp.Symbol, sp.Expr] = {}
        for name, value in conditions.items():
            sym = self.symbols.resolve(name)
            local[name] = sym
            if isinstance(value, str):
                expr = sp.sympify(value, locals=local)
            elif isinstance(value, (int, float)):
                expr = exact_rational(value)
            else:
                expr = sp.sympify(value)
            parsed[sym] = normalize_trig(rationalize(expr))
        check_unchained(parsed)
        return parsed


def check_unchained(conditions: Mapping[sp.Symbol, sp.Expr]) -> None:
    """Condition values must not use conditioned variables (they are applied in one pass)."""
    chained = {s for e in conditions.values() for s in e.free_symbols} & conditions.keys()
    if chained:
        raise ValueError(
            f"condition values must not use conditioned variables: {sorted(map(str, chained))}"
        )
