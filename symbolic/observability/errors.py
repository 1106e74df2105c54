"""Errors of the observability package, and the sound partial result a budget overrun carries.

(4.13) is why a partial result is sound: the rank of ``Q`` up to a derivative order is a lower
bound of the rank with more orders, since adding rows never lowers a rank.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


class ObservabilityError(Exception):
    """Base class of the errors of this package."""


class UnsupportedExpressionError(ObservabilityError, ValueError):
    """The model uses a function that cannot be evaluated exactly at a rational point."""


class SamplingError(ObservabilityError):
    """No point with nonzero denominators was found (the condition set is singular)."""


@dataclass(frozen=True)
class PartialResult:
    """What was established before a budget ran out.

    ``rank_lower_bound`` is the rank of ``Q`` (4.7) restricted to the derivative orders
    ``0..orders_completed`` at a point mod P: a sound lower bound on the generic rank (4.13).
    """

    model: str
    unknowns: tuple[str, ...]
    n_unknowns: int
    rank_lower_bound: int
    orders_completed: int
    rank_by_order: tuple[int, ...]
    reason: str
    elapsed_seconds: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "unknowns": list(self.unknowns),
            "n_unknowns": self.n_unknowns,
            "rank_lower_bound": self.rank_lower_bound,
            "orders_completed": self.orders_completed,
            "rank_by_order": list(self.rank_by_order),
            "reason": self.reason,
            "elapsed_seconds": self.elapsed_seconds,
        }


class BudgetExceeded(ObservabilityError):
    """The size or time budget was exceeded; :attr:`partial` holds the sound lower bound."""

    def __init__(self, message: str, partial: PartialResult) -> None:
        super().__init__(message)
        self.partial = partial


class BudgetHit(Exception):
    """Internal: raised inside the Lie-derivative engine, turned into :class:`BudgetExceeded`."""


class ZeroDenominator(Exception):
    """Internal: a denominator vanished at the sampled point; the point must be redrawn."""
