"""The implicit integrator's prefactored solve (`sim.implicit`), laid out by supernodes.

The matrix is factored once (scipy's SuperLU, a symmetric fill-reducing ordering): A = Pr^T L U Pc^T
with L unit lower and U upper, of the same sparsity pattern transposed. A substep then does a forward
sweep with L and a backward sweep with U for three right-hand sides (x, y, z); at ~350k entries a
factor, those sweeps are most of the step.

A run of consecutive columns of L with one pattern below them (a supernode: the columns s..e-1, a
dense triangle inside the run and the same rows R below it) is stored as dense blocks: one list of
rows R for L and U together, L's |R| x w values column by column, U's w x |R| values by the columns
of R, and the w x w triangles (L's below the diagonal, U's above, by columns). Each sweep then
works a run at a time on a small buffer of its rows: the forward sweep subtracts column s from all
of R, then column s + 1, ...; the backward sweep subtracts the last column of R from all of the
run's rows, then the one before, .... Those innermost loops run over contiguous values of
independent rows, which the compiler turns into vector instructions, and the index lists shrink
to a fourteenth (one list of rows per run instead of a row index per entry of each factor).
(Runs of one column scatter directly; narrow runs take each backward row in registers.) Where a run
has four columns or more, each pass over the buffer applies four of them (four rows of U going
backward), one value after the other, so the buffer is read and written a quarter as often.

The arithmetic is the column sweeps', operation for operation: every value of the right-hand side
receives its subtractions in the same order (the forward sweep's in increasing column, the
backward's in decreasing column) and each is a separate multiply and subtract, so a solve gives the
same bits as the plain column-by-column sweeps over the same factors.

The matrix is symmetric and factored with one permutation for rows and columns, so U = D L^T up to
rounding (D: U's diagonal): `_sym_sweeps` solves from L and D alone, L^-T D^-1 L^-1, reading each
value of L twice and none of U's: the same answer to rounding, other bits (new takes; the take
header's "solve", sim.Simulator.symmetric_solve), fewer bytes to bring from memory each solve. Its
backward sweep takes L's columns (contiguous) as sums over the rows below a run, which it
adds in four lanes of vector code (a lone column's straight from y by index: `_lone_back`);
`_sn_sweeps` stays for the takes recorded with it. Both sweeps take the row indices as uint32
(`PrefactoredSolver.factors`), so no index is checked for being negative in their loops.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

if TYPE_CHECKING:
    import scipy.sparse as sp


#: how far ahead (values) of the one in use each sweep asks the memory for the factors: a substep's
#: solve finds them out of the caches (the rest of the tick and other programs evicted them), and
#: runs of a few columns are too short for the processor's own prefetcher to get ahead
AHEAD = 1024
NARROW = 4  # runs narrower than this: the backward sweep takes each row in registers
BLOCK = 4  # columns (rows of U) a sweep applies in one pass over a run's buffer: 4 x 3 multipliers fit the registers


@intrinsic
def _prefetch(typingctx, arr, i):  # type: ignore[no-untyped-def]
    """Ask for the cache line holding arr[i] (LLVM's prefetch: read, high locality); no effect on
    any value. i must lie inside arr."""
    sig = types.void(arr, i)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        byte = ir.IntType(8).as_pointer()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [byte] + [ir.IntType(32)] * 3),
                                            "llvm.prefetch.p0")
        i32 = ir.IntType(32)
        builder.call(fn, [builder.bitcast(builder.gep(ary.data, [args[1]]), byte), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _dot4(typingctx, col, g0, g1, g2, blocks):  # type: ignore[no-untyped-def]
    """Four lanes a right-hand side: lane k of s_r sums col[i] * g_r[i] over the rows i = 4 b + k,
    b < blocks, in increasing i (each a multiply then an add, as the scalar loop would); returns
    (s_0 lanes 0-3, s_1 lanes 0-3, s_2 lanes 0-3). Written as vectors of four float64 so the lanes
    run side by side (numba's straight-line vectorizer is off); the same bits on any processor."""
    sig = types.UniTuple(types.float64, 12)(col, g0, g1, g2, blocks)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        f64 = ir.DoubleType()
        vec = ir.VectorType(f64, 4)
        vptr = vec.as_pointer()
        datas = [context.make_array(signature.args[j])(context, builder, args[j]).data for j in range(4)]
        zero = ir.Constant(vec, [0.0] * 4)
        accs = [cgutils.alloca_once_value(builder, zero) for _ in range(3)]
        with cgutils.for_range(builder, args[4]) as loop:
            off = builder.mul(loop.index, ir.Constant(loop.index.type, 4))

            def load(data):  # type: ignore[no-untyped-def]
                ld = builder.load(builder.bitcast(builder.gep(data, [off]), vptr))
                ld.align = 8
                return ld

            c = load(datas[0])
            for r in range(3):
                builder.store(builder.fadd(builder.load(accs[r]), builder.fmul(c, load(datas[r + 1]))), accs[r])
        i32 = ir.IntType(32)
        vals = [builder.extract_element(builder.load(accs[r]), i32(k)) for r in range(3) for k in range(4)]
        return context.make_tuple(builder, signature.return_type, vals)

    return sig, codegen


@numba.njit(inline="always")
def _prefetch_back(arr, p, start):  # type: ignore[no-untyped-def]
    """A backward sweep's read-ahead: the cache lines of arr from p down to AHEAD values before
    `start` (the next run's first value), a line of float64 at a time; returns the next p."""
    end = max(start - AHEAD, 0)
    while p >= end:
        _prefetch(arr, p)
        p -= 8
    return p


@numba.njit(inline="always")
def _put4(y, i, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2):  # type: ignore[no-untyped-def]
    """Four unknowns of a backward sweep stored: rows i, i - 1, i - 2, i - 3 of y take (p, q, u, z)."""
    y[i, 0] = p0
    y[i, 1] = p1
    y[i, 2] = p2
    y[i - 1, 0] = q0
    y[i - 1, 1] = q1
    y[i - 1, 2] = q2
    y[i - 2, 0] = u0
    y[i - 2, 1] = u1
    y[i - 2, 2] = u2
    y[i - 3, 0] = z0
    y[i - 3, 1] = z1
    y[i - 3, 2] = z2


@numba.njit(inline="always")
def _take4(a0, a1, a2, c0, c1, c2, c3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, lo, hi):  # type: ignore[no-untyped-def]
    """Rows lo..hi-1 of the buffer (a0, a1, a2) take four columns c0..c3 in turn, times the
    values (p, q, u, z): each subtraction separate and in that order (one pass, the column sweeps'
    bits)."""
    for i in range(lo, hi):
        b0 = a0[i] - c0[i] * p0
        b1 = a1[i] - c0[i] * p1
        b2 = a2[i] - c0[i] * p2
        b0 = b0 - c1[i] * q0
        b1 = b1 - c1[i] * q1
        b2 = b2 - c1[i] * q2
        b0 = b0 - c2[i] * u0
        b1 = b1 - c2[i] * u1
        b2 = b2 - c2[i] * u2
        a0[i] = b0 - c3[i] * z0
        a1[i] = b1 - c3[i] * z1
        a2[i] = b2 - c3[i] * z2


@numba.njit(inline="always")
def _take1(a0, a1, a2, col, x0, x1, x2, lo, hi):  # type: ignore[no-untyped-def]
    """Rows lo..hi-1 of the buffer take one column times (x0, x1, x2)."""
    for i in range(lo, hi):
        a0[i] -= col[i] * x0
        a1[i] -= col[i] * x1
        a2[i] -= col[i] * x2


@numba.njit(inline="always")
def _forward(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, t_ptr, tv, acc):  # type: ignore[no-untyped-def]
    """y = L^-1 y in place (L unit lower), the forward sweep of `_sn_sweeps` and `_sym_sweeps`."""
    a0 = acc[0]
    a1 = acc[1]
    a2 = acc[2]
    nodes = sn_ptr.shape[0] - 1
    nl = lv.shape[0]
    nt = tv.shape[0]
    pl = 0  # the next value of lv (tv) to prefetch
    pt = 0
    for k in range(nodes):  # forward: L has a unit diagonal
        end = min(v_ptr[k + 1] + AHEAD, nl)
        while pl < end:
            _prefetch(lv, pl)
            pl += 8  # a cache line of float64
        end = min(t_ptr[k + 1] + AHEAD, nt)
        while pt < end:
            _prefetch(tv, pt)
            pt += 8
        s = sn_ptr[k]
        w = sn_ptr[k + 1] - s
        t = t_ptr[k]
        base = v_ptr[k]
        r0 = r_ptr[k]
        m = r_ptr[k + 1] - r0
        if w == 1:  # a lone column: scatter it
            x0 = y[s, 0]
            x1 = y[s, 1]
            x2 = y[s, 2]
            for i in range(m):
                r = r_idx[r0 + i]
                a = lv[base + i]
                y[r, 0] -= a * x0
                y[r, 1] -= a * x1
                y[r, 2] -= a * x2
            continue
        for ii in range(w):
            a0[ii] = y[s + ii, 0]
            a1[ii] = y[s + ii, 1]
            a2[ii] = y[s + ii, 2]
        jj = 0
        while jj + BLOCK <= w:  # inside the run: four columns at a time, the first three finished in turn
            c0 = tv[t + jj * w:t + (jj + 1) * w]
            c1 = tv[t + (jj + 1) * w:t + (jj + 2) * w]
            c2 = tv[t + (jj + 2) * w:t + (jj + 3) * w]
            c3 = tv[t + (jj + 3) * w:t + (jj + 4) * w]
            p0 = a0[jj]
            p1 = a1[jj]
            p2 = a2[jj]
            q0 = a0[jj + 1] - c0[jj + 1] * p0
            q1 = a1[jj + 1] - c0[jj + 1] * p1
            q2 = a2[jj + 1] - c0[jj + 1] * p2
            u0 = (a0[jj + 2] - c0[jj + 2] * p0) - c1[jj + 2] * q0
            u1 = (a1[jj + 2] - c0[jj + 2] * p1) - c1[jj + 2] * q1
            u2 = (a2[jj + 2] - c0[jj + 2] * p2) - c1[jj + 2] * q2
            z0 = ((a0[jj + 3] - c0[jj + 3] * p0) - c1[jj + 3] * q0) - c2[jj + 3] * u0
            z1 = ((a1[jj + 3] - c0[jj + 3] * p1) - c1[jj + 3] * q1) - c2[jj + 3] * u1
            z2 = ((a2[jj + 3] - c0[jj + 3] * p2) - c1[jj + 3] * q2) - c2[jj + 3] * u2
            a0[jj + 1] = q0
            a1[jj + 1] = q1
            a2[jj + 1] = q2
            a0[jj + 2] = u0
            a1[jj + 2] = u1
            a2[jj + 2] = u2
            a0[jj + 3] = z0
            a1[jj + 3] = z1
            a2[jj + 3] = z2
            _take4(a0, a1, a2, c0, c1, c2, c3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, jj + BLOCK, w)
            jj += BLOCK
        while jj < w:  # the run's last columns one by one
            x0 = a0[jj]
            x1 = a1[jj]
            x2 = a2[jj]
            col = tv[t + jj * w:t + (jj + 1) * w]
            _take1(a0, a1, a2, col, x0, x1, x2, jj + 1, w)
            jj += 1
        for ii in range(w):
            y[s + ii, 0] = a0[ii]
            y[s + ii, 1] = a1[ii]
            y[s + ii, 2] = a2[ii]
        for i in range(m):  # the rows below: all of them take column s, then s + 1, ...
            r = r_idx[r0 + i]
            a0[i] = y[r, 0]
            a1[i] = y[r, 1]
            a2[i] = y[r, 2]
        jj = 0
        while jj + BLOCK <= w:  # four columns at a time
            p0 = y[s + jj, 0]
            p1 = y[s + jj, 1]
            p2 = y[s + jj, 2]
            q0 = y[s + jj + 1, 0]
            q1 = y[s + jj + 1, 1]
            q2 = y[s + jj + 1, 2]
            u0 = y[s + jj + 2, 0]
            u1 = y[s + jj + 2, 1]
            u2 = y[s + jj + 2, 2]
            z0 = y[s + jj + 3, 0]
            z1 = y[s + jj + 3, 1]
            z2 = y[s + jj + 3, 2]
            c0 = lv[base + jj * m:base + (jj + 1) * m]
            c1 = lv[base + (jj + 1) * m:base + (jj + 2) * m]
            c2 = lv[base + (jj + 2) * m:base + (jj + 3) * m]
            c3 = lv[base + (jj + 3) * m:base + (jj + 4) * m]
            _take4(a0, a1, a2, c0, c1, c2, c3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, 0, m)
            jj += BLOCK
        while jj < w:
            x0 = y[s + jj, 0]
            x1 = y[s + jj, 1]
            x2 = y[s + jj, 2]
            col = lv[base + jj * m:base + (jj + 1) * m]
            _take1(a0, a1, a2, col, x0, x1, x2, 0, m)
            jj += 1
        for i in range(m):
            r = r_idx[r0 + i]
            y[r, 0] = a0[i]
            y[r, 1] = a1[i]
            y[r, 2] = a2[i]


@numba.njit(cache=True, nogil=True)
def _sn_sweeps(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, uv, t_ptr, tv, u_diag, acc):  # type: ignore[no-untyped-def]
    """y = U^-1 L^-1 y in place for 3 right-hand sides, supernode by supernode (module docstring);
    acc: a (3, longest run or row list) work buffer. The innermost loops index slices (never a
    computed offset, whose possible negative value would keep the compiler from vectorizing), and
    take BLOCK columns (rows of U) at once where a run has them: each value still receives their
    subtractions one by one in the sweep's order, so the bits are the column sweeps'."""
    _forward(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, t_ptr, tv, acc)
    a0 = acc[0]
    a1 = acc[1]
    a2 = acc[2]
    nodes = sn_ptr.shape[0] - 1
    nl = lv.shape[0]
    nt = tv.shape[0]
    pl = nl - 1  # uv and tv are read from their ends
    pt = nt - 1
    for k in range(nodes - 1, -1, -1):  # backward: the columns after the run first, from the last
        pl = _prefetch_back(uv, pl, v_ptr[k])
        pt = _prefetch_back(tv, pt, t_ptr[k])
        s = sn_ptr[k]
        w = sn_ptr[k + 1] - s
        t = t_ptr[k]
        base = v_ptr[k]
        r0 = r_ptr[k]
        m = r_ptr[k + 1] - r0
        for ii in range(w):
            a0[ii] = y[s + ii, 0]
            a1[ii] = y[s + ii, 1]
            a2[ii] = y[s + ii, 2]
        if w < NARROW:  # few rows: each one's terms in registers
            for ii in range(w):
                b0 = a0[ii]
                b1 = a1[ii]
                b2 = a2[ii]
                for i in range(m - 1, -1, -1):
                    c = r_idx[r0 + i]
                    a = uv[base + i * w + ii]
                    b0 -= a * y[c, 0]
                    b1 -= a * y[c, 1]
                    b2 -= a * y[c, 2]
                a0[ii] = b0
                a1[ii] = b1
                a2[ii] = b2
        else:  # many rows: all of them take the last column, then the one before, ... four at a time
            i = m - 1
            while i >= BLOCK - 1:
                c = r_idx[r0 + i]
                p0 = y[c, 0]
                p1 = y[c, 1]
                p2 = y[c, 2]
                c = r_idx[r0 + i - 1]
                q0 = y[c, 0]
                q1 = y[c, 1]
                q2 = y[c, 2]
                c = r_idx[r0 + i - 2]
                u0 = y[c, 0]
                u1 = y[c, 1]
                u2 = y[c, 2]
                c = r_idx[r0 + i - 3]
                z0 = y[c, 0]
                z1 = y[c, 1]
                z2 = y[c, 2]
                e0 = uv[base + i * w:base + (i + 1) * w]
                e1 = uv[base + (i - 1) * w:base + i * w]
                e2 = uv[base + (i - 2) * w:base + (i - 1) * w]
                e3 = uv[base + (i - 3) * w:base + (i - 2) * w]
                _take4(a0, a1, a2, e0, e1, e2, e3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, 0, w)
                i -= BLOCK
            while i >= 0:
                c = r_idx[r0 + i]
                x0 = y[c, 0]
                x1 = y[c, 1]
                x2 = y[c, 2]
                row = uv[base + i * w:base + (i + 1) * w]
                _take1(a0, a1, a2, row, x0, x1, x2, 0, w)
                i -= 1
        jj = w - 1
        while jj >= BLOCK - 1:  # then the run's own columns from the last, four at a time, each once final
            c0 = tv[t + jj * w:t + (jj + 1) * w]
            c1 = tv[t + (jj - 1) * w:t + jj * w]
            c2 = tv[t + (jj - 2) * w:t + (jj - 1) * w]
            d = u_diag[s + jj]
            p0 = a0[jj] / d
            p1 = a1[jj] / d
            p2 = a2[jj] / d
            d = u_diag[s + jj - 1]
            q0 = (a0[jj - 1] - c0[jj - 1] * p0) / d
            q1 = (a1[jj - 1] - c0[jj - 1] * p1) / d
            q2 = (a2[jj - 1] - c0[jj - 1] * p2) / d
            d = u_diag[s + jj - 2]
            u0 = ((a0[jj - 2] - c0[jj - 2] * p0) - c1[jj - 2] * q0) / d
            u1 = ((a1[jj - 2] - c0[jj - 2] * p1) - c1[jj - 2] * q1) / d
            u2 = ((a2[jj - 2] - c0[jj - 2] * p2) - c1[jj - 2] * q2) / d
            d = u_diag[s + jj - 3]
            z0 = (((a0[jj - 3] - c0[jj - 3] * p0) - c1[jj - 3] * q0) - c2[jj - 3] * u0) / d
            z1 = (((a1[jj - 3] - c0[jj - 3] * p1) - c1[jj - 3] * q1) - c2[jj - 3] * u1) / d
            z2 = (((a2[jj - 3] - c0[jj - 3] * p2) - c1[jj - 3] * q2) - c2[jj - 3] * u2) / d
            _put4(y, s + jj, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2)
            c3 = tv[t + (jj - 3) * w:t + (jj - 2) * w]
            _take4(a0, a1, a2, c0, c1, c2, c3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, 0, jj - 3)
            jj -= BLOCK
        while jj >= 0:  # the run's first columns one by one
            d = u_diag[s + jj]
            x0 = a0[jj] / d
            x1 = a1[jj] / d
            x2 = a2[jj] / d
            y[s + jj, 0] = x0
            y[s + jj, 1] = x1
            y[s + jj, 2] = x2
            col = tv[t + jj * w:t + (jj + 1) * w]
            _take1(a0, a1, a2, col, x0, x1, x2, 0, jj)
            jj -= 1


@numba.njit(inline="always")
def _lone_back(y, s, r_idx, r0, m, lv, base, d):  # type: ignore[no-untyped-def]
    """`_sym_sweeps`' backward step for a run of one column s: y[s] / d less the sum of L's column
    below it times the unknowns there, in the four lanes `_dot4` defines (lane k the rows k, k + 4,
    ... of the row list in turn, each a multiply then an add from 0; the rows past the last four
    to lanes 0, 1, 2; then (0 + 1) + (2 + 3)), read straight from y by index: the same bits as the
    lanes over a copy of the rows side by side, without the copy (a lone column has ~20 rows)."""
    s00 = s01 = s02 = s03 = 0.0
    s10 = s11 = s12 = s13 = 0.0
    s20 = s21 = s22 = s23 = 0.0
    q = m - m % 4
    for i in range(0, q, 4):
        r = r_idx[r0 + i]
        c = lv[base + i]
        s00 += c * y[r, 0]
        s10 += c * y[r, 1]
        s20 += c * y[r, 2]
        r = r_idx[r0 + i + 1]
        c = lv[base + i + 1]
        s01 += c * y[r, 0]
        s11 += c * y[r, 1]
        s21 += c * y[r, 2]
        r = r_idx[r0 + i + 2]
        c = lv[base + i + 2]
        s02 += c * y[r, 0]
        s12 += c * y[r, 1]
        s22 += c * y[r, 2]
        r = r_idx[r0 + i + 3]
        c = lv[base + i + 3]
        s03 += c * y[r, 0]
        s13 += c * y[r, 1]
        s23 += c * y[r, 2]
    if q < m:
        r = r_idx[r0 + q]
        c = lv[base + q]
        s00 += c * y[r, 0]
        s10 += c * y[r, 1]
        s20 += c * y[r, 2]
    if q + 1 < m:
        r = r_idx[r0 + q + 1]
        c = lv[base + q + 1]
        s01 += c * y[r, 0]
        s11 += c * y[r, 1]
        s21 += c * y[r, 2]
    if q + 2 < m:
        r = r_idx[r0 + q + 2]
        c = lv[base + q + 2]
        s02 += c * y[r, 0]
        s12 += c * y[r, 1]
        s22 += c * y[r, 2]
    y[s, 0] = y[s, 0] / d - ((s00 + s01) + (s02 + s03))
    y[s, 1] = y[s, 1] / d - ((s10 + s11) + (s12 + s13))
    y[s, 2] = y[s, 2] / d - ((s20 + s21) + (s22 + s23))


@numba.njit(cache=True, nogil=True)
def _sym_sweeps(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, t_ptr, tl, u_diag, acc):  # type: ignore[no-untyped-def]
    """y = L^-T D^-1 L^-1 y in place for 3 right-hand sides: the solve from the symmetric factor
    alone (module docstring), `_sn_sweeps`' forward sweep, then a backward sweep that reads L's
    values where `_sn_sweeps` reads U's. Run by run from the last, each unknown of the run is its
    value divided by its pivot less the sum of L's column below the run times the (final) unknowns
    there: lane k of four sums the rows k, k + 4, ... of the run's row list in turn (`_dot4`, vector
    code), the lanes added (0 + 1) + (2 + 3); then the run's own unknowns from the last, each final
    value subtracted, times L's row inside the run, from the earlier ones (four at a time as in
    `_sn_sweeps`, one after the other for each value). tl: the runs' triangles with L's values on
    both sides of the diagonal (`mirrored`; the forward sweep reads the lower side, tv's values).
    Not the bits of `_sn_sweeps` (a take's header says which solve it was recorded with). The run's
    own back substitution is written out here and in `_sn_sweeps` on purpose: shared as one inlined
    kernel (dividing by the pivot or not), the bits stayed but the L and U solve ran 8 % slower.
    acc: (6, `work_size`)."""
    _forward(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, t_ptr, tl, acc)
    a0 = acc[0]
    a1 = acc[1]
    a2 = acc[2]
    g0 = acc[3]
    g1 = acc[4]
    g2 = acc[5]
    nodes = sn_ptr.shape[0] - 1
    pl = lv.shape[0] - 1  # lv and tv are read from their ends
    pt = tl.shape[0] - 1
    for k in range(nodes - 1, -1, -1):
        pl = _prefetch_back(lv, pl, v_ptr[k])
        pt = _prefetch_back(tl, pt, t_ptr[k])
        s = sn_ptr[k]
        w = sn_ptr[k + 1] - s
        t = t_ptr[k]
        base = v_ptr[k]
        r0 = r_ptr[k]
        m = r_ptr[k + 1] - r0
        if w == 1:  # a lone column: its four lanes summed straight from y (no copy side by side)
            _lone_back(y, s, r_idx, r0, m, lv, base, u_diag[s])
            continue
        for i in range(m):  # the unknowns below the run, final already, side by side
            r = r_idx[r0 + i]
            g0[i] = y[r, 0]
            g1[i] = y[r, 1]
            g2[i] = y[r, 2]
        q = m - m % 4
        for jj in range(w):  # the sums below the run: lane k sums the rows i = k (mod 4), in increasing i
            col = lv[base + jj * m:base + (jj + 1) * m]
            s00, s01, s02, s03, s10, s11, s12, s13, s20, s21, s22, s23 = _dot4(col, g0, g1, g2, q // 4)
            if q < m:
                s00 += col[q] * g0[q]
                s10 += col[q] * g1[q]
                s20 += col[q] * g2[q]
            if q + 1 < m:
                s01 += col[q + 1] * g0[q + 1]
                s11 += col[q + 1] * g1[q + 1]
                s21 += col[q + 1] * g2[q + 1]
            if q + 2 < m:
                s02 += col[q + 2] * g0[q + 2]
                s12 += col[q + 2] * g1[q + 2]
                s22 += col[q + 2] * g2[q + 2]
            d = u_diag[s + jj]
            a0[jj] = y[s + jj, 0] / d - ((s00 + s01) + (s02 + s03))
            a1[jj] = y[s + jj, 1] / d - ((s10 + s11) + (s12 + s13))
            a2[jj] = y[s + jj, 2] / d - ((s20 + s21) + (s22 + s23))
        jj = w - 1
        while jj >= BLOCK - 1:  # then the run's own columns from the last (L's rows, mirrored), four at a time
            c0 = tl[t + jj * w:t + (jj + 1) * w]
            c1 = tl[t + (jj - 1) * w:t + jj * w]
            c2 = tl[t + (jj - 2) * w:t + (jj - 1) * w]
            p0 = a0[jj]
            p1 = a1[jj]
            p2 = a2[jj]
            q0 = a0[jj - 1] - c0[jj - 1] * p0
            q1 = a1[jj - 1] - c0[jj - 1] * p1
            q2 = a2[jj - 1] - c0[jj - 1] * p2
            u0 = (a0[jj - 2] - c0[jj - 2] * p0) - c1[jj - 2] * q0
            u1 = (a1[jj - 2] - c0[jj - 2] * p1) - c1[jj - 2] * q1
            u2 = (a2[jj - 2] - c0[jj - 2] * p2) - c1[jj - 2] * q2
            z0 = ((a0[jj - 3] - c0[jj - 3] * p0) - c1[jj - 3] * q0) - c2[jj - 3] * u0
            z1 = ((a1[jj - 3] - c0[jj - 3] * p1) - c1[jj - 3] * q1) - c2[jj - 3] * u1
            z2 = ((a2[jj - 3] - c0[jj - 3] * p2) - c1[jj - 3] * q2) - c2[jj - 3] * u2
            _put4(y, s + jj, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2)
            c3 = tl[t + (jj - 3) * w:t + (jj - 2) * w]
            _take4(a0, a1, a2, c0, c1, c2, c3, p0, p1, p2, q0, q1, q2, u0, u1, u2, z0, z1, z2, 0, jj - 3)
            jj -= BLOCK
        while jj >= 0:  # the run's first columns one by one
            x0 = a0[jj]
            x1 = a1[jj]
            x2 = a2[jj]
            y[s + jj, 0] = x0
            y[s + jj, 1] = x1
            y[s + jj, 2] = x2
            col = tl[t + jj * w:t + (jj + 1) * w]
            _take1(a0, a1, a2, col, x0, x1, x2, 0, jj)
            jj -= 1


@numba.njit(cache=True, nogil=True)
def _sn_solve(b, perm_r, perm_c, sn_ptr, r_ptr, r_idx, v_ptr, lv, uv, t_ptr, tv, u_diag, acc, y, out):  # type: ignore[no-untyped-def]
    """x = Pc U^-1 L^-1 Pr b for 3 right-hand sides (see _sn_sweeps)."""
    n = b.shape[0]
    for i in range(n):
        r = perm_r[i]
        for k in range(3):
            y[r, k] = b[i, k]
    _sn_sweeps(y, sn_ptr, r_ptr, r_idx, v_ptr, lv, uv, t_ptr, tv, u_diag, acc)
    for i in range(n):
        c = perm_c[i]
        for k in range(3):
            out[i, k] = y[c, k]


def supernodes(lower: sp.csc_matrix, upper: sp.csc_matrix) -> dict[str, np.ndarray]:
    """The supernodal layout (module docstring) of the factors L (unit lower) and U (upper) of one
    n x n matrix whose patterns are each other's transpose: sn_ptr (the runs' first columns),
    r_ptr/r_idx (each run's rows below it, ascending, int32), v_ptr/lv/uv (L's |R| x w values by
    columns, U's w x |R| values by the columns of R), t_ptr/tv (the w x w triangles by columns: L's
    below the diagonal, U's above) and u_diag."""
    import scipy.sparse as sp

    n = lower.shape[0]
    lo = sp.csc_matrix(lower, dtype=np.float64)
    up = sp.csr_matrix(upper, dtype=np.float64)  # U by rows: row j of U pairs with column j of L
    lo.sort_indices()
    up.sort_indices()
    def below_diagonal(m: sp.spmatrix, j: int) -> tuple[np.ndarray, np.ndarray]:
        idx, val = m.indices[m.indptr[j]:m.indptr[j + 1]], m.data[m.indptr[j]:m.indptr[j + 1]]
        return idx[idx > j], val[idx > j]

    low = [below_diagonal(lo, j) for j in range(n)]  # column j of L below the diagonal
    upr = [below_diagonal(up, j) for j in range(n)]  # row j of U right of the diagonal
    cols = [c for c, _ in low]
    if any(not np.array_equal(cols[j], upr[j][0]) for j in range(n)):
        raise ValueError("the factors' patterns are not each other's transpose")
    u_diag = np.zeros(n)
    for j in range(n):
        on = up.indices[up.indptr[j]:up.indptr[j + 1]] == j
        u_diag[j] = up.data[up.indptr[j]:up.indptr[j + 1]][on].sum()
    starts = [0]
    for j in range(1, n):  # column j continues the run when column j-1 is {j} + column j's pattern
        prev, cur = cols[j - 1], cols[j]
        if not (len(prev) == len(cur) + 1 and prev[0] == j and np.array_equal(prev[1:], cur)):
            starts.append(j)
    starts.append(n)
    r_ptr, v_ptr, t_ptr = [0], [0], [0]
    r_idx: list[np.ndarray] = []
    lv: list[np.ndarray] = []
    uv: list[np.ndarray] = []
    tv: list[np.ndarray] = []
    for k in range(len(starts) - 1):
        s, e = starts[k], starts[k + 1]
        w = e - s
        below = cols[e - 1]
        m = len(below)
        tri = np.zeros((w, w))  # [column, row] in the run: L's below the diagonal, U's above
        low_block = np.zeros((w, m))  # [column in run, row below]
        up_block = np.zeros((m, w))  # [column below, row in run]
        for jj in range(w):  # a column's (a row's) first w - 1 - jj entries lie in the run, the rest below
            lvals, uvals = low[s + jj][1], upr[s + jj][1]
            tri[jj, jj + 1:] = lvals[:w - 1 - jj]
            tri[jj + 1:, jj] = uvals[:w - 1 - jj]
            low_block[jj] = lvals[w - 1 - jj:]
            up_block[:, jj] = uvals[w - 1 - jj:]
        r_idx.append(below)
        lv.append(low_block.ravel())
        uv.append(up_block.ravel())
        tv.append(tri.ravel())
        r_ptr.append(r_ptr[-1] + m)
        v_ptr.append(v_ptr[-1] + m * w)
        t_ptr.append(t_ptr[-1] + w * w)

    def cat(parts: list[np.ndarray], dtype: type) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros(0), dtype=dtype)

    return dict(sn_ptr=np.asarray(starts, dtype=np.int64), r_ptr=np.asarray(r_ptr, dtype=np.int64),
                r_idx=cat(r_idx, np.int32), v_ptr=np.asarray(v_ptr, dtype=np.int64), lv=cat(lv, np.float64),
                uv=cat(uv, np.float64), t_ptr=np.asarray(t_ptr, dtype=np.int64), tv=cat(tv, np.float64),
                u_diag=u_diag)


def mirrored(sn_ptr: np.ndarray, t_ptr: np.ndarray, tv: np.ndarray) -> np.ndarray:
    """The runs' triangles with L's values on both sides of the diagonal (`_sym_sweeps` reads a
    row of L inside a run where `_sn_sweeps` reads a column of U): as long as tv."""
    out = np.array(tv, dtype=np.float64)
    widths = np.diff(np.asarray(sn_ptr, dtype=np.int64))
    starts = np.asarray(t_ptr, dtype=np.int64)[:-1]
    # the runs of each width at once (a loop over the runs took 10-20 ms of every start): the
    # same operations on every value as run by run, so the same bits
    for w in np.unique(widths[widths > 1]).tolist():
        at = starts[widths == w][:, None] + np.arange(w * w)  # (runs, w*w) offsets into tv
        tri = out[at].reshape(-1, w, w)  # [column, row]: L's below the diagonal: row > column
        low = np.triu(tri, 1)
        out[at] = (low + low.transpose(0, 2, 1)).reshape(-1, w * w)
    return out


def check_layout(a: dict[str, np.ndarray], n: int, prefix: str = "lu_") -> None:
    """Raises ValueError unless the arrays (`prefix` + the keys of `supernodes`) are a layout the
    kernel can follow for n unknowns without reading outside them."""
    sn, rp, vp, tp = (a[prefix + k] for k in ("sn_ptr", "r_ptr", "v_ptr", "t_ptr"))
    ri = a[prefix + "r_idx"]
    if ri.dtype != np.int32:
        raise ValueError("factor indices: not int32")
    nodes = len(sn) - 1
    if nodes < 0 or sn[0] != 0 or sn[-1] != n or np.any(np.diff(sn) <= 0):
        raise ValueError("bad supernodes")
    for ptr in (rp, vp, tp):
        if ptr.shape != (nodes + 1,) or ptr[0] != 0 or np.any(np.diff(ptr) < 0):
            raise ValueError("bad supernode offsets")
    w, m = np.diff(sn), np.diff(rp)
    if rp[-1] != len(ri) or np.any(np.diff(vp) != w * m) or np.any(np.diff(tp) != w * w):
        raise ValueError("supernode offsets do not match")
    if len(ri) and (ri.min() < 0 or ri.max() >= n):
        raise ValueError("index out of range")
    if len(a[prefix + "lv"]) != vp[-1] or len(a[prefix + "uv"]) != vp[-1] or len(a[prefix + "tv"]) != tp[-1]:
        raise ValueError("supernode values of the wrong length")
    if a[prefix + "u_diag"].shape != (n,) or np.any(a[prefix + "u_diag"] == 0.0):
        raise ValueError("a singular factor")


def work_size(arrays: dict[str, np.ndarray], prefix: str = "") -> int:
    """The length of the kernel's work buffer: the widest run or longest list of rows below one."""
    return int(max(np.diff(arrays[prefix + "sn_ptr"]).max(initial=1), np.diff(arrays[prefix + "r_ptr"]).max(initial=1)))


def _unsigned(r_idx: np.ndarray) -> np.ndarray:
    """The factors' row indices (int32, >= 0) viewed as uint32, as the sweeps take them."""
    return np.ascontiguousarray(r_idx, dtype=np.int32).view(np.uint32)


#: `mirrored` of a factor's triangles by the array they came from (never written to), with it
_MIRRORED: dict[int, tuple[np.ndarray, np.ndarray]] = {}


class PrefactoredSolver:
    """A sparse LU of a fixed matrix with a compiled supernodal solve for (n, 3) right-hand sides.
    `arrays` holds everything the solve reads (kept in the face cache, `sim.prepared`); a solver
    made from them gives the same bits as the one they came from."""

    KEYS = ("perm_r", "perm_c", "sn_ptr", "r_ptr", "r_idx", "v_ptr", "lv", "uv", "t_ptr", "tv", "u_diag")

    def __init__(self, a: sp.spmatrix | None = None, arrays: dict[str, np.ndarray] | None = None) -> None:
        if arrays is None:
            import scipy.sparse as sp
            from scipy.sparse.linalg import splu

            lu = splu(sp.csc_matrix(a), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
            arrays = dict(perm_r=np.ascontiguousarray(lu.perm_r, dtype=np.int64),
                          perm_c=np.ascontiguousarray(lu.perm_c, dtype=np.int64), **supernodes(lu.L, lu.U))
        self.arrays = arrays
        self.n = len(arrays["perm_r"])
        self.perm_r, self.perm_c = arrays["perm_r"], arrays["perm_c"]
        #: what `_sn_sweeps` reads; the row indices (int32, never negative: `check_layout`) as uint32,
        #: so indexing y with them needs no check for a negative index (the same values: 0.52 ->
        #: 0.48 ms a solve from L and D on the scanned head, the factors in the caches)
        self.factors = tuple(_unsigned(arrays[k]) if k == "r_idx" else arrays[k] for k in self.KEYS[2:])
        self.fill = int(2 * len(arrays["lv"]) + len(arrays["tv"]) + self.n)
        #: the symmetric solve needs the same permutation of rows and columns (A = P^T L D L^T P)
        self.symmetric = bool(np.array_equal(self.perm_r, self.perm_c))
        self.work = np.zeros((6, work_size(arrays)))
        self._y = np.zeros((self.n, 3))

    def solve(self, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out = A^-1 b for b (n, 3)."""
        _sn_solve(b, self.perm_r, self.perm_c, *self.factors, self.work, self._y, out)
        return out

    @functools.cached_property
    def sym_factors(self) -> tuple[np.ndarray, ...]:
        """What `_sym_sweeps` reads: L's values, the runs' triangles with L's values on both sides
        (`mirrored`, made on first use: 0.86 MB on the scanned head) and D; U's (uv) left unread."""
        a = self.arrays
        hit = _MIRRORED.get(id(a["tv"]))  # (the solvers of one face's prepared arrays share one)
        if hit is None or hit[0] is not a["tv"]:
            if len(_MIRRORED) >= 4:
                _MIRRORED.clear()
            hit = _MIRRORED[id(a["tv"])] = (a["tv"], mirrored(a["sn_ptr"], a["t_ptr"], a["tv"]))
        return (a["sn_ptr"], a["r_ptr"], _unsigned(a["r_idx"]), a["v_ptr"], a["lv"], a["t_ptr"], hit[1], a["u_diag"])

    def solve_symmetric(self, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out = A^-1 b for b (n, 3) from L and D alone (`_sym_sweeps`): the same up to rounding."""
        if not self.symmetric:
            raise ValueError("rows and columns permuted differently: no symmetric factor")
        y = self._y
        y[self.perm_r] = b
        _sym_sweeps(y, *self.sym_factors, self.work)
        out[...] = y[self.perm_c]
        return out
