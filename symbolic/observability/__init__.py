"""Lie-derivative observability and structural identifiability of any :class:`Model`.

The generic engine behind thesis section 4.1 (equations 4.1–4.13), one module per step:

* :mod:`.system` — the augmented system (4.1): estimated parameters appended to the state as
  random walks (``dp/dt = 0``), model numbers made exact, input excitation models
  (``generic``, ``constant``, ``poly:K``).
* :mod:`.lie` — the Lie engine (4.4)–(4.7): the outputs differentiated along the dynamics, with
  the input derivatives ``u, u', u'', ...`` as further variables (the ``h_k(x, u, ..., u^(k))``
  of (4.4)), and ``Q`` = the Jacobian of the stacked derivatives by the augmented state (4.7).
  Computed in SymEngine and cached per derivative order.
* :mod:`.exact` — exact arithmetic: random points, evaluation of ``Q`` mod the prime
  ``2^61 - 1`` and over the rationals, row echelon forms; :mod:`.bounds` — the
  Schwartz–Zippel bound of a rank-deficient verdict.
* :mod:`.rank` — the rank decision (4.12), (4.13): screening mod P, a full-rank verdict proved
  by a nonzero minor re-verified in exact rationals (:class:`RankWitness`), a deficient one
  decided over the rationals, with its kernel and an error bound. Never a float tolerance.
* :mod:`.session` — the state follow-up questions reuse: model, estimated parameters, input
  models, one cached Lie engine per set of input models.
* :mod:`.drops`, :mod:`.search`, :mod:`.minor` — the rank on a condition set, and the one drop
  search (inputs held at zero or constant, zero sets of the witness minor, nested sets),
  each drop followed to higher orders.
* :mod:`.modes` — the same verdict per mode of the hybrid shift model
  (:func:`analyze_modes`), a μ excluded where its element does not slide.
* :mod:`.report` — the analysis of a gearbox's shift model behind ``gearsym observability`` and
  the notebook API (:func:`analyze_shift` → :class:`ObservabilityReport`): the augmented shift
  model (4.1), outputs, input models, conditions and parameters given as text, the verdict and
  the drop search.
"""

from gearsym.symbolic.observability.drops import (
    DropSearch,
    RankDrop,
    RankDropReport,
    rank_under_conditions,
)
from gearsym.symbolic.observability.errors import (
    BudgetExceeded,
    ObservabilityError,
    PartialResult,
    SamplingError,
    UnsupportedExpressionError,
)
from gearsym.symbolic.observability.exact import MODULUS, exact_rational, rationalize
from gearsym.symbolic.observability.lie import ObservabilityMatrix, observability_matrix
from gearsym.symbolic.observability.modes import ModeObservability, analyze_modes
from gearsym.symbolic.observability.rank import (
    ObservabilityResult,
    RankWitness,
    analyze_observability,
)
from gearsym.symbolic.observability.report import (
    ObservabilityReport,
    analyze_shift,
    order_label,
    partial_text,
    select_outputs,
)
from gearsym.symbolic.observability.search import find_rank_drops, propose_rank_drop_conditions
from gearsym.symbolic.observability.session import ObservabilitySession, RankSettings
from gearsym.symbolic.observability.system import AugmentedSystem, InputModel, augment
from gearsym.symbolic.sympy_utils import smart_jacobian

#: The earlier name of :class:`RankDrop` (a candidate set of the drop search).
CandidateCondition = RankDrop

__all__ = [
    "MODULUS",
    "AugmentedSystem",
    "BudgetExceeded",
    "CandidateCondition",
    "DropSearch",
    "InputModel",
    "ModeObservability",
    "ObservabilityError",
    "ObservabilityMatrix",
    "ObservabilityReport",
    "ObservabilityResult",
    "ObservabilitySession",
    "PartialResult",
    "RankDrop",
    "RankDropReport",
    "RankSettings",
    "RankWitness",
    "SamplingError",
    "UnsupportedExpressionError",
    "analyze_modes",
    "analyze_observability",
    "analyze_shift",
    "augment",
    "exact_rational",
    "find_rank_drops",
    "observability_matrix",
    "order_label",
    "partial_text",
    "propose_rank_drop_conditions",
    "rank_under_conditions",
    "rationalize",
    "select_outputs",
    "smart_jacobian",
]
