"""Code generation: one :class:`~gearsym.symbolic.model.Model` in, C99 and CasADi sources out.

One module per concern (every stage a pure function; the output is byte-identical across runs
and ``PYTHONHASHSEED`` values):

* :mod:`.config`: :class:`CodegenConfig`, every language decision (integrators, parameter
  bounds, number printing, Jacobian layout, CSE) on one object;
* :mod:`.table`: the function table, one row per emitted function (:data:`~.table.ROWS`),
  bound to a model by :func:`build_function_table`; every signature comes from it;
* :mod:`.jacobian`: ∂f/∂x, ∂f/∂u, ∂f/∂p in one forward pass over one CSE (cached), and the
  compressed-column :class:`SparsityPattern` of the sparse Jacobian functions;
* :mod:`.cse`: one common-subexpression elimination per function over all its outputs;
* :mod:`.ops`: the operation count every emitted function states;
* :mod:`.printing`, :mod:`.expressions`: the rules both printers share;
* :mod:`.c`, :mod:`.casadi`: one folder per backend, printer and emitter;
* :mod:`.views`, :mod:`.render`: typed views and the one strict Jinja2 entry point.

Public entry points: :func:`emit_c`, :func:`emit_casadi`, :func:`emit_all`.

Conventions of the emitted code (also written into the generated header):

* dense matrices are **column-major**: entry ``(i, j)`` of an ``r x c`` matrix is element
  ``i + j*r`` (the layout of CasADi, LAPACK and MATLAB, and of ``numpy.ravel(order="F")``);
  the sparse Jacobians ``jac_*_sparse`` hold the structural nonzeros in compressed-column order
  (CasADi's layout), their pattern in ``const`` arrays declared in the header;
* ``gearsym_real`` is ``double``, or ``float`` when compiled with ``-DGEARSYM_SINGLE_PRECISION``;
  literals go through ``GEARSYM_LIT`` and math calls through ``GEARSYM_<FN>`` macros so that the
  float build has ``f`` literals and ``sinf``-style calls and never promotes to double;
* the pointer parameters of the expression functions (rhs, outputs, Jacobians) are ``restrict``
  in their definitions (outputs never alias inputs there), so the compiler keeps inputs in
  registers across the stores; the header declarations omit it (the function type is the same;
  ``CodegenConfig.restrict_pointers`` turns it off);
* math-library calls come first in a function, so that few values live across them;
* rationals are exact constant quotients when numerator and denominator are exact in float
  (at most 2**24), else 21-digit decimals (never a float literal out of range);
* NaN is never hidden: ``Min``/``Max`` print as helpers that return NaN for a NaN argument
  (C99's and CasADi's fmin/fmax return the other one), and a ``Piecewise`` returns NaN when an
  operand of its conditions is NaN (a comparison with NaN is false and would pick a branch);
* Jacobians are taken with model symbols treated as real, and the Dirac deltas that appear when
  differentiating ``sign``/``Heaviside`` are dropped: the emitted Jacobian is the derivative almost
  everywhere, which is what a Newton step or an EKF can use.
"""

from gearsym.symbolic.codegen.c.printer import GearsymCPrinter
from gearsym.symbolic.codegen.casadi.printer import CasadiPrinter
from gearsym.symbolic.codegen.config import (
    INTEGRATORS,
    Bounds,
    CodegenConfig,
    EkfLayout,
    EkfModeElement,
    EuioLayout,
    Precision,
    Sparsity,
    as_config,
)
from gearsym.symbolic.codegen.cse import CseForm, cse_function
from gearsym.symbolic.codegen.emit import cse_forms, emit_all, emit_c, emit_casadi
from gearsym.symbolic.codegen.jacobian import (
    SparsityPattern,
    clear_caches,
    clear_jacobian_cache,
    jacobian_blocks,
    smart_jacobian,
)
from gearsym.symbolic.codegen.ops import OpCount, count_operations
from gearsym.symbolic.codegen.printing import comment_text, float_repr
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.codegen.table import (
    Arg,
    FunctionSpec,
    FunctionTable,
    Output,
    build_function_table,
    file_names,
    function_names,
    real_symbols,
)

__all__ = [
    "INTEGRATORS",
    "Arg",
    "Bounds",
    "CasadiPrinter",
    "CodegenConfig",
    "CseForm",
    "EkfLayout",
    "EkfModeElement",
    "EuioLayout",
    "FunctionSpec",
    "FunctionTable",
    "GearsymCPrinter",
    "OpCount",
    "Output",
    "Precision",
    "Sparsity",
    "SparsityPattern",
    "as_config",
    "build_function_table",
    "clear_caches",
    "clear_jacobian_cache",
    "comment_text",
    "count_operations",
    "cse_forms",
    "cse_function",
    "emit_all",
    "emit_c",
    "emit_casadi",
    "file_names",
    "float_repr",
    "function_names",
    "jacobian_blocks",
    "real_symbols",
    "render",
    "smart_jacobian",
]
