"""Explicit-SIMD inner loop of the back-projection adjoint (private; the maths is in operator.py).

Why this exists: LLVM does not vectorise the gather ``row[i0(u)]`` of the plain numba
kernel (it cannot prove the gathered trace and the accumulator do not alias, and its
cost model for some Intel CPUs avoids gathers), so that loop ran one voxel at a time.
Here the loop over depths is written directly in LLVM vector IR, ``W`` = 16 depths per
step:

* the two legs ``sqrt(h^2 + (depth + height)^2)`` of tx and rx, the time, the clamp,
* ONE gather of 64-bit pairs ``(row[i0], row[i0 + 1])`` (a pair is two neighbouring
  float32 samples, so the pair gather reads the trace itself, with no extra table),
  split into the two neighbours by a shuffle,
* linear interpolation, optional weights, accumulation.

``llvm.masked.gather`` is generic LLVM: it becomes ``vpgatherdq`` on AVX-512/AVX2 and
scalar loads elsewhere, so the code is correct on any CPU numba supports. A variant reads the
pairs with ``W`` scalar loads instead (for CPUs whose hardware gathers are slow). Depths before
the aperture's first depth ``k0`` are masked off (they gather zeros).

The arrays passed in must be padded to a multiple of ``W`` (``depth``, ``slow``,
``acc``), and the trace ``row`` must end with two zero samples (``umax`` = its last
real index + 1 reads ``(0, 0)``).
"""

from __future__ import annotations

W = 16

_STACKS = {}


def _gather_names():
    import llvmlite.binding as llb

    if llb.llvm_version_info[0] >= 17:  # opaque pointers
        return "llvm.masked.gather.v16i64.v16p0"
    return "llvm.masked.gather.v16i64.v16p0i64"


