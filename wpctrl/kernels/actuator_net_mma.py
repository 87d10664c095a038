"""The MLP actuator network on tensor cores at float32 accuracy (3xTF32): each layer a warp-wide matrix product.

Private module (see :mod:`.actuator_net`). Tensor cores multiply in TF32 (a 10-bit mantissa). This kernel keeps
float32 accuracy the way CUTLASS's "3xTF32" does: each operand ``v`` is split into ``hi = tf32(v)`` and a remainder
``lo = tf32(v - hi)``, and each product is ``lo_a*hi_b + hi_a*lo_b + hi_a*hi_b`` accumulated in float32 (the dropped
``lo*lo`` is ~2^-22 of the product): three ``mma.sync.m16n8k8`` instructions where TF32 takes one. The weights are
split on the host (rounded to nearest, ties away, as ``cvt.rna.tf32``); an activation's ``hi`` is rounded the same
way in two integer instructions and its remainder truncated to TF32.

One warp evaluates 32 rows, two 16-row tiles; each lane owns one row. It gathers the row and advances its history
with the unrolled kernel's code (:func:`.actuator_net_unrolled.mlp_row_input`), writes the row's inputs to the warp's
slice of shared memory and reads its fragments of both tiles back. From there the activations stay in registers: a
layer's accumulator fragment is the next layer's operand fragment, because the weights' input order is permuted on
the host to match (a lane holds output units ``2t`` and ``2t + 1`` of each 8-unit tile, and reads operand columns
``t`` and ``t + 4``: column ``t`` of tile ``k`` stands for unit ``8k + 2t``, column ``t + 4`` for unit
``8k + 2t + 1``). The weights are data: per layer, tile and lane a float4 ``(b0_hi, b1_hi, b0_lo, b1_lo)`` read
through the read-only cache, the biases a float2 per lane (:func:`pack`). The output unit is a float32 dot product
per lane over its share of the last hidden layer, summed over the lane's group of four by two shuffles; the row's
owner then scales, clamps and writes ``joint_f`` as the unrolled kernel does. Layer widths are padded to multiples of
8 with zero weights.

What it is worth, measured on an H100 (``docs/performance.md``): through ``mma.sync`` one float32-accurate
multiply-add (three TF32 products) costs about what an FP32 fused multiply-add costs, so for an actuator-sized MLP
this kernel is no faster than the unrolled one (whose weights are instruction operands); for an MLP too large to
compile in it is 5-7x faster than the tiled kernel, and ``kernel="auto"`` runs it there.

Compiled per network shape (the weights are arguments). CUDA needs sm_80 or later (TF32 ``mma``). On the CPU the
same snippet evaluates each row alone with the same splits and roundings and the same packed weights, so the packing
and the split are tested there; the warp-level data movement runs only on a GPU.
"""

from __future__ import annotations

import hashlib

import numpy as np
import warp as wp

from .actuator_net import (
    ACT_ELU,
    ACT_LEAKY,
    ACT_RELU,
    ACT_SIGMOID,
    ACT_SOFTSIGN,
    ACT_TANH,
    NetIO,
    NetLayout,
    dense_matrices,
    net_kernel,
    read_row,
    write_effort,
)
from .actuator_net_unrolled import _scaled, mlp_row_input

wp.set_module_options({"enable_backward": False})

BLOCK_DIM = 64
"""CUDA threads per block: two warps, each with its own slice of the block's shared memory for the row inputs."""

_KERNELS: dict[tuple, wp.Kernel] = {}


def _pad8(n: int) -> int:
    return -(-int(n) // 8) * 8


def tf32(a: np.ndarray) -> np.ndarray:
    """``a`` (float32) rounded to TF32 as ``cvt.rna.tf32.f32`` does: the 13 low mantissa bits dropped, round to
    nearest, ties away from zero (an increment of the magnitude's bit pattern)."""
    u = np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)
    return ((u + np.uint32(0x1000)) & np.uint32(0xFFFFE000)).view(np.float32)


