"""The exact moments of a linear estimator's error in the analytic predictor: the error system
(estimator and noise states in modal form), the window sums of its modal covariance, and the
mean square [rad²/s²], window and run sums of the white, walk, Gauss–Markov and flicker parts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from scipy import signal

from gyroarray.core.errors import InputError
from gyroarray.design.noise_sources import NoiseSources


#: The flicker (bias instability) models :func:`flicker_moments` knows (``design --flicker``).
FLICKER_MODELS = ("circular", "kasdin")

#: The flicker model the design predictor uses unless told (``design --flicker``): Kasdin's
#: 1/f noise from switch-on, the defensible one for the angle at a horizon from switch-on.
FLICKER_MODEL = "kasdin"

#: Each flicker model in words, and what the other gives (the decision's assumptions).
FLICKER_WORDS = {
    "circular": (
        "circular (stationary) 1/f noise: sinusoids at the frequencies j/(M·dt), j = 1..M/2, M ≈ 2 × "
        "the run's samples, each of variance B²/(π j) (one-sided S(f) = B²/(π f), the simulator's "
        "core.physics.flicker_noise), as if the gyro had been running forever before switch-on; "
        "no power below 1/(M·dt), so the angle it predicts is the most optimistic of the flicker "
        "models: Kasdin's 1/f noise from switch-on (design --flicker kasdin) gives about twice the "
        "bias-instability angle at the horizon for the same Allan floor (issue 43: 1.17 against "
        "2.60 deg on the demo's array)"),
    "kasdin": (
        "Kasdin (1995) 1/f noise from switch-on: b_k = B Σ_{j=0..k} h_j w_{k−j}, w white of unit "
        "variance, h_j = Γ(j + 1/2)/(Γ(1/2) j!) (the α = 1 fractional integration started at "
        "k = 0); scaled like the circular model, one-sided S(f) ≈ B²/(π f) at low frequency "
        "(innovation σ = B per sample), so the Allan floor is √(2 ln 2/π)·B ≈ 0.664 B; it has "
        "power at every frequency down to 1/T, so it is the defensible one for the angle at a "
        "horizon from switch-on; the circular (stationary) model (design --flicker circular, the "
        "simulator's) gives about half the bias-instability angle at the horizon for the same "
        "Allan floor (issue 43: 1.17 against 2.60 deg on the demo's array)"),
}

#: The default flicker model in words (kept for importers).
FLICKER_MODEL_WORDS = FLICKER_WORDS[FLICKER_MODEL]


def check_flicker_model(model: str) -> str:
    """``model`` if it is one of :data:`FLICKER_MODELS` (else :class:`InputError`)."""
    if model not in FLICKER_MODELS:
        raise InputError(f"the flicker model must be one of {', '.join(FLICKER_MODELS)}, got {model!r}")
    return str(model)


def _mat_power(T: np.ndarray, m: int) -> np.ndarray:
    """T^m for a stack of square matrices (E, s, s), by repeated squaring."""
    out = np.broadcast_to(np.eye(T.shape[-1]), T.shape).copy()
    base = T.copy()
    while m > 0:
        if m & 1:
            out = out @ base
        m >>= 1
        if m:
            base = base @ base
    return out


def window_sums(nu: np.ndarray, k0: int, k1: int) -> tuple[np.ndarray, ...]:
    """Sums over k = k0..k1 of the modal covariance terms, for every pair (i, l).

    With a = ν_i ν_l, S_k(a) = Σ_{j<k} a^j and g_i(k) = Σ_{j=0}^{k1−k} ν_i^j:

    X1 = Σ a^k,  Y1 = Σ S_k(a),  X2 = Σ (g_i + g_l − 1) a^k,  Y2 = Σ (g_i + g_l − 1) S_k(a).

    For complex modes (a cascaded Butterworth filter) a = ν_i conj(ν_l) and
    g_l sums conj(ν_l): the sums of E[ξ ξᴴ].

    Parameters
    ----------
    nu : ndarray, shape (d,)
        Mode factors, |ν| <= 1 [-] (real in [0, 1], or complex).
    k0, k1 : int
        First and last sample of the window (0 <= k0 <= k1).

    Returns
    -------
    X1, Y1, X2, Y2 : ndarray, shape (d, d)
    """
    nu = np.asarray(nu)
    nu = nu.astype(complex if np.iscomplexobj(nu) else float)
    d = nu.size
    a = np.outer(nu, np.conj(nu)).ravel()
    ni = np.repeat(nu, d)
    nl = np.tile(np.conj(nu), d)
    E = a.size
    # phase 1: p_k = a p_{k-1} + c from k = 0 to k0, for the two unit inputs (p_0, c) = (1, 0), (0, 1)
    t1 = np.zeros((E, 2, 2), dtype=nu.dtype)
    t1[:, 0, 0], t1[:, 0, 1], t1[:, 1, 1] = a, 1.0, 1.0
    p1 = _mat_power(t1, k0)
    # phase 2: [p, q, r, A1, A2, c] from k0 to k1
    t2 = np.zeros((E, 6, 6), dtype=nu.dtype)
    t2[:, :5, 0] = a[:, None]
    t2[:, :5, 5] = 1.0
    t2[:, 1, 1] = t2[:, 4, 1] = ni
    t2[:, 2, 2] = t2[:, 4, 2] = nl
    t2[:, 3, 3] = t2[:, 4, 4] = t2[:, 5, 5] = 1.0
    p2 = _mat_power(t2, k1 - k0)
    out = []
    for col in (0, 1):                            # response to P0 = 1, then to W = 1
        p_k0 = p1[:, 0, col]
        s0 = np.stack([p_k0, p_k0, p_k0, p_k0, p_k0, np.full(E, float(col))], axis=1)
        s = np.einsum("eij,ej->ei", p2, s0)
        out.append((s[:, 3].reshape(d, d), s[:, 4].reshape(d, d)))
    (x1, x2), (y1, y2) = out
    return x1, y1, x2, y2


@dataclass(frozen=True, eq=False)
class _ErrorSystem:
    """ξ_k = diag(ν) ξ_{k-1} + B u_k (k >= 1), Cov ξ_0 = P0, e_k = c ξ_k."""

    nu: np.ndarray
    P0: np.ndarray
    W: np.ndarray
    c: np.ndarray


def _error_system(sys, noise: NoiseSources, *, white: bool = True, walk: bool = True,
                  gm: bool = True) -> _ErrorSystem:
    """The modal error system of a linear estimator under the noise (module Notes)."""
    N = noise.n_gyros
    dt = noise.dt_s
    R = noise.R if white else np.zeros((N, N))
    # noise states: the N random walks (Φ = 1, from 0), then the Gauss–Markov gyros (stationary)
    gm_idx = np.flatnonzero(noise.gm_sigma_rad_s > 0) if gm else np.array([], int)
    phi_gm = np.exp(-dt / noise.gm_tau_s[gm_idx])
    s2 = noise.gm_sigma_rad_s[gm_idx] ** 2
    n_rw = N if walk and np.any(noise.Qb != 0) else 0
    ng = n_rw + gm_idx.size
    phi = np.concatenate([np.ones(n_rw), phi_gm])
    gout = np.zeros((N, ng))
    if n_rw:
        gout[:, :N] = np.eye(N)
    gout[gm_idx, n_rw + np.arange(gm_idx.size)] = 1.0
    qg = np.zeros((ng, ng))
    pgm1 = np.zeros((ng, ng))
    if n_rw:
        qg[:N, :N] = noise.Qb
    j = n_rw + np.arange(gm_idx.size)
    qg[j, j] = s2 * (1.0 - phi_gm ** 2)                              # σ²(1 − φ²)
    pgm1[j, j] = s2                                                  # stationary start
    lam = sys.lam
    kt = sys.S_inv @ sys.K                                           # K̃ = S⁻¹ K
    kg = kt @ gout
    den = phi[None, :] - lam[:, None]
    res = np.abs(den) < 1e-12
    if kg.size and np.any(np.abs(kg[res]) > 1e-9 * max(1.0, float(np.max(np.abs(kg))))):
        raise InputError("a filter mode resonates with a noise state (equal poles): the "
                         "predictor has no stationary decomposition for this estimator")
    X = np.where(res, 0.0, kg * phi[None, :] / np.where(res, 1.0, den))   # Λ X − X Φ = −K̃ G Φ
    D = lam.size
    B = np.zeros((D + ng, ng + N), dtype=np.result_type(lam, kt, float))
    B[:D, :ng] = kg - X
    B[:D, ng:] = kt
    B[D:, :ng] = np.eye(ng)
    U = np.zeros((ng + N, ng + N))
    U[:ng, :ng] = qg
    U[ng:, ng:] = R
    W = B @ U @ B.conj().T
    # start: x̂_0 = (A X0 + K) z_0, z_0 = G g_0 + v_0, g_0 = Φ g_{-1} + ε_0
    m0 = lam[:, None] * (sys.S_inv @ sys.X0) + kt                   # S⁻¹(A X0 + K)
    tg = np.vstack([m0 @ gout - X, np.eye(ng)])
    tv = np.vstack([m0, np.zeros((ng, N))])
    pg0 = phi[:, None] * pgm1 * phi[None, :] + qg
    P0 = tg @ pg0 @ tg.conj().T + tv @ R @ tv.conj().T
    cs = sys.C @ sys.S
    c = np.hstack([cs, cs @ X])
    return _ErrorSystem(nu=np.concatenate([lam, phi]), P0=P0, W=W, c=c)


@dataclass(frozen=True)
class Moments:
    """Second moments of the noise-driven rate error over a run (3×3 each) [rad²/s², rad²/s²·samples²].

    Attributes
    ----------
    ms_window : ndarray
        E[(1/n_W) Σ_W e eᵀ].
    sum_window : ndarray
        E[(Σ_W e)(Σ_W e)ᵀ].
    sum_full : ndarray
        E[(Σ_{k<n} e)(Σ_{k<n} e)ᵀ].
    n_window : int
    """

    ms_window: np.ndarray
    sum_window: np.ndarray
    sum_full: np.ndarray
    n_window: int

    def __add__(self, other: "Moments") -> "Moments":
        return Moments(self.ms_window + other.ms_window, self.sum_window + other.sum_window,
                       self.sum_full + other.sum_full, self.n_window)


def error_moments(sys, noise: NoiseSources, n: int, k0: int, **parts) -> Moments:
    """Exact second moments of the state-space part of the noise (white, RRW, Gauss–Markov).

    Parameters
    ----------
    sys : LinearSystem
    noise : NoiseSources
    n : int
        Samples in the run.
    k0 : int
        First scored sample (after the start-up).
    **parts
        ``white``, ``walk``, ``gm`` (bool): which noise terms to include.
    """
    es = _error_system(sys, noise, **parts)
    x1, y1, x2, y2 = window_sums(es.nu, k0, n - 1)
    c = es.c
    ch = c.conj().T
    ms = np.real(c @ (es.P0 * x1 + es.W * y1) @ ch) / (n - k0)
    sw = np.real(c @ (es.P0 * x2 + es.W * y2) @ ch)
    if k0 == 0:
        sf = sw
    else:
        _, _, fx2, fy2 = window_sums(es.nu, 0, n - 1)
        sf = np.real(c @ (es.P0 * fx2 + es.W * fy2) @ ch)
    return Moments(_sym(ms), _sym(sw), _sym(sf), n - k0)


def _sym(a):
    return 0.5 * (a + a.T)


def flicker_moments(sys, bi_rad_s: np.ndarray, n: int, k0: int, dt_s: float, *,
                    model: str = "circular", corr: np.ndarray | None = None) -> Moments:
    """Second moments of the error from flicker (bias-instability) noise.

    Parameters
    ----------
    sys : LinearSystem
        The estimator (its sensor filter cascaded), N inputs.
    bi_rad_s : ndarray (N,)
        Flicker coefficient B per gyro [rad/s].
    n, k0 : int
        Samples in the run; first scored sample.
    dt_s : float
        Sample period [s].
    model : {"circular", "kasdin"}
        ``circular``: the simulator's stationary flicker (each FFT frequency of the circular
        process through the filter's steady-state response, the window sums following the
        Fejér kernel); ``kasdin``: Kasdin's 1/f noise from switch-on (:func:`kasdin_moments`).
    corr : ndarray (N, N), optional
        Correlation of the gyros' flicker processes [-] (None: independent); the flicker
        covariance is B Bᵀ ∘ corr.
    """
    if check_flicker_model(model) == "kasdin":
        return kasdin_moments(sys, bi_rad_s, n, k0, dt_s, corr=corr)
    bi = np.asarray(bi_rad_s, dtype=float)
    zero = np.zeros((3, 3))
    if not np.any(bi > 0):
        return Moments(zero, zero, zero, n - k0)
    cov = _flicker_cov(bi, corr)
    M = sfft.next_fast_len(2 * n, real=True)
    j = np.arange(1, M // 2 + 1, dtype=float)
    # variance of each sinusoid per B²: the simulator's line j carries S(f_j)·Δf = 1/(π j)
    # (S = B²/(π f) one-sided, Δf = 1/(M dt); core.physics.flicker_noise), not 2/(π j)
    v = 1.0 / (np.pi * j)
    if M % 2 == 0:
        v[-1] *= 0.5                                       # the Nyquist bin is real
    theta = 2.0 * np.pi * j / M

    def fejer(m, th):                                      # |Σ_{k<m} e^{jθk}|²
        s = np.sin(0.5 * th)
        return np.where(s == 0, float(m) ** 2, (np.sin(0.5 * m * th) / np.where(s == 0, 1, s)) ** 2)
    fw, ff = fejer(n - k0, theta), fejer(n, theta)
    ms, sw, sf = zero.copy(), zero.copy(), zero.copy()
    for lo in range(0, theta.size, 32768):                # bounded memory
        sl = slice(lo, lo + 32768)
        T = sys.response(theta[sl])                        # (t, 3, N)
        g = np.einsum("tai,ij,tbj->tab", T, cov, np.conj(T)).real * v[sl, None, None]
        ms += g.sum(axis=0)
        sw += np.einsum("tab,t->ab", g, fw[sl])
        sf += np.einsum("tab,t->ab", g, ff[sl])
    return Moments(ms, sw, sf, n - k0)


def _flicker_cov(bi: np.ndarray, corr: np.ndarray | None) -> np.ndarray:
    """B Bᵀ ∘ corr (N, N) [rad²/s²] (corr None: diag B²)."""
    return np.diag(bi ** 2) if corr is None else np.outer(bi, bi) * np.asarray(corr, dtype=float)


def kasdin_coefficients(n: int) -> np.ndarray:
    """h_0..h_{n−1} of Kasdin's α = 1 (1/f) fractional integration [-]:
    h_0 = 1, h_j = h_{j−1}·(j − 1/2)/j = Γ(j + 1/2)/(Γ(1/2) j!)."""
    j = np.arange(1, int(n), dtype=float)
    return np.concatenate([[1.0], np.cumprod((j - 0.5) / j)])


def kasdin_moments(sys, bi_rad_s: np.ndarray, n: int, k0: int, dt_s: float, *,
                   corr: np.ndarray | None = None) -> Moments:
    """Exact second moments of the error from Kasdin 1/f noise started at switch-on.

    Gyro i's flicker is b_k = B_i Σ_{j=0..k} h_j w_{i,k−j} (k >= 0, :func:`kasdin_coefficients`),
    with w white, unit variance, correlated between gyros by ``corr``: the one-sided spectrum at
    low frequency is B²/(π f), as the circular model's, so both have the Allan floor
    √(2 ln 2/π)·B (the scaling: innovation σ = B per sample).

    Parameters
    ----------
    sys : LinearSystem
        The estimator, N inputs (modal form λ, S, S⁻¹; started at x̂_{−1} = X0 z_0).
    bi_rad_s : ndarray (N,)
        B per gyro [rad/s].
    n, k0 : int
        Samples in the run; first scored sample.
    dt_s : float
        Sample period [s] (the moments are per sample; unused otherwise).
    corr : ndarray (N, N), optional
        Correlation of the gyros' innovations w [-] (None: independent).

    Notes
    -----
    With y_m = h filtered by mode m (y_m[k] = λ_m y_m[k−1] + h_k from rest), an innovation at
    sample i >= 1 reaches the error at k >= i as q_{k−i} = CS diag(y[k−i]) S⁻¹K; the one at
    sample 0 also sets the start (x̂_{−1} = X0 b_0), r_k = CS diag([y_k, λ^{k+1}]) [S⁻¹K; S⁻¹X0].
    Every second moment is then CS (Σ_l c_l y_l y_lᴴ ∘ P) (CS)ᴴ with P = S⁻¹K Cov S⁻¹Kᴴ, the
    weights c_l counting the window samples each lag reaches: sums over the run, no simulation.
    """
    bi = np.asarray(bi_rad_s, dtype=float)
    zero = np.zeros((3, 3))
    if not np.any(bi > 0):
        return Moments(zero, zero, zero, n - k0)
    cov = _flicker_cov(bi, corr)
    lam = np.asarray(sys.lam)
    bk = sys.S_inv @ sys.K                                           # (D, N)
    s0 = sys.S_inv @ sys.X0                                          # (D, N)
    cs = sys.C @ sys.S                                               # (p, D)
    cplx = np.iscomplexobj(lam) or np.iscomplexobj(bk) or np.iscomplexobj(cs)
    h = kasdin_coefficients(n)
    D = lam.size
    y = np.empty((n, D), dtype=complex if cplx else float)
    for m in range(D):
        y[:, m] = signal.lfilter([1.0], [1.0, -lam[m]], h.astype(y.dtype))
    k = np.arange(n)
    pw = lam[None, :] ** (k[:, None] + 1)                            # λ^{k+1} (n, D)
    u = np.hstack([y, pw])                                           # (n, 2D)
    b2 = np.vstack([bk, s0])
    P = bk @ cov @ bk.conj().T                                       # (D, D)
    P2 = b2 @ cov @ b2.conj().T                                      # (2D, 2D)
    cs2 = np.hstack([cs, cs])

    def quad(c, A, Pm):                                              # c (A ∘ P) cᴴ, real part
        return np.real(c @ (A * Pm) @ c.conj().T)

    def gram(a, w=None):                                             # Σ_l w_l a_l a_lᴴ
        return (a.T * (1.0 if w is None else w)) @ a.conj()
    nw = n - k0
    # mean square over the window: innovations i >= 1 reach sample k at lags l = 0..k−1
    lags = np.arange(n - 1)
    cnt = (n - np.maximum(k0, lags + 1)).astype(float)               # window samples past lag l
    ms = quad(cs, gram(y[:n - 1], cnt), P) + quad(cs2, gram(u[k0:]), P2)

    def sums(lo_k):                                                  # E[(Σ_{k>=lo_k} e)(...)ᵀ]
        cy = np.vstack([np.zeros((1, D), dtype=y.dtype), np.cumsum(y, axis=0)])   # cy[m] = Σ_{l<m} y_l
        i = np.arange(1, n)
        hi_l = n - i                                                 # lags l < n − i
        lo_l = np.maximum(lo_k - i, 0)                               # lags l >= max(lo_k, i) − i
        ys = cy[hi_l] - cy[lo_l]                                     # (n−1, D)
        return quad(cs, gram(ys), P) + quad(cs2, gram(u[lo_k:].sum(axis=0)[None, :]), P2)
    sw = sums(k0)
    sf = sw if k0 == 0 else sums(0)
    return Moments(_sym(ms / nw), _sym(sw), _sym(sf), nw)
