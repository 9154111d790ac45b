#!/usr/bin/env python3
"""Generate the quad's covariance prediction kernel from its symbolic model.

    python3 firmware/codegen/quad_predict.py [--out FILE] [--check]

The model is written once, here, with sympy: the body-rate dynamics of a quad
with a diagonal inertia (docs/math.md §1),

    J omega_dot = sum_i kf_i u_i (r_i x z) + sum_i km_i u_i s_i z - omega x (J omega),

with the thrust and drag coefficients and the gyro biases random walks. Its
Jacobian with respect to the 14-state vector (rates, kf, km, biases) gives the
structurally non-zero entries of the rate rows of G = F - I: the step's fixed
quad layout (propid_internal.h: row a has the two other rates, then the four
thrust columns in the roll and pitch rows or the four drag columns in the yaw
row). From that structure the script writes the straight-line kernel

    P := F P F^T + Q dt + PROPID_VAR_LOADING diag(F P F^T) on the thrust
         coefficients and biases, + Ld diag_drag(P) on the drag coefficients,
         + PROPID_RATE_LOADING m (P_aa + sum_p G_ap^2 P_pp) on the rates
         (their rounding scale, m = 7 terms a row)

(the rounding loading; the caller's Ld, drag_factor = 1 + Ld: docs/math.md §2)
on the packed upper triangle (firmware/src/propid_quad_predict.h): column by
column, each P_cj of the 11 non-bias rows loaded once and shared by the three
rows of T = F_rate P, the rate block's six elements collected in registers
during the sweep (every term, the rate columns' too: no T_ab is kept for the
end; each element of the rate block is written after the last column that adds
to it, which frees its register for the later columns). Every element the kernel writes is checked, symbolically,
against F P F^T + Q of the model before the file is written: the C is the
model's arithmetic, only ordered for the Cortex-M4 (one multiply-add per term,
the own element last so each sum starts in a fresh register, but in the yaw
row, which starts from it: OWN_FIRST_ROW, after the other rows' first two
products have read that element (PROPID_REGISTER_ORDER3: no copy of it); a
variance's loading and noise, (1 + L) P_jj + q, in one).

The same file holds the size-lean build's kernel (PROPID_SIZE_LEAN): the same
sums per element (its rate block's terms, also collected in the sweep, in
another order) as a loop over the columns over the model's column table
(propid_quad_jac_entry and the column indices written from the structure
above), interpreted symbolically here loop by loop and checked against the
model the same way.

--check regenerates in memory and exits 1 when the committed file differs (the
test suite runs it: tests/host_tools/test_codegen.py).
"""

from __future__ import annotations

import pathlib
import sys

import sympy

import quad_predict_arm
from generated_file import generator_main

N_RATE, N_ROTOR, N_BIAS = 3, 4, 3
N = N_RATE + 2 * N_ROTOR + N_BIAS          # 14 states
FIRST_THRUST, FIRST_DRAG, FIRST_BIAS = 3, 7, 11
# The row of T = F_rate P whose sum starts from its own element P_aj (a chain of
# multiply-adds in that register, no multiply to start and add to end it): one
# row per column can, the other two rows' sums still read P_aj (measured: row 2
# 10 instructions a step fewer, row 0 9, rows 1 and 2 9, all three 3).
OWN_FIRST_ROW = 2
OUT = pathlib.Path(__file__).resolve().parents[1] / "src" / "propid_quad_predict.h"


def rate_jacobian_structure() -> list[list[int]]:
    """Columns of the structurally non-zero entries of each rate row of
    d(omega_dot)/dx for a quad with a diagonal inertia and arbitrary arms, yaw
    signs and rotor speeds (zero for every value of the symbols = absent)."""
    omega = sympy.symbols("w0:3")
    kf = sympy.symbols("kf0:4")
    km = sympy.symbols("km0:4")
    bias = sympy.symbols("b0:3")
    jx, jy, jz = sympy.symbols("Jx Jy Jz", positive=True)
    inertia = sympy.diag(jx, jy, jz)
    w = sympy.Matrix(omega)
    torque = sympy.zeros(3, 1)
    for i in range(N_ROTOR):
        rx, ry, u, s = sympy.symbols(f"rx{i} ry{i} u{i} s{i}")
        arm_cross_z = sympy.Matrix([ry, -rx, 0])          # r x z, r in the xy-plane
        torque += kf[i] * u * arm_cross_z + km[i] * u * s * sympy.Matrix([0, 0, 1])
    torque -= w.cross(inertia * w)
    rate_dot = inertia.inv() * torque
    state = list(omega) + list(kf) + list(km) + list(bias)
    rows = []
    for a in range(3):
        columns = [c for c, x in enumerate(state)
                   if sympy.simplify(sympy.diff(rate_dot[a], x)) != 0]
        rows.append(columns)
    return rows


