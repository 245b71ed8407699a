"""Kalman machinery shared by the KF estimators: the array model, its
steady-state gain on the observable subspace, the modal (lfilter) form of
the steady-state filter, and the plain textbook recursions.

The model (paper 003 §2.1, Eq. 4–5, discretised at the sample period dt):

    x = [ω (p); b (N)]          x_k = F x_{k-1} + w_k,  F = I,  Q = blkdiag(q_ω·dt, Q_b)
    z = H1 x + v,  H1 = [H  I_N],  R = cov(v)

(without bias states: x = ω, H1 = H, Q = q_ω·dt). ω and b are random walks;
(F, H1) has rank N of N + p, so the covariance P diverges along the
unobservable subspace {[u; −H u]} while the gain K converges.

Symbols follow the textbook (and filterpy): x, P, F, Q, H, R, K, S.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import signal
from scipy.optimize import brentq

from gyroarray.core.errors import InputError

__all__ = ["modal_lfilter", "StateModel", "state_model", "SteadyStateFilter", "steady_state", "NoSteadyState",
           "kf_step", "first_order_lowpass", "lowpass_pole", "solve_log"]


class NoSteadyState(InputError):
    """The Riccati equation of the observable subsystem has no stabilising solution."""



def modal_lfilter(lam: np.ndarray, u: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Run decoupled first-order modes m_k = λ m_{k-1} + u_k through ``scipy.signal.lfilter``.

    Parameters
    ----------
    lam : ndarray (d,)
        Real eigenvalues; modes of equal λ next to each other share one call.
    u : ndarray (d, n)
        Inputs, one row per mode.
    zi : ndarray (d,)
        lfilter's initial condition per mode (λ·m_{-1}).

    Returns
    -------
    y : ndarray (d, n)
        The modes.
    zf : ndarray (d,)
        The final conditions (``zi`` of the next block).
    """
    y = np.empty_like(u)
    zf = np.empty(lam.size)
    start = 0
    while start < lam.size:                                      # equal eigenvalues share a call
        stop = start + 1
        while stop < lam.size and lam[stop] == lam[start]:
            stop += 1
        y[start:stop], z_end = signal.lfilter([1.0], [1.0, -lam[start]], u[start:stop], axis=-1,
                                              zi=zi[start:stop, None])
        zf[start:stop] = z_end[:, 0]
        start = stop
    return y, zf

@dataclass(frozen=True, eq=False)
class StateModel:
    """A discrete linear-Gaussian model x_k = F x_{k-1} + w, z_k = H1 x_k + v.

    Attributes
    ----------
    F, H1, Q, R : ndarray
        Transition (D×D), measurement (N×D), process (D×D) and measurement
        (N×N) covariances [rad²/s²].
    p : int
        Number of rate states (the first p entries of x).
    bias : bool
        Whether the last N entries of x are gyro biases.
    """

    F: np.ndarray
    H1: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    p: int
    bias: bool

    @property
    def dim(self) -> int:
        return int(self.F.shape[0])


def state_model(H: np.ndarray, R: np.ndarray, q_rate: np.ndarray, Qb: np.ndarray | None) -> StateModel:
    """The array model for rate axes H (N×p), R (N×N), rate increments q_rate (p,)
    [rad²/s² per sample] and bias increments Qb (N×N) (None: no bias states)."""
    n, p = H.shape
    if Qb is None:
        return StateModel(np.eye(p), H.copy(), np.diag(q_rate), R.copy(), p, False)
    h1 = np.hstack([H, np.eye(n)])                               # H1 = [H I]
    return StateModel(np.eye(p + n), h1, sla.block_diag(np.diag(q_rate), Qb), R.copy(), p, True)


