"""The emitted EKF's predict and update (thesis 4.3), unrolled from structure known at generation.

The time update needs F, the Jacobian of the RK4 step, by the chain rule through the four
stages: K_1 = J(x), K_i = J(stage_i) (I + c_i K_(i-1)), F = I + h/6 (K_1 + 2 K_2 + 2 K_3 + K_4)
with J = ∂f/∂z. Dense, the three stage products alone cost 3 n^3 multiplications. Here every
product is written out over the *structural* nonzeros of J (the pattern of ``jac_x_sparse``): the
pattern of K_i is that of J joined with J K_(i-1), known when the code is generated, so each
entry of K_i is a sum over exactly the k with J[r, k] and K_(i-1)[k, j] both structurally
nonzero. A row of J that is structurally zero (a parameter's random walk of the augmented model
(4.1), or any state whose derivative does not depend on the states) is a zero row of every K_i
and so a unit row of F. With R the rows of F that are not unit rows, F P F^T is computed
blockwise: A = F[R, :] P (|R| x n, unit coefficients not multiplied), P+[R, R] = A F[R, :]^T
(upper triangle, mirrored), P+[R, not R] = A[:, not R] (mirrored), and P+[not R, not R] = P
(the parameter block: no product at all, only h q added on the diagonal, its upper triangle
copied to the lower). The result is exactly symmetric: each mirrored pair is computed once.

The measurement update: when the output Jacobian H = ∂h/∂z is a constant selection (each output
*is* one state, as the speeds of the shift model), the sequential scalar update needs no
product with H: v = P h^T is a column of P and h v one entry of it. The Joseph form
(I - k h) P (I - k h)^T + R k k^T is evaluated expanded, P - k v^T - v k^T + s k k^T with
s = h v + R, on the upper triangle and mirrored: algebraically the Joseph form for *any* gain k
(so the zeroed gain of a frozen state keeps P exact, and that state's row and variance are
untouched), at 2 multiplications and 2 additions per entry instead of a dense n x n product.
When H is constant but not a selection (an output is a fixed combination of states, as the speed
of a shaft the model eliminates: omega_8 of the 3-4 is one of omega_1 and omega_2), v = P h^T
is the sum over the row's few nonzeros of coefficient times a column of P, s = h v + R over the
same nonzeros; the covariance update is the same, since it needs only v and s.

Every count returned here is that of the statements returned (no estimate).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.c.ekf_stage import JAC, SLOPE, FusedStage
from gearsym.symbolic.codegen.ops import OpCount

__all__ = [
    "EkfPredictCode",
    "linear_update_ops",
    "output_rows",
    "output_selection",
    "predict_code",
    "selection_update_ops",
]

_ONE = "GEARSYM_LIT(1.0)"

Entry = tuple[int, int]


@dataclass(frozen=True)
class EkfPredictCode:
    """The unrolled body of ``ekf_predict`` after the process-noise rates are set.

    ``declarations`` and ``statements`` are C lines (without indentation); ``ops`` counts the
    statements' own floating-point operations (those of the fused stage, once and per stage,
    not included: see :class:`~.ekf_stage.FusedStage`);
    ``stack`` is the number of reals the declarations put on the stack.
    """

    declarations: tuple[str, ...]
    statements: tuple[str, ...]
    ops: OpCount
    stack: int


def _column_major(entries: set[Entry]) -> list[Entry]:
    return sorted(entries, key=lambda e: (e[1], e[0]))


def _product_pattern(left: set[Entry], right: set[Entry]) -> set[Entry]:
    """Structural nonzeros of left @ right."""
    by_row: dict[int, list[int]] = {}
    for k, j in right:
        by_row.setdefault(k, []).append(j)
    return {(r, j) for r, k in left for j in by_row.get(k, ())}


def _sum(terms: Sequence[tuple[str | None, str]], ops: OpCount) -> str:
    """``a*b + c + ...`` of (coefficient or None, value) terms; counts its operations."""
    assert terms
    ops.add += len(terms) - 1
    parts = []
    for coef, value in terms:
        if coef is None:
            parts.append(value)
        else:
            ops.mul += 1
            parts.append(f"{coef} * {value}")
    return " + ".join(parts)


def predict_code(
    n: int,
    jac_entries: Sequence[Entry],
    zero_rhs: Sequence[int],
    fused: FusedStage,
) -> EkfPredictCode:
    """The stage tangents, x+ and P+ = F P F^T + h diag(rate) of one RK4 step, unrolled.

    ``jac_entries``: the structural nonzeros (row, column) of ∂f/∂z, in the order of the
    ``j1``/``js`` arrays the ``fused`` stage (:mod:`.ekf_stage`) writes; ``zero_rhs`` the states
    whose right-hand side is identically 0 (their stage values are x). The J entries the fused
    stage computes once (``fused.invariant``) are the same in all four stages: their products
    with the stage coefficients c (h/2 for stages 2 and 3, h for stage 4) are formed once each.
    The statements expect ``x``, ``P``, ``u``, ``p``, ``h`` and ``rate[n]`` (the process-noise
    intensities with frozen states set to 0) in scope; chain rule (4.3) through the RK4 stages.
    """
    ops = OpCount()
    J = set(jac_entries)
    jac_index = {e: k for k, e in enumerate(jac_entries)}
    jac_size = len(jac_entries)
    invariant = fused.invariant
    moving = [i for i in range(n) if i not in set(zero_rhs)]
    # the stage tangents' patterns: K_1 = J, K_i = J + J K_(i-1) (growing)
    patterns = [set(J)]
    for _ in range(3):
        patterns.append(J | _product_pattern(J, patterns[-1]))
    total = set().union(*patterns)
    order = _column_major(total)
    index = {e: k for k, e in enumerate(order)}
    rows = sorted({r for r, _ in total})
    row_pos = {r: k for k, r in enumerate(rows)}
    nr = len(rows)
    nt = max(len(order), 1)
    js = max(jac_size, 1)

    declarations = [
        "const gearsym_real half_h = GEARSYM_LIT(0.5) * h;",
        "const gearsym_real sixth_h = h * (GEARSYM_LIT(1.0) / GEARSYM_LIT(6.0));",
        "const gearsym_real third_h = h * (GEARSYM_LIT(1.0) / GEARSYM_LIT(3.0));",
        f"gearsym_real slopes[4][{n}]; /* k1 .. k4 (the moving rows) */",
        f"gearsym_real stage[{n}];",
        f"gearsym_real j1[{js}]; /* K1 = J(x), {len(J)} structural nonzeros */",
    ]
    stack = 5 * n + js
    if J - invariant:
        declarations.append(f"gearsym_real js[{js}]; /* J(stage_i), its moving entries */")
        stack += js
    declarations.append("/* f and J: their terms without the moving states, once per step */")
    declarations += [line for line in fused.once if line.startswith("const ")]
    body: list[str] = [line for line in fused.once if not line.startswith("const ")]
    ops.mul += 3  # half_h, sixth_h, third_h

    def stage_block(source: str, slope: int, jac: str) -> None:
        body.append("{")
        body.append(f"    const gearsym_real *const xs = {source};")
        for line in fused.stage:
            body.append("    " + line.replace(SLOPE, f"slopes[{slope}]").replace(JAC, jac))
        body.append("}")

    body.append("/* stage 1: f and the moving entries of J at x (one CSE, inline) */")
    stage_block("x", 0, "j1")
    for i in range(n):
        if i not in moving:
            body.append(f"stage[{i}] = x[{i}]; /* its right-hand side is 0 */")

    def jac_value(stage_no: int, e: Entry) -> str:
        array = "j1" if stage_no == 1 or e in invariant else "js"
        return f"{array}[{jac_index[e]}]"

    def tangent(array: str, stage_no: int, e: Entry) -> str:
        """K_(stage_no) at entry e: J(x) for stage 1, else the stored tan array."""
        return jac_value(1, e) if stage_no == 1 else f"{array}{stage_no}[{index[e]}]"

    cj_names = {"half_h": "cjh", "h": "cjf"}
    formed: set[tuple[str, Entry]] = set()
    used_cj: set[str] = set()
    g_terms: dict[Entry, str] = {}
    for stage_no in (2, 3, 4):
        c = "h" if stage_no == 4 else "half_h"
        body.append(f"/* stage {stage_no}: stage = x + {c} k{stage_no - 1} */")
        for i in moving:
            ops.add += 1
            ops.mul += 1
            body.append(f"stage[{i}] = x[{i}] + {c} * slopes[{stage_no - 2}][{i}];")
        stage_block("stage", stage_no - 1, "js")
        previous = patterns[stage_no - 2]
        by_row: dict[int, list[int]] = {}
        for k, j in previous:
            by_row.setdefault(k, []).append(j)
        needed = sorted((e for e in J if e[1] in by_row), key=lambda e: jac_index[e])
        body.append(f"/* K{stage_no} = J + {c} J K{stage_no - 1}, over structural nonzeros */")

        def cj(e: Entry, c: str = c) -> str:
            if e in invariant:
                return f"{cj_names[c]}[{jac_index[e]}]"
            return f"cj[{jac_index[e]}]"

        for e in needed:
            if e in invariant:
                if (c, e) in formed:
                    continue  # J(stage) = J(x) here: c J formed in an earlier stage
                formed.add((c, e))
                used_cj.add(cj_names[c])
                ops.mul += 1
                body.append(f"{cj(e)} = {c} * j1[{jac_index[e]}];")
            else:
                used_cj.add("cj")
                ops.mul += 1
                body.append(f"cj[{jac_index[e]}] = {c} * js[{jac_index[e]}];")
        for e in _column_major(patterns[stage_no - 1]):
            r, j = e
            terms: list[tuple[str | None, str]] = []
            if e in J:
                terms.append((None, jac_value(stage_no, e)))
            for k in sorted(k for rr, k in J if rr == r):
                if (k, j) in previous:
                    terms.append((cj((r, k)), tangent("tan", stage_no - 1, (k, j))))
            value = _sum(terms, ops)
            if stage_no < 4:
                body.append(f"tan{stage_no}[{index[e]}] = {value};")
            else:
                g_terms[e] = value
        if stage_no < 4 and patterns[stage_no - 1]:
            declarations.append(f"gearsym_real tan{stage_no}[{nt}]; /* K{stage_no} */")
            stack += nt
    for name, what in (
        ("cj", "c J(stage_i)"),
        ("cjh", "h/2 J, the entries without moving states"),
        ("cjf", "h J, the entries without moving states"),
    ):
        if name in used_cj:
            declarations.append(f"gearsym_real {name}[{js}]; /* {what} */")
            stack += js
    # F = I + h/6 (K1 + K4) + h/3 (K2 + K3), on the joined pattern
    body.append("/* F = I + h/6 (K1 + K4) + h/3 (K2 + K3): its rows outside R are unit rows */")
    if order:
        declarations.append(f"gearsym_real F[{nt}]; /* F on the tangents' pattern */")
        stack += nt
    for e in order:
        outer = []
        if e in patterns[0]:
            outer.append((None, jac_value(1, e)))
        if e in g_terms:
            outer.append((None, f"({g_terms[e]})" if "+" in g_terms[e] else g_terms[e]))
        inner = [(None, f"tan{s}[{index[e]}]") for s in (2, 3) if e in patterns[s - 1]]
        parts = []
        if outer:
            text = _sum(outer, ops)
            ops.mul += 1
            parts.append(f"sixth_h * ({text})" if len(outer) > 1 else f"sixth_h * {text}")
        if inner:
            text = _sum(inner, ops)
            ops.mul += 1
            parts.append(f"third_h * ({text})" if len(inner) > 1 else f"third_h * {text}")
        ops.add += len(parts) - 1
        value = " + ".join(parts)
        if e[0] == e[1]:
            ops.add += 1
            value = f"{_ONE} + {value}"
        body.append(f"F[{index[e]}] = {value};")
    body.append("/* x = x + h/6 (k1 + 2 (k2 + k3) + k4) */")
    for i in moving:
        ops.add += 4
        ops.mul += 2
        body.append(
            f"x[{i}] = x[{i}] + sixth_h * (slopes[0][{i}] + GEARSYM_LIT(2.0) * "
            f"(slopes[1][{i}] + slopes[2][{i}]) + slopes[3][{i}]);"
        )

    def f_terms(r: int) -> list[tuple[str | None, int]]:
        """Row r of F: (coefficient or None for a unit entry, column)."""
        cols = {j: f"F[{index[(r, j)]}]" for rr, j in total if rr == r}
        if r not in cols:
            cols[r] = None  # type: ignore[assignment]
        return [(cols[j], j) for j in sorted(cols)]

    body.append(f"/* A = F[R, :] P with R = {{{', '.join(map(str, rows))}}} (A[r + j*{nr}]) */")
    if rows:
        declarations.append(f"gearsym_real A[{nr * n}]; /* F[R, :] P */")
        stack += nr * n
    needed_a = {
        (r1, k) for b, r2 in enumerate(rows) for r1 in rows[: b + 1] for _, k in f_terms(r2)
    }
    needed_a |= {(r, j) for r in rows for j in range(n) if j not in row_pos}
    for j in range(n):
        for r in rows:
            if (r, j) not in needed_a:
                continue
            terms = [(coef, f"P[{k + j * n}]") for coef, k in f_terms(r)]
            body.append(f"A[{row_pos[r] + j * nr}] = {_sum(terms, ops)};")
    body.append("/* P = F P F^T + h diag(rate), blockwise, symmetric by construction */")
    for b, r2 in enumerate(rows):
        for r1 in rows[: b + 1]:
            terms = [(coef, f"A[{row_pos[r1] + k * nr}]") for coef, k in f_terms(r2)]
            value = _sum(terms, ops)
            if r1 == r2:
                ops.add += 1
                ops.mul += 1
                body.append(f"P[{r1 + r1 * n}] = {value} + h * rate[{r1}];")
            else:
                body.append(f"P[{r1 + r2 * n}] = {value};")
                body.append(f"P[{r2 + r1 * n}] = P[{r1 + r2 * n}];")
    fixed = [j for j in range(n) if j not in row_pos]
    for j in fixed:
        for r in rows:
            body.append(f"P[{r + j * n}] = A[{row_pos[r] + j * nr}];")
            body.append(f"P[{j + r * n}] = P[{r + j * n}];")
    for b, j2 in enumerate(fixed):
        for j1 in fixed[:b]:
            body.append(f"P[{j2 + j1 * n}] = P[{j1 + j2 * n}]; /* exactly symmetric */")
        ops.add += 1
        ops.mul += 1
        body.append(f"P[{j2 + j2 * n}] += h * rate[{j2}]; /* a unit row of F: no product */")
    return EkfPredictCode(tuple(declarations), tuple(body), ops, stack)


def output_selection(jacobian: sp.MatrixBase) -> tuple[int, ...] | None:
    """The state each output selects if ∂h/∂z is a constant 0/1 matrix with one 1 per row."""
    selection = []
    for i in range(jacobian.rows):
        row = [jacobian[i, j] for j in range(jacobian.cols)]
        ones = [j for j, v in enumerate(row) if v == 1]
        if len(ones) != 1 or any(v != 0 for j, v in enumerate(row) if j != ones[0]):
            return None
        selection.append(ones[0])
    return tuple(selection)


def output_rows(jacobian: sp.MatrixBase) -> tuple[tuple[tuple[int, sp.Expr], ...], ...] | None:
    """Per output, its (state, coefficient) nonzeros in state order if ∂h/∂z is a constant
    matrix (numbers only); else None (the update then takes H from ``jac_outputs`` at every
    output). A row may be empty: an output no state moves (the speed of a shaft both gears of
    the shift hold still, as shaft 8 in the 8-9), whose update changes neither x nor P."""
    rows = []
    for i in range(jacobian.rows):
        entries = [(j, sp.sympify(jacobian[i, j])) for j in range(jacobian.cols)]
        if any(not v.is_number for _, v in entries):
            return None
        rows.append(tuple((j, v) for j, v in entries if v != 0))
    if not any(rows):
        return None  # nothing measured moves: no coefficient table to index
    return tuple(rows)


def linear_update_ops(
    n: int, row_sizes: Sequence[int], n_frozen: int, form: str = "symmetric"
) -> OpCount:
    """Operations of the constant-H update (see the template): those of the selection update
    (:func:`selection_update_ops`) for each output with a nonzero row of H plus, per such row
    of k nonzeros, v = P h^T (n k mul, n (k - 1) add) and s = R + h v (k mul, k add, where the
    selection has 1 add); an output with a zero row of H costs its R, s's checks and its NIS
    term only (x and P stay as they are)."""
    used = [k for k in row_sizes if k > 0]
    ops = selection_update_ops(n, len(used), n_frozen, form)
    for k in used:
        ops = ops + OpCount(mul=n * k + k, add=n * (k - 1) + k - 1)
    empty = len(row_sizes) - len(used)
    # isfinite(y), y < 0, level < floor, s > 0, isfinite(s); R; the innovation and ν²/s
    return ops + OpCount(compare=5, mul=3, add=2, div=1).scaled(empty)


def selection_update_ops(n: int, ny: int, n_frozen: int, form: str = "symmetric") -> OpCount:
    """Operations of the selection update's statements (see the template), all outputs used.

    ``form`` ``"symmetric"``: the Schmidt update P_ab - v_a w_b (w = v/s) on the upper
    triangle, whose equality with the Joseph form of the Schmidt gain (thesis 4.3) is this
    block algebra. Split the states into free ones F and frozen ones Z; the Schmidt gain is
    k_F = v_F / s, k_Z = 0, and the Joseph form (I - k h) P (I - k h)^T + R k k^T expands to
    P - k v^T - v k^T + s k k^T (v = P h^T, s = h v + R) for any k. Blockwise:

    - FF: P_FF - 2 v_F v_F^T / s + s v_F v_F^T / s^2 = P_FF - v_F v_F^T / s;
    - FZ (and ZF mirrored): P_FZ - k_F v_Z^T - v_F k_Z^T + s k_F k_Z^T = P_FZ - v_F v_Z^T / s;
    - ZZ: every term carries k_Z = 0, so P_ZZ is unchanged.

    So P_ab - v_a v_b / s for every pair but two frozen states: 1 mul + 1 add per entry
    instead of the expanded Joseph form's 2 + 2 (``"joseph"``). The frozen flags are
    evaluated once per call, not per output.
    """
    per = OpCount()
    per.compare += 2  # isfinite(y), y < 0
    per.compare += 1  # level < floor
    per.mul += 2  # R = (r level)^2
    per.add += 1  # s = P[s, s] + R
    per.compare += 2  # s > 0, isfinite(s)
    per.div += 1  # 1 / s
    per.add += 1  # innovation
    entries = n * (n + 1) // 2
    if form == "joseph":
        per.mul += n  # gain
        per.mul += n  # x += gain innovation
        per.add += n
        per.mul += n  # g = s gain - v
        per.add += n
        per.mul += 2 * entries  # P + (gain_a g_b - v_a gain_b)
        per.add += 2 * entries
    else:
        per.mul += n  # w = v / s
        per.mul += n  # x += w innovation (at most: not for a frozen state)
        per.add += n
        per.mul += entries  # P - v_a w_b (at most: not for two frozen states)
        per.add += entries
    per.mul += 2  # nis
    per.add += 1
    return per.scaled(ny) + OpCount(compare=2 * n_frozen)  # the frozen flags, once
