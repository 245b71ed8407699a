"""Numba kernels behind :mod:`gyroarray.estimators.bound` (private).

The time-varying Kalman filter and the Rauch–Tung–Striebel smoother on the
array state x = [ω_b (p); b (N)] (D = p + N), for the model of
:func:`~gyroarray.estimators.kalman.state_model` with bias states:

    x_k = x_{k-1} + w_k,  cov w = Q           (F = I: random walks)
    z_k = H1 x_k + v_k,   cov v = R,  H1 = [H  I_N]

Two kernels, one sequential pass each (fixed operation order, no threads:
the same inputs give the same bits):

* :func:`forward` — the textbook predict/update of ``kalman.kf_step``
  with its Joseph covariance update (expanded, see :func:`forward`), S⁻¹
  applied through a Cholesky factor instead of numpy's LU solve, and the
  Cholesky factor of each one-step prediction P_{k+1|k} = P_k + Q stored
  packed (the lower triangle row by row, D(D+1)/2 doubles per sample).
  The results differ from ``kf_step``'s by rounding only.
* :func:`backward` — the RTS pass. The smoother gain is
  C_k = P_k F' (F P_k F' + Q)⁻¹ = P_k P_{k+1|k}⁻¹ = I − Q P_{k+1|k}⁻¹ (F = I),
  so x_s,k = x_k + C_k (x_s,k+1 − x_k) is evaluated as

      x_s,k = x_s,k+1 − Q P_{k+1|k}⁻¹ (x_s,k+1 − x_k)

  with one pair of triangular solves on the stored factor: C_k itself is
  never formed nor stored.

The D×D and D×N products are axpy loops over the contiguous index
(``y[j] += c * x[j]``) and the Cholesky steps plain dot loops, all in a
fixed order: no sum is reassociated (no fastmath), so LLVM vectorises only
what keeps IEEE semantics. The sizes are run-time values (one compiled
kernel for every N). Nothing here validates its input:
:mod:`gyroarray.estimators.bound` does.
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.jit import njit


@njit(cache=True, error_model="numpy")
def _cholesky_packed(L, n, rdiag):  # pragma: no cover - compiled
    """In-place Cholesky factorisation A = L Lᵀ of a symmetric positive
    definite n×n matrix held as its packed lower triangle ``L``
    (L[i(i+1)/2 + j] = A_ij, j <= i); the factor overwrites it.

    Row by row (Cholesky–Banachiewicz): each entry is one contiguous dot
    product of two rows already computed, a plain scalar loop (measured 2×
    faster at n = 8–11 than the outer-product order, whose short in-place
    updates the vectoriser guards with overlap checks). ``rdiag[j]`` gets
    1/L_jj. Returns False on a pivot that is not > 0 (or NaN): A is not
    positive definite.
    """
    for i in range(n):
        ri = i * (i + 1) // 2
        for j in range(i):
            rj = j * (j + 1) // 2
            s = L[ri + j]
            for m in range(j):
                s -= L[ri + m] * L[rj + m]
            L[ri + j] = s * rdiag[j]                                 # L_ij = (A_ij − Σ L_im L_jm)/L_jj
        s = L[ri + i]
        for m in range(i):
            s -= L[ri + m] * L[ri + m]
        if not s > 0.0:
            return False
        lii = np.sqrt(s)
        L[ri + i] = lii                                              # L_ii = √(A_ii − Σ L_im²)
        rdiag[i] = 1.0 / lii
    return True


@njit(cache=True, error_model="numpy")
def _cholesky_solve_packed(L, n, rdiag, v):  # pragma: no cover - compiled
    """Solve L Lᵀ w = v in place (``v`` becomes w), L the packed lower factor
    of :func:`_cholesky_packed` and ``rdiag`` its reciprocal diagonal."""
    for i in range(n):                                               # L y = v (row dot)
        ri = i * (i + 1) // 2
        s = v[i]
        for m in range(i):
            s -= L[ri + m] * v[m]
        v[i] = s * rdiag[i]
    for i in range(n - 1, -1, -1):                                   # Lᵀ w = y (row sweep)
        ri = i * (i + 1) // 2
        w = v[i] * rdiag[i]
        v[i] = w
        for m in range(i):
            v[m] -= L[ri + m] * w


@njit(cache=True, error_model="numpy")
def _innovation(Pp, Hr, R, p, Ut, S, Sf):      # pragma: no cover - compiled
    """U' = H P and S = H P H' + R for H = [Hr I] (S full and packed in ``Sf``)."""
    N, D = Ut.shape
    # U' = H P, H = [Hr I]
    for m in range(N):
        for j in range(D):
            Ut[m, j] = Pp[p + m, j]
        for c_ in range(p):
            c = Hr[m, c_]
            for j in range(D):
                Ut[m, j] += c * Pp[c_, j]
    # S = H P H' + R (symmetric: lower triangle, mirrored)
    t = 0
    for i in range(N):
        for m in range(i + 1):
            s = Ut[m, p + i] + R[i, m]
            for c_ in range(p):
                s += Hr[i, c_] * Ut[m, c_]
            S[i, m] = s                                              # S = H P H' + R
            S[m, i] = s
            Sf[t] = s
            t += 1


@njit(cache=True, error_model="numpy")
def _gain(Ut, Sf, rs, Kt):      # pragma: no cover - compiled
    """K' = S⁻¹ U' from the packed factor Ls of S (``rs`` its inverse diagonal)."""
    N, D = Ut.shape
    # K' = S⁻¹ U': Ls Y = U', then Lsᵀ K' = Y, on the D columns at once
    for i in range(N):
        ri = i * (i + 1) // 2
        for j in range(D):
            Kt[i, j] = Ut[i, j]
        for m in range(i):
            c = Sf[ri + m]
            for j in range(D):
                Kt[i, j] -= c * Kt[m, j]
        r = rs[i]
        for j in range(D):
            Kt[i, j] *= r
    for i in range(N - 1, -1, -1):
        ri = i * (i + 1) // 2
        r = rs[i]
        for j in range(D):
            Kt[i, j] *= r
        for m in range(i):
            c = Sf[ri + m]
            for j in range(D):
                Kt[m, j] -= c * Kt[i, j]                             # K = P H' S⁻¹


@njit(cache=True, error_model="numpy")
def _joseph(P, Pp, Ut, Kt, S, Gt):      # pragma: no cover - compiled
    """Joseph update of P in place from the predicted ``Pp`` (see :func:`forward`)."""
    N, D = Ut.shape
    # Joseph form: P = (I−KH) P (I−KH)' + K R K' = P − K U' − G K'
    for m in range(N):
        for j in range(D):
            Gt[m, j] = Ut[m, j]
        for q in range(N):
            c = S[m, q]
            for j in range(D):
                Gt[m, j] -= c * Kt[q, j]                             # G = U − K S = (I−KH)P H' − K R
    for i in range(D):
        for j in range(i + 1):
            P[i, j] = Pp[i, j]
        for m in range(N):
            c1 = Kt[m, i]
            c2 = Gt[m, i]
            for j in range(i + 1):
                P[i, j] -= c1 * Ut[m, j] + c2 * Kt[m, j]             # P = P − K U' − G K'
        for j in range(i):
            P[j, i] = P[i, j]


@njit(cache=True, error_model="numpy")
def forward(z, x0, P0, Hr, R, Q, xs, lfac):  # pragma: no cover - compiled
    """Time-varying KF over the readings; returns -1, or the failing sample.

    Parameters
    ----------
    z : (n, N) float64
        Readings [rad/s].
    x0 : (D,) float64, P0 : (D, D) float64
        Prior x̂_{-1} [rad/s] and P_{-1} [rad²/s²] (symmetric).
    Hr : (N, p) float64
        Rate columns of H1 = [Hr  I_N] [-].
    R, Q : (N, N), (D, D) float64
        Measurement and process covariances of one sample [rad²/s²].
    xs : (n, D) float64, out
        Filtered states x̂_k|k [rad/s].
    lfac : (n - 1, D(D+1)/2) float64, out
        Packed lower Cholesky factor L_k of P_{k+1|k} = P_k|k + Q
        (= L_k L_kᵀ), k = 0 .. n-2.

    Returns
    -------
    int
        -1 on success; else the sample k at which S_k or P_{k|k-1} was not
        positive definite (the outputs from there on are undefined).

    Notes
    -----
    The Joseph update P = (I−KH) P (I−KH)' + K R K' is evaluated as
    P = P − K U' − G K' with U = P H' and G = U − K S (S = H P H' + R): an
    identity for any gain K (expand (I−KH)P(I−KH)' + KRK'), so the Joseph
    form's first-order insensitivity to the rounding of K is kept: G is
    that rounding, times S. Only the lower triangle is formed, then
    mirrored (the Joseph form is symmetric for any K).
    """
    n, N = z.shape
    p = Hr.shape[1]
    D = p + N
    x = x0.copy()
    P = P0.copy()
    Pp = np.empty((D, D))
    Ut = np.empty((N, D))                                            # U' = (P H')' = H P
    S = np.empty((N, N))
    Sf = np.empty(N * (N + 1) // 2)                                  # packed factor Ls of S
    rs = np.empty(N)
    rp = np.empty(D)
    Kt = np.empty((N, D))                                            # K'
    Gt = np.empty((N, D))                                            # G' = U' − S K'
    nu = np.empty(N)
    for k in range(n):
        # predict, F = I: x = F x leaves x as it is
        for i in range(D):
            for j in range(D):
                Pp[i, j] = P[i, j] + Q[i, j]                         # P = F P F' + Q
        if k > 0:
            lk = lfac[k - 1]
            t = 0
            for i in range(D):
                for j in range(i + 1):
                    lk[t] = Pp[i, j]
                    t += 1
            if not _cholesky_packed(lk, D, rp):                      # P_k|k-1 = L Lᵀ (for C_{k−1})
                return k
        _innovation(Pp, Hr, R, p, Ut, S, Sf)                         # U' = H P, S = H P H' + R
        if not _cholesky_packed(Sf, N, rs):                          # S = Ls Lsᵀ
            return k
        _gain(Ut, Sf, rs, Kt)                                        # K = P H' S⁻¹
        # x = x + K (z − H x)
        for m in range(N):
            s = z[k, m] - x[p + m]
            for c_ in range(p):
                s -= Hr[m, c_] * x[c_]
            nu[m] = s                                                # y = z − H x
        for m in range(N):
            c = nu[m]
            for j in range(D):
                x[j] += c * Kt[m, j]                                 # x = x + K y
        for j in range(D):
            xs[k, j] = x[j]
        _joseph(P, Pp, Ut, Kt, S, Gt)                                # P = P − K U' − G K'
    return -1


@njit(cache=True, error_model="numpy")
def backward(xs, lfac, Q, xsm):  # pragma: no cover - compiled
    """RTS pass: smoothed states ``xsm`` (n, D) [rad/s] from the filtered
    ``xs`` and the packed factors L_k of P_{k+1|k} written by :func:`forward`.
    ``xsm`` may be ``xs`` (each x_k is read before x_s,k overwrites it).

    x_s,k = x_k + C_k (x_s,k+1 − x_k) with C_k = P_k P_{k+1|k}⁻¹
    = I − Q P_{k+1|k}⁻¹, i.e. x_s,k = x_s,k+1 − Q L_k⁻ᵀ L_k⁻¹ (x_s,k+1 − x_k).
    """
    n, D = xs.shape
    d = np.empty(D)
    rinv = np.empty(D)
    for j in range(D):
        xsm[n - 1, j] = xs[n - 1, j]
    for k in range(n - 2, -1, -1):
        L = lfac[k]
        for i in range(D):
            rinv[i] = 1.0 / L[i * (i + 1) // 2 + i]
        for j in range(D):
            d[j] = xsm[k + 1, j] - xs[k, j]                          # d = x_s⁺ − F x
        _cholesky_solve_packed(L, D, rinv, d)                        # w = (F P F' + Q)⁻¹ d
        for i in range(D):
            s = xsm[k + 1, i]
            for j in range(D):
                s -= Q[i, j] * d[j]
            xsm[k, i] = s                                            # x_s = x_s⁺ − Q w = x + C d