def pack(layout: NetLayout, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The weights as the kernel reads them: ``(wfrag (tiles, 32, 4), bfrag (bias tiles, 32, 2))`` float32.

    Layer ``l`` of ``out x in`` weights, padded to ``NP x KP`` (multiples of 8), is ``KP/8 x NP/8`` tiles ``(k, n)``,
    in that order after the previous layers'. Lane ``4g + t`` of tile ``(k, n)`` holds the hi and lo TF32 parts of
    ``W[8n + g, 8k + 2t]`` and ``W[8n + g, 8k + 2t + 1]`` (the ``b0`` / ``b1`` operands of ``mma.m16n8k8``, whose
    ``k`` index ``t`` / ``t + 4`` stands for input ``8k + 2t`` / ``8k + 2t + 1``); its bias tile ``n`` holds
    ``b[8n + 2t]`` and ``b[8n + 2t + 1]`` (the accumulator's columns ``2t``, ``2t + 1``)."""
    wf, bf = [], []
    lane = np.arange(32)
    g, t = lane // 4, lane % 4
    layers = dense_matrices(layout, np.asarray(weights, np.float32))
    for li, (w, b, _, _) in enumerate(layers):
        n_out, n_in = w.shape
        KP, NP = _pad8(n_in), _pad8(n_out)
        wp_ = np.zeros((NP, KP), np.float32)
        wp_[:n_out, :n_in] = w
        bp = np.zeros(NP, np.float32)
        bp[:n_out] = b
        if li == len(layers) - 1:  # the output unit: float32 weights for the lanes' dot products
            c0 = 8 * np.arange(KP // 8)[:, None] + 2 * t
            wf.append(np.stack([wp_[0, c0], wp_[0, c0 + 1], 0 * c0, 0 * c0], -1).astype(np.float32))
            bf.append(np.stack([np.full(32, bp[0]), np.zeros(32)], -1)[None].astype(np.float32))
            break
        hi = tf32(wp_)
        lo = tf32(wp_ - hi)
        kt, nt = np.meshgrid(np.arange(KP // 8), np.arange(NP // 8), indexing="ij")
        rows = 8 * nt[..., None] + g  # (KT, NT, 32)
        c0 = 8 * kt[..., None] + 2 * t
        wf.append(np.stack([hi[rows, c0], hi[rows, c0 + 1], lo[rows, c0], lo[rows, c0 + 1]], -1).reshape(-1, 32, 4))
        u = 8 * np.arange(NP // 8)[:, None] + 2 * t
        bf.append(np.stack([bp[u], bp[u + 1]], -1))
    return np.concatenate(wf).astype(np.float32), np.concatenate(bf).astype(np.float32)


def mma_kernel(layout: NetLayout, scales: tuple[float, float, float]) -> wp.Kernel:
    """The kernel of ``layout`` (an MLP: :func:`.actuator_net.mma_unsupported`) with ``scales`` (``pos_scale``,
    ``vel_scale``, ``torque_scale``) compiled in; the weights are its ``wfrag`` / ``bfrag`` arguments (:func:`pack`).
    Launched over :func:`launch_dim` threads with ``block_dim = BLOCK_DIM``."""
    scales = tuple(float(np.float32(x)) for x in scales)
    key = (layout, scales)
    k = _KERNELS.get(key)
    if k is None:
        k = _KERNELS[key] = _make(layout, scales)
    return k


def launch_dim(num_rows: int) -> int:
    """Threads of a launch over ``num_rows`` rows: whole warps (a warp's ``mma`` needs all 32 lanes)."""
    return -(-int(num_rows) // 32) * 32


# -- the network as a native snippet: the CUDA branch (warp-wide) and the CPU branch (one row) ----------------------


def _f(x: float) -> str:
    return f"{float(np.float32(x))!r}f"


_ACT_CPP = {
    ACT_RELU: "({v} > 0.0f ? {v} : 0.0f)",
    ACT_ELU: "({v} > 0.0f ? {v} : {a} * (wp::exp({v}) - 1.0f))",
    ACT_TANH: "(1.0f - 2.0f / (wp::exp(2.0f * {v}) + 1.0f))",
    ACT_SIGMOID: "(1.0f / (1.0f + wp::exp(-{v})))",
    ACT_SOFTSIGN: "({v} / (1.0f + wp::abs({v})))",
    ACT_LEAKY: "({v} > 0.0f ? {v} : {a} * {v})",
}
"""C++ of each activation code (:mod:`.actuator_net`'s, the same formulas as its ``activate``); identity: absent."""


def _act(v: str, code: int, a: float) -> str:
    """C++ of activation ``code`` of ``v`` (:data:`_ACT_CPP`)."""
    return _ACT_CPP.get(code, "{v}").format(v=v, a=_f(a))


def _snippet(layout: NetLayout, tag: str) -> str:
    """The network's native code: on CUDA the warp's 32 rows as two 16-row tiles through every layer (the two tiles'
    products interleaved), on the CPU one row."""
    dims = [(_pad8(d[0]), _pad8(d[1]), int(d[2]), float(d[3])) for d in layout.dense]
    K0 = dims[0][0]
    warps = BLOCK_DIM // 32
    cu = [
        "__syncwarp();",
        "const int lane = threadIdx.x & 31, g = lane >> 2, t = lane & 3;",
        f"__shared__ float xs_{tag}[{warps}][32][{K0 + 1}];",
        f"typedef float xrow_t[{K0 + 1}];",
        f"xrow_t* xw = xs_{tag}[threadIdx.x >> 5];",
        "const int own = 16 * (t >> 1) + g + 8 * (t & 1);  // this lane's row in the warp's 32",
        f"#pragma unroll\nfor (int k = 0; k < {K0}; ++k) xw[own][k] = x.c[k];",
        "__syncwarp();",
        f"float a0[2][{K0 // 8}][4];",
        f"#pragma unroll\nfor (int m = 0; m < 2; ++m)\n#pragma unroll\nfor (int k = 0; k < {K0 // 8}; ++k) {{",
        "  const int r = 16 * m + g;",
        "  a0[m][k][0] = xw[r][8 * k + 2 * t]; a0[m][k][1] = xw[r + 8][8 * k + 2 * t];",
        "  a0[m][k][2] = xw[r][8 * k + 2 * t + 1]; a0[m][k][3] = xw[r + 8][8 * k + 2 * t + 1];",
        "}",
        "const float4* wf = reinterpret_cast<const float4*>(wfrag.data);",
        "const float2* bf = reinterpret_cast<const float2*>(bfrag.data);",
        "auto mma = [](float* d, const unsigned* a, unsigned b0, unsigned b1) {",
        '  asm("mma.sync.aligned.m16n8k8.row.col.f32.tf32.tf32.f32 {%0,%1,%2,%3}, {%4,%5,%6,%7}, {%8,%9}, '
        '{%0,%1,%2,%3};"',
        '      : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3])',
        '      : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b0), "r"(b1));',
        "};",
        # hi: v rounded to TF32 (nearest, ties away: cvt.rna's result for finite v, in two integer instructions
        # where cvt.rna.tf32 is four); lo: the rest, truncated to TF32 (~2^-23 of v lost)
        "auto split = [](float v, unsigned& h, unsigned& l) {",
        "  h = (__float_as_uint(v) + 0x1000u) & 0xffffe000u;",
        "  l = __float_as_uint(v - __uint_as_float(h)) & 0xffffe000u;",
        "};",
    ]
    cpu = [
        "auto bits = [](float v, unsigned add) -> float {",
        "  unsigned u; __builtin_memcpy(&u, &v, 4); u = (u + add) & 0xffffe000u;",
        "  float r; __builtin_memcpy(&r, &u, 4); return r;",
        "};",
        f"float v0[{K0}];",
        f"for (int k = 0; k < {K0}; ++k) v0[k] = x.c[k];",
    ]
    woff = boff = 0
    last = len(dims)
    for li, (KP, NP, code, a) in enumerate(dims, start=1):
        KT, NT = KP // 8, NP // 8
        p = li - 1
        if li == last:
            break
        cu += [
            f"float c{li}[2][{NT}][4];",
            f"#pragma unroll\nfor (int n = 0; n < {NT}; ++n) {{",
            f"  const float2 b = __ldg(bf + ({boff} + n) * 32 + lane);",
            f"  #pragma unroll\n  for (int m = 0; m < 2; ++m) {{ c{li}[m][n][0] = b.x; c{li}[m][n][1] = b.y; "
            f"c{li}[m][n][2] = b.x; c{li}[m][n][3] = b.y; }}",
            "}",
            f"#pragma unroll\nfor (int k = 0; k < {KT}; ++k) {{",
            "  unsigned hi[2][4], lo[2][4];",
            "  #pragma unroll\n  for (int m = 0; m < 2; ++m)\n  #pragma unroll\n  for (int i = 0; i < 4; ++i) "
            f"split(a{p}[m][k][i], hi[m][i], lo[m][i]);",
            f"  #pragma unroll\n  for (int n = 0; n < {NT}; ++n) {{",
            f"    const float4 w = __ldg(wf + ({woff} + k * {NT} + n) * 32 + lane);",
            "    const unsigned h0 = __float_as_uint(w.x), h1 = __float_as_uint(w.y);",
            "    const unsigned l0 = __float_as_uint(w.z), l1 = __float_as_uint(w.w);",
            "    #pragma unroll\n    for (int m = 0; m < 2; ++m) {",
            f"      mma(c{li}[m][n], lo[m], h0, h1); mma(c{li}[m][n], hi[m], l0, l1); mma(c{li}[m][n], hi[m], h0, h1);",
            "    }",
            "  }",
            "}",
            # the accumulator (rows g, g+8; units 2t, 2t+1) is the next operand (cols t, t+4 = units 2t, 2t+1)
            f"float a{li}[2][{NT}][4];",
            f"#pragma unroll\nfor (int m = 0; m < 2; ++m)\n#pragma unroll\nfor (int n = 0; n < {NT}; ++n) {{",
            "  float v;",
            f"  v = c{li}[m][n][0]; a{li}[m][n][0] = {_act('v', code, a)};",
            f"  v = c{li}[m][n][2]; a{li}[m][n][1] = {_act('v', code, a)};",
            f"  v = c{li}[m][n][1]; a{li}[m][n][2] = {_act('v', code, a)};",
            f"  v = c{li}[m][n][3]; a{li}[m][n][3] = {_act('v', code, a)};",
            "}",
        ]
        cpu += [
            f"float v{li}[{NP}];",
            f"for (int n = 0; n < {NP}; ++n) {{",
            f"  float acc = bfrag.data[({boff} + (n >> 3)) * 32 + ((n & 7) >> 1)].c[n & 1];",
            f"  for (int k = 0; k < {KT}; ++k) for (int tt = 0; tt < 4; ++tt) {{",
            f"    const wp::vec_t<4, float> w = wfrag.data[({woff} + k * {NT} + (n >> 3)) * 32 + 4 * (n & 7) + tt];",
            f"    const float x0 = v{p}[8 * k + 2 * tt], x1 = v{p}[8 * k + 2 * tt + 1];",
            "    const float h0 = bits(x0, 0x1000u), l0 = bits(x0 - h0, 0u);",
            "    const float h1 = bits(x1, 0x1000u), l1 = bits(x1 - h1, 0u);",
            "    acc += l0 * w.c[0]; acc += h0 * w.c[2]; acc += h0 * w.c[0];",
            "    acc += l1 * w.c[1]; acc += h1 * w.c[3]; acc += h1 * w.c[1];",
            "  }",
            f"  float v = acc; v{li}[n] = {_act('v', code, a)};",
            "}",
        ]
        woff += KT * NT
        boff += NT
    # The output unit: each lane's dot product over its inputs (8k + 2t, 8k + 2t + 1) of rows g and g + 8 of both
    # tiles, summed over the group's four lanes (t) by two butterfly shuffles; every lane of group g then holds its
    # four rows' sums, and the owner of row 16m + g + 8h (lane 4g + 2m + h) takes its own.
    p = last - 1
    cu += [
        "float y[2][2] = {{0.0f, 0.0f}, {0.0f, 0.0f}};",
        f"#pragma unroll\nfor (int k = 0; k < {KT}; ++k) {{",
        f"  const float4 w = __ldg(wf + ({woff} + k) * 32 + lane);",
        "  #pragma unroll\n  for (int m = 0; m < 2; ++m) {",
        f"    y[m][0] = fmaf(a{p}[m][k][0], w.x, y[m][0]); y[m][0] = fmaf(a{p}[m][k][2], w.y, y[m][0]);",
        f"    y[m][1] = fmaf(a{p}[m][k][1], w.x, y[m][1]); y[m][1] = fmaf(a{p}[m][k][3], w.y, y[m][1]);",
        "  }",
        "}",
        "#pragma unroll\nfor (int m = 0; m < 2; ++m)\n#pragma unroll\nfor (int h = 0; h < 2; ++h) {",
        "  y[m][h] += __shfl_xor_sync(0xffffffffu, y[m][h], 1);",
        "  y[m][h] += __shfl_xor_sync(0xffffffffu, y[m][h], 2);",
        "}",
        "float v = (t >> 1) ? ((t & 1) ? y[1][1] : y[1][0]) : ((t & 1) ? y[0][1] : y[0][0]);",
        f"v += __ldg(bf + {boff} * 32 + lane).x;",
        f"return {_act('v', code, a)};",
    ]
    cpu += [
        "float acc = 0.0f;",
        f"for (int k = 0; k < {KT}; ++k) for (int tt = 0; tt < 4; ++tt) {{",
        f"  const wp::vec_t<4, float> w = wfrag.data[({woff} + k) * 32 + tt];",
        f"  acc += v{p}[8 * k + 2 * tt] * w.c[0]; acc += v{p}[8 * k + 2 * tt + 1] * w.c[1];",
        "}",
        f"float v = acc + bfrag.data[{boff} * 32].c[0];",
        f"return {_act('v', code, a)};",
    ]
    return "#if defined(__CUDA_ARCH__)\n" + "\n".join(cu) + "\n#else\n" + "\n".join(cpu) + "\n#endif\n"


class _Native:
    """``wp.func_native`` under a name of our choosing. Warp registers a snippet's function under its qualified name
    (one per network shape here, not the stub's ``_make.<locals>.net_fn``), and reads the return type only from a
    decorator spelled ``<...>.func_native(...)``."""

    @staticmethod
    def func_native(snippet: str, name: str, vec_x):
        def decorate(f):
            f.__qualname__ = f.__name__ = name
            f.__annotations__ = {"x": vec_x, "wfrag": wp.array[wp.vec4], "bfrag": wp.array[wp.vec2], "return": float}
            return wp.func_native(snippet)(f)

        return decorate


def _make(L: NetLayout, scales: tuple[float, float, float]) -> wp.Kernel:
    N = L.rows
    PS, VS, TS = scales
    K0 = _pad8(L.dense[0][0])
    vec_x = wp.types.vector(length=K0, dtype=wp.float32)
    vec_p = wp.types.vector(length=max(2 * L.past, 1), dtype=wp.float32)
    mlp_x = mlp_row_input(L, (PS, VS), vec_x)
    digest = hashlib.sha256(repr((L, scales, BLOCK_DIM)).encode()).hexdigest()[:16]

    @_Native.func_native(_snippet(L, digest), "wpctrl_actuator_net_mma_" + digest, vec_x)
    def net_fn(x: vec_x, wfrag: wp.array[wp.vec4], bfrag: wp.array[wp.vec2]) -> float: ...

    def net(
        row0: int,  # the network's rows: row0 .. row0 + n in the mode's tables
        num_rows: int,  # num_envs * n (the launch is whole warps: launch_dim)
        io: NetIO,
        wfrag: wp.array[wp.vec4],  # the packed weights (pack)
        bfrag: wp.array[wp.vec2],
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],
        # In/out: the MLP's past samples per row (position errors, then velocities, newest first):
        hist_out: wp.array[vec_p],
        # Out:
        joint_f_out: wp.array[float],
    ):
        i = wp.tid()
        lane = i % 32
        g = lane // 4
        t = lane % 4
        # the lane's row: the one whose output its fragments hand it (row 16m + g + 8h of the warp's 32 is lane
        # 4g + 2m + h's)
        s = i - lane + 16 * (t // 2) + g + 8 * (t % 2)
        env = s // wp.static(N)
        j = s - env * wp.static(N)
        r = row0 + j
        x = vec_x()
        di = int(0)
        qd = float(0.0)
        lim = float(0.0)
        sat = float(0.0)
        vl = float(0.0)
        if s < num_rows:
            qi, di, q, qd, lim, sat, vl = read_row(io, wp.static(L.q_lin), wp.static(L.qd_lin), env, r, j,
                                                     joint_q_in, joint_qd_in)  # fmt: skip
            x = mlp_x(s, joint_target_q_in[qi] - q, qd, hist_out)
        y = net_fn(x, wfrag, bfrag)  # every lane of the warp, rows past the end with zero inputs
        if s < num_rows:
            write_effort(_scaled(y, wp.static(TS)), qd, env, r, di, lim, sat, vl, joint_f_out, io)

    net.__annotations__["hist_out"] = wp.array[vec_p]
    return net_kernel(net, "wpctrl_actuator_net_mma", grid_stride=False)
