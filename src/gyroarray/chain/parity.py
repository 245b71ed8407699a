"""Parity-space self-calibration of a moving gyro array: scale factor and axis errors per gyro.

A redundant array (N > 3 gyros) reads y = H ω + b + n. With small errors each
gyro reads instead

    y_i = (1 + s_i) h_iᵀ ω + δh_iᵀ ω + b_i + n_i,   δh_i = a_i u_i + c_i v_i,

s_i its scale-factor error [-], (a_i, c_i) two small tilts [rad] of its
sensitive axis h_i toward the unit vectors u_i, v_i ⟂ h_i (:func:`tilt_axes`:
the two body axes other than the one h_i is closest to, made orthonormal to
h_i). Stacked, y = (H + E) ω + b + n with row i of E = s_i h_iᵀ + a_i u_iᵀ +
c_i v_iᵀ.

The parity p = P y (P = V W, V spanning the left null space of W H, W the
whitening of the white-noise covariance R, so P H = 0 and P R Pᵀ = I) does
not see the body rate, only the errors:

    p = P E ω + P b + P n  ≈  P E ω̂ + P b + P n,

ω̂ the fused rate (GLS; its own error is second order in E). This is linear
in θ = (s_i, a_i, c_i)_i: p_k = Σ_i P[:, i] (s_i h_iᵀ ω̂_k + a_i u_iᵀ ω̂_k + c_i
v_iᵀ ω̂_k), solved by least squares over the moving samples with one
intercept per moving stretch (the biases P b) (Carlsson, Skog, Jaldén,
"Self-calibration of inertial sensor arrays", IEEE Sensors J. 2021, use the
same parity idea with accelerometers and gyros together).

Gauge (what parity cannot see): any E = H A (A a 3×3 matrix) gives P E = 0.
A common scale factor, a common misalignment, any common linear map of all
gyros is absorbed into the fused rate and is invisible without a reference.
Nine combinations of θ are therefore free. The normal equations' pseudo-
inverse gives the minimum-norm solution, Hᵀ E = 0: the errors relative to
the array's own mean (for an array with k gyros along each axis, the scale-
factor errors of each axis group, signed by the axis direction, sum to zero,
and so do their tilts); see below for the default gauge. A motion that does not
turn about all three axes leaves more combinations unseen: those gyros'
terms are reported as not identified (σ = None), never as 0.

Uncertainty: the residual parity of a real array is not white (vibration
lines, sampling instants that differ between chips), so the covariance is
the textbook σ̂²(AᵀA)⁺ inflated by the median ratio of the sandwich
(AᵀA)⁺ Ω (AᵀA)⁺ (Ω summed over blocks of ``block_s`` of the per-block
scores: heteroscedasticity- and autocorrelation-consistent) to it, never
deflated; on white noise the σ are calibrated (tests: z scatter ≈ 1 over
repeated draws). A gyro is "off" when its terms together are as far from
zero as one term ``Z_OFF`` σ away (χ² over its identified terms).

The gauge is fixed by default as "majority": the common transform shared
by most gyros is taken out (a robust, group-L1 fit of E = H A), so when a
few gyros are off their errors come out as they are; ``gauge="mean"``
gives Hᵀ E = 0 instead (errors relative to the array's mean). The fused
rate the parity is regressed on is re-fused from the corrected readings in
that gauge (:data:`REFINE_PASSES`), which removes the second-order frame
error of the first pass.

Samples where any gyro sits at its output limit (a saturated gyro reads the
clip value, not (1+s)hᵀω) and the still parts (no leverage) are left out.

Units: SI inside (rad/s, rad); ppm and mrad in the results (keys say which).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg, optimize, stats

from gyroarray.analysis.motion import still_mask
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import Measurement, true_runs
from gyroarray.core.units import rad_s_to_deg_s
from gyroarray.estimators.fdi import MIN_CLIP_RUN, SATURATION_GUARD, saturated_mask  # noqa: F401 (the home of the clip test)
from gyroarray.estimators.fdi import estimate_noise, model_noise

__all__ = ["Z_OFF", "ParityCalibration", "tilt_axes", "saturated_mask", "fused_rate",
           "self_calibrate", "calibrate_measurement", "calibrate_record", "format_parity",
           "MIN_MOTION_DEG_S"]

#: A gyro term more than this many σ from zero is reported as off [-].
Z_OFF = 3.0

#: Smallest rms fused rate of the moving samples that the calibration is tried on [deg/s]:
#: below it the motion-correlated parity is below the noise of any real gyro array.
MIN_MOTION_DEG_S = 5.0

#: Fewest moving samples per unknown (3 per gyro) the fit needs [-].
MIN_SAMPLES_PER_UNKNOWN = 4

#: Passes that refit with the fused rate of the readings less the errors fitted so far [-].
REFINE_PASSES = 2


_AXIS_NAMES = ("x", "y", "z")


@dataclass(frozen=True, eq=False)
class ParityCalibration:
    """Scale factor and axis errors of each gyro from the parity of a moving array.

    Attributes
    ----------
    scale_ppm, scale_sigma_ppm : ndarray, shape (N,)
        Scale-factor error s_i and its 1σ [ppm] (NaN σ: not identified).
    tilt_mrad, tilt_sigma_mrad : ndarray, shape (N, 2)
        Tilts (a_i, c_i) of the axis toward ``toward[i]`` and their 1σ [mrad].
    toward : tuple of (str, str)
        The body axes the two tilts point to (``"y"``, ``"z"`` for an x gyro).
    z : ndarray, shape (N, 3)
        Each term over its σ [-] (NaN where not identified).
    off : tuple of int
        1-based gyros whose terms are off: Σ z² over its identified terms beyond the
        χ² quantile of the two-sided tail of :data:`Z_OFF` σ (p = 0.0027 for 3σ).
    E : ndarray, shape (N, 3)
        The error matrix in the chosen gauge: y ≈ (H + E) ω [-] (``"mean"``:
        Hᵀ E = 0); terms not identified are 0.
    n_samples : int
        Moving samples fitted.
    rms_rate_deg_s : float
        Rms fused rate of those samples [deg/s].
    parity_rms_deg_s : tuple of float
        Rms parity (V y, unwhitened, per component, averaged) before and after
        removing the fitted errors [deg/s].
    explained : float
        Share of the parity variance of the moving samples the errors explain [-].
    chi2, dof, p_value : float
        Wald test of "no motion-dependent parity" (all identified terms 0).
    excess : tuple of float
        (c², d²): the whitened parity left after the fit has variance
        1 + c²|ω̂|² + d²|ω̂'|² per component (c² [1/(rad/s)²], d² [1/(rad/s²)²],
        non-negative least squares over the moving samples): what the
        errors do not explain grows with the rate and the angular
        acceleration (:meth:`excess_scale`).
    gauge : str
    notes : tuple of str
    gauge_dependent : bool
        True when no gauge makes the per-gyro numbers per-gyro errors: with N = 4 there is
        one parity equation, the record determines only the 3 numbers of ``observable``
        and any split of them over the gyros fits as well (the per-gyro numbers are one
        split, the gauge's; ``off`` is empty: which gyro is off cannot be told).
    observable : dict or None
        N = 4: what the record determines, gauge-free: ``parity_vector`` v (unit, vᵀH = 0,
        largest entry positive), ``response_ppm`` c = Σ_i v_i e_i (e_i gyro i's error row,
        y ≈ (H + E) ω: the parity v·y reads c·ω), its ``sigma_ppm`` and ``z`` per body axis
        (None: not excited), and a ``statement``. None for N >= 5.
    """

    scale_ppm: np.ndarray
    scale_sigma_ppm: np.ndarray
    tilt_mrad: np.ndarray
    tilt_sigma_mrad: np.ndarray
    toward: tuple
    z: np.ndarray
    off: tuple
    E: np.ndarray
    n_samples: int
    rms_rate_deg_s: float
    parity_rms_deg_s: tuple
    explained: float
    chi2: float
    dof: int
    p_value: float
    gauge: str
    notes: tuple = field(default_factory=tuple)
    excess: tuple = (0.0, 0.0)
    gauge_dependent: bool = False
    observable: dict | None = None

    def correct(self, y: np.ndarray, H: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """The readings less the fitted errors, y − E ω̂ [rad/s] (n, N).

        ω̂ is re-fused from the corrected readings (:data:`REFINE_PASSES` times), as in
        the fit, so the correction is made in the gauge's own frame. Only the parity
        changes up to a common transform of the body rate (the gauge).
        """
        y = np.asarray(y, dtype=float)
        om = fused_rate(y, H, R)
        for _ in range(REFINE_PASSES):
            om = fused_rate(y - om @ self.E.T, H, R)
        return y - om @ self.E.T

    def excess_scale(self, y: np.ndarray, H: np.ndarray, dt_s: float,
                     R: np.ndarray | None = None) -> np.ndarray:
        """√(1 + c²|ω̂|² + d²|ω̂'|²) at each sample (n,): the parity's spread beyond white noise.

        Parameters
        ----------
        y : ndarray, shape (n, N)
            Outputs [rad/s].
        H : ndarray, shape (N, 3)
        dt_s : float
            Sample step [s].
        R : ndarray, shape (N, N), optional
            White-noise covariance of one sample (the GLS rate).
        """
        om = fused_rate(y, H, R)
        c2, d2 = self.excess
        return np.sqrt(1.0 + c2 * np.sum(om * om, axis=1) + d2 * jerk2(om, dt_s))

    @property
    def significant(self) -> bool:
        """Whether the motion-dependent parity is real (Wald p < 1e-3 and a gyro off; with
        N = 4, where no gyro can be singled out, the Wald test alone)."""
        return bool(self.p_value < 1e-3 and (self.off or self.gauge_dependent))

    def to_json_dict(self) -> dict:
        """Per gyro (1-based keys) scale factor [ppm] and tilts [mrad] with 1σ and z; summary."""
        def num(x):
            return None if not math.isfinite(float(x)) else float(x)
        gyros = {}
        for i in range(self.scale_ppm.size):
            gyros[str(i + 1)] = {
                "scale_factor_ppm": num(self.scale_ppm[i]),
                "scale_factor_sigma_ppm": num(self.scale_sigma_ppm[i]),
                "misalignment_mrad": [num(v) for v in self.tilt_mrad[i]],
                "misalignment_sigma_mrad": [num(v) for v in self.tilt_sigma_mrad[i]],
                "misalignment_toward": list(self.toward[i]),
                "z": [num(v) for v in self.z[i]],
                "off": (i + 1) in self.off}
        return {"gyros": gyros, "off": list(self.off), "n_samples": int(self.n_samples),
                "rms_rate_deg_s": num(self.rms_rate_deg_s),
                "parity_rms_deg_s": {"before": num(self.parity_rms_deg_s[0]),
                                     "after": num(self.parity_rms_deg_s[1])},
                "explained": num(self.explained), "chi2": num(self.chi2), "dof": int(self.dof),
                "p_value": num(self.p_value), "significant": self.significant,
                "gauge": self.gauge, "gauge_dependent": bool(self.gauge_dependent),
                **({"observable": {**self.observable,
                                   **{k: {ax: num(v) for ax, v in zip(_AXIS_NAMES, self.observable[k])}
                                      for k in ("response_ppm", "sigma_ppm", "z")}}}
                   if self.observable is not None else {}),
                "notes": list(self.notes)}


def tilt_axes(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Two unit vectors ⟂ each axis, toward the two body axes it is least aligned with.

    Parameters
    ----------
    H : ndarray, shape (N, 3)
        Unit sensitive axes [-].

    Returns
    -------
    U, Vt : ndarray, shape (N, 3)
        Orthonormal with each h_i: U[i] from the first of the two other body
        axes (Gram–Schmidt), Vt[i] = h_i × U[i] signed toward the second.
    names : tuple of (str, str)
        The body axes ``U[i]`` and ``Vt[i]`` point to.
    """
    H = np.asarray(H, dtype=float)
    U, W, names = np.empty_like(H), np.empty_like(H), []
    for i, h in enumerate(H):
        k = int(np.argmax(np.abs(h)))
        a, b = [j for j in range(3) if j != k]
        e = np.eye(3)
        u = e[a] - (e[a] @ h) * h
        u /= np.linalg.norm(u)
        w = e[b] - (e[b] @ h) * h - (e[b] @ u) * u
        w /= np.linalg.norm(w)
        U[i], W[i] = u, w
        names.append((_AXIS_NAMES[a], _AXIS_NAMES[b]))
    return U, W, tuple(names)


def _whitening(R: np.ndarray | None, n: int) -> np.ndarray:
    if R is None:
        return np.eye(n)
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        raise InputError("the white-noise covariance is not positive definite: give every gyro "
                         "a positive white level and correlations within (−1, 1)") from None
    return linalg.solve_triangular(L, np.eye(n), lower=True)


def fused_rate(y: np.ndarray, H: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
    """GLS body rate ω̂ = (HᵀR⁻¹H)⁻¹HᵀR⁻¹y (OLS without R) [rad/s], shape (n, 3)."""
    W = _whitening(R, H.shape[0])
    G = np.linalg.pinv(W @ H) @ W
    return np.asarray(y, dtype=float) @ G.T


def self_calibrate(y: np.ndarray, H: np.ndarray, dt_s: float, *, R: np.ndarray | None = None,
                   use: np.ndarray | None = None, block_s: float = 1.0,
                   gauge: str = "majority") -> ParityCalibration:
    """Scale factor and axis errors of each gyro from the parity of a moving record.

    Parameters
    ----------
    y : ndarray, shape (n, N)
        Gyro outputs [rad/s] (N >= 4).
    H : ndarray, shape (N, 3)
        Unit sensitive axes [-], rank 3.
    dt_s : float
        Sample step [s].
    R : ndarray, shape (N, N), optional
        Covariance of one sample of the white noise [rad²/s²]: the parity is
        whitened with it and ω̂ is its GLS rate (default: alike gyros).
    use : ndarray of bool, shape (n,), optional
        Samples to fit (default all). Each run of consecutive True samples
        gets its own intercept (the gyros' biases).
    block_s : float
        Block length of the sandwich covariance [s].
    gauge : {"majority", "mean"}
        How the 9 invisible combinations are fixed. ``"mean"``: Hᵀ E = 0, the
        errors relative to the array's mean (the minimum-norm solution).
        ``"majority"`` (default): the common transform H A that makes the
        most gyros error-free is taken out (A minimising Σ_i ‖E_i − h_iᵀA‖,
        iteratively reweighted least squares): when a few gyros are off and
        the rest agree, their errors come out as they are instead of spread
        over the whole array by the mean.

    Returns
    -------
    ParityCalibration

    Raises
    ------
    InputError
        Fewer than 4 gyros, H not of rank 3, or fewer than
        :data:`MIN_SAMPLES_PER_UNKNOWN` × 3N samples to fit.
    """
    y = np.asarray(y, dtype=float)
    H = np.asarray(H, dtype=float)
    n, N = y.shape
    if N < 4 or H.shape != (N, 3):
        raise InputError(f"self-calibration needs at least 4 gyros with axes (N, 3), got {N} "
                         f"gyros and axes of shape {H.shape}")
    if np.linalg.matrix_rank(H) < 3:
        raise InputError("the gyros' axes do not span 3 dimensions: no fused rate to calibrate against")
    use = np.ones(n, dtype=bool) if use is None else np.asarray(use, dtype=bool)
    runs = [(a, b) for a, b in true_runs(use) if b - a >= 2]
    k = sum(b - a for a, b in runs)
    if k < MIN_SAMPLES_PER_UNKNOWN * 3 * N:
        raise InputError(f"self-calibration needs at least {MIN_SAMPLES_PER_UNKNOWN * 3 * N} moving "
                         f"samples (not still, no gyro at its output limit) for {3 * N} unknowns, "
                         f"the record has {k}: record more motion about all three axes")
    W = _whitening(R, N)
    V = linalg.null_space((W @ H).T).T
    P = V @ W                                                  # P H = 0, P R Pᵀ = I
    Vu = linalg.null_space(H.T).T                              # unwhitened, for rms in deg/s
    U, Wt, names = tilt_axes(H)
    Q = P.T @ P                                                # (N, N)
    E_prev = np.zeros((N, 3))
    for _ in range(REFINE_PASSES + 1):
        # ω̂ from the readings less the errors fitted so far: the regressor's own error (ω̂ − ω =
        # G E ω) is second order in E, and each pass takes one more order out
        rows_normal = np.zeros((3 * N, 3 * N))
        rhs = np.zeros(3 * N)
        sq = 0.0
        pieces = []                                            # per run, demeaned
        for a, b in runs:
            om = fused_rate(y[a:b], H, R)
            om = fused_rate(y[a:b] - om @ E_prev.T, H, R)
            g = np.stack([om @ H.T, om @ U.T, om @ Wt.T], axis=2)  # (len, N, 3): s, tilt u, v
            g -= g.mean(axis=0, keepdims=True)
            p = y[a:b] @ P.T
            p -= p.mean(axis=0, keepdims=True)
            r = p @ P                                          # Pᵀ p_k: (len, N)
            gf = g.reshape(g.shape[0], 3 * N)
            rows_normal += (gf.T @ gf) * np.kron(Q, np.ones((3, 3)))
            rhs += (g * r[:, :, None]).reshape(-1, 3 * N).sum(axis=0)
            sq += float(np.sum(p * p))
            pieces.append((a, gf, p, y[a:b] @ Vu.T, om))
        # gauge and what the motion does not excite: eigen-decomposition of the normal matrix
        lam, vec = np.linalg.eigh(0.5 * (rows_normal + rows_normal.T))
        tol = max(float(lam[-1]), 1e-300) * 1e-10
        keep = lam > tol
        Ninv = (vec[:, keep] / lam[keep]) @ vec[:, keep].T
        theta = Ninv @ rhs
        th_g = theta
        if gauge == "majority":                                # ω̂ in the frame of the majority
            rss = max(sq - float(theta @ rhs), 0.0) / max(k * P.shape[0], 1)
            th_g = theta - _majority_gauge(theta, np.sqrt(np.maximum(np.diag(Ninv), 0.0) * rss),
                                           H, U, Wt) @ theta
        E_prev = _error_matrix(th_g, H, U, Wt)
    # which parameters are identified: the null space beyond the 9-dimensional gauge
    Z = vec[:, ~keep]
    gauge_q = _gauge_basis(H, U, Wt)
    extra_null = Z.shape[1] > gauge_q.shape[1]
    ident = np.ones(3 * N, dtype=bool)
    if extra_null:
        Pz = Z @ Z.T - gauge_q @ gauge_q.T                         # projector on the unseen beyond gauge
        ident = np.einsum("ij,ij->j", Pz, np.eye(3 * N)) < 1e-6
    # residuals, sandwich covariance over blocks
    L = max(1, int(round(block_s / dt_s)))
    Omega = np.zeros((3 * N, 3 * N))
    res_sq, res_u, raw_u, cnt = 0.0, 0.0, 0.0, 0
    E = _error_matrix(theta, H, U, Wt)
    ex_rows, ex_b = [], []
    for a, gf, p, pu, om in pieces:
        fit = (gf.reshape(-1, N, 3) * theta.reshape(N, 3)[None]).sum(axis=2) @ P.T
        e = p - fit
        res_sq += float(np.sum(e * e))
        ex_rows.append(np.c_[np.sum(om * om, axis=1), jerk2(om, dt_s)])
        ex_b.append(np.mean(e * e, axis=1) - 1.0)
        fit_u = om @ E.T @ Vu.T
        pu = pu - pu.mean(axis=0)
        fit_u -= fit_u.mean(axis=0)
        res_u += float(np.sum((pu - fit_u) ** 2))
        raw_u += float(np.sum(pu * pu))
        cnt += pu.size
        s = (gf.reshape(-1, N, 3) * (e @ P)[:, :, None]).reshape(-1, 3 * N)   # per-sample scores
        for j in range(0, s.shape[0], L):
            sb = s[j:j + L].sum(axis=0)
            Omega += np.outer(sb, sb)
    # classical covariance σ̂²(AᵀA)⁺, inflated by the sandwich's median excess over it (the residual
    # of a real array is not white); the sandwich itself is too noisy to invert for the Wald test
    # (with B blocks and p terms its inverse is biased up by about B/(B − p − 1))
    dof_res = max(k * P.shape[0] - int(np.sum(keep)) - len(runs) * P.shape[0], 1)
    s2 = res_sq / dof_res
    classical = s2 * Ninv
    dc = np.diag(classical)
    ok = dc > 0
    infl = max(1.0, float(np.median(np.diag(Ninv @ Omega @ Ninv)[ok] / dc[ok]))) if ok.any() else 1.0
    cov = infl * classical
    gauge_text = ("H^T E = 0: errors relative to the array's mean (a common scale factor or axis "
                  "transform of all gyros is invisible without a reference rate)")
    if gauge == "majority":
        M = _majority_gauge(theta, np.sqrt(np.maximum(np.diag(cov), 0.0)), H, U, Wt)
        theta = theta - M @ theta
        cov = (np.eye(3 * N) - M) @ cov @ (np.eye(3 * N) - M).T
        gauge_text = ("majority: errors relative to the common axis transform that most gyros share "
                      "(a common scale factor or axis transform of all gyros is invisible without "
                      "a reference rate)")
    elif gauge != "mean":
        raise InputError(f"gauge must be 'majority' or 'mean', got {gauge!r}")
    Xe, be = np.vstack(ex_rows), np.concatenate(ex_b)
    cs = np.maximum(Xe.max(axis=0), 1e-300)                    # column scaling for NNLS
    excess = tuple(float(v) for v in optimize.nnls(Xe / cs, be)[0] / cs)
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    sig[~ident] = np.nan
    th = np.where(ident, theta, np.nan)
    zz = np.where(ident & (sig > 0), th / np.where(sig > 0, sig, 1.0), np.nan)
    z3 = zz.reshape(N, 3)
    # off: the gyro's three terms together as far from 0 as one term Z_OFF σ away (χ² with as many
    # dof as it has identified terms, at the two-sided tail probability of Z_OFF)
    z2 = np.nan_to_num(z3, nan=0.0) ** 2
    n_id = np.sum(np.isfinite(z3), axis=1)
    p_off = 2.0 * stats.norm.sf(Z_OFF)
    lim = np.where(n_id > 0, stats.chi2.isf(p_off, np.maximum(n_id, 1)), np.inf)
    off = tuple(int(i) + 1 for i in np.flatnonzero(z2.sum(axis=1) > lim))
    # Wald test of all identified terms = 0 (rank of the identified space)
    r_keep = int(np.sum(keep)) - (int(np.sum(~ident)) if extra_null else 0)
    th_id = np.where(ident, theta, 0.0)
    chi2 = float(th_id @ rows_normal @ th_id) / (infl * s2) if s2 > 0 else float("nan")
    dof = max(r_keep, 1)
    pval = float(stats.chi2.sf(chi2, dof)) if math.isfinite(chi2) else float("nan")
    rate = math.sqrt(sum(float(np.sum(om * om)) for *_, om in pieces) / max(k, 1))
    notes = []
    if extra_null:
        notes.append(f"the motion does not excite every axis: {int(np.sum(~ident))} of the {3 * N} "
                     "terms are not identified (σ None); turn the array about all three axes")
    th3 = th.reshape(N, 3)
    s3 = sig.reshape(N, 3)
    observable = None
    if N == 4:
        # one parity equation: only c = vᵀE (3 numbers, gauge-free since vᵀH = 0) is seen; which
        # gyro carries it cannot be told, so no gyro is named off
        observable = _observable_4(theta, cov, H, U, Wt, Vu[0], (Pz if extra_null else None))
        off = ()
        notes.append(observable["statement"])
    return ParityCalibration(
        gauge_dependent=N == 4, observable=observable,
        scale_ppm=th3[:, 0] * 1e6, scale_sigma_ppm=s3[:, 0] * 1e6,
        tilt_mrad=th3[:, 1:] * 1e3, tilt_sigma_mrad=s3[:, 1:] * 1e3, toward=names, z=z3, off=off,
        E=_error_matrix(np.where(np.isfinite(th), th, 0.0), H, U, Wt), n_samples=int(k), rms_rate_deg_s=float(rad_s_to_deg_s(rate)),
        parity_rms_deg_s=(float(rad_s_to_deg_s(math.sqrt(raw_u / max(cnt, 1)))),
                          float(rad_s_to_deg_s(math.sqrt(res_u / max(cnt, 1))))),
        explained=float(1.0 - res_sq / sq) if sq > 0 else 0.0, chi2=chi2, dof=int(dof),
        p_value=pval, excess=excess, gauge=gauge_text, notes=tuple(notes))


def _observable_4(theta, cov, H, U, Wt, v, Pz) -> dict:
    """What a 4-gyro record determines: c = Σ_i v_i e_i [ppm] per body axis with its σ and z
    (None where the motion leaves it unseen, ``Pz`` the projector on the unseen beyond gauge)."""
    v = v * np.sign(v[int(np.argmax(np.abs(v)))])
    N = H.shape[0]
    J = np.zeros((3, 3 * N))                                   # c = J θ
    for i in range(N):
        J[:, 3 * i], J[:, 3 * i + 1], J[:, 3 * i + 2] = v[i] * H[i], v[i] * U[i], v[i] * Wt[i]
    c = J @ theta
    sc = np.sqrt(np.maximum(np.diag(J @ cov @ J.T), 0.0))
    seen = np.ones(3, dtype=bool)
    if Pz is not None:
        seen = np.diag(J @ Pz @ J.T) <= 1e-6 * np.diag(J @ J.T)
    c, sc = np.where(seen, c, np.nan), np.where(seen, sc, np.nan)
    z = np.where(seen & (sc > 0), c / np.where(sc > 0, sc, 1.0), np.nan)
    vs = ", ".join(f"{x:+.4f}" for x in v)
    statement = ("4 gyros give one parity equation (N − 3 = 1): the record determines only the 3 "
                 f"numbers c = Σ_i v_i e_i, v = [{vs}] (e_i gyro i's error row: scale factor along "
                 "its axis, tilts across), the parity's response to a rate about x, y, z "
                 f"(observable: c = [{', '.join('unseen' if not math.isfinite(x) else f'{x * 1e6:.4g}' for x in c)}] "
                 "ppm); the per-gyro scale factors and tilts are gauge-dependent (one split of c "
                 "over the gyros; any other fits as well), not per-gyro errors, and no gyro can be "
                 "named off (with 5 or more gyros, N − 3 >= 2 parity equations, one off gyro can be singled out)")
    return {"parity_vector": [float(x) for x in v], "response_ppm": c * 1e6, "sigma_ppm": sc * 1e6,
            "z": z, "statement": statement}


def jerk2(om: np.ndarray, dt_s: float) -> np.ndarray:
    """|ω̂'|² per sample [rad²/s⁴]: the larger of the backward and forward differences (a sampling
    instant that differs between gyros shows at the sharpest change next to the sample)."""
    if om.shape[0] < 2:
        return np.zeros(om.shape[0])
    d = np.sum(np.diff(om, axis=0) ** 2, axis=1) / dt_s ** 2
    return np.maximum(np.r_[d[:1], d], np.r_[d, d[-1:]])


def _error_matrix(theta: np.ndarray, H, U, Wt) -> np.ndarray:
    """E (N, 3): row i = s_i h_i + a_i u_i + c_i v_i."""
    t = theta.reshape(-1, 3)
    return t[:, :1] * H + t[:, 1:2] * U + t[:, 2:3] * Wt


def _gauge_map(H, U, Wt) -> np.ndarray:
    """B (3N, 9): θ of E = H A for the 9 unit matrices A (column r·3 + c: A[r, c] = 1)."""
    cols = []
    for r in range(3):
        for c in range(3):
            A = np.zeros((3, 3))
            A[r, c] = 1.0
            E = H @ A                                          # rows h_iᵀ A
            cols.append(np.stack([np.sum(E * H, axis=1), np.sum(E * U, axis=1),
                                  np.sum(E * Wt, axis=1)], axis=1).reshape(-1))
    return np.array(cols).T


def _majority_gauge(theta, sig, H, U, Wt, iterations: int = 50) -> np.ndarray:
    """The linear map M (3N, 3N) with θ − Mθ the errors relative to the majority's transform.

    A minimises Σ_i ‖θ_i − (B a)_i‖ (a group L1 norm, robust to a minority of gyros that
    are off) by iteratively reweighted least squares, w_i = 1/max(‖r_i‖, δ), δ the median
    σ of the terms; at convergence Bâ = Mθ with M = B (BᵀWB)⁻¹BᵀW.
    """
    B = _gauge_map(H, U, Wt)
    N = H.shape[0]
    fin = sig[np.isfinite(sig) & (sig > 0)]
    delta = float(np.median(fin)) if fin.size else 1e-12
    w = np.ones(N)
    M = np.zeros((3 * N, 3 * N))
    for _ in range(iterations):
        Wd = np.repeat(w, 3)
        BtW = B.T * Wd[None, :]
        M = B @ np.linalg.pinv(BtW @ B) @ BtW
        r = (theta - M @ theta).reshape(N, 3)
        w_new = 1.0 / np.maximum(np.linalg.norm(r, axis=1), delta)
        if np.allclose(w_new, w, rtol=1e-6):
            break
        w = w_new
    return M


def _gauge_basis(H, U, Wt) -> np.ndarray:
    """Orthonormal basis (3N, 9) of the θ that give E = H A (invisible to the parity)."""
    q, _ = np.linalg.qr(_gauge_map(H, U, Wt))
    return q


def calibrate_measurement(meas: Measurement, *, R: np.ndarray | None = None,
                          still: np.ndarray | None = None) -> ParityCalibration | None:
    """:func:`self_calibrate` on the moving, unsaturated samples of a record.

    Parameters
    ----------
    meas : Measurement
    R : ndarray, shape (N, N), optional
        White-noise covariance of one sample [rad²/s²] (default alike gyros).
    still : ndarray of bool, shape (n,), optional
        Still samples (default :func:`~gyroarray.analysis.motion.still_mask`).

    Returns
    -------
    ParityCalibration or None
        None when the record has too little motion (rms variation of the fused
        rate of the moving samples below :data:`MIN_MOTION_DEG_S`, or too few
        samples). A record in which no still part is found but whose rate
        varies that much is fitted whole. :func:`calibrate_record` says why.
    """
    return _calibrate_or_reason(meas, R, still)[0]


def _calibrate_or_reason(meas: Measurement, R: np.ndarray | None = None,
                         still: np.ndarray | None = None) -> tuple[ParityCalibration | None, str | None]:
    """:func:`calibrate_measurement` and, when it gives None, why (one sentence)."""
    y = meas.gyro_rad_s
    H = meas.layout.H
    if meas.n_gyros < 4 or np.linalg.matrix_rank(H) < 3:
        return None, (f"the parity self-calibration needs at least 4 gyros whose axes span 3-D, the "
                      f"measurement has {meas.n_gyros}")
    if still is None:
        try:
            still = still_mask(y, H, meas.dt_s)
        except InputError:                                     # fewer than 3 windows: all of it
            still = np.zeros(y.shape[0], dtype=bool)
    sat, clip = saturated_mask(y)
    need = MIN_SAMPLES_PER_UNKNOWN * 3 * meas.n_gyros
    use = ~np.asarray(still, dtype=bool) & ~sat
    whole = False
    if use.sum() < need and (~sat).sum() >= need:
        # the still test assumes a mostly still record: one that turns all the time can read as
        # still throughout; then the whole record is used if its rate varies enough
        om_all = fused_rate(y[~sat], H, R)
        whole = _rms_variation_deg_s(om_all) >= MIN_MOTION_DEG_S
        if whole:
            use = ~sat
    if use.sum() < need or (not whole and _rms_variation_deg_s(fused_rate(y[use], H, R)) < MIN_MOTION_DEG_S):
        return None, _no_calibration_reason(y, H, R, use, sat, need)
    cal = self_calibrate(y, H, meas.dt_s, R=R, use=use)
    if whole:
        cal = _with_notes(cal, list(cal.notes) + ["no still part found: the whole record is fitted"])
    n_sat = int(sat.sum())
    if n_sat:
        n_at = int(np.sum((np.abs(y) >= np.nan_to_num(clip, nan=np.inf)[None, :]).any(axis=1)))
        notes = list(cal.notes) + [f"{n_at * meas.dt_s:.3g} s with a gyro at its output limit "
                                   f"({n_sat * meas.dt_s:.3g} s with {SATURATION_GUARD} samples on "
                                   "each side) left out: a saturated gyro reads its limit, not its rate"]
        cal = _with_notes(cal, notes)
    return cal, None


def _no_calibration_reason(y, H, R, use, sat, need: int) -> str:
    """Why a record gives no parity self-calibration: too short, no motion, too few moving samples."""
    n, N = y.shape
    what = (f"parity self-calibration of {N} gyros needs at least {need} moving samples "
            f"({MIN_SAMPLES_PER_UNKNOWN} per unknown, 3 unknowns per gyro)")
    if n < need:
        return f"the record has {n} samples: {what}; record longer, turning about all three axes"
    spread = _rms_variation_deg_s(fused_rate(y, H, R))
    moving = _rms_variation_deg_s(fused_rate(y[use], H, R)) if use.any() else 0.0
    if spread < MIN_MOTION_DEG_S or (use.sum() >= need and moving < MIN_MOTION_DEG_S):
        return (f"the record has no motion: parity self-calibration needs the array to turn, its fused "
                f"rate varying by at least {MIN_MOTION_DEG_S:g} deg/s rms over the moving samples (about "
                f"all three axes to identify every term); the rate's spread is {spread:.3g} deg/s"
                + (f" ({moving:.3g} deg/s over the {int(use.sum())} moving samples)" if use.any() else ""))
    return (f"too few moving samples: {int(use.sum())} of the record's {n} samples are moving with no "
            f"gyro at its output limit ({int(sat.sum())} near a limit): {what}; record more motion")


def calibrate_record(meas: Measurement, model=None) -> tuple[ParityCalibration, list]:
    """``gyroarray parity``: :func:`calibrate_measurement` with the record's own noise weighting.

    Parameters
    ----------
    meas : Measurement
    model : NoiseModel, optional
        White noise (and ``[array]`` correlations) of the gyros; default each
        gyro's own level on the record's still parts
        (:func:`gyroarray.estimators.fdi.estimate_noise`).

    Returns
    -------
    ParityCalibration, list of str (notes)

    Raises
    ------
    InputError
        Fewer than 4 gyros, axes that do not span 3 dimensions, a model the
        parity cannot be weighted with, a record too short or with too little
        motion (the reason, with the rate's spread) (each naming the file).
    """
    if meas.n_gyros < 4:
        raise InputError(f"the parity self-calibration needs at least 4 gyros (a parity), the "
                         f"measurement has {meas.n_gyros}", file=meas.source)
    H = meas.layout.H
    if np.linalg.matrix_rank(H) < 3:
        raise InputError("the gyros' axes do not span 3 dimensions: no fused rate to calibrate "
                         "against; check the sidecar's [layout]", file=meas.source)
    notes = list(meas.notes)
    try:
        still = still_mask(meas.gyro_rad_s, H, meas.dt_s)
    except InputError:
        still = None
    if model is not None:
        try:
            R = model_noise(model, meas.n_gyros).R(meas.dt_s)
        except InputError as err:
            raise InputError(err.message, file=getattr(model, "source", None) or meas.source) from None
        notes.append("parity weighted by the model's white noise")
    else:
        try:
            noise, more = estimate_noise(meas.gyro_rad_s, meas.layout, meas.dt_s, None, still=still)
            R = noise.R(meas.dt_s)
            notes += more
        except InputError as err:
            R = None
            notes.append(f"the gyros' noise could not be fitted ({err.message}): the parity is "
                         "weighted as for alike gyros")
    if meas.has_reference:
        notes.append("the record's reference rate is not used: the parity needs none (compare "
                     "gives the absolute errors against it)")
    cal, why = _calibrate_or_reason(meas, R=R, still=still)
    if cal is None:
        raise InputError(why or "no parity self-calibration", file=meas.source)
    return cal, notes


def _rms_variation_deg_s(om: np.ndarray) -> float:
    """Rms of the rate about its mean [deg/s] (a constant rate or bias is no motion)."""
    if om.shape[0] == 0:
        return 0.0
    d = om - om.mean(axis=0)
    return float(rad_s_to_deg_s(math.sqrt(float(np.mean(np.sum(d * d, axis=1))))))


def _with_notes(cal: ParityCalibration, notes: list) -> ParityCalibration:
    return replace(cal, notes=tuple(notes))


def format_parity(cal: ParityCalibration | None, source: str) -> str:
    """The text of ``gyroarray parity``: one line per gyro, the off gyros, the gauge."""
    if cal is None:
        return (f"{source}: too little motion for a parity self-calibration (the array must turn, "
                f"rate varying by >= {MIN_MOTION_DEG_S:g} deg/s rms over the moving samples)")
    out = [f"{source}: parity self-calibration on {cal.n_samples} moving samples "
           f"(rms rate {cal.rms_rate_deg_s:.4g} deg/s)",
           f"parity rms {cal.parity_rms_deg_s[0]:.4g} deg/s, {cal.parity_rms_deg_s[1]:.4g} deg/s "
           f"after the fitted errors ({100 * cal.explained:.1f} % of the parity variance explained); "
           f"Wald chi2 {cal.chi2:.4g} on {cal.dof} dof, p = {cal.p_value:.3g}",
           "gyro  scale factor [%]      tilt 1 [mrad]          tilt 2 [mrad]"]
    if cal.gauge_dependent and cal.observable is not None:
        ob = cal.observable
        cells = []
        for ax, c, sg in zip(_AXIS_NAMES, ob["response_ppm"], ob["sigma_ppm"]):
            cells.append(f"{ax} unseen" if not math.isfinite(sg) else f"{ax} {c:+.4g} ± {sg:.3g}")
        out[-1:] = [f"observable (the one parity equation's response to a rate, c = Σ v_i e_i with "
                    f"v = [{', '.join(f'{x:+.4f}' for x in ob['parity_vector'])}]): "
                    + ", ".join(cells) + " ppm",
                    "gauge-dependent split over the gyros (NOT per-gyro errors: with 4 gyros any "
                    "split of c fits as well)",
                    "gyro  scale factor [%]      tilt 1 [mrad]          tilt 2 [mrad]"]
    for i in range(cal.scale_ppm.size):
        def pm(v, s, f=1.0):
            return "not identified" if not math.isfinite(s) else f"{v * f:+8.3f} ± {s * f:6.3f}"
        t1, t2 = cal.toward[i]
        flag = "  OFF" if (i + 1) in cal.off else ""
        out.append(f"{i + 1:>4}  {pm(cal.scale_ppm[i], cal.scale_sigma_ppm[i], 1e-4)}   "
                   f"{pm(cal.tilt_mrad[i, 0], cal.tilt_sigma_mrad[i, 0])} →{t1}   "
                   f"{pm(cal.tilt_mrad[i, 1], cal.tilt_sigma_mrad[i, 1])} →{t2}{flag}")
    if cal.gauge_dependent:
        out.append("off: cannot be told with 4 gyros (one parity equation); motion-dependent parity "
                   + ("detected" if cal.p_value < 1e-3 else "not detected") + f" (p = {cal.p_value:.3g})")
    else:
        out.append("off (terms together beyond the %g-sigma tail): %s" % (Z_OFF, ", ".join(map(str, cal.off)) or "none"))
    out.append(f"gauge: {cal.gauge}")
    c2, d2 = cal.excess
    if c2 > 0 or d2 > 0:
        out.append(f"left over: the parity's spread grows with the motion beyond the fitted errors, "
                   f"x{math.sqrt(1 + c2 * math.radians(1000.0) ** 2):.3g} of the white level at "
                   f"1000 deg/s, x{math.sqrt(1 + d2 * math.radians(1e4) ** 2):.3g} at 10^4 deg/s^2")
    out += list(cal.notes)
    return "\n".join(out)
