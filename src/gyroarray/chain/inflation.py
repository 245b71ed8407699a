"""The noise an IMU shows in motion, measured against a reference attitude (issue 42, item 6).

Users' calibrated (static) noise values fail in motion, and they inflate them by a guess. A bag
that holds the IMU and a reference attitude (motion capture, a VIO/SLAM odometry output) can
measure the inflation: :func:`measure_inflation` estimates the white-noise density the gyros
show per motion level and checks it on a held-out segment with a plain filter.

Method
------
1. **Alignment.** IMU stamps t_i (in the reference's time base; a constant offset may be
   given, or estimated: ``time_offset_s="estimate"``, by the cross-correlation of the rate
   magnitudes, parabolic peak, then refined by least squares of the windowed error on the
   windowed angular acceleration). The reference attitude is interpolated (slerp) onto the
   IMU stamps inside the common span. Gyro sample i is held over [t_i, t_i+1).
2. **Error.** Per IMU step the error angle ε_i = ω_imu,i·Δt_i − Log(R_iᵀ R_i+1) (body frame);
   over a window of T (``window_s``, whole IMU steps) e_k = Σε_i / T [rad/s] = bias + white
   noise (variance N²/T per axis) + the reference's attitude noise (ρ̃_start − ρ̃_end)/T.
   With the reference's attitude noise σ_ref white per pose and isotropic, an endpoint
   interpolated between poses m, m+1 with weight α holds (1−α)ρ_m + αρ_m+1, so the variance
   it adds is σ_ref²·(c_aa + c_bb − 2c_ab)/T² with c the known interpolation overlaps
   (2σ_ref²/T² for endpoints on poses).
3. **σ_ref** from the lag structure of short windows (about two pose intervals): adjacent
   windows share an endpoint, so their errors correlate by −σ_ref²·c/T² while the white noise
   does not correlate at all. Taken from the static part (|ω| below ``static_rate_rad_s`` over
   ``STATIC_SMOOTH_S``) when it has :data:`MIN_STATIC_WINDOWS` short windows, else from all of
   them (the rotation within a short window neglected); each run's mean (bias) removed, and the
   mean removal's own share solved for with the static density (two equations, two unknowns).
4. **Bias** as a slow walk: for each long window the mean of its neighbours within ±``bias_span``
   windows, leaving out the window and its two adjacent ones (no shared endpoint, so the
   reference noise of the window and of the bias estimate are independent).
5. **Density per motion level**: each long window gets the mean |ω| of the reference
   (smoothed over :data:`LEVEL_SMOOTH_S`) as its level (bins ``levels`` [rad/s]; with an
   accelerometer also bins of |‖f‖ − g0| [m/s²], reported beside). With r_k = e_k − b̂_k,
   E[r_k²]·T = N_L² + (neighbour share) + T·(reference share) + T·(walk share, with the given
   K); N_L² is solved for by a fixed point over the levels, pooled over the three axes and per
   axis. CI: Σr² is a scaled χ² with ν = 3·n_L (n_L per axis) windows, reduced by (1 + 2/m)
   for the correlation the shared neighbours bring (m neighbours), shifted by the corrections
   and widened by z·σ of the reference share.
6. **Held-out check.** The last ``holdout`` fraction of the motion segment (from the first
   window above ``static_rate_rad_s``) is not used in steps 4–5. A scalar Kalman filter per
   axis (state: bias, random walk Q = K²·Δt; measurement e_k with R = N²/T + reference share)
   runs over every window and its normalised innovation squared NIS = ν²/S is averaged over the
   held-out windows and axes, with (a) the measured level densities, (b) the static N, K and
   (c) the static N, K times ``factor_for_export``. A consistent filter has mean NIS 1 within
   1 ± z·√(2/n_eff + v) (χ²₁ mean of n_eff independent innovations; v the variance the
   estimated densities add, zero for the static values).
7. ``factor_for_export`` f: the factor on the static N and K that makes the plain white + walk
   filter of step 6 consistent (mean NIS 1) on the fitted motion windows (:func:`nis_factor`;
   what ``--inflate auto`` finds on a simulated record), at least 1. The motion-weighted
   density √(Σ_L w_L N_L²) / N_static (w_L the share of the fitted motion windows at level L)
   is reported beside it (``density_factor``): with the walk scaled too and the levels mixed,
   the two differ (robot_localization's Husky, z: 25.0 against the NIS's 16.8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from gyroarray.core.bag_reference import Reference
from gyroarray.core.constants import G0_M_S2
from gyroarray.core.errors import InputError

__all__ = ["DEFAULT_LEVELS_RAD_S", "DEFAULT_ACC_LEVELS_M_S2", "LevelDensity", "NisCheck",
           "MeasuredInflation", "measure_inflation", "inflation_for_export"]

#: Bin edges of the rate magnitude |ω| [rad/s].
DEFAULT_LEVELS_RAD_S = (0.0, 0.05, 0.2, 0.5, 1.0, 1.5, 2.5, 4.0, math.inf)
#: Bin edges of |‖f‖ − g0| [m/s²] (IMUs with an accelerometer).
DEFAULT_ACC_LEVELS_M_S2 = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, math.inf)
#: Fewest long windows a level needs to get a density [-].
MIN_LEVEL_WINDOWS = 20
#: Fewest short windows the σ_ref estimate of the static part needs [-].
MIN_STATIC_WINDOWS = 200
#: Span over which the reference rate is smoothed to call a stretch static [s].
STATIC_SMOOTH_S = 1.0
#: Span over which the reference rate is smoothed for the level of a window [s].
LEVEL_SMOOTH_S = 0.1
#: Longest stretch of short windows whose mean is removed together (no static part) [s].
CHUNK_S = 10.0
#: A step longer than this many median steps is a gap (windows across it are dropped) [-].
GAP_FACTOR = 1.5
#: Fewest long windows of common span [-].
MIN_WINDOWS = 50


@dataclass(frozen=True)
class LevelDensity:
    """The white-noise density at one motion level.

    Parameters
    ----------
    lo, hi : float
        Bin edges [rad/s for rate levels, m/s² for acceleration levels].
    n_windows : int
        Long windows of the fitted part in the bin.
    mean_level : float
        Mean level of those windows [rad/s or m/s²].
    density_rad_rt_s : float
        Pooled-axes white density N [rad/√s] (nan when too few windows).
    ci_rad_rt_s : tuple of float
        Its confidence interval [rad/√s].
    axis_density_rad_rt_s : tuple of float
        Per axis (x, y, z) [rad/√s].
    axis_ci_rad_rt_s : tuple of tuple
        Their intervals [rad/√s].
    factor : float
        density / static density [-] (nan without a static value).
    """

    lo: float
    hi: float
    n_windows: int
    mean_level: float
    density_rad_rt_s: float
    ci_rad_rt_s: tuple[float, float]
    axis_density_rad_rt_s: tuple[float, float, float]
    axis_ci_rad_rt_s: tuple[tuple[float, float], ...]
    factor: float

    def as_dict(self) -> dict:
        return {"lo": self.lo, "hi": self.hi, "n_windows": self.n_windows,
                "mean_level": self.mean_level, "density_rad_rt_s": self.density_rad_rt_s,
                "ci_rad_rt_s": list(self.ci_rad_rt_s),
                "axis_density_rad_rt_s": list(self.axis_density_rad_rt_s),
                "axis_ci_rad_rt_s": [list(c) for c in self.axis_ci_rad_rt_s],
                "factor": self.factor}


@dataclass(frozen=True)
class NisCheck:
    """Mean NIS of the held-out segment for one set of values.

    Parameters
    ----------
    label : str
        ``"measured"``, ``"static"`` or ``"export"``.
    mean_nis : float
        Mean normalised innovation squared [-] (1 for a consistent filter).
    interval : tuple of float
        Its interval under consistency [-].
    n_eff : int
        Independent innovations (held-out windows × axes) [-].
    inside : bool
        ``interval[0] <= mean_nis <= interval[1]``.
    axis_mean_nis : tuple of float
        Per axis [-].
    """

    label: str
    mean_nis: float
    interval: tuple[float, float]
    n_eff: int
    inside: bool
    axis_mean_nis: tuple[float, float, float]

    def as_dict(self) -> dict:
        return {"label": self.label, "mean_nis": self.mean_nis, "interval": list(self.interval),
                "n_eff": self.n_eff, "inside": self.inside,
                "axis_mean_nis": list(self.axis_mean_nis)}


@dataclass(frozen=True)
class MeasuredInflation:
    """What :func:`measure_inflation` found.

    Parameters
    ----------
    levels : tuple of LevelDensity
        Per rate level (every bin; too few windows give nan densities).
    acc_levels : tuple of LevelDensity
        Per acceleration level (empty without an accelerometer).
    static_n_rad_rt_s, static_k_rad_s_rt_s : float
        The static values compared with [rad/√s, rad/s/√s].
    sigma_ref_rad : float
        The reference's attitude noise per pose, per axis [rad].
    sigma_ref_sd_rad2 : float
        Standard deviation of the σ_ref² estimate [rad²].
    time_offset_s : float
        Offset added to the IMU stamps [s].
    window_s : float
        Long window T [s].
    nis : tuple of NisCheck
        measured, static, export.
    factor_for_export : float
        Inflation factor for the export [-], ≥ 1: the one that makes a white + walk filter with
        the static values times it consistent on the fitted motion windows (:func:`nis_factor`).
    factor_ci : tuple of float
        Its interval (before the clamp to 1) [-].
    axis_factor : tuple of float
        Per axis, ≥ 1 [-] (NaN on an axis the reference does not observe).
    windows_t0_s : ndarray
        Start of each long window [s, reference time base].
    windows_level : ndarray
        Its rate-level index (into ``levels``).
    windows_holdout : ndarray of bool
        Held out (True) or fitted.
    notes : tuple of str
        How it was done, what was assumed.
    unobserved_axes : tuple of str
        Body axes about which the reference never turns over the common span ("x", "y" for a
        planar reference: a ground robot's wheel odometry holds roll and pitch at 0) while the
        gyro does: there the "motion noise" is the body's own motion, not the gyro's noise.
    density_factor : float
        √(Σ_L w_L N_L²) / N_static, the motion-weighted measured density over the static one [-]
        (w_L the share of the fitted motion windows at level L), reported beside the factor.
    density_factor_ci : tuple of float
        Its interval (parametric bootstrap of the level χ²s) [-].
    """

    levels: tuple[LevelDensity, ...]
    acc_levels: tuple[LevelDensity, ...]
    static_n_rad_rt_s: float
    static_k_rad_s_rt_s: float
    sigma_ref_rad: float
    sigma_ref_sd_rad2: float
    time_offset_s: float
    window_s: float
    nis: tuple[NisCheck, ...]
    factor_for_export: float
    factor_ci: tuple[float, float]
    axis_factor: tuple[float, float, float]
    windows_t0_s: np.ndarray
    windows_level: np.ndarray
    windows_holdout: np.ndarray
    notes: tuple[str, ...] = field(default_factory=tuple)
    unobserved_axes: tuple[str, ...] = ()
    density_factor: float = math.nan
    density_factor_ci: tuple[float, float] = (math.nan, math.nan)

    def nis_check(self, label: str) -> NisCheck:
        """The NIS result of ``label`` (measured, static, export)."""
        return next(c for c in self.nis if c.label == label)

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {"levels": [lv.as_dict() for lv in self.levels],
                "acc_levels": [lv.as_dict() for lv in self.acc_levels],
                "static_n_rad_rt_s": self.static_n_rad_rt_s,
                "static_k_rad_s_rt_s": self.static_k_rad_s_rt_s,
                "sigma_ref_rad": self.sigma_ref_rad, "sigma_ref_sd_rad2": self.sigma_ref_sd_rad2,
                "time_offset_s": self.time_offset_s, "window_s": self.window_s,
                "nis": [c.as_dict() for c in self.nis],
                "factor_for_export": self.factor_for_export, "factor_ci": list(self.factor_ci),
                "axis_factor": list(self.axis_factor), "notes": list(self.notes),
                "unobserved_axes": list(self.unobserved_axes),
                "density_factor": self.density_factor, "density_factor_ci": list(self.density_factor_ci)}


# ---------------------------------------------------------------------------------------------
# alignment
# ---------------------------------------------------------------------------------------------
def _rotations(quat_wxyz: np.ndarray):
    from scipy.spatial.transform import Rotation      # deferred: heavy
    return Rotation.from_quat(np.asarray(quat_wxyz)[:, [1, 2, 3, 0]])


def _slerp(ref: Reference, t: np.ndarray):
    """Reference rotations at times ``t`` (inside its span), with the pose index m and the
    weight α of each: R(t) = R_m·Exp(α·Log(R_mᵀ R_m+1))."""
    from scipy.spatial.transform import Rotation      # deferred: heavy
    tau = ref.time_s
    r = _rotations(ref.quat_wxyz)
    rel = (r[:-1].inv() * r[1:]).as_rotvec()
    m = np.clip(np.searchsorted(tau, t, side="right") - 1, 0, tau.size - 2)
    alpha = np.clip((t - tau[m]) / (tau[m + 1] - tau[m]), 0.0, 1.0)
    rot = r[m] * Rotation.from_rotvec(alpha[:, None] * rel[m])
    return rot, m, alpha


def _overlap(imu_t: np.ndarray, ref: Reference) -> tuple[int, int]:
    """The IMU samples [i0, i1) inside the reference's span."""
    lo, hi = max(imu_t[0], ref.time_s[0]), min(imu_t[-1], ref.time_s[-1])
    i0 = int(np.searchsorted(imu_t, lo, side="left"))
    i1 = int(np.searchsorted(imu_t, hi, side="right"))
    return i0, i1


def moving_mean(x: np.ndarray, half: int) -> np.ndarray:
    """Centred moving mean over ±half rows (shorter at the ends), along axis 0."""
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    i = np.arange(x.shape[0])
    a, b = np.maximum(i - half, 0), np.minimum(i + half + 1, x.shape[0])
    return (c[b] - c[a]) / (b - a).reshape((-1,) + (1,) * (x.ndim - 1))


class _Steps:
    """Per-IMU-step quantities on the common span."""

    def __init__(self, t: np.ndarray, gyro: np.ndarray, ref: Reference):
        rot, m, alpha = _slerp(ref, t)
        self.t, self.m, self.alpha = t, m, alpha
        self.dt = np.diff(t)
        self.phi = (rot[:-1].inv() * rot[1:]).as_rotvec()          # reference step [rad]
        self.gamma = gyro[:-1] * self.dt[:, None]                   # IMU step [rad]
        self.eps = self.gamma - self.phi
        self.n = self.dt.size


def _ref_rate_smoothed(st: _Steps, span_s: float) -> np.ndarray:
    med = float(np.median(st.dt))
    half = max(1, int(round(0.5 * span_s / med)))
    return moving_mean(st.phi, half) / med


def _windows(st: _Steps, w: int, ref: Reference) -> dict:
    """Non-overlapping windows of ``w`` steps: angle error sums, lengths, endpoints, validity."""
    nk = st.n // w
    idx = np.arange(nk) * w
    sums = np.add.reduceat(st.eps[: nk * w], idx, axis=0) if nk else np.zeros((0, 3))
    lengths = st.t[idx + w] - st.t[idx]
    med = float(np.median(st.dt))
    gap = (st.dt > GAP_FACTOR * med)[: nk * w].reshape(nk, w).any(axis=1) if nk else np.zeros(0, bool)
    tau_step = np.diff(ref.time_s)
    tau_med = float(np.median(tau_step))
    # a pose interval longer than GAP_FACTOR medians inside a window: the slerp spans a gap
    pose_gap_at = tau_step > GAP_FACTOR * tau_med
    pg = np.zeros(nk, bool)
    if pose_gap_at.any() and nk:
        m_steps = st.m[: nk * w + 1]
        lo, hi = m_steps[idx], m_steps[idx + w]
        cum = np.concatenate([[0], np.cumsum(pose_gap_at)])
        pg = (cum[np.minimum(hi + 1, cum.size - 1)] - cum[lo]) > 0
    return {"sums": sums, "T": lengths, "start": idx, "end": idx + w,
            "valid": ~(gap | pg), "t0": st.t[idx]}


def _overlap_c(ma, aa, mb, ab) -> np.ndarray:
    """Σ_m w_a,m·w_b,m of two interpolated endpoints (pose indices m, weights α)."""
    ma, mb = np.asarray(ma), np.asarray(mb)
    out = np.where(ma == mb, (1 - aa) * (1 - ab) + aa * ab, 0.0)
    out = out + np.where(mb == ma + 1, aa * (1 - ab), 0.0)
    out = out + np.where(ma == mb + 1, (1 - aa) * ab, 0.0)
    return out


def _ref_var_coef(st: _Steps, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Var of (ρ̃_a − ρ̃_b) per axis, in units of σ_ref²."""
    ma, aa, mb, ab = st.m[a], st.alpha[a], st.m[b], st.alpha[b]
    return (_overlap_c(ma, aa, ma, aa) + _overlap_c(mb, ab, mb, ab)
            - 2 * _overlap_c(ma, aa, mb, ab))


# ---------------------------------------------------------------------------------------------
# σ_ref
# ---------------------------------------------------------------------------------------------
def _sigma_ref(st: _Steps, ref: Reference, static_rate: float, notes: list) -> tuple[float, float,
                                                                                      np.ndarray]:
    """σ_ref² [rad²], its standard deviation, and the static flag per step."""
    med = float(np.median(st.dt))
    tau_med = float(np.median(np.diff(ref.time_s)))
    ws = max(1, int(math.ceil(2.0 * tau_med / med - 1e-9)))
    smooth = np.linalg.norm(_ref_rate_smoothed(st, STATIC_SMOOTH_S), axis=1)
    static_step = smooth < static_rate
    win = _windows(st, ws, ref)
    nk = win["sums"].shape[0]
    stat_w = static_step[: nk * ws].reshape(nk, ws).all(axis=1) & win["valid"]
    use_static = int(stat_w.sum()) >= MIN_STATIC_WINDOWS
    if use_static:
        keep = stat_w
        where = f"the static part ({int(stat_w.sum())} short windows of {ws * med * 1e3:.3g} ms)"
    else:
        keep = win["valid"].copy()
        where = (f"all {int(keep.sum())} short windows of {ws * med * 1e3:.3g} ms (no static part "
                 f"of {MIN_STATIC_WINDOWS} windows below {static_rate:g} rad/s; the rotation within "
                 "a short window neglected)")
    # runs: contiguous kept windows, cut every CHUNK_S
    chunk = max(2, int(CHUNK_S / (ws * med)))
    run_id = np.cumsum(np.concatenate([[1], (~keep[1:] | ~keep[:-1]).astype(int)]))
    run_id = run_id * (nk // chunk + 2) + np.arange(nk) // chunk
    E = win["sums"]
    P = V = 0.0
    sum_coef = sum_v = 0.0
    n_kept = n_runs = 0
    for rid in np.unique(run_id[keep]):
        sel = np.flatnonzero(keep & (run_id == rid))
        if sel.size < 3:
            continue
        r = E[sel] - E[sel].mean(axis=0)
        s, e = win["start"][sel], win["end"][sel]
        v = _ref_var_coef(st, s, e)
        # lag-1: windows k, k+1 share endpoint b = e_k = s_k+1
        a, b, c = s[:-1], e[:-1], e[1:]
        cab = _overlap_c(st.m[a], st.alpha[a], st.m[b], st.alpha[b])
        cac = _overlap_c(st.m[a], st.alpha[a], st.m[c], st.alpha[c])
        cbb = _overlap_c(st.m[b], st.alpha[b], st.m[b], st.alpha[b])
        cbc = _overlap_c(st.m[b], st.alpha[b], st.m[c], st.alpha[c])
        coef = cab - cac - cbb + cbc
        P += float(np.sum(r[:-1] * r[1:])) / 3.0
        V += float(np.sum(r * r)) / 3.0
        sum_coef += float(coef.sum())
        sum_v += float(v.sum())
        n_kept += sel.size
        n_runs += 1
    if n_runs == 0 or sum_coef >= 0:
        notes.append("σ_ref: too few short windows to estimate it; taken as 0")
        return 0.0, 0.0, static_step
    # E[V] = (n − runs)·x + σ²·Σv ;  E[P] = σ²·Σcoef − runs·x   (x = N²·T_s, a run mean removed)
    a_mat = np.array([[n_kept - n_runs, sum_v], [-n_runs, sum_coef]], dtype=float)
    x, s2 = np.linalg.solve(a_mat, np.array([V, P]))
    gamma0 = V / max(n_kept, 1)
    sd = math.sqrt(max(n_kept, 1) / 3.0) * gamma0 / abs(sum_coef)
    if s2 < 0:
        notes.append(f"σ_ref² estimate {s2:.3g} rad² < 0 (sd {sd:.2g}): taken as 0")
        s2 = 0.0
    notes.append(f"σ_ref = {math.sqrt(s2):.4g} rad per pose and axis (σ_ref² sd {sd:.2g} rad²), "
                 f"from the lag-1 covariance of {where}: adjacent windows share an endpoint, so "
                 "their errors correlate through the reference alone")
    return float(s2), float(sd), static_step


# ---------------------------------------------------------------------------------------------
# time offset
# ---------------------------------------------------------------------------------------------
def _xcorr_offset(t: np.ndarray, gyro: np.ndarray, ref: Reference, max_offset_s: float) -> float:
    """Offset [s] to add to the IMU stamps that best lines up |ω_imu| with |ω_ref| (FFT
    cross-correlation on the IMU's median step, parabolic peak)."""
    dt = float(np.median(np.diff(t)))
    lo, hi = max(t[0], ref.rate_time_s[0]), min(t[-1], ref.rate_time_s[-1])
    if hi - lo < 10 * max_offset_s:
        lo, hi = t[0], t[-1]
    grid = np.arange(lo, hi, dt)
    smooth = max(1, int(round(LEVEL_SMOOTH_S / dt)))
    a = np.interp(grid, t, np.linalg.norm(gyro, axis=1))
    b = np.interp(grid, ref.rate_time_s, np.linalg.norm(ref.rate_rad_s, axis=1))
    a = moving_mean(a, smooth // 2)
    b = moving_mean(b, smooth // 2)
    a, b = a - a.mean(), b - b.mean()
    n = 1 << int(math.ceil(math.log2(2 * grid.size)))
    cc = np.fft.irfft(np.fft.rfft(b, n) * np.conj(np.fft.rfft(a, n)), n)
    lag_max = int(max_offset_s / dt)
    lags = np.concatenate([np.arange(0, lag_max + 1), np.arange(-lag_max, 0)])
    vals = np.concatenate([cc[: lag_max + 1], cc[n - lag_max:]])
    j = int(np.argmax(vals))
    lag = float(lags[j])
    order = np.argsort(lags)
    ls, vs = lags[order], vals[order]
    k = int(np.searchsorted(ls, lags[j]))
    if 0 < k < ls.size - 1:
        y0, y1, y2 = vs[k - 1], vs[k], vs[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            lag += 0.5 * (y0 - y2) / den
    return lag * dt


def _ls_offset(st: _Steps, w: int, ref: Reference) -> float:
    """Residual offset [s] from the least squares of the windowed error on the windowed angular
    acceleration of the reference (bias removed by first differences)."""
    win = _windows(st, w, ref)
    rate = _ref_rate_smoothed(st, LEVEL_SMOOTH_S)
    s, e = win["start"], np.minimum(win["end"], st.n - 1)
    acc = (rate[e] - rate[s]) / win["T"][:, None]             # mean dω/dt over each window
    err = win["sums"] / win["T"][:, None]
    ok = win["valid"][1:] & win["valid"][:-1]
    de, da = (err[1:] - err[:-1])[ok], (acc[1:] - acc[:-1])[ok]
    den = float(np.sum(da * da))
    if den <= 0:
        return 0.0
    # IMU late by d: ω_imu(t) = ω(t − d) ≈ ω − d·ω̇  → e ≈ −d·ω̇ ; offset to add is −d
    return float(np.sum(de * da)) / den


# ---------------------------------------------------------------------------------------------
# densities
# ---------------------------------------------------------------------------------------------
def walk_share(h: int) -> float:
    """Var of (b_k − mean of b_k+s, 2 ≤ |s| ≤ h) for a walk of unit increment variance per
    window: (1/m²)·2·Σ_{s,s'∈[2,h]} min(s, s')."""
    s = np.arange(2, h + 1)
    m = 2 * s.size
    return float(2.0 * np.minimum.outer(s, s).sum() / m ** 2) if m else 0.0


class NeighbourFit:
    """Residuals of the long windows of one set (fitted or held out), bias removed."""

    def __init__(self, e: np.ndarray, T: np.ndarray, refv: np.ndarray, members: np.ndarray,
                 h: int):
        self.k = members                          # window indices (into all windows), sorted
        n = members.size
        self.nbr: list[np.ndarray] = []
        b = np.zeros((n, e.shape[1]))              # 3 axes, or the parity's N − 3 components
        ref_b = np.zeros(n)
        for j in range(n):
            pos = members[j]
            lo, hi = np.searchsorted(members, [pos - h, pos + h + 1])
            cand = np.arange(lo, hi)
            cand = cand[np.abs(members[cand] - pos) >= 2]
            self.nbr.append(cand)
            if cand.size:
                b[j] = e[members[cand]].mean(axis=0)
                # reference share of the neighbour mean: its two contiguous runs telescope to
                # their end points, about one window's share each, over m²
                ref_b[j] = 2.0 * float(refv[members[cand]].mean()) / cand.size ** 2
        self.r = e[members] - b
        self.m = np.array([c.size for c in self.nbr])
        self.ref_share = refv[members] + ref_b     # [rad²/s² per σ_ref²-scaled, see caller]


def _solve_levels(y: np.ndarray, T: np.ndarray, extra: np.ndarray, fit: NeighbourFit, lev: np.ndarray,
                  n_levels: int, iters: int = 20) -> np.ndarray:
    """N_L² [rad²/s] of each level from E[y_k] = N_L(k)² + T_k/m_k²·Σ_nbr N_L(j)²/T_j + extra_k."""
    x = np.full(n_levels, np.nan)
    have = np.array([np.any(lev == L) for L in range(n_levels)])
    base = np.array([np.mean(y[lev == L] - extra[lev == L]) if have[L] else np.nan
                     for L in range(n_levels)])
    x = base.copy()
    fill = np.nanmean(x) if np.any(have) else 0.0
    from scipy import sparse                            # deferred: heavy
    rows = np.concatenate([np.full(c.size, j) for j, c in enumerate(fit.nbr)] + [np.zeros(0, int)])
    cols = np.concatenate(list(fit.nbr) + [np.zeros(0, int)])
    vals = T[rows] / T[cols] / np.maximum(fit.m[rows], 1) ** 2
    mix = sparse.csr_matrix((vals, (rows, cols)), shape=(T.size, T.size))
    for _ in range(iters):
        xf = np.where(np.isnan(x), fill, x)
        share = mix @ xf[lev]
        x = np.array([np.mean(y[lev == L] - extra[lev == L] - share[lev == L]) if have[L]
                      else np.nan for L in range(n_levels)])
    return x


def _chi2_ci(total_y: float, count: int, nu: float, shift: float, widen: float,
             conf: float) -> tuple[float, float]:
    from scipy import stats                             # deferred: heavy
    if count == 0 or nu <= 0:
        return (math.nan, math.nan)
    a = 1.0 - conf
    mean_y = total_y / count
    lo = mean_y * nu / stats.chi2.ppf(1 - a / 2, nu) - shift - widen
    hi = mean_y * nu / stats.chi2.ppf(a / 2, nu) - shift + widen
    return (math.sqrt(max(lo, 0.0)), math.sqrt(max(hi, 0.0)))


def level_table(fit: NeighbourFit, T: np.ndarray, lev_all: np.ndarray, level_value: np.ndarray,
                 edges, sigma2: float, sigma2_sd: float, walk: float, static_n: float,
                 conf: float) -> tuple[list, np.ndarray, np.ndarray]:
    """Per level: LevelDensity list, pooled N² per level, per-axis N² per level."""
    from scipy import stats                             # deferred: heavy
    n_levels = len(edges) - 1
    Tm = T[fit.k]
    lev = lev_all[fit.k]
    extra = Tm * fit.ref_share * sigma2 + Tm * walk
    y_axes = fit.r ** 2 * Tm[:, None]
    d = y_axes.shape[1]                                 # 3 axes, or the parity's N − 3 components
    pooled = _solve_levels(y_axes.mean(axis=1), Tm, extra, fit, lev, n_levels)
    per_axis = np.stack([_solve_levels(y_axes[:, a], Tm, extra, fit, lev, n_levels)
                         for a in range(d)], axis=1)
    z = float(stats.norm.ppf(0.5 + conf / 2))
    out = []
    for L in range(n_levels):
        sel = lev == L
        n = int(sel.sum())
        if n < MIN_LEVEL_WINDOWS:
            pooled[L] = math.nan
            per_axis[L] = math.nan
        m_mean = float(fit.m[sel].mean()) if n else 1.0
        red = 1.0 + 2.0 / max(m_mean, 1.0)
        shift = float((y_axes.mean(axis=1)[sel].mean() - pooled[L])) if n else 0.0
        widen = z * float(np.mean(Tm[sel] * fit.ref_share[sel])) * sigma2_sd if n else 0.0
        if n >= MIN_LEVEL_WINDOWS:
            ci = _chi2_ci(float(y_axes[sel].sum()), d * n, d * n / red, shift, widen, conf)
            axis_ci = tuple(_chi2_ci(float(y_axes[sel, a].sum()), n, n / red,
                                     float(y_axes[sel, a].mean() - per_axis[L, a]), widen, conf)
                            for a in range(d))
        else:
            ci = (math.nan, math.nan)
            axis_ci = ((math.nan, math.nan),) * d
        dens = math.sqrt(pooled[L]) if np.isfinite(pooled[L]) and pooled[L] > 0 else (
            0.0 if np.isfinite(pooled[L]) else math.nan)
        out.append(LevelDensity(
            lo=float(edges[L]), hi=float(edges[L + 1]), n_windows=n,
            mean_level=float(level_value[fit.k][sel].mean()) if n else math.nan,
            density_rad_rt_s=dens, ci_rad_rt_s=ci,
            axis_density_rad_rt_s=tuple(float(math.sqrt(v)) if np.isfinite(v) and v > 0 else
                                        (0.0 if np.isfinite(v) else math.nan)
                                        for v in per_axis[L]),  # type: ignore[arg-type]
            axis_ci_rad_rt_s=axis_ci,
            factor=dens / static_n if static_n > 0 and np.isfinite(dens) else math.nan))
    return out, pooled, per_axis


def assign_levels(value: np.ndarray, edges) -> np.ndarray:
    e = np.asarray(edges, dtype=float)
    return np.clip(np.searchsorted(e, value, side="right") - 1, 0, e.size - 2)


def source_level(L: int, ok: np.ndarray) -> int:
    """Level L, or the nearest level with a density when L has none."""
    filled = np.flatnonzero(ok)
    return L if ok[L] else int(filled[np.argmin(np.abs(filled - L))])


def nearest_filled(x: np.ndarray) -> np.ndarray:
    """Levels without a density take the nearest level's that has one."""
    ok = np.flatnonzero(np.isfinite(x))
    if ok.size == 0:
        return x
    idx = np.arange(x.size)
    near = ok[np.argmin(np.abs(idx[:, None] - ok[None, :]), axis=1)]
    return x[near]


# ---------------------------------------------------------------------------------------------
# filter
# ---------------------------------------------------------------------------------------------
def kf_nis(e: np.ndarray, t0: np.ndarray, T: np.ndarray, R: np.ndarray, q_rate: float,
            valid: np.ndarray) -> np.ndarray:
    """NIS per window of a scalar Kalman filter of the bias per axis: bias walk of
    ``q_rate`` [rad²/s³] (Q = q_rate·Δt), measurement e_k with variance R_k [rad²/s²].
    Windows not valid are skipped (the walk propagates over them)."""
    n = e.shape[0]
    nis = np.full(e.shape, np.nan)                      # 3 axes, or the parity's components
    first = int(np.flatnonzero(valid)[0])
    b = e[first].copy()
    P = R[first].copy() if R.ndim == 2 else np.full(e.shape[1], R[first])
    t_last = t0[first] + 0.5 * T[first]
    for k in range(first + 1, n):
        if not valid[k]:
            continue
        tc = t0[k] + 0.5 * T[k]
        P = P + q_rate * (tc - t_last)
        t_last = tc
        Rk = R[k]
        S = P + Rk
        nu = e[k] - b
        nis[k] = nu * nu / S
        g = P / S
        b = b + g * nu
        P = (1 - g) * P
    return nis


# ---------------------------------------------------------------------------------------------
# the measurement
# ---------------------------------------------------------------------------------------------
def holdout_by_level(valid: np.ndarray, lev: np.ndarray, m0: int, holdout: float) -> np.ndarray:
    """The held-out windows (bool, per window): per rate level, the last ``holdout`` fraction
    (rounded) of its valid windows from the motion segment's start ``m0`` on, in time order.

    Held out per level, not as the record's last part: a record whose last part holds a motion
    its first part never reached (MIMU4444 exp 2: 391 held-out windows above 2 rad/s against 4
    fitted) would test a level the fit never saw, not the values it measured. Each level's check
    still lies later in time than the windows it was fitted on. A level that has at least
    :data:`MIN_LEVEL_WINDOWS` windows keeps that many fitted (fewer held out), so that holding
    out never leaves a level unresolved that the whole record resolves.
    """
    hold = np.zeros(valid.size, bool)
    after = np.arange(valid.size) >= m0
    for L in np.unique(lev[after & valid]):
        idx = np.flatnonzero(valid & after & (lev == L))
        fitted_before = int(np.sum(valid & ~after & (lev == L)))   # the still start's windows
        k = int(round(holdout * idx.size))
        if idx.size + fitted_before >= MIN_LEVEL_WINDOWS:
            k = min(k, idx.size + fitted_before - MIN_LEVEL_WINDOWS)
        if k > 0:
            hold[idx[idx.size - k:]] = True
    return hold


def held_out_nis(nis: np.ndarray, hold: np.ndarray) -> np.ndarray:
    """The NIS of the held-out windows ``hold`` (bool, per window), rows with a non-finite
    component dropped: shape (n, components) [-]."""
    hv = nis[hold]
    return hv[np.all(np.isfinite(hv), axis=1)]


def nis_check(label: str, hv: np.ndarray, var_param: float, z: float) -> NisCheck:
    """The held-out check of one set of values: the mean NIS of ``hv`` (:func:`held_out_nis`)
    against 1 ± z·√(2/n_eff + var_param) (χ²₁ mean of n_eff innovations; ``var_param`` the
    variance the estimated densities add, 0 for given values)."""
    n_eff = int(hv.size)
    mean = float(hv.mean()) if n_eff else math.nan
    half = z * math.sqrt(2.0 / max(n_eff, 1) + var_param)
    interval = (1.0 - half, 1.0 + half)
    return NisCheck(label=label, mean_nis=mean, interval=interval, n_eff=n_eff,
                    inside=bool(interval[0] <= mean <= interval[1]),
                    axis_mean_nis=tuple(float(v) for v in hv.mean(axis=0))
                    if n_eff else (math.nan,) * hv.shape[1])  # type: ignore[arg-type]


def export_factor(pooled: np.ndarray, motion_levels: np.ndarray, n_levels: int, nu_l: np.ndarray,
                  static_n: float, rng: np.random.Generator, confidence: float) -> tuple:
    """The export factor: the motion-weighted density over the static one, with its interval.

    Parameters
    ----------
    pooled : ndarray, shape (L,)
        N_L² per level [rad²/s] (NaN where a level has too few windows).
    motion_levels : ndarray of int
        The level of each fitted window of the motion segment (pauses included) [-].
    n_levels : int
        L.
    nu_l : ndarray, shape (L,)
        Degrees of freedom of each level's N_L² [-].
    static_n : float
        The static density [rad/√s].
    rng : numpy.random.Generator
        For the interval's χ² draws (2000).
    confidence : float
        Two-sided level of the interval [-].

    Returns
    -------
    tuple
        (N_L² with empty levels filled from the nearest, the levels' weights, levels with a
        density, the raw factor, its interval (lo, hi), the factor kept: at least 1) [-].
    """
    filled = nearest_filled(pooled)
    wts = np.bincount(motion_levels, minlength=n_levels) / max(motion_levels.size, 1)
    ok = np.isfinite(pooled) & (nu_l > 0)
    raw = math.sqrt(max(float(np.sum(wts * filled)), 0.0)) / static_n
    draws = np.zeros(2000)
    for L in (int(j) for j in np.flatnonzero(wts > 0)):
        src = source_level(L, ok)
        draws += wts[L] * filled[L] * rng.chisquare(nu_l[src], draws.size) / nu_l[src]
    a = 1.0 - confidence
    f_ci = (float(np.sqrt(np.quantile(draws, a / 2))) / static_n,
            float(np.sqrt(np.quantile(draws, 1 - a / 2))) / static_n)
    return filled, wts, ok, raw, f_ci, max(1.0, raw)


def nis_factor(e: np.ndarray, t0: np.ndarray, T: np.ndarray, n2: float, ref_R: np.ndarray, k2: float,
               valid: np.ndarray, fitted: np.ndarray, cols, confidence: float) -> tuple:
    """The factor f on the static N and K that makes a plain white + walk filter consistent on
    the fitted motion windows: mean NIS = 1 there with R = f²N²/T + the reference's share and
    Q = f²K²·Δt (:func:`kf_nis`), the factor ``--inflate auto`` finds on a simulated record.

    Scaling R and Q by f² leaves the gain alone and divides the NIS by f², so without a
    reference share f² is the static filter's mean NIS; with one, f is the root of a monotone
    function (Brent). Its interval treats the n fitted innovations as a χ²_n/n mean.

    Parameters
    ----------
    e : ndarray (windows, components)
        Window means of the error [rad/s].
    t0, T : ndarray (windows,)
        Window starts and lengths [s].
    n2, k2 : float
        Static N² [rad²/s] and K² [rad²/s³].
    ref_R : ndarray (windows,)
        The reference's share of each window's variance [rad²/s²] (zeros for the parity).
    valid, fitted : ndarray of bool (windows,)
        Windows the filter uses; the fitted motion windows the mean is taken over.
    cols : sequence of int
        Components the mean is taken over (the observed axes).
    confidence : float
        Two-sided level of the interval [-].

    Returns
    -------
    tuple
        (f, (lo, hi)) [-], before any floor at 1; (nan, (nan, nan)) without fitted windows.
    """
    from scipy import optimize, stats                    # deferred: heavy
    cols = list(cols)

    def mean_nis(f: float) -> tuple[float, int]:
        R = np.repeat((f * f * n2 / T + ref_R)[:, None], e.shape[1], axis=1)
        hv = held_out_nis(kf_nis(e, t0, T, R, f * f * k2, valid)[:, cols], fitted)
        return (float(hv.mean()) if hv.size else math.nan), int(hv.size)

    m1, n_inn = mean_nis(1.0)
    if not (n_inn and math.isfinite(m1) and m1 > 0):
        return math.nan, (math.nan, math.nan)
    if not np.any(ref_R > 0):
        f = math.sqrt(m1)
    else:
        g = lambda lf: math.log(mean_nis(math.exp(lf))[0])                      # noqa: E731
        lo, hi = -0.5 * math.log(1e6), 0.5 * math.log(1e8)
        f = (math.exp(optimize.brentq(g, lo, hi, xtol=1e-10)) if g(lo) > 0 > g(hi)
             else math.sqrt(m1))
    a = 1.0 - confidence
    q_lo, q_hi = stats.chi2.ppf(a / 2, n_inn) / n_inn, stats.chi2.ppf(1 - a / 2, n_inn) / n_inn
    return f, (f * math.sqrt(q_lo), f * math.sqrt(q_hi))


#: Largest reference increment about a body axis [rad] over the whole common span for that
#: axis to count as not observed by the reference (a planar pose holds roll and pitch at exactly
#: 0; a real 3-D reference turns by far more than this on any record).
UNOBSERVED_RAD = 1e-9

#: The gyro's own increment over the same span [rad] above which that matters (below it the
#: body did not turn about the axis either, and a zero reference is the truth).
UNOBSERVED_GYRO_RAD = 1e-3


def unobserved_axes(st: "_Steps", ref: Reference) -> tuple[str, ...]:
    """The body axes the reference never turns about over the common span while the gyro does
    (:data:`UNOBSERVED_RAD`, :data:`UNOBSERVED_GYRO_RAD`): the largest |increment| per step of
    the reference, and the gyro's total absolute angle."""
    ref_inc = np.max(np.abs(st.phi), axis=0)
    gyro_angle = np.sum(np.abs(st.gamma), axis=0)
    return tuple(a for i, a in enumerate("xyz") if ref_inc[i] < UNOBSERVED_RAD and gyro_angle[i] > UNOBSERVED_GYRO_RAD)


def measure_inflation(imu_time_s, gyro_rad_s, ref: Reference, *,
                      levels=DEFAULT_LEVELS_RAD_S, holdout: float = 0.3,
                      rng: np.random.Generator | None = None,
                      static_n_rad_rt_s: float | None = None,
                      static_k_rad_s_rt_s: float = 0.0,
                      acc_m_s2=None, acc_levels=DEFAULT_ACC_LEVELS_M_S2,
                      window_s: float = 1.0, bias_span: int = 15,
                      time_offset_s: float | str = 0.0, max_offset_s: float = 0.5,
                      static_rate_rad_s: float = 0.01, confidence: float = 0.95,
                      source: str | None = None) -> MeasuredInflation:
    """The white-noise density a gyro triad shows per motion level, against a reference.

    Parameters
    ----------
    imu_time_s : array_like, shape (n,)
        IMU stamps [s] in the reference's time base (seconds from ``ref.t0_ns``), strictly
        increasing.
    gyro_rad_s : array_like, shape (n, 3)
        Gyro rates [rad/s] about the body (reference child) frame's x, y, z axes.
    ref : Reference
        The reference attitude (:func:`gyroarray.core.bag_reference.read_reference`).
    levels : sequence of float
        Bin edges of the rate magnitude [rad/s].
    holdout : float
        Fraction of the motion segment held out at its end for the NIS check [-], in (0, 0.9].
    rng : numpy.random.Generator, optional
        For the parametric bootstrap of ``factor_ci`` (default: ``default_rng(0)``).
    static_n_rad_rt_s : float, optional
        The static (model's) white density N [rad/√s]; default the measured density of the
        lowest level that has one (noted).
    static_k_rad_s_rt_s : float
        The static (model's) walk K [rad/s/√s]; also the walk the filters and the bias
        estimate's share assume.
    acc_m_s2 : array_like, shape (n, 3), optional
        Specific force [m/s²] at the IMU stamps: adds the acceleration-level table.
    acc_levels : sequence of float
        Bin edges of |‖f‖ − g0| [m/s²].
    window_s : float
        Long window T [s] (whole IMU steps; at least two pose intervals).
    bias_span : int
        Neighbour windows on each side in the bias estimate [-].
    time_offset_s : float or "estimate"
        Offset added to the IMU stamps [s], or estimated (module docstring).
    max_offset_s : float
        Largest offset searched [s].
    static_rate_rad_s : float
        Smoothed reference rate below which the record is static [rad/s].
    confidence : float
        Level of the density intervals and the NIS interval [-].
    source : str, optional
        The file named in refusals (default ``ref.source``).

    Returns
    -------
    MeasuredInflation

    Raises
    ------
    InputError
        When the IMU and the reference do not overlap in time, or overlap too little.
    """
    from scipy import stats                             # deferred: heavy
    where = source if source is not None else ref.source
    t = np.asarray(imu_time_s, dtype=np.float64)
    g = np.asarray(gyro_rad_s, dtype=np.float64)
    if t.ndim != 1 or g.shape != (t.size, 3):
        raise ValueError(f"gyro_rad_s must have shape ({t.size}, 3), got {g.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(g)) and np.all(np.diff(t) > 0)):
        raise ValueError("imu_time_s must be finite and strictly increasing, gyro_rad_s finite")
    if not 0.0 < holdout <= 0.9:
        raise ValueError(f"holdout must be in (0, 0.9], got {holdout}")
    acc = None if acc_m_s2 is None else np.asarray(acc_m_s2, dtype=np.float64)
    rng = np.random.default_rng(0) if rng is None else rng
    notes: list[str] = []
    med_dt = float(np.median(np.diff(t)))
    tau_med = float(np.median(np.diff(ref.time_s)))
    w = max(1, int(round(window_s / med_dt)))
    if w * med_dt < 2 * tau_med:
        raise InputError(f"the window of {w * med_dt:.3g} s is shorter than two reference pose "
                         f"intervals ({2 * tau_med:.3g} s); give a longer window", file=where)

    def span(tt):
        return _overlap(tt, ref)

    offset = 0.0
    if isinstance(time_offset_s, str):
        if time_offset_s != "estimate":
            raise ValueError(f"time_offset_s must be a number or 'estimate', got {time_offset_s!r}")
        offset = _xcorr_offset(t, g, ref, max_offset_s)
        coarse = offset
        i0, i1 = span(t + offset)
        if i1 - i0 > 2 * w:
            for _ in range(2):
                i0, i1 = span(t + offset)
                offset += _ls_offset(_Steps(t[i0:i1] + offset, g[i0:i1], ref), w, ref)
        notes.append(f"time offset estimated: {offset * 1e3:.4g} ms added to the IMU stamps "
                     f"(cross-correlation of |ω| {coarse * 1e3:.4g} ms, refined by least squares "
                     "of the windowed error on the windowed angular acceleration)")
    else:
        offset = float(time_offset_s)
        notes.append(f"time offset {offset * 1e3:.4g} ms added to the IMU stamps (as given"
                     f"{'' if offset else '; none estimated'})")
    tt = t + offset
    i0, i1 = span(tt)
    n_common = (tt[i1 - 1] - tt[i0]) if i1 - i0 >= 2 else 0.0
    if i1 - i0 < 2 or n_common < MIN_WINDOWS * w * med_dt:
        raise InputError(
            f"the IMU ({tt[0]:.3f} to {tt[-1]:.3f} s) and the reference {ref.topic or ''} "
            f"({ref.time_s[0]:.3f} to {ref.time_s[-1]:.3f} s, from t0 = {ref.t0_ns / 1e9:.9f} s) "
            f"{'do not overlap in time' if i1 - i0 < 2 else f'overlap only {n_common:.3g} s'}; "
            f"the measurement needs {MIN_WINDOWS} windows of {w * med_dt:.3g} s in common "
            "(same clock? give time_offset_s)", file=where)
    st = _Steps(tt[i0:i1], g[i0:i1], ref)
    notes.append(f"common span {st.t[0]:.3f} to {st.t[-1]:.3f} s ({st.n} IMU steps); reference "
                 f"slerped onto the IMU stamps; gyro sample i held over [t_i, t_i+1); error per "
                 f"step ω_imu·Δt − Log(R_iᵀR_i+1) in the body frame, summed over windows of "
                 f"{w * med_dt:.4g} s ({w} steps)")

    sigma2, sigma2_sd, static_step = _sigma_ref(st, ref, static_rate_rad_s, notes)
    unobserved = unobserved_axes(st, ref)
    obs = [i for i, a in enumerate("xyz") if a not in unobserved]
    if not obs:
        raise InputError("the reference never turns about any body axis over the common span while the "
                         "gyro does: it observes no axis, so no density in motion can be measured", file=where)
    if unobserved:
        notes.append(
            f"the reference never turns about the body's {' and '.join(unobserved)} "
            f"{'axes' if len(unobserved) > 1 else 'axis'} over the common "
            f"span (its increments there are below {UNOBSERVED_RAD:g} rad: "
            + ("a planar pose, as a ground robot's wheel odometry gives" if len(unobserved) == 2 else "held")
            + ") while the gyro does: on " + ", ".join(unobserved) + " the measured excess is the body's own "
            "motion (rocking, vibration), not the gyro's noise, so those densities and the NIS there "
            "do not measure the gyro; a 3-D reference (motion capture, a VIO or SLAM pose) does")

    win = _windows(st, w, ref)
    nk = win["sums"].shape[0]
    T = win["T"]
    e = win["sums"] / T[:, None]
    refv = _ref_var_coef(st, win["start"], win["end"]) / T ** 2       # × σ² → rad²/s²
    rate_s = np.linalg.norm(_ref_rate_smoothed(st, LEVEL_SMOOTH_S), axis=1)
    c = np.concatenate([[0.0], np.cumsum(rate_s)])
    level_value = (c[win["end"]] - c[win["start"]]) / w
    lev = assign_levels(level_value, levels)
    valid = win["valid"]
    n_levels = len(levels) - 1

    # motion segment and hold-out
    moving = np.flatnonzero(valid & (level_value >= static_rate_rad_s))
    if moving.size < MIN_WINDOWS:
        raise InputError(f"only {moving.size} windows in motion (mean |ω| ≥ "
                         f"{static_rate_rad_s:g} rad/s) in the common span; a measured inflation "
                         f"needs {MIN_WINDOWS}", file=where)
    m0 = int(moving[0])
    hold = holdout_by_level(valid, lev, m0, holdout)
    fit_members = np.flatnonzero(valid & ~hold)
    hold_members = np.flatnonzero(valid & hold)
    notes.append(f"motion segment from {win['t0'][m0]:.3f} s; per rate level the last {holdout:.0%} "
                 f"of its windows from there held out ({hold_members.size}), the rest fitted "
                 f"({fit_members.size}): each level is checked on later windows the fit did not see; "
                 f"{int((~valid).sum())} windows dropped across gaps")

    K = float(static_k_rad_s_rt_s)
    walk = K ** 2 * float(np.mean(T)) * walk_share(bias_span)
    fit = NeighbourFit(e, T, refv, fit_members, bias_span)
    table, pooled, per_axis = level_table(fit, T, lev, level_value, levels, sigma2, sigma2_sd,
                                           walk, static_n_rad_rt_s or 0.0, confidence)
    if unobserved:
        # the pooled density, its interval and the export factor from the observed axes only
        fit_o = NeighbourFit(e[:, obs], T, refv, fit_members, bias_span)
        table_o, pooled, _ = level_table(fit_o, T, lev, level_value, levels, sigma2, sigma2_sd,
                                         walk, static_n_rad_rt_s or 0.0, confidence)
        table = [LevelDensity(**{**lv.__dict__, "density_rad_rt_s": lo.density_rad_rt_s,
                                 "ci_rad_rt_s": lo.ci_rad_rt_s, "factor": lo.factor})
                 for lv, lo in zip(table, table_o)]
        notes.append(f"pooled densities, the export factor and the held-out NIS from the observed "
                     f"{'axes' if len(obs) > 1 else 'axis'} {', '.join('xyz'[i] for i in obs)} only; the "
                     f"per-axis values of {', '.join(unobserved)} are given but not measured against the truth")
    if static_n_rad_rt_s is None:
        lowest = next((lv for lv in table if np.isfinite(lv.density_rad_rt_s)), None)
        static_n = lowest.density_rad_rt_s if lowest else math.nan
        notes.append(f"static N not given: the lowest level's measured density {static_n:.4g} "
                     "rad/√s taken as the static one")
        table = [LevelDensity(**{**lv.__dict__, "factor": lv.density_rad_rt_s / static_n})
                 for lv in table]
    else:
        static_n = float(static_n_rad_rt_s)
    acc_table: list[LevelDensity] = []
    if acc is not None:
        dev = np.abs(np.linalg.norm(acc[i0:i1][:-1], axis=1) - G0_M_S2)
        cd = np.concatenate([[0.0], np.cumsum(dev)])
        acc_value = (cd[win["end"]] - cd[win["start"]]) / w
        acc_table, _, _ = level_table(fit, T, assign_levels(acc_value, acc_levels), acc_value,
                                       acc_levels, sigma2, sigma2_sd, walk, static_n, confidence)
        notes.append("acceleration levels: mean |‖f‖ − g0| over each window (reported beside; "
                     "the export and the NIS check use the rate levels)")

    if not any(np.isfinite(lv.density_rad_rt_s) for lv in table):
        raise InputError(f"no rate level has {MIN_LEVEL_WINDOWS} fitted windows of "
                         f"{w * med_dt:.3g} s (a longer record, fewer levels or a shorter "
                         "window)", file=where)
    # export factor: motion-weighted measured density over the static one
    nu_l = np.array([float(len(obs)) * lv.n_windows for lv in table])
    ef = export_factor(pooled, lev[fit_members[fit_members >= m0]], n_levels, nu_l, static_n, rng,
                       confidence)
    filled, wts, ok, density_factor, density_ci, _ = ef
    ref_R_all = refv * sigma2
    fit_motion = np.zeros(nk, bool)
    fit_motion[fit_members[fit_members >= m0]] = True
    raw_factor, f_ci = nis_factor(e, win["t0"], T, static_n ** 2, ref_R_all, K ** 2, valid, fit_motion, obs,
                                  confidence)
    factor = max(1.0, raw_factor) if math.isfinite(raw_factor) else 1.0
    notes.append(f"export factor ×{factor:.4g}: the one that makes a white + walk filter with the static N, K "
                 f"times it consistent (mean NIS 1) on the fitted motion windows (as --inflate auto on a "
                 f"simulated record); the motion-weighted measured density is ×{density_factor:.4g} the static "
                 "one (reported beside)")
    if raw_factor < 1.0:
        notes.append(f"the fitted windows' factor is {raw_factor:.3g}, below 1: the export keeps the static "
                     "values (factor 1)")
    axis_factor = tuple(max(1.0, nis_factor(e, win["t0"], T, static_n ** 2, ref_R_all, K ** 2, valid,
                                            fit_motion, [a], confidence)[0])
                        if a in obs else math.nan for a in range(3))

    # the held-out NIS check
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    ref_R = refv * sigma2
    R_meas_axes = np.stack([nearest_filled(per_axis[:, a])[lev] for a in range(3)], axis=1)
    R_meas = np.where(np.isfinite(R_meas_axes), R_meas_axes,
                      filled[lev][:, None]) / T[:, None] + ref_R[:, None]
    hold_valid = np.zeros(nk, bool)
    hold_valid[hold_members] = True
    checks = []
    for label, R, q in (
            ("measured", R_meas, K ** 2),
            ("static", np.repeat((static_n ** 2 / T + ref_R)[:, None], 3, axis=1), K ** 2),
            ("export", np.repeat(((factor * static_n) ** 2 / T + ref_R)[:, None], 3, axis=1),
             (factor * K) ** 2)):
        nis_all = kf_nis(e, win["t0"], T, R, q, valid)
        hv_all = held_out_nis(nis_all, hold_valid)
        hv = held_out_nis(nis_all[:, obs], hold_valid)              # the observed axes
        var_param = 0.0
        if label == "measured" and hv.size:
            # a density estimated with ν dof moves the mean NIS by its R share × δ ln N²
            share = (R - ref_R[:, None])[hold_valid][:, obs] / (R[hold_valid][:, obs])
            for L in range(n_levels):
                sel = lev[hold_valid] == L
                if sel.any():
                    cL = float(share[sel].sum()) / max(hv.size, 1)
                    src = source_level(L, ok)
                    var_param += cL ** 2 * 2.0 / (nu_l[src] / (1.0 + 2.0 / max(bias_span, 1)))
        chk = nis_check(label, hv, var_param, z)
        if unobserved and hv_all.size:                  # every axis's mean, the unobserved too
            chk = replace(chk, axis_mean_nis=tuple(float(v) for v in hv_all.mean(axis=0)))  # type: ignore[arg-type]
        checks.append(chk)
    st_chk = checks[1]
    notes.append(f"held-out NIS: measured {checks[0].mean_nis:.3g} (interval "
                 f"{checks[0].interval[0]:.3g}–{checks[0].interval[1]:.3g}), static "
                 f"{st_chk.mean_nis:.3g} ({'inside' if st_chk.inside else 'outside'}; the static "
                 f"values are off by ×{math.sqrt(max(st_chk.mean_nis, 0.0)):.3g} in density), "
                 f"export ×{factor:.3g}: {checks[2].mean_nis:.3g}; the filters' R holds the "
                 "reference's share too")
    return MeasuredInflation(
        levels=tuple(table), acc_levels=tuple(acc_table), static_n_rad_rt_s=float(static_n),
        static_k_rad_s_rt_s=K, sigma_ref_rad=math.sqrt(sigma2), sigma_ref_sd_rad2=sigma2_sd,
        time_offset_s=offset, window_s=float(np.median(T)), nis=tuple(checks),
        factor_for_export=float(factor), factor_ci=f_ci,
        axis_factor=axis_factor,  # type: ignore[arg-type]
        density_factor=float(density_factor), density_factor_ci=density_ci,
        windows_t0_s=win["t0"], windows_level=lev, windows_holdout=hold,
        notes=(*ref.notes, *notes), unobserved_axes=unobserved)


# ---------------------------------------------------------------------------------------------
# for the export
# ---------------------------------------------------------------------------------------------
#: A CSV's time_s above this [s] is taken as seconds since the epoch (1976 onwards).
EPOCH_TIME_S = 2e8


def fmt_g(x: float) -> str:
    return "nan" if not np.isfinite(x) else f"{x:.4g}"


def inflation_for_export(meas_path, reference_path, reference_topic: str,
                         static_n_rad_rt_s: float, static_k_rad_s_rt_s: float, gyro_index: int,
                         *, imu_topic: str | None = None, time_offset_s: float | str = "estimate",
                         window_s: float = 1.0, holdout: float = 0.3,
                         rng: np.random.Generator | None = None, levels=DEFAULT_LEVELS_RAD_S,
                         ) -> tuple[float, dict, list[str]]:
    """The measured inflation the export applies, from a bag with a reference pose topic.

    Parameters
    ----------
    meas_path : str or os.PathLike
        The IMU record: a ROS bag (``sensor_msgs/msg/Imu``) or a measurement CSV with three gyros
        along x, y, z (gyros 1-3) in the reference's body frame.
    reference_path : str or os.PathLike
        The bag with the reference topic (often the same bag).
    reference_topic : str
        Its ``geometry_msgs/PoseStamped`` or ``nav_msgs/Odometry`` topic.
    static_n_rad_rt_s : float
        The model's white density N of the exported axis [rad/√s], > 0.
    static_k_rad_s_rt_s : float
        The model's walk K of the exported axis [rad/s/√s], ≥ 0.
    gyro_index : int
        The exported gyro, 1-3 (x, y, z), or 0 for the axes pooled (``--axis mean``).
    imu_topic : str, optional
        The bag's IMU topic (default: its one IMU topic).
    time_offset_s : float or "estimate"
        Offset added to the IMU stamps [s] (default: estimated, stated in the header).
    window_s : float
        Long window [s].
    levels : sequence of float
        Bin edges of the rate magnitude [rad/s] (:func:`measure_inflation`).
    holdout : float
        Held-out fraction of the motion segment [-].
    rng : numpy.random.Generator, optional
        For the factor's interval (default ``default_rng(0)``).

    Returns
    -------
    factor : float
        Inflation factor on both numbers [-], ≥ 1.
    summary : dict
        JSON-ready: :meth:`MeasuredInflation.as_dict` and the axis, files and topic.
    header_lines : list of str
        ASCII lines for the file's header (without a comment mark): from what, the density per
        level beside the static one, the held-out NIS with the measured, static and exported
        values.

    Raises
    ------
    InputError
        Bad files or topics (:func:`~gyroarray.core.bag_reference.read_reference`,
        ``read_measurement``), a record that is no x, y, z gyro triad, no overlap in time.
    """
    # deferred: the readers (rosbags, pandas) load only when asked
    from gyroarray.core.bag_reference import first_stamp_ns, read_reference
    from gyroarray.core.bags import imu_topics, is_bag
    from gyroarray.core.measurement import read_measurement
    n_s, k_s = float(static_n_rad_rt_s), float(static_k_rad_s_rt_s)
    if not (math.isfinite(n_s) and n_s > 0 and math.isfinite(k_s) and k_s >= 0):
        raise InputError(f"--inflate measured needs the model's N > 0 and K >= 0, got N = {n_s!r} "
                         f"rad/sqrt(s), K = {k_s!r} rad/s/sqrt(s)", file=str(meas_path))
    if gyro_index not in (0, 1, 2, 3):
        raise InputError(f"--inflate measured reads a gyro triad: gyro 1, 2 or 3 (x, y, z) or the "
                         f"axes pooled, not gyro {gyro_index}", file=str(meas_path))
    meas = read_measurement(meas_path, topic=imu_topic)
    if meas.n_gyros != 3 or not np.allclose(meas.layout.axes, np.eye(3), atol=1e-6):
        raise InputError(f"--inflate measured needs three gyros along x, y, z (a bag's IMU, or a "
                         f"CSV with gyros 1-3 on the body axes); this record has {meas.n_gyros} "
                         "gyros on other axes", file=str(meas_path))
    ref = read_reference(reference_path, reference_topic)
    notes = []
    if is_bag(meas_path):
        topic = imu_topic or next(iter(imu_topics(meas_path)))
        t0_imu = first_stamp_ns(meas_path, topic)
        imu_t = (t0_imu - ref.t0_ns) / 1e9 + np.asarray(meas.time_s)
        notes.append(f"IMU {topic}: header stamps, in the reference's clock")
    else:
        tm = np.asarray(meas.time_s)
        if tm[0] > EPOCH_TIME_S:
            imu_t = tm - ref.t0_ns / 1e9
            notes.append("the CSV's time_s taken as seconds since the epoch")
        else:
            imu_t = tm
            notes.append("the CSV's time_s taken as seconds from the reference's first stamp")
    m = measure_inflation(imu_t, np.asarray(meas.gyro_rad_s), ref, holdout=holdout, rng=rng, levels=levels,
                          static_n_rad_rt_s=n_s, static_k_rad_s_rt_s=k_s, acc_m_s2=meas.acc_m_s2,
                          window_s=window_s, time_offset_s=time_offset_s,
                          source=str(reference_path))
    if gyro_index and "xyz"[gyro_index - 1] in m.unobserved_axes:
        seen = [i + 1 for i, a in enumerate("xyz") if a not in m.unobserved_axes]
        raise InputError(f"the reference {reference_topic} never turns about {'xyz'[gyro_index - 1]} (gyro "
                         f"{gyro_index}, the axis exported) while the gyro does: its inflation cannot be "
                         f"measured there; export an observed axis (--axis {', --axis '.join(map(str, seen))}, "
                         "or --axis mean: the observed axes pooled) or use a 3-D reference", file=str(reference_path))
    factor = m.factor_for_export if gyro_index == 0 else m.axis_factor[gyro_index - 1]
    axis = ("the axes pooled" + (f" (the observed ones, {', '.join(a for a in 'xyz' if a not in m.unobserved_axes)})"
                                 if m.unobserved_axes else "")
            if gyro_index == 0 else f"gyro {gyro_index} ({'xyz'[gyro_index - 1]})")
    summary = {**m.as_dict(), "factor": factor, "axis": axis, "measurement": str(meas_path),
               "reference": str(reference_path), "reference_topic": reference_topic,
               "notes": [*notes, *m.notes]}
    a = None if gyro_index == 0 else gyro_index - 1
    levels = []
    for lv in m.levels:
        d = lv.density_rad_rt_s if a is None else lv.axis_density_rad_rt_s[a]
        ci = lv.ci_rad_rt_s if a is None else lv.axis_ci_rad_rt_s[a]
        if np.isfinite(d):
            hi = "inf" if not np.isfinite(lv.hi) else f"{lv.hi:g}"
            levels.append(f"|w| {lv.lo:g}-{hi} rad/s ({lv.n_windows} windows): {fmt_g(d)} "
                          f"[{fmt_g(ci[0])}, {fmt_g(ci[1])}] rad/sqrt(s) = x{fmt_g(d / n_s)}")
    nis = {c.label: c for c in m.nis}
    meas_c, st_c, ex_c = nis["measured"], nis["static"], nis["export"]
    header = [
        f"inflation: measured x{factor:.4g} on both numbers ({axis}), from {reference_path} topic "
        f"{reference_topic} ({ref.msgtype}) against {meas_path}: the factor on the static N = "
        f"{fmt_g(n_s)} rad/sqrt(s) and K that makes a white + walk filter consistent (mean NIS 1) on the "
        f"fitted motion windows (interval x{fmt_g(m.factor_ci[0])}-x{fmt_g(m.factor_ci[1])}, before the "
        f"floor at 1; the motion-weighted white density is x{fmt_g(m.density_factor)} the static one)",
        "measured white density per motion level, windows of "
        f"{m.window_s:.3g} s: " + "; ".join(levels),
        f"reference attitude noise {fmt_g(m.sigma_ref_rad)} rad per pose (subtracted); time offset "
        f"{m.time_offset_s * 1e3:.4g} ms added to the IMU stamps",
        f"held-out check (last {holdout:.0%} of each motion level, {meas_c.n_eff} innovations), mean NIS "
        f"of a bias filter (1 when consistent): measured values {fmt_g(meas_c.mean_nis)} "
        f"(interval {fmt_g(meas_c.interval[0])}-{fmt_g(meas_c.interval[1])}, "
        f"{'inside' if meas_c.inside else 'OUTSIDE'}); static values {fmt_g(st_c.mean_nis)} "
        f"({'inside' if st_c.inside else 'outside'}, off x{fmt_g(math.sqrt(max(st_c.mean_nis, 0)))} "
        f"in density); exported values {fmt_g(ex_c.mean_nis)} "
        f"({'inside' if ex_c.inside else 'outside'} {fmt_g(ex_c.interval[0])}-{fmt_g(ex_c.interval[1])})",
    ]
    return float(factor), summary, header
