"""The noise a redundant gyro array shows in motion, measured from its parity residual (issue 42,
item 6, second half): no reference attitude needed.

An array of N > 3 gyros (layout H, N × 3, rank 3) reads y = H ω + b + n. With V an orthonormal
basis (N × (N − 3)) of the left null space of H (Vᵀ H = 0, Vᵀ V = I), the parity residual
p = Vᵀ y = Vᵀ b + Vᵀ n holds no rate: in motion it shows the noise the gyros have while they
turn (and the errors a moving array has beyond noise, see the caveat below).

Method (:func:`measure_parity_inflation`)
-----------------------------------------
1. **Parity and level.** p per sample; the level of a sample is the magnitude of the array's own
   fused rate ω̂ = H⁺ y (least squares), smoothed over
   :data:`gyroarray.chain.inflation.LEVEL_SMOOTH_S`; a window's level is its mean.
2. **Windows.** Non-overlapping windows of T (``window_s``, whole samples); e_k = the mean of p
   over the window [rad/s], per parity component: the bias Vᵀ b (a slow walk) plus white noise
   of variance N_p²/T. Windows across a gap (a step over
   :data:`gyroarray.chain.inflation.GAP_FACTOR` median steps) are dropped.
3. **Noise → density.** With equal white density N_L on every gyro at level L (the
   *equal-noise assumption*), Vᵀ (N_L² I) V = N_L² I: every parity component has the density
   N_L, independent of the others, so the parity's density *is* the gyros' density. With a
   model's per-gyro white covariance R (``model``) the static parity density is the generalised
   N_p² = tr(Vᵀ R V)/(N − 3), and the motion factor f_L = N_L/N_p is taken as common to every
   gyro (R → f_L² R).
4. **Bias and densities**: exactly as :mod:`gyroarray.chain.inflation` (its helpers, imported):
   the bias of a window is the mean of its neighbours within ±``bias_span`` windows, leaving
   out the window and its two adjacent ones; N_L² solved for by a fixed point over the levels
   (the neighbours' share, the walk's share with the model's K, or none without a model); the
   interval a scaled χ² with ν = (N − 3)·n_L windows, reduced by (1 + 2/m). There is no
   reference share (σ_ref = 0): the parity needs no reference.
5. **Static N**: the model's (step 3), or, without a model, the density of the still level
   (mean |ω̂| below ``static_rate_rad_s``, the first bin).
6. **Held-out check.** The last ``holdout`` fraction of the motion segment is not fitted. A
   scalar Kalman filter per parity component (state: bias, walk Q = K_p²·Δt; measurement e_k
   with R = N_L²/T) runs over every window; its mean NIS over the held-out windows and
   components is compared with 1 ± z·√(2/n_eff + v) (v the share of the densities' own
   uncertainty, 0 for static values), with (a) the measured densities, (b) the static N, K,
   (c) the static values × ``factor_for_export``.
7. ``density_factor`` = √(Σ_L w_L N_L²)/N_static (reported; ``factor_for_export`` is the factor on
   the static values that makes a white + walk filter consistent on the fitted motion windows,
   :func:`gyroarray.chain.inflation.nis_factor`), w_L the share of the fitted windows from
   the start of the motion at level L (pauses within the motion included, as
   :mod:`gyroarray.chain.inflation`), at least 1.

Caveat: scale-factor and axis errors of the gyros also reach the parity in motion (Vᵀ E ω, see
:mod:`gyroarray.chain.parity`) and are counted here as noise whose level grows with the rate.
A filter that does not estimate them sees them the same way; ``gyroarray parity`` estimates
them apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gyroarray.chain.inflation import (
    DEFAULT_LEVELS_RAD_S, GAP_FACTOR, LEVEL_SMOOTH_S, MIN_LEVEL_WINDOWS, MIN_WINDOWS, LevelDensity,
    NeighbourFit, NisCheck, assign_levels, export_factor, fmt_g, held_out_nis, holdout_by_level, kf_nis, level_table,
    nis_factor,
    moving_mean, nis_check,
    source_level, walk_share)
from gyroarray.analysis.motion import still_mask
from gyroarray.chain.parity import MIN_SAMPLES_PER_UNKNOWN, self_calibrate
from gyroarray.core.errors import InputError
from gyroarray.estimators.fdi import saturated_mask

__all__ = ["ParityInflation", "parity_basis", "measure_parity_inflation",
           "parity_inflation_for_export", "DEFAULT_STATIC_RATE_RAD_S"]

#: Smoothed |fused rate| below which a window is still [rad/s] (the first default level's edge:
#: above a MEMS gyro's bias, below any motion a VIO run makes).
DEFAULT_STATIC_RATE_RAD_S = 0.05


@dataclass(frozen=True)
class ParityInflation:
    """What :func:`measure_parity_inflation` found.

    Parameters
    ----------
    n_gyros : int
        N [-].
    n_parity : int
        Parity components N − 3 [-].
    levels : tuple of LevelDensity
        Per rate level of the fused rate; ``axis_*`` hold the parity components (not x, y, z).
    static_n_rad_rt_s : float
        The static parity density compared with [rad/√s].
    static_source : str
        ``"model"`` (tr(VᵀRV)/(N − 3)) or ``"still part"``.
    static_k_rad_s_rt_s : float
        The parity's walk the filters assume [rad/s/√s] (0 without a model).
    window_s : float
        Window T [s].
    nis : tuple of NisCheck
        measured, static, export.
    factor_for_export : float
        [-], ≥ 1: the factor on the static values that makes a white + walk filter consistent on
        the fitted motion windows (:func:`gyroarray.chain.inflation.nis_factor`).
    factor_ci : tuple of float
        Its interval before the floor at 1 [-].
    windows_t0_s, windows_level, windows_holdout : ndarray
        Per window: start [s], level index, held out.
    notes : tuple of str
    density_factor : float
        The motion-weighted density over the static one [-], reported beside.
    density_factor_ci : tuple of float
        Its interval [-].
    """

    n_gyros: int
    n_parity: int
    levels: tuple[LevelDensity, ...]
    static_n_rad_rt_s: float
    static_source: str
    static_k_rad_s_rt_s: float
    window_s: float
    nis: tuple[NisCheck, ...]
    factor_for_export: float
    factor_ci: tuple[float, float]
    windows_t0_s: np.ndarray
    windows_level: np.ndarray
    windows_holdout: np.ndarray
    notes: tuple[str, ...] = field(default_factory=tuple)
    density_factor: float = math.nan
    density_factor_ci: tuple[float, float] = (math.nan, math.nan)

    def nis_check(self, label: str) -> NisCheck:
        """The NIS result of ``label`` (measured, static, export)."""
        return next(c for c in self.nis if c.label == label)

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {"method": "parity", "density_factor": self.density_factor,
                "density_factor_ci": list(self.density_factor_ci), "n_gyros": self.n_gyros, "n_parity": self.n_parity,
                "levels": [lv.as_dict() for lv in self.levels],
                "static_n_rad_rt_s": self.static_n_rad_rt_s, "static_source": self.static_source,
                "static_k_rad_s_rt_s": self.static_k_rad_s_rt_s, "window_s": self.window_s,
                "nis": [c.as_dict() for c in self.nis],
                "factor_for_export": self.factor_for_export, "factor_ci": list(self.factor_ci),
                "notes": list(self.notes)}


def parity_basis(H: np.ndarray, *, source: str | None = None) -> np.ndarray:
    """V, N × (N − 3): an orthonormal basis of the left null space of H (Vᵀ H = 0).

    Raises
    ------
    InputError
        N ≤ 3 (no parity) or H not of rank 3.
    """
    from scipy import linalg                               # deferred: heavy
    H = np.asarray(H, dtype=float)
    n = H.shape[0]
    if n <= 3:
        raise InputError(f"the parity residual needs a redundant array of more than 3 gyros; this "
                         f"record has {n} (a gyro triad: measure the inflation against a reference "
                         "pose instead, --reference BAG --reference-topic T)", file=source)
    if np.linalg.matrix_rank(H, tol=1e-6) < 3:
        raise InputError(f"the {n} gyro axes do not span 3-D (rank "
                         f"{np.linalg.matrix_rank(H, tol=1e-6)}): no parity residual free of the "
                         "rate", file=source)
    return linalg.null_space(H.T)


def _model_parity(model, V: np.ndarray, source) -> tuple[float, float]:
    """The static parity density and walk from a model's per-gyro levels [rad/√s, rad/s/√s]:
    √(tr(Vᵀ R V)/d), R the white covariance (and the walk's alike)."""
    from gyroarray.estimators.fdi import model_noise       # deferred: the estimators
    an = model_noise(model, V.shape[0])
    n, k = np.asarray(an.arw_rad_rt_s, float), np.asarray(an.rrw_rad_s_rt_s, float)
    R = np.asarray(an.corr_arw, float) * np.outer(n, n)
    Q = np.asarray(an.corr_rrw, float) * np.outer(k, k)
    d = V.shape[1]
    nn = math.sqrt(max(float(np.trace(V.T @ R @ V)) / d, 0.0))
    kk = math.sqrt(max(float(np.trace(V.T @ Q @ V)) / d, 0.0))
    if not nn > 0:
        raise InputError("the model gives the array no white noise: no static parity density to "
                         "compare with", file=source)
    return nn, kk


def measure_parity_inflation(meas, *, levels=DEFAULT_LEVELS_RAD_S, window_s: float = 1.0,
                             holdout: float = 0.3, model=None, bias_span: int = 15,
                             static_rate_rad_s: float = DEFAULT_STATIC_RATE_RAD_S,
                             confidence: float = 0.95,
                             rng: np.random.Generator | None = None,
                             calibrate: bool = True) -> ParityInflation:
    """The white density an N > 3 gyro array shows per motion level, from its parity residual.

    Parameters
    ----------
    meas : Measurement
        The array's record (N > 3 gyros; its layout's axes H).
    levels : sequence of float
        Bin edges of the smoothed |fused rate| [rad/s]; the first bin should hold the still part
        (default :data:`gyroarray.chain.inflation.DEFAULT_LEVELS_RAD_S`, first edge 0.05).
    window_s : float
        Window T [s] (whole samples).
    holdout : float
        Fraction of the motion segment held out at its end [-], in (0, 0.9].
    model : NoiseModel, optional
        The static per-gyro white (and walk) levels: the static parity density is
        √(tr(VᵀRV)/(N − 3)); without, the still level's measured density (and no walk).
    bias_span : int
        Neighbour windows on each side in the bias estimate [-].
    static_rate_rad_s : float
        Smoothed |fused rate| below which a window is still [rad/s].
    confidence : float
        Level of the intervals [-].
    rng : numpy.random.Generator, optional
        For the factor's interval (default ``default_rng(0)``).
    calibrate : bool
        Take the array's scale-factor and axis errors out first (default): the parity
        self-calibration (:func:`gyroarray.chain.parity.self_calibrate`) fitted on the moving,
        unsaturated samples of the FITTED part only (never the held-out one), its correction
        y − E ω̂ applied to the whole record. Those errors put V ᵀE ω into the parity, a
        deterministic term that follows the rate history, which the densities would otherwise
        read as noise growing with the rate. When the record cannot be calibrated (too little
        motion), nothing is corrected and a note says why.

    Returns
    -------
    ParityInflation

    Raises
    ------
    InputError
        N ≤ 3, axes not spanning 3-D, too few windows in motion or per level, no still part and
        no model.
    """
    from scipy import stats                                # deferred: heavy
    where = meas.source
    if not 0.0 < holdout <= 0.9:
        raise ValueError(f"holdout must be in (0, 0.9], got {holdout}")
    if not (math.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s must be > 0 s, got {window_s!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    H = np.asarray(meas.layout.H, dtype=float)
    V = parity_basis(H, source=where)
    N, d = H.shape[0], V.shape[1]
    t = np.asarray(meas.time_s, dtype=float)
    y = np.asarray(meas.gyro_rad_s, dtype=float)
    notes = [f"parity residual p = Vᵀy of {N} gyros ({d} components, V an orthonormal basis of "
             "the left null space of the layout H: p holds no rate); level = |fused rate H⁺y| "
             f"smoothed over {LEVEL_SMOOTH_S:g} s",
             "equal-noise assumption: with the same white density N_L on every gyro, each parity "
             "component has the density N_L (VᵀV = I), so the parity's density is the gyros'"]
    p = y @ V
    omega = y @ np.linalg.pinv(H).T
    dt = np.diff(t)
    med = float(np.median(dt))
    w = max(1, int(round(window_s / med)))
    nk = (t.size - 1) // w
    if nk < MIN_WINDOWS:
        raise InputError(f"the record holds {nk} windows of {w * med:.3g} s; the parity inflation "
                         f"needs {MIN_WINDOWS}", file=where)
    idx = np.arange(nk) * w
    e = np.add.reduceat(p[: nk * w], idx, axis=0) / w                 # window means [rad/s]
    T = np.full(nk, w * med)
    valid = ~(dt > GAP_FACTOR * med)[: nk * w].reshape(nk, w).any(axis=1)
    rate_s = np.linalg.norm(moving_mean(omega, max(1, int(round(0.5 * LEVEL_SMOOTH_S / med)))),
                            axis=1)
    level_value = rate_s[: nk * w].reshape(nk, w).mean(axis=1)
    lev = assign_levels(level_value, levels)
    n_levels = len(levels) - 1
    t0 = t[idx]

    moving = np.flatnonzero(valid & (level_value >= static_rate_rad_s))
    if moving.size < MIN_WINDOWS:
        raise InputError(f"only {moving.size} windows in motion (mean |fused rate| ≥ "
                         f"{static_rate_rad_s:g} rad/s); the parity inflation needs {MIN_WINDOWS}",
                         file=where)
    m0 = int(moving[0])
    hold = holdout_by_level(np.asarray(valid, dtype=bool), lev, m0, holdout)
    fit_members = np.flatnonzero(valid & ~hold)
    hold_members = np.flatnonzero(valid & hold)
    notes.append(f"{nk} windows of {w * med:.4g} s ({w} samples); motion from {t0[m0]:.3f} s; per "
                 f"rate level the last {holdout:.0%} of its windows from there held out "
                 f"({hold_members.size}), the rest fitted ({fit_members.size}); "
                 f"{int((~valid).sum())} dropped across gaps")

    if calibrate:
        fitted = np.zeros(t.size, bool)
        fitted[: nk * w] = np.repeat(~hold, w)            # the samples of windows not held out
        y, cal_note = _calibrated(y, H, med, fitted=fitted, where=where)
        notes.append(cal_note)
        p = y @ V
        e = np.add.reduceat(p[: nk * w], idx, axis=0) / w
    if model is not None:
        static_n, K = _model_parity(model, V, where)
        static_source = "model"
        notes.append(f"static parity density from the model's per-gyro white levels R: "
                     f"√(tr(VᵀRV)/{d}) = {static_n:.4g} rad/√s (walk alike: {K:.4g} rad/s/√s); the "
                     "motion factor N_L/that is taken as common to every gyro")
    else:
        static_n, K, static_source = math.nan, 0.0, "still part"
    walk = K ** 2 * float(np.mean(T)) * walk_share(bias_span)
    fit = NeighbourFit(e, T, np.zeros(nk), fit_members, bias_span)
    table, pooled, _ = level_table(fit, T, lev, level_value, levels, 0.0, 0.0, walk,
                                    static_n if model is not None else 0.0, confidence)
    if model is None:
        still = table[0] if levels[0] <= 0.0 and levels[1] <= static_rate_rad_s + 1e-12 else None
        if still is None or not np.isfinite(still.density_rad_rt_s):
            raise InputError(f"no still part of {MIN_LEVEL_WINDOWS} windows below "
                             f"{static_rate_rad_s:g} rad/s and no model: no static density to "
                             "compare with (give the model, or a record with a still start)",
                             file=where)
        static_n = still.density_rad_rt_s
        notes.append(f"static density from the still level (|fused rate| < {levels[1]:g} rad/s, "
                     f"{still.n_windows} windows): {static_n:.4g} rad/√s; no walk assumed (no "
                     "model)")
        table = [LevelDensity(**{**lv.__dict__, "factor": lv.density_rad_rt_s / static_n})
                 for lv in table]
    if not any(np.isfinite(lv.density_rad_rt_s) for lv in table[1:]):
        raise InputError(f"no motion level has {MIN_LEVEL_WINDOWS} fitted windows of "
                         f"{w * med:.3g} s (a longer record, fewer levels or a shorter window)",
                         file=where)

    # export factor: the motion-weighted density over the static one
    nu_l = np.array([float(d * lv.n_windows) for lv in table])
    # as inflation.py: the pauses in motion count
    filled, wts, ok, density_factor, density_ci, _ = export_factor(
        pooled, lev[fit_members[fit_members >= m0]], n_levels, nu_l, static_n, rng, confidence)
    fit_motion = np.zeros(nk, bool)
    fit_motion[fit_members[fit_members >= m0]] = True
    raw, f_ci = nis_factor(e, t0, T, static_n ** 2, np.zeros(nk), K ** 2, np.asarray(valid), fit_motion,
                           range(d), confidence)
    factor = max(1.0, raw) if math.isfinite(raw) else 1.0
    notes.append(f"export factor ×{factor:.4g}: the one that makes a white + walk filter with the static values "
                 f"times it consistent (mean NIS 1) on the fitted motion windows; the motion-weighted density "
                 f"is ×{density_factor:.4g} the static one (reported beside)")
    if raw < 1.0:
        notes.append(f"the fitted windows' factor is {raw:.3g}, below 1: the export keeps the static values "
                     "(factor 1)")

    # held-out NIS
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    hv_mask = np.zeros(nk, bool)
    hv_mask[hold_members] = True
    red = 1.0 + 2.0 / max(bias_span, 1)
    checks = []
    for label, dens2, q in (("measured", filled[lev], K ** 2),
                            ("static", np.full(nk, static_n ** 2), K ** 2),
                            ("export", np.full(nk, (factor * static_n) ** 2), (factor * K) ** 2)):
        R = np.repeat((dens2 / T)[:, None], d, axis=1)
        hv = held_out_nis(kf_nis(e, t0, T, R, q, np.asarray(valid)), hv_mask)
        var_param = 0.0
        if label == "measured" and hv.size:
            # a density estimated with ν dof moves the mean NIS by its share × δ ln N²
            lh = lev[hv_mask]
            for L in np.unique(lh):
                cL = float(np.mean(lh == L))
                var_param += cL ** 2 * 2.0 / (nu_l[source_level(int(L), ok)] / red)
        checks.append(nis_check(label, hv, var_param, z))
    st = checks[1]
    notes.append(f"held-out NIS: measured {checks[0].mean_nis:.3g} (interval "
                 f"{checks[0].interval[0]:.3g}–{checks[0].interval[1]:.3g}), static "
                 f"{st.mean_nis:.3g} ({'inside' if st.inside else 'outside'}; off by "
                 f"×{math.sqrt(max(st.mean_nis, 0.0)):.3g} in density), export ×{factor:.3g}: "
                 f"{checks[2].mean_nis:.3g}")
    if not calibrate:
        notes.append("scale-factor and axis errors reach the parity in motion too (Vᵀ E ω): counted "
                     "here as noise that grows with the rate (calibrate=True takes them out first)")
    return ParityInflation(
        n_gyros=N, n_parity=d, levels=tuple(table), static_n_rad_rt_s=float(static_n),
        static_source=static_source, static_k_rad_s_rt_s=float(K), window_s=float(w * med),
        nis=tuple(checks), factor_for_export=float(factor), factor_ci=f_ci,
        density_factor=float(density_factor), density_factor_ci=density_ci,
        windows_t0_s=t0, windows_level=lev, windows_holdout=hold, notes=tuple(notes))


def _calibrated(y: np.ndarray, H: np.ndarray, dt_s: float, *, fitted: np.ndarray, where) -> tuple[np.ndarray, str]:
    """The readings less the array's scale-factor and axis errors fitted on the moving,
    unsaturated samples among ``fitted`` (bool, per sample: the windows not held out) (:func:`gyroarray.chain.parity.self_calibrate`), and a note; the
    readings unchanged and the reason when they cannot be fitted."""
    try:
        still = still_mask(y, H, dt_s)
    except InputError:
        still = np.zeros(y.shape[0], dtype=bool)
    sat, _ = saturated_mask(y)
    use = ~still & ~sat & fitted
    need = MIN_SAMPLES_PER_UNKNOWN * 3 * H.shape[0]
    if use.sum() < need:
        return y, (f"scale-factor and axis errors NOT taken out: the fitted part has {int(use.sum())} moving "
                   f"samples, the parity self-calibration needs {need}; they reach the parity in motion "
                   "(Vᵀ E ω) and are counted here as noise that grows with the rate")
    try:
        cal = self_calibrate(y, H, dt_s, use=use)
    except InputError as err:
        return y, (f"scale-factor and axis errors NOT taken out ({err.message}); "
                   "they are counted here as noise that grows with the rate")
    s_ppm = np.abs(np.asarray(cal.scale_ppm, dtype=float))
    t_mrad = np.abs(np.asarray(cal.tilt_mrad, dtype=float))
    return cal.correct(y, H), (
        f"scale-factor and axis errors taken out first: the parity self-calibration fitted on the "
        f"{int(use.sum())} moving samples of the fitted part (not the held-out windows), |scale| up to "
        f"{np.nanmax(s_ppm):.4g} ppm, |tilt| up to {np.nanmax(t_mrad):.4g} mrad (gauge {cal.gauge}), "
        "its correction y − E ω̂ applied to the whole record; what is left in motion is noise or "
        "what the calibration's model lacks")


def parity_inflation_for_export(meas_path, model, static_n_rad_rt_s: float, axis: str, *,
                                imu_topic: str | None = None, window_s: float = 1.0,
                                holdout: float = 0.3, rng: np.random.Generator | None = None,
                                levels=DEFAULT_LEVELS_RAD_S) -> tuple[float, dict, list[str]]:
    """The measured inflation the export applies, from an N > 3 array record's parity residual.

    Parameters
    ----------
    meas_path : str or os.PathLike
        The array's record (measurement CSV/Parquet with sidecar, or a bag).
    model : NoiseModel
        The exported model: its per-gyro white levels give the static parity density.
    static_n_rad_rt_s : float
        The exported axis's N [rad/√s] (for the header's absolute densities).
    axis : str
        What the file gets (``"gyro 2"``, ``"the axes pooled"``), for the header.
    imu_topic : str, optional
        A bag record's IMU topic.
    window_s : float
        Window [s].
    levels : sequence of float
        Bin edges of the smoothed |fused rate| [rad/s] (:func:`measure_parity_inflation`).
    holdout : float
        Held-out fraction of the motion [-].
    rng : numpy.random.Generator, optional

    Returns
    -------
    factor : float
        [-], ≥ 1, on both gyro numbers.
    summary : dict
        :meth:`ParityInflation.as_dict`, ``factor``, ``axis``, ``measurement``, ``from``.
    header_lines : list of str
        ASCII lines for the file's header (no comment mark).

    Raises
    ------
    InputError
        A record of 3 gyros or fewer (the message names what is needed), and as
        :func:`measure_parity_inflation`.
    """
    from gyroarray.core.measurement import read_measurement   # deferred: the readers
    meas = read_measurement(meas_path, topic=imu_topic)
    if meas.n_gyros <= 3:
        raise InputError(f"--inflate measured without --reference needs a record of a redundant "
                         f"array (more than 3 gyros: its parity residual); {meas_path} has "
                         f"{meas.n_gyros} gyros: give --reference BAG --reference-topic T (a "
                         "reference pose topic) instead", file=str(meas_path))
    m = measure_parity_inflation(meas, window_s=window_s, holdout=holdout, model=model, rng=rng, levels=levels)
    frm = f"from the parity residual of {m.n_gyros} gyros during motion"
    factor = m.factor_for_export
    summary = {**m.as_dict(), "factor": factor, "axis": axis, "measurement": str(meas_path),
               "from": frm}
    s = m.static_n_rad_rt_s
    levels = []
    for lv in m.levels:
        if np.isfinite(lv.density_rad_rt_s):
            hi = "inf" if not np.isfinite(lv.hi) else f"{lv.hi:g}"
            levels.append(f"|w| {lv.lo:g}-{hi} rad/s ({lv.n_windows} windows): x{fmt_g(lv.density_rad_rt_s / s)} "
                          f"[x{fmt_g(lv.ci_rad_rt_s[0] / s)}, x{fmt_g(lv.ci_rad_rt_s[1] / s)}] = "
                          f"{fmt_g(lv.density_rad_rt_s / s * static_n_rad_rt_s)} rad/sqrt(s) on {axis}")
    nis = {c.label: c for c in m.nis}
    mc, sc, ec = nis["measured"], nis["static"], nis["export"]
    header = [
        f"inflation: measured x{factor:.4g} on both numbers ({axis}), {frm}, in {meas_path}: the "
        f"factor on the static parity density {fmt_g(s)} rad/sqrt(s) (the model's sqrt(tr(V'RV)/"
        f"{m.n_parity})) and walk that makes a white + walk filter consistent (mean NIS 1) on the fitted "
        f"motion windows (interval x{fmt_g(m.factor_ci[0])}-x{fmt_g(m.factor_ci[1])}, before the floor at "
        f"1; the motion-weighted density is x{fmt_g(m.density_factor)} the static one); equal-noise "
        "assumption: the factor is common to every gyro",
        f"measured density per motion level (|fused rate|), windows of {m.window_s:.3g} s: "
        + "; ".join(levels),
        f"held-out check (last {holdout:.0%} of each motion level, {mc.n_eff} innovations), mean NIS of a "
        f"bias filter on the parity (1 when consistent): measured values {fmt_g(mc.mean_nis)} "
        f"(interval {fmt_g(mc.interval[0])}-{fmt_g(mc.interval[1])}, "
        f"{'inside' if mc.inside else 'OUTSIDE'}); static values {fmt_g(sc.mean_nis)} "
        f"({'inside' if sc.inside else 'outside'}, off x{fmt_g(math.sqrt(max(sc.mean_nis, 0)))} in "
        f"density); exported values {fmt_g(ec.mean_nis)} "
        f"({'inside' if ec.inside else 'outside'} {fmt_g(ec.interval[0])}-{fmt_g(ec.interval[1])})",
    ]
    return float(factor), summary, header