@dataclass(frozen=True, eq=False)
class SteadyStateFilter:
    """The steady-state KF x̂_k = A x̂_{k-1} + K z_k, A = (I − K H1) F, in modal form.

    With V_o, V_u orthonormal bases of the observable (row space of H1) and
    unobservable (null space of H1) subspaces, x = V_o x_o + V_u x_u, the
    filter is x_o,k = A_o x_o,k-1 + K_o z_k and x_u,k − J x_o,k = const. A_o
    = P⁺P⁻¹ is similar to the symmetric L⁻¹P⁺L⁻ᵀ (P = L Lᵀ), so
    A_o = W Λ W⁻¹ with real λ in [0, 1): each mode m = W⁻¹ x_o is a
    first-order IIR filter m_k = λ m_{k-1} + (B z_k), B = W⁻¹ K_o.

    Attributes
    ----------
    model : StateModel
    K : ndarray, shape (D, N)
        Steady-state gain [-].
    P_prior : ndarray, shape (d, d)
        Steady prior covariance of the observable coordinates x_o [rad²/s²].
    lam : ndarray, shape (d,)
        Eigenvalues of A_o [-].
    B : ndarray, shape (d, N)
        Input matrix of the modes.
    modes : ndarray, shape (D, d)
        State of each stable mode: x̂ = modes @ m + V_u c.
    Vu : ndarray, shape (D, p_u)
        Unobservable directions (the modes of eigenvalue 1).
    to_modes : ndarray, shape (D, D)
        Inverse modal transform: [m; c] = to_modes @ x̂.
    Vo : ndarray, shape (D, d)
        Observable directions (orthonormal).
    P_cross : ndarray, shape (p_u, d)
        Steady prior cross covariance P_uo of the unobservable and observable
        coordinates [rad²/s²].
    """

    model: StateModel
    K: np.ndarray
    P_prior: np.ndarray
    lam: np.ndarray
    B: np.ndarray
    modes: np.ndarray
    Vu: np.ndarray
    to_modes: np.ndarray
    Vo: np.ndarray
    P_cross: np.ndarray

    # -- running the filter -----------------------------------------------
    def apply(self, z: np.ndarray, x0: np.ndarray, *, full: bool = False) -> np.ndarray:
        """Filter readings z (n, N) from the prior state x0 (D,) = x̂_{-1}.

        Returns the rate estimates (n, p), or every state (n, D) if ``full``.
        Each mode runs through ``scipy.signal.lfilter`` (one call per
        distinct eigenvalue; for the rates only the :attr:`rate_modes`); no
        Python loop over samples.
        """
        d = self.lam.size
        mc = self.to_modes @ x0
        m0, c = mc[:d], mc[d:]
        rows = slice(None) if full else slice(0, self.model.p)
        keep = np.arange(d) if full else self.rate_modes
        lam, m0 = self.lam[keep], m0[keep]
        u = self.B[keep] @ z.T                                       # (d, n): B z_k
        y, _ = modal_lfilter(lam, u, lam * m0)
        out = y.T @ self.modes[rows][:, keep].T
        out += self.Vu[rows] @ c
        return out

    @property
    def rate_modes(self) -> np.ndarray:
        """Indices of the modes that reach the rate estimate.

        A mode whose largest possible effect on the rates, |c_i|·|b_i|/(1 − λ_i)
        (the ℓ1 norm of its impulse response), is below 1e-13 of the largest
        one's is left out of the rate output: an error < 1e-12 of the signal.
        (On symmetric layouts with equal noise the parity-space bias modes are
        exactly decoupled from the rates; rounding leaves ~1e-14.)
        """
        reach = (np.max(np.abs(self.modes[:self.model.p]), axis=0) * np.max(np.abs(self.B), axis=1)
                 / (1.0 - self.lam))
        return np.flatnonzero(reach > 1e-13 * np.max(reach))

    def initial_covariance(self) -> np.ndarray:
        """A posterior covariance P_{-1} (D×D) from which the textbook
        recursion runs with the steady-state gain K at every step.

        Its prediction P_{-1} + Q is [V_o V_u] [[P, P_uoᵀ], [P_uo, P_uu]]
        [V_o V_u]ᵀ: the observable and cross blocks at their fixed points and
        P_uu = c·I (the block that diverges and does not enter K), c doubled
        from max(P) until P_{-1} is positive semi-definite.
        """
        T = np.hstack([self.Vo, self.Vu])
        Q = self.model.Q
        c = float(np.max(self.P_prior))
        for _ in range(200):
            blk = np.block([[self.P_prior, self.P_cross.T], [self.P_cross, c * np.eye(self.Vu.shape[1])]])
            P0 = _sym(T @ blk @ T.T) - Q
            if np.linalg.eigvalsh(P0)[0] >= 0:
                return P0
            c *= 2.0
        raise RuntimeError("no positive semi-definite start found")  # pragma: no cover

    # -- frequency response and bandwidth ----------------------------------
    def rate_response(self, H: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Frequency response (len(theta), p, p) from body rates (z = H ω) to the
        rate estimates, at normalised angular frequencies θ = 2π f dt [rad]."""
        p = self.model.p
        g = 1.0 / (1.0 - self.lam[None, :] * np.exp(-1j * np.asarray(theta))[:, None])  # 1/(1 − λ e^{−jθ})
        bh = self.B @ H
        return np.einsum("ai,ti,ib->tab", self.modes[:p], g, bh)

    def bandwidth_hz(self, H: np.ndarray, dt_s: float) -> np.ndarray:
        """−3 dB bandwidth [Hz] of each rate axis (|T_aa| = |T_aa(0)|/√2).

        The first crossing on a log grid of θ is refined by Brent's method;
        an axis that stays above −3 dB up to Nyquist reports 0.5/dt.
        """
        p = self.model.p
        grid = np.pi * np.logspace(-9, 0, 400)
        dc = np.abs(np.diagonal(self.rate_response(H, np.array([0.0]))[0]))
        resp = np.abs(np.diagonal(self.rate_response(H, grid), axis1=1, axis2=2)) / dc
        out = np.full(p, 0.5 / dt_s)
        for a in range(p):
            below = np.flatnonzero(resp[:, a] < 2 ** -0.5)
            if below.size == 0:
                continue
            k = below[0]
            if k == 0:
                out[a] = grid[0] / (2 * np.pi * dt_s)
                continue

            def f(th, a=a):
                return abs(self.rate_response(H, np.array([th]))[0, a, a]) / dc[a] - 2 ** -0.5
            out[a] = brentq(f, grid[k - 1], grid[k], xtol=1e-14, rtol=1e-13) / (2 * np.pi * dt_s)
        return out

    # -- error covariances ------------------------------------------------
    def stationary_rate_covariance(self, R: np.ndarray) -> np.ndarray:
        """Steady covariance (p, p) of the rate error driven by white measurement
        noise of covariance R (the unit modes are not driven: ℓᵀK = 0)."""
        p = self.model.p
        br = self.B @ R @ self.B.T
        m = br / (1.0 - np.outer(self.lam, self.lam))             # M = Λ M Λ + B R Bᵀ
        c = self.modes[:p]
        return _sym(c @ m @ c.T)

    def error_covariance(self, n: int, R: np.ndarray, Qb: np.ndarray, x0_map: np.ndarray) -> np.ndarray:
        """Exact covariance (n, p, p) of the noise-driven rate error at each sample.

        The truth has zero rate and biases b_k = b_{k-1} + w_k (cov Qb,
        b_{-1} = 0); the readings z_k = b_k + v_k (cov R); the filter starts
        from x̂_{-1} = x0_map @ z_0. With A = 𝒮 Λ 𝒮⁻¹ (the stable modes and
        the unit modes), P̃ = 𝒮⁻¹ P 𝒮⁻ᵀ follows P̃_k = Λ(P̃_{k-1} + Q̃)Λ + R̃
        elementwise, summed in closed form: no loop over samples.
        """
        mdl = self.model
        if not mdl.bias:
            raise InputError("error_covariance needs the bias states")
        D, N, p = mdl.dim, mdl.R.shape[0], mdl.p
        K = self.K
        A = (np.eye(D) - K @ mdl.H1) @ mdl.F                      # A = (I − K H1) F
        pib = np.vstack([np.zeros((p, N)), np.eye(N)])
        m0 = A @ x0_map + K                                          # x̂_0 = M0 z_0
        x = A @ pib + K - m0                                         # e_0 = X w_0 − M0 v_0
        P0 = x @ Qb @ x.T + m0 @ R @ m0.T
        Ti = self.to_modes
        lam = np.concatenate([self.lam, np.ones(D - self.lam.size)])
        a = np.outer(lam, lam)
        p0 = Ti @ P0 @ Ti.T
        q = Ti @ (pib @ Qb @ pib.T) @ Ti.T
        r = Ti @ (K @ R @ K.T) @ Ti.T
        unit = np.abs(1.0 - a) < 1e-13
        one_minus_a = np.where(unit, 1.0, 1.0 - a)
        sfull = np.hstack([self.modes, self.Vu])[:p]
        out = np.empty((n, p, p))
        for k0 in range(0, n, 8192):                                  # bounded memory: 8192·D² doubles
            k = np.arange(k0, min(n, k0 + 8192), dtype=float)[:, None, None]
            ak = np.power(a[None], k)
            s = np.where(unit[None], k, (1.0 - ak) / one_minus_a[None])  # Σ_{j<k} a^j
            pk = ak * p0[None] + s * (a * q + r)[None]              # P̃_k = a^k P̃_0 + S_k (a q̃ + r̃)
            out[k0:k0 + k.shape[0]] = np.einsum("ai,kij,bj->kab", sfull, pk, sfull)
        return 0.5 * (out + np.swapaxes(out, 1, 2))


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


def steady_state(model: StateModel) -> SteadyStateFilter:
    """Steady-state gain from the DARE on the observable subspace, in modal form.

    Notes
    -----
    Let [V_o V_u] be the complete QR basis of H1ᵀ: V_o spans the row space of
    H1 (observable, dimension N with bias states), V_u its null space. In
    these coordinates F = I stays block diagonal and H1 = [H_o 0], so the
    observable subsystem (I, H_o, Q_oo, R) has the stabilising DARE solution

        P = P − P H_oᵀ (H_o P H_oᵀ + R)⁻¹ H_o P + Q_oo     (prior covariance)

    (``scipy.linalg.solve_discrete_are``, on R-normalised covariances), and
    K_o = P H_oᵀ S⁻¹. The cross covariance P_uo of the diverging block
    converges: P_uo = P_uo (I − H_oᵀS⁻¹H_o P) + Q_uo gives
    P_uo = Q_uo P⁻¹ H_o⁻¹ S H_o⁻ᵀ and the unobservable gain
    K_u = P_uo H_oᵀ S⁻¹ = Q_uo P⁻¹ H_o⁻¹. Then K = V_o K_o + V_u K_u.
    The tests check K against the plain recursion iterated to convergence.

    Raises
    ------
    NoSteadyState
        Q_oo singular (e.g. no rate random walk with bias states): the gain
        then decays like 1/k and never settles.
    """
    H1, Q, R = model.H1, model.Q, model.R
    D, N = model.dim, R.shape[0]
    if model.bias:
        basis, _ = np.linalg.qr(H1.T, mode="complete")
        Vo, Vu = basis[:, :N], basis[:, N:]
    else:
        Vo, Vu = np.eye(D), np.zeros((D, 0))
    Ho = H1 @ Vo
    scale = np.trace(R) / N                                          # the DARE is homogeneous in (Q, R)
    Qoo = _sym(Vo.T @ Q @ Vo) / scale
    w = np.linalg.eigvalsh(Qoo)
    if w[0] <= 1e-14 * w[-1]:
        raise NoSteadyState("the process noise does not reach every observable direction "
                            "(a bias combination with no rate random walk): the Kalman gain "
                            "never settles")
    Rs = R / scale
    d = Vo.shape[1]
    P = _sym(sla.solve_discrete_are(np.eye(d), Ho.T, Qoo, Rs))
    # posterior in information form, exact also when P ≫ R (q_ω → ∞):
    # P⁺ = (P⁻¹ + H'R⁻¹H)⁻¹, K = P⁺ H' R⁻¹ (= P H' S⁻¹)
    rih = np.linalg.solve(Rs, Ho)                                    # R⁻¹ H
    Ppost = _sym(np.linalg.inv(np.linalg.inv(P) + Ho.T @ rih))
    Ko = Ppost @ rih.T                                               # K = P⁺ H' R⁻¹
    if model.bias:
        Quo = Vu.T @ Q @ Vo / scale
        Ku = np.linalg.solve(Ho.T, np.linalg.solve(P, Quo.T)).T      # K_u = Q_uo P⁻¹ H_o⁻¹
        J = np.linalg.solve(Ko.T, Ku.T).T                            # x_u − J x_o is invariant
    else:
        Ku, J = np.zeros((0, N)), np.zeros((0, d))
    L = np.linalg.cholesky(P)
    Linv = np.linalg.inv(L)
    lam, U = np.linalg.eigh(_sym(Linv @ Ppost @ Linv.T))           # A_o = P⁺P⁻¹ = L (L⁻¹P⁺L⁻ᵀ) L⁻¹
    lam = np.clip(lam, 0.0, np.nextafter(1.0, 0.0))
    W, Winv = L @ U, U.T @ Linv
    K = Vo @ Ko + Vu @ Ku
    modes = (Vo + Vu @ J) @ W
    to_modes = np.vstack([Winv @ Vo.T, Vu.T - J @ Vo.T])
    Pcross = Ku @ (Ho @ P @ Ho.T + Rs) @ np.linalg.inv(Ho).T if model.bias else np.zeros((0, d))
    return SteadyStateFilter(model=model, K=K, P_prior=P * scale, lam=lam, B=Winv @ Ko,
                             modes=modes, Vu=Vu, to_modes=to_modes, Vo=Vo, P_cross=Pcross * scale)


# -- the plain textbook recursions --------------------------------------------

def kf_step(x, P, z, F, H, Q, R):
    """One predict/update of the textbook KF; returns x, P (posterior), K, P_prior."""
    x = F @ x                                                        # x = F x
    P = F @ P @ F.T + Q                                              # P = F P F' + Q
    S = H @ P @ H.T + R                                              # S = H P H' + R
    K = np.linalg.solve(S, H @ P).T                                  # K = P H' S⁻¹
    x = x + K @ (z - H @ x)                                          # x = x + K (z − H x)
    IKH = np.eye(P.shape[0]) - K @ H
    Pp = P
    P = IKH @ P @ IKH.T + K @ R @ K.T                                # P = (I−KH) P (I−KH)' + K R K'
    return x, P, K, Pp


# -- the comparison low-pass --------------------------------------------------

def lowpass_pole(f_hz: float, dt_s: float) -> float:
    """Pole a of y_k = a y_{k-1} + (1 − a) x_k with its −3 dB point at f [Hz].

    |1 − a|²·2 = |1 − a e^{−jθ}|², θ = 2π f dt, gives
    a² − 2a(2 − cos θ) + 1 = 0, a = c − √(c² − 1), c = 2 − cos θ.
    """
    c = 2.0 - np.cos(2.0 * np.pi * f_hz * dt_s)
    return float(c - np.sqrt(c * c - 1.0))


def first_order_lowpass(x: np.ndarray, f_hz: float, dt_s: float) -> np.ndarray:
    """First-order low-pass along axis 0 with unit DC gain, −3 dB at f [Hz],
    started in steady state on the first sample (y_{-1} = x_0)."""
    a = lowpass_pole(f_hz, dt_s)
    y, _ = signal.lfilter([1.0 - a], [1.0, -a], x, axis=0, zi=a * x[:1])  # y = a y + (1−a) x
    return y


# -- designing q_ω for a bandwidth ------------------------------------------------

def solve_log(fun, x0: float, *, what: str) -> float:
    """Root x > 0 of an increasing ``fun`` (fun(x) = log(achieved/target)),
    bracketed from ``x0`` by factors of e² and refined by Brent's method in log x."""
    lo = hi = np.log(x0)
    flo = fhi = fun(x0)
    for _ in range(40):
        if flo <= 0.0 <= fhi:
            break
        if flo > 0:
            hi, fhi = lo, flo
            lo -= 2.0
            flo = fun(np.exp(lo))
        else:
            lo, flo = hi, fhi
            hi += 2.0
            fhi = fun(np.exp(hi))
    else:
        raise InputError(f"no {what} reaches the requested bandwidth (searched "
                         f"{np.exp(lo):.3g} .. {np.exp(hi):.3g})")
    if flo == 0.0:
        return float(np.exp(lo))
    return float(np.exp(brentq(lambda t: fun(np.exp(t)), lo, hi, xtol=1e-12, rtol=1e-13)))
