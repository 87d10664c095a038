"""The one Cholesky of the kernels: symmetric positive definite systems of a size fixed at compile time.

Private module. :func:`factorisation` compiles ``M = L L^T`` and its solve for a size and scalar type, every loop
unrolled so the matrices stay in registers on CUDA, with one of two pivot rules. The EE kernels' small systems
(``J J^T + λ I``, ``J^T J + λ I``: :mod:`.ee_math`, through :func:`spd_solve`) take IEEE square roots and
divisions in float32. The articulation's n x n joint-space inertia and the controlled rows' block of its inverse
(:func:`cholesky_funcs`, for :mod:`.inertia_unrolled`, :mod:`.coupled_drive`, :mod:`wpctrl.impedance.warp_kernels`)
take float64 pivots floored as in Newton's ``JointSpaceResponse``, from a refined float32 reciprocal square root: no
IEEE float64 division or square root, whose slow-path branches serialise a one-thread-per-env kernel.
"""

import warp as wp

from .spatial import _FLOAT32_EPS

wp.set_module_options({"enable_backward": False})


@wp.func
def _rsqrt(x: wp.float64):
    """1 / sqrt(x) in float64 for a positive normal x without the IEEE square root's and division's slow paths: a
    float32 estimate refined by two Newton steps (relative error ~1e-7, then ~1e-14, then rounding)."""
    y = wp.float64(1.0 / wp.sqrt(wp.float32(x)))
    h = wp.float64(0.5) * x
    y = y * (wp.float64(1.5) - h * y * y)
    return y * (wp.float64(1.5) - h * y * y)


_cache: dict[tuple, tuple] = {}
_factor_cache: dict[tuple, tuple] = {}
_solve_cache: dict[tuple, wp.Function] = {}


def factorisation(n: int, dtype=wp.float64, ieee: bool = False) -> tuple:
    """``(factor, solve)``, the one Cholesky of the kernels, for an n x n symmetric positive definite matrix of
    ``dtype``, every loop unrolled:

    - ``factor(M)``: ``M = L L^T`` (L in M's lower triangle, in place; the upper one is left as it was); returns L and
      the pivots' reciprocals;
    - ``solve(L, inv, x)``: ``(L L^T)^-1 x``.

    Two pivot rules: ``ieee`` (the EE solves, float32): ``sqrt(max(s, 1e-30))`` and divisions by the pivot; else
    (the joint-space inertia, float64 only): pivots floored at float32's epsilon relative to the diagonal, as Newton's
    ``JointSpaceResponse`` floors them, and multiplications by a refined reciprocal square root.
    """
    key = (n, dtype, ieee)
    if key in _factor_cache:
        return _factor_cache[key]
    if not ieee and dtype is not wp.float64:
        raise TypeError("the refined reciprocal square root pivots are float64 only")
    N = n
    Mat = wp.types.matrix(shape=(n, n), dtype=dtype)
    Vec = wp.types.vector(length=n, dtype=dtype)
    floor = dtype(1.0e-30)
    eps32 = dtype(_FLOAT32_EPS)
    one = dtype(1.0)

    @wp.func
    def factor(M: Mat):
        inv = Vec()
        for jc in range(wp.static(N)):
            s = M[jc, jc]
            for k in range(wp.static(jc)):
                s -= M[jc, k] * M[jc, k]
            if wp.static(ieee):
                M[jc, jc] = wp.sqrt(wp.max(s, floor))
                inv[jc] = one / M[jc, jc]
            else:
                s = wp.max(s, eps32 * wp.max(wp.abs(M[jc, jc]), one))
                y = _rsqrt(s)
                M[jc, jc] = s * y
                inv[jc] = y
            for i in range(wp.static(jc + 1), wp.static(N)):
                t = M[i, jc]
                for k in range(wp.static(jc)):
                    t -= M[i, k] * M[jc, k]
                if wp.static(ieee):
                    M[i, jc] = t / M[jc, jc]
                else:
                    M[i, jc] = t * inv[jc]
        return M, inv

    @wp.func
    def solve(L: Mat, inv: Vec, x: Vec):
        y = Vec()
        for i in range(wp.static(N)):
            t = x[i]
            for k in range(wp.static(i)):
                t -= L[i, k] * y[k]
            if wp.static(ieee):
                y[i] = t / L[i, i]
            else:
                y[i] = t * inv[i]
        z = Vec()
        for ii in range(wp.static(N)):
            i = wp.static(N - 1 - ii)
            t = y[i]
            for k in range(wp.static(i + 1), wp.static(N)):
                t -= L[k, i] * z[k]
            if wp.static(ieee):
                z[i] = t / L[i, i]
            else:
                z[i] = t * inv[i]
        return z

    _factor_cache[key] = (factor, solve)
    return factor, solve