def stack(weights: int, fold: bool = False):
    """The intrinsic ``stack(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather)``.

    Adds, for depth blocks ``k0 // W .. nblk - 1``, ``w * row(u)`` into ``acc`` where
    ``u = (t0 + (ra + rb) * slow) * inv_dt`` and ``ra = sqrt(h2a + (depth + ha)^2)`` (``rb``
    likewise). ``weights``: bit 0 obliquity ``(za/ra + zb/rb) / 2``, bit 1 spreading ``(ra + rb) / 2``.
    ``fold``: the intrinsic takes one more array after ``acc``, ``facc``, and adds into it what a trace of ones
    would give, ``w * clamp(umax - u, 0, 1)`` (the fold, in the same pass).
    ``gather`` (an integer, at run time): non-zero reads the sample pairs with one hardware gather, zero with ``W``
    scalar 64-bit loads put into a vector (for CPUs whose gathers are slow: several AMD generations); the loop is
    emitted once for each, behind one branch.
    """
    key = (weights, fold)
    if key in _STACKS:
        return _STACKS[key]
    from llvmlite import ir
    from numba import types
    from numba.core import cgutils
    from numba.extending import intrinsic

    gather_name = _gather_names()

    def _codegen(context, builder, signature, args):
        na = 5 if fold else 4
        arrays = [context.make_array(signature.args[i])(context, builder, args[i]) for i in range(na)]
        row_p, depth_p, slow_p, acc_p = (a.data for a in arrays[:4])
        facc_p = arrays[4].data if fold else None
        h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather = args[na:]
        f32, i1, i32, i64 = ir.FloatType(), ir.IntType(1), ir.IntType(32), ir.IntType(64)
        vf, vi, vq = ir.VectorType(f32, W), ir.VectorType(i32, W), ir.VectorType(i64, W)
        vmask = ir.VectorType(i1, W)
        vpq = ir.VectorType(i64.as_pointer(), W)
        v2f = ir.VectorType(f32, 2 * W)
        mod = builder.module
        gather_fn = cgutils.get_or_insert_function(mod, ir.FunctionType(vq, [vpq, i32, vmask, vq]), gather_name)
        sqrt = cgutils.get_or_insert_function(mod, ir.FunctionType(vf, [vf]), "llvm.sqrt.v16f32")
        vmax = cgutils.get_or_insert_function(mod, ir.FunctionType(vf, [vf, vf]), "llvm.maxnum.v16f32")
        vmin = cgutils.get_or_insert_function(mod, ir.FunctionType(vf, [vf, vf]), "llvm.minnum.v16f32")
        fast = ("fast",)

        def splat(x, vt):
            v = builder.insert_element(ir.Constant(vt, ir.Undefined), x, ir.Constant(i32, 0))
            return builder.shuffle_vector(v, ir.Constant(vt, ir.Undefined), ir.Constant(vi, [0] * W))

        def vload(ptr, off):
            return builder.load(builder.bitcast(builder.gep(ptr, [off]), vf.as_pointer()), align=4)

        def add(a, b):
            return builder.fadd(a, b, flags=fast)

        def mul(a, b):
            return builder.fmul(a, b, flags=fast)

        h2a_v, h2b_v, ha_v, hb_v, t0_v, idt_v, umax_v = (splat(s, vf) for s in (h2a, h2b, ha, hb, t0, inv_dt,
                                                                                 umax))
        k0_v = splat(builder.trunc(k0, i32), vi)
        lanes = ir.Constant(vi, list(range(W)))
        zero_f = ir.Constant(vf, [0.0] * W)
        zero_q = ir.Constant(vq, [0] * W)
        half = ir.Constant(vf, [0.5] * W)
        align = ir.Constant(i32, 4)
        evens = ir.Constant(vi, list(range(0, 2 * W, 2)))
        odds = ir.Constant(vi, list(range(1, 2 * W, 2)))
        tiny2 = ir.Constant(vf, [1e-24] * W)
        one_f = ir.Constant(vf, [1.0] * W)
        first = builder.udiv(k0, ir.Constant(k0.type, W))

        def depth_loop(use_gather):
            with cgutils.for_range_slice(builder, first, nblk, ir.Constant(k0.type, 1)) as (blk, _):
                off = builder.mul(blk, ir.Constant(blk.type, W))
                d = vload(depth_p, off)
                za, zb = add(d, ha_v), add(d, hb_v)
                # each leg's length r = q / sqrt(q) through its reciprocal 1 / sqrt(q), which LLVM computes with
                # the CPU's reciprocal-square-root estimate and a Newton step under these flags (vrsqrt14ps on
                # AVX-512: a fraction of a full vsqrtps' throughput), and which the obliquity's cosine z / r
                # reuses; q kept off 0 (a voxel exactly at an antenna: r = 1e-12, its cosine 0, not 0/0)
                qa = builder.call(vmax, [add(mul(za, za), h2a_v), tiny2])
                qb = builder.call(vmax, [add(mul(zb, zb), h2b_v), tiny2])
                ia = builder.fdiv(one_f, builder.call(sqrt, [qa], fastmath=fast), flags=fast)
                ib = builder.fdiv(one_f, builder.call(sqrt, [qb], fastmath=fast), flags=fast)
                ra, rb = mul(qa, ia), mul(qb, ib)
                u = mul(add(t0_v, mul(add(ra, rb), vload(slow_p, off))), idt_v)
                u = builder.call(vmin, [builder.call(vmax, [u, zero_f]), umax_v])
                i0 = builder.fptoui(u, vi)
                frac = builder.fsub(u, builder.uitofp(i0, vf), flags=fast)
                depth_index = builder.add(splat(builder.trunc(off, i32), vi), lanes)
                live = builder.icmp_unsigned(">=", depth_index, k0_v)
                if use_gather:
                    ptrs = builder.gep(row_p, [i0], source_etype=f32)
                    ptrs.type = ir.VectorType(f32.as_pointer(), W)  # llvmlite types a vector GEP as a scalar pointer
                    pairs = builder.call(gather_fn, [builder.bitcast(ptrs, vpq), align, live, zero_q])
                else:  # W scalar loads: every index is inside the padded row (u is clamped), so none needs the mask
                    pairs = zero_q
                    for lane in range(W):
                        at = builder.extract_element(i0, ir.Constant(i32, lane))
                        p = builder.bitcast(builder.gep(row_p, [at]), i64.as_pointer())
                        pairs = builder.insert_element(pairs, builder.load(p, align=4), ir.Constant(i32, lane))
                    pairs = builder.select(live, pairs, zero_q)
                pairs = builder.bitcast(pairs, v2f)
                g0 = builder.shuffle_vector(pairs, ir.Constant(v2f, ir.Undefined), evens)
                g1 = builder.shuffle_vector(pairs, ir.Constant(v2f, ir.Undefined), odds)
                val = add(g0, mul(frac, builder.fsub(g1, g0, flags=fast)))
                w = None
                if weights & 1:
                    w = mul(half, add(mul(za, ia), mul(zb, ib)))
                if weights & 2:
                    ws = mul(half, add(ra, rb))
                    w = ws if w is None else mul(w, ws)
                if w is not None:
                    val = mul(val, w)
                acc_ptr = builder.bitcast(builder.gep(acc_p, [off]), vf.as_pointer())
                builder.store(add(builder.load(acc_ptr, align=4), val), acc_ptr, align=4)
                if fold:  # a trace of ones read at u: 1 inside the record, 1 - frac on the last sample, 0 past it
                    ones = builder.call(vmin, [builder.call(vmax, [builder.fsub(umax_v, u, flags=fast), zero_f]),
                                               ir.Constant(vf, [1.0] * W)])
                    ones = builder.select(live, ones, zero_f)
                    if w is not None:
                        ones = mul(ones, w)
                    f_ptr = builder.bitcast(builder.gep(facc_p, [off]), vf.as_pointer())
                    builder.store(add(builder.load(f_ptr, align=4), ones), f_ptr, align=4)

        with builder.if_else(builder.icmp_signed("!=", gather, ir.Constant(gather.type, 0))) as (hw, loads):
            with hw:
                depth_loop(True)
            with loads:
                depth_loop(False)
        return context.get_dummy_value()

    if fold:
        @intrinsic
        def _stack(typingctx, row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather):
            return (types.void(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather),
                    _codegen)
    else:
        @intrinsic
        def _stack(typingctx, row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather):
            return types.void(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather), _codegen

    _STACKS[key] = _stack
    return _stack