def p_symbol(i: int, j: int) -> sympy.Symbol:
    i, j = min(i, j), max(i, j)
    return sympy.Symbol(f"P_{i}_{j}")


def generate() -> str:
    structure = rate_jacobian_structure()
    # The fixed layout the C kernels and propid_jacobian_column() assume.
    expected = [[1, 2, 3, 4, 5, 6], [0, 2, 3, 4, 5, 6], [0, 1, 7, 8, 9, 10]]
    if structure != expected:
        raise SystemExit(f"quad_predict: the model's Jacobian structure {structure} is not the "
                         f"fixed quad layout {expected}")
    entries = len(expected[0])
    g = [[sympy.Symbol(f"g{a}_{p}") for p in range(entries)] for a in range(3)]
    loading = sympy.Symbol("L")
    drag_loading = sympy.Symbol("Ld")  # this step's loading of the drag coefficients
    rate_loading = sympy.Symbol("Lr")  # the rates' loading, above the update's rounding
    q = {kind: sympy.Symbol(f"q_{kind}") for kind in ("rate", "thrust", "drag", "bias")}

    # The model's F P F^T + Q dt + the rate variances' loading, densely and symbolically.
    p_full = sympy.Matrix(N, N, lambda i, j: p_symbol(i, j))
    f = sympy.eye(N)
    for a in range(3):
        for p, column in enumerate(structure[a]):
            f[a, column] += g[a][p]
    predicted = f * p_full * f.T

    def kind(k: int) -> str:
        return "rate" if k < FIRST_THRUST else "thrust" if k < FIRST_DRAG else "drag" \
            if k < FIRST_BIAS else "bias"

    def own_loading(k: int) -> sympy.Symbol:
        return {"drag": drag_loading, "rate": rate_loading}.get(kind(k), loading)

    # The rates' rounding scale (docs/math.md §2, "The rate block's loading"):
    # m (P_aa + sum_p G_ap^2 P_pp) >= (sum_k |F_ak| sigma_k)^2 >= (|F| |P| |F|^T)_aa
    # by Cauchy-Schwarz over the row's m = 1 + entries terms.
    row_terms = 1 + entries
    rate_scale_loading = f"({row_terms}.0f * PROPID_RATE_LOADING)"
    scale_factor = rate_loading * row_terms                 # c of the C above, symbolically
    rate_scale = [p_symbol(a, a) + sum(g[a][p] ** 2 * p_symbol(column, column)
                                       for p, column in enumerate(structure[a])) for a in range(3)]

    def wanted(i: int, j: int) -> sympy.Expr:
        value = predicted[i, j]
        if i == j:
            if kind(i) == "rate":
                value += rate_loading * row_terms * rate_scale[i] + q["rate"]
            else:
                value += own_loading(i) * value + q[kind(i)]
        return sympy.expand(value)

    def check_against_model(written: dict[tuple[int, int], sympy.Expr], what: str) -> None:
        """Every element the model changes is written, and each equals the model's."""
        for i in range(N):
            for j in range(i, N):
                if (i, j) in written:
                    if sympy.expand(written[(i, j)] - wanted(i, j)) != 0:
                        raise SystemExit(f"quad_predict: {what} ({i}, {j}) differs from the model")
                elif sympy.expand(wanted(i, j) - p_symbol(i, j)) != 0:
                    raise SystemExit(f"quad_predict: {what} ({i}, {j}) changes but is not written")

    lines: list[str] = []
    emit = lines.append
    checked: dict[tuple[int, int], sympy.Expr] = {}

    def store(i: int, j: int, c_value: str, value: sympy.Expr) -> None:
        emit(f"        cov[propid_cov_index({i}u, {j}u)] = {c_value};")
        checked[(i, j)] = value

    names = {0: "p0", 1: "p1", 2: "p2"}
    names.update({FIRST_THRUST + i: f"k{i}" for i in range(N_ROTOR)})
    names.update({FIRST_DRAG + i: f"d{i}" for i in range(N_ROTOR)})
    loaded_rows = list(range(FIRST_BIAS))                # the 11 non-bias rows
    block: dict[tuple[int, int], sympy.Expr] = {(a, b): sympy.Integer(0)
                                               for a in range(3) for b in range(a, 3)}
    block_terms: dict[tuple[int, int], list[str]] = {key: [] for key in block}
    # Each element of the rate block is written after the last column that adds to
    # it (row b's Jacobian columns, its own rate column), not at the end: its
    # register is free for the later columns.
    block_done = {(a, b): max([b] + list(structure[b])) for (a, b) in block}

    def write_block(after: int) -> None:
        done = [key for key in sorted(block) if block_done[key] == after]
        if not done:
            return
        emit(f"    /* The rate block's elements complete after column {after}: (T F^T)_ab = T_ab + sum_p")
        emit("     * T_a,(column p of row b) G_bp, on the diagonal with the loading c (P_aa + sum_p G_ap^2 P_pp)")
        emit("     * and Q dt. */")
        for a, b in done:
            if a == b:
                emit(f"    cov[propid_cov_index({a}u, {b}u)] = block{a}{b} + q_rate;")
                checked[(a, b)] = block[(a, b)] + q["rate"]
            else:
                emit(f"    cov[propid_cov_index({a}u, {b}u)] = block{a}{b};")
                checked[(a, b)] = block[(a, b)]

    for j in range(N):
        if j > 0:
            write_block(j - 1)
        emit(f"    {{ /* column {j} */")
        sym = {}
        loads = []
        for c in loaded_rows:
            loads.append(f"{names[c]} = cov[propid_cov_index({min(c, j)}u, {max(c, j)}u)]")
            sym[c] = p_symbol(c, j)
        emit("        const float " + ", ".join(loads[:3]) + ";")
        emit("        const float " + ", ".join(loads[3:7]) + ";")
        emit("        const float " + ", ".join(loads[7:]) + ";")
        # The rows' sums in the C's order. The two rows that end with their own
        # element start with products of the rate elements, one of which is the
        # element the third row starts from: those two heads are formed first and
        # the third row's start taken as renamed after them (no instruction), so
        # its sum accumulates in that element's register instead of a copy.
        t = []
        heads = []
        own = names[OWN_FIRST_ROW]
        for a in range(3):
            products = [f"g{a}_{p} * {names[col]}" for p, col in enumerate(structure[a])]
            if a != OWN_FIRST_ROW:
                heads.append(f"head{a} = {products[0]} + {products[1]}")
        emit("        float " + ", ".join(heads) + f", {own}_sum = {own};")
        emit("        PROPID_REGISTER_ORDER3(" + ", ".join(h.split(" =")[0] for h in heads) + f", {own}_sum);")
        for a in range(3):
            products = [f"g{a}_{p} * {names[col]}" for p, col in enumerate(structure[a])]
            if a == OWN_FIRST_ROW:
                emit(f"        const float t{a} = {own}_sum + {' + '.join(products)};")
            else:
                emit(f"        const float t{a} = (head{a} + {' + '.join(products[2:])}) + {names[a]};")
            t.append(sum(g[a][p] * sym[col] for p, col in enumerate(structure[a])) + sym[a])
        if j < FIRST_THRUST:
            # A rate column's share of the rate block, collected here like the
            # coefficient columns' (no T_ab kept for the end): T_ab itself when
            # j = b, T_aj G_bp when j is row b's rate column p, and on the
            # diagonal the loading's rate terms, c P_jj once and
            # (T_aj + c G_aj P_jj) G_aj (docs/math.md §2).
            emit(f"        const float {names[j]}_loaded = {rate_scale_loading} * {names[j]};")
            for a in range(3):
                for b in range(a, 3):
                    value = block[(a, b)]
                    terms = []
                    if b == j:
                        terms.append(f"t{a}")
                        value += t[a]
                        if a == b:
                            terms.append(f"{names[j]}_loaded")
                            value += scale_factor * sym[j]
                    if j in structure[b]:
                        p = structure[b].index(j)
                        if a == b:
                            terms.append(f"(t{a} + g{b}_{p} * {names[j]}_loaded) * g{b}_{p}")
                            value += (t[a] + g[b][p] * scale_factor * sym[j]) * g[b][p]
                        else:
                            terms.append(f"t{a} * g{b}_{p}")
                            value += t[a] * g[b][p]
                    if not terms:
                        continue
                    if j == 0:
                        emit(f"        block{a}{b} = {' + '.join(terms)};")
                    else:
                        for term in terms:
                            emit(f"        block{a}{b} += {term};")
                    block[(a, b)] = value
            emit("        PROPID_SCHEDULE_BARRIER();")
            emit("    }")
            continue
        # The coefficient columns' share of the rate block (T F^T)_ab, b >= a; on
        # the diagonal with the column's share of the rate's loading folded in,
        # (T_aj + c G_aj P_jj) G_aj, c P_jj loaded once for the rows that use it.
        if any(j in structure[a] for a in range(3)):
            emit(f"        const float {names[j]}_loaded = {rate_scale_loading} * {names[j]};")
        for a in range(3):
            for b in range(a, 3):
                if j in structure[b]:
                    p = structure[b].index(j)
                    if a == b:
                        emit(f"        block{a}{b} += (t{a} + g{b}_{p} * {names[j]}_loaded) * g{b}_{p};")
                        block[(a, b)] += (t[a] + g[b][p] * scale_factor * sym[j]) * g[b][p]
                    else:
                        emit(f"        block{a}{b} += t{a} * g{b}_{p};")
                        block[(a, b)] += t[a] * g[b][p]
        for a in range(3):
            store(a, j, f"t{a}", t[a])
        own = names.get(j, None)
        if own is None:                                   # a bias column: not loaded yet
            emit(f"        const float own = cov[propid_cov_index({j}u, {j}u)];")
            own = "own"
        if kind(j) == "drag":
            emit(f"        cov[propid_cov_index({j}u, {j}u)] = drag_factor * {own} + q_drag;")
            checked[(j, j)] = (1 + drag_loading) * p_symbol(j, j) + q["drag"]
        else:
            emit(f"        cov[propid_cov_index({j}u, {j}u)] = (1.0f + PROPID_VAR_LOADING) * {own} + "
                 f"q_{kind(j)};")
            checked[(j, j)] = (1 + loading) * p_symbol(j, j) + q[kind(j)]
        emit("        PROPID_SCHEDULE_BARRIER();")
        emit("    }")
    write_block(N - 1)
    if len([key for key in block if key in checked]) != len(block):
        raise SystemExit("quad_predict: an element of the rate block is not written")

    check_against_model(checked, "element")

    # The size-lean build's kernel: the same per-element arithmetic as loops over
    # the model's column table; interpreted here, symbolically, loop by loop as the
    # C below runs it, and checked against the model the same way.
    lean: dict[tuple[int, int], sympy.Expr] = {}
    lean_block = {(a, b): sympy.Integer(0) for a in range(3) for b in range(a, 3)}
    for j in range(N):
        t = []
        for a in range(3):
            acc = g[a][0] * p_symbol(structure[a][0], j)
            for p in range(1, entries):
                acc += g[a][p] * p_symbol(structure[a][p], j)
            t.append(acc + p_symbol(a, j))
        own_loaded = scale_factor * p_symbol(j, j)
        for b in range(3):
            for p in range(entries):
                if structure[b][p] == j:
                    for a in range(b + 1):
                        own_share = g[b][p] * own_loaded if a == b else 0
                        lean_block[(a, b)] += (t[a] + own_share) * g[b][p]
        if j < FIRST_THRUST:
            for a in range(j + 1):
                lean_block[(a, j)] += t[a]
            lean_block[(j, j)] += own_loaded
            continue
        for a in range(3):
            lean[(a, j)] = t[a]
        factor = 1 + (drag_loading if kind(j) == "drag" else loading)
        lean[(j, j)] = factor * p_symbol(j, j) + q[kind(j)]
    for b in range(3):
        for a in range(b + 1):
            lean[(a, b)] = lean_block[(a, b)] + q["rate"] if a == b else lean_block[(a, b)]
    check_against_model(lean, "lean kernel's element")
    entry_table = ", ".join("{" + ", ".join(f"{row.index(c)}u" if c in row else "0xFFu"
                                            for c in range(N)) + "}" for row in structure)

    # The C of the size-lean kernel: a loop over the columns j, its body written
    # out here with the model's columns as constant indices (the loop's values
    # stay in registers; the rows' sums in the order interpreted above).
    lean_lines: list[str] = []
    out = lean_lines.append
    out("/* The size-lean build (PROPID_SIZE_LEAN): the same sums per element as a loop")
    out(" * over the columns j, each column's body written out (its 11 loads walked")
    out(" * through the packed triangle, the three rows' sums, the rate block's")
    out(" * terms found through propid_quad_jac_entry, the rate columns' too, and")
    out(" * collected in the sweep as in the fast kernel, in its own order); small")
    out(" * code, more instructions. */")
    out(f"static const uint8_t propid_quad_jac_entry[3][{N}] = {{{entry_table}}};")
    out("")
    out("static inline __attribute__((always_inline)) void")
    out("propid_quad_predict_covariance(float *restrict cov, const float jacobian_dt[3][PROPID_JAC_ROW],")
    out("                               float q_rate, float q_thrust, float q_drag, float q_bias,")
    out("                               float drag_factor)")
    out("{")
    out("    float block00 = 0.0f, block01 = 0.0f, block02 = 0.0f; /* the rate block's terms */")
    out("    float block11 = 0.0f, block12 = 0.0f, block22 = 0.0f;")
    out(f"    for (uint8_t j = 0; j < {N}u; ++j) {{")
    out(f"        /* P_cj of the {FIRST_BIAS} non-bias rows c: down column j above the diagonal")
    out("         * (the packed step shrinks by one per row), then along row j. */")
    out(f"        float column_j[{FIRST_BIAS}];")
    out("        uint32_t at = j;")
    out(f"#pragma GCC unroll {FIRST_BIAS}")
    out(f"        for (uint8_t c = 0; c < {FIRST_BIAS}u; ++c) {{")
    out("            column_j[c] = cov[at];")
    out("            at += c < j ? (uint32_t)PROPID_MAX_STATES - 1u - c : 1u;")
    out("        }")
    for a_ in range(3):
        first = f"jacobian_dt[{a_}][0] * column_j[{structure[a_][0]}]"
        rest = "".join(f" + jacobian_dt[{a_}][{p_}] * column_j[{c_}]"
                       for p_, c_ in enumerate(structure[a_]) if p_ > 0)
        out(f"        const float t{a_} = ({first}{rest}) + column_j[{a_}];")
    out("        float *diagonal = &cov[propid_cov_index(j, j)];")
    out("        const float own = *diagonal;")
    out(f"        const float own_loaded = {rate_scale_loading} * own; /* the diagonal's share of the loading */")
    for b_ in range(3):
        out(f"        const uint8_t p{b_} = propid_quad_jac_entry[{b_}][j];")
        out(f"        if (p{b_} < {entries}u) {{")
        for a_ in range(b_ + 1):
            if a_ == b_:
                out(f"            block{a_}{b_} += (t{a_} + jacobian_dt[{b_}][p{b_}] * own_loaded) * jacobian_dt[{b_}][p{b_}];")
            else:
                out(f"            block{a_}{b_} += t{a_} * jacobian_dt[{b_}][p{b_}];")
        out("        }")
    out(f"        if (j < {FIRST_THRUST}u) {{ /* a rate column: T_aj in the rate block, not stored */")
    for j_ in range(FIRST_THRUST):
        keyword = "if" if j_ == 0 else "} else if" if j_ < FIRST_THRUST - 1 else "} else"
        condition = f" (j == {j_}u)" if j_ < FIRST_THRUST - 1 else ""
        out(f"            {keyword}{condition} {{")
        for a_ in range(j_ + 1):
            out(f"                block{a_}{j_} += t{a_};")
        out(f"                block{j_}{j_} += own_loaded;")
    out("            }")
    out("            continue;")
    out("        }")
    for a_ in range(3):
        out(f"        cov[propid_cov_index({a_}u, j)] = t{a_};")
    out(f"        if (j < {FIRST_DRAG}u) {{")
    out("            *diagonal = (1.0f + PROPID_VAR_LOADING) * own + q_thrust;")
    out(f"        }} else if (j < {FIRST_BIAS}u) {{")
    out("            *diagonal = drag_factor * own + q_drag;")
    out("        } else {")
    out("            *diagonal = (1.0f + PROPID_VAR_LOADING) * own + q_bias;")
    out("        }")
    out("    }")
    out("    /* The rate block, every term collected in the sweep. */")
    for a_ in range(3):
        for b_ in range(a_, 3):
            out(f"    cov[propid_cov_index({a_}u, {b_}u)] = block{a_}{b_}{' + q_rate' if a_ == b_ else ''};")
    out("}")
    lean_text = "\n".join(lean_lines) + "\n"

    g_loads = []
    for a in range(3):
        g_loads.append(f"    const float " + ", ".join(f"g{a}_{p} = jacobian_dt[{a}][{p}]"
                                                          for p in range(entries)) + ";")
    header = f"""/* Generated by firmware/codegen/quad_predict.py from its symbolic quad model:
 * do not edit (regenerate; tests/host_tools/test_codegen.py checks it is current).
 *
 * P := F P F^T + Q dt + PROPID_VAR_LOADING diag(F P F^T) (rates: PROPID_RATE_LOADING
 * of their rounding scale 7 (P_aa + sum_p G_ap^2 P_pp), docs/math.md §2; drag
 * coefficients: drag_factor - 1) for the fixed quad layout (propid_internal.h), on the packed upper triangle, F = I + G with G in the 3
 * rate rows only: column by column, the 11 non-bias P_cj loaded once for the
 * three rows of T = F_rate P, the 18 G entries in registers, the rate block's
 * six elements collected in registers during the sweep (every term: T_ab, the
 * rate and coefficient columns' T_aj G_bp, the loading) and each written after the
 * last column that adds to it. Every element
 * written was checked against the model's F P F^T + Q by the generator. */
#ifndef PROPID_QUAD_PREDICT_H
#define PROPID_QUAD_PREDICT_H

#include "propid_internal.h"

/* jacobian_dt: entries of the rate rows of G in the quad layout; q_*: Q dt per
 * kind of state; drag_factor: 1 + this step's loading of the drag coefficients. */
#if PROPID_SIZE_LEAN
{lean_text}#else
static inline __attribute__((always_inline)) void
propid_quad_predict_covariance(float *restrict cov, const float jacobian_dt[3][PROPID_JAC_ROW],
                               float q_rate, float q_thrust, float q_drag, float q_bias,
                               float drag_factor)
{{
{chr(10).join(g_loads)}
    float block00, block01, block02, block11, block12, block22; /* the rate block's terms */
{chr(10).join(lines)}
}}
#endif

#endif /* PROPID_QUAD_PREDICT_H */
"""
    # The Cortex-M4 assembly kernel: its graph checked against the model like the C.
    arm_graph, arm_stores, arm_lines, arm_counts = quad_predict_arm.kernel(structure)
    symbols = {}

    def leaf_symbol(node):
        if node.kind == "P":
            return p_symbol(*node.key)
        if node.kind == "G":
            return g[node.key[0]][node.key[1]]
        return {"c7": scale_factor, "c1l": 1 + loading, "drag_factor": 1 + drag_loading,
                "dt": sympy.Symbol("dt"), "psd_rate": q["rate"] / sympy.Symbol("dt"),
                "psd_thrust": q["thrust"] / sympy.Symbol("dt"), "psd_drag": q["drag"] / sympy.Symbol("dt"),
                "psd_bias": q["bias"] / sympy.Symbol("dt")}[node.key]
    values = quad_predict_arm.evaluate(arm_graph, leaf_symbol)
    check_against_model({(i, j): values[node] for i, j, node, _after in arm_stores}, "assembly kernel's element")
    arm_text = quad_predict_arm.c_function(structure, arm_lines, arm_counts)
    header = header.replace("#endif /* PROPID_QUAD_PREDICT_H */", f"""#if !PROPID_SIZE_LEAN && PROPID_ARM_BLOCK_MOVES && !PROPID_GENERAL_VEHICLES
#define PROPID_ARM_PREDICT_KERNEL 1
{arm_text}#else
#define PROPID_ARM_PREDICT_KERNEL 0
#endif

#endif /* PROPID_QUAD_PREDICT_H */""")
    return header


def main() -> int:
    return generator_main("quad_predict", __doc__.splitlines()[0], OUT, generate)


if __name__ == "__main__":
    sys.exit(main())