def spd_solve(n: int, dtype=wp.float32) -> wp.Function:
    """``solve(a, b)``: x with ``a x = b`` for a symmetric positive definite n x n ``a`` of ``dtype``
    (:func:`factorisation` with IEEE pivots)."""
    key = (n, dtype)
    if key in _solve_cache:
        return _solve_cache[key]
    factor, solve_l = factorisation(n, dtype, ieee=True)
    Mat = wp.types.matrix(shape=(n, n), dtype=dtype)
    Vec = wp.types.vector(length=n, dtype=dtype)

    @wp.func
    def solve(a: Mat, b: Vec):
        lo, inv = factor(a)
        return solve_l(lo, inv, b)

    _solve_cache[key] = solve
    return solve


def cholesky_funcs(n: int, row_dof: tuple) -> tuple:
    """``(factor, solve, inverse_block, inverse_diag)`` for n DOFs and the controlled rows at the DOFs ``row_dof``:

    - ``factor(M)``, ``solve(L, inv, x)``: :func:`factorisation` in float64;
    - ``inverse_block(H)``: ``A = S H^-1 S^T`` (rows x rows), H's lower triangle read;
    - ``inverse_diag(H)``: the same with only its diagonal filled.
    """
    ROWD = tuple(int(d) for d in row_dof)
    key = (n, ROWD)
    if key in _cache:
        return _cache[key]
    N, NR = n, len(ROWD)
    MatN = wp.types.matrix(shape=(n, n), dtype=wp.float64)
    MatRN = wp.types.matrix(shape=(NR, n), dtype=wp.float64)
    MatR = wp.types.matrix(shape=(NR, NR), dtype=wp.float64)
    factor, solve = factorisation(n, wp.float64)

    @wp.func
    def rows_y(H: MatN):
        """``Y`` with row r = ``L^-1 e_{d_r}`` (forward substitution from row d_r; the entries above it are 0), so
        that ``A_rc = y_r . y_c``."""
        L, inv = factor(H)
        Y = MatRN()
        for r in range(wp.static(NR)):
            for i in range(wp.static(ROWD[r]), wp.static(N)):
                t = wp.float64(0.0)
                if wp.static(i == ROWD[r]):
                    t = wp.float64(1.0)
                for k in range(wp.static(ROWD[r]), wp.static(i)):
                    t -= L[i, k] * Y[r, k]
                Y[r, i] = t * inv[i]
        return Y

    def inverse(diagonal_only: bool):
        @wp.func
        def rows_inverse(H: MatN):
            Y = rows_y(H)
            A = MatR()
            for r in range(wp.static(NR)):
                for c in range(wp.static(r if diagonal_only else 0), wp.static(r + 1)):
                    v = wp.float64(0.0)
                    for k in range(wp.static(max(ROWD[r], ROWD[c])), wp.static(N)):
                        v += Y[r, k] * Y[c, k]
                    A[r, c] = v
                    A[c, r] = v
            return A

        return rows_inverse

    inverse_block, inverse_diag = inverse(False), inverse(True)
    out = (factor, solve, inverse_block, inverse_diag)
    _cache[key] = out
    return out
