"""The evidence the design report shows beside a recommendation, computed here, drawn by reports/.

* :func:`noise_and_space`: the :class:`~gyroarray.design.recommend.GyroNoise`
  and :class:`~gyroarray.design.recommend.DesignSpace` of a saved
  ``design --recommend`` result's assumptions.
* :func:`recommended_adev`: one simulated record of the recommended design,
  the Allan deviation of its single gyros against its fused output (an
  :class:`~gyroarray.analysis.adev_curves.AdevFigure`); :func:`cached_recommended_adev`
  keeps it in a JSON file beside the design result, keyed by a hash of the
  design, its assumptions and the seed, so the report re-renders without simulating.
* :func:`gdop_robustness_table`: per scheme and N, the cone angle optimal at the
  largest ρ evaluated where it is worst, and the min-max cone angle (rows of
  :class:`GdopRobustnessRow`).
* :func:`mirror_comparison`: a design against its mounting mirror, worst case over
  ρ × failures of the fixed-weight least squares' white-noise GDOP (the reason a
  cone at α > 90° or a reversed gyro wins under correlated noise).
* :func:`what_would_change`: what would change the choice, from the ranked designs,
  for a result that does not say it.
* :func:`fused_single_ratio`: the plotted record's fused/single Allan deviation
  ratio at long τ, against √(3/N).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from gyroarray.analysis.adev_curves import AdevFigure, single_vs_fused
from gyroarray.core import units
from gyroarray.core.gdop import gdop_robustness, minmax_alpha, optimal_alpha
from gyroarray.core.layout import Layout
from gyroarray.core.result_cache import ResultCache, input_key
from gyroarray.design.predict import Swing, settle_start, swing_truth
from gyroarray.design.recommend import DesignSpace, GyroNoise, design_label, estimator_kwargs
from gyroarray.design.robust import fixed_weights, kept_sets, mirror_pattern, mounted_axes, worst_over_interval
from gyroarray.estimators import get_estimator
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.names import ARW, BIAS_INSTABILITY, GAUSS_MARKOV, RRW

__all__ = ["ADEV_SEED", "GdopRobustnessRow", "noise_and_space", "recommended_adev",
           "cached_recommended_adev", "adev_file", "gdop_robustness_table", "mirror_comparison",
           "what_would_change", "fused_single_ratio", "record_rho"]

#: Seed of the recommended design's simulated record.
ADEV_SEED = 20260413
AXES = ("x", "y", "z")


def noise_and_space(a: dict) -> tuple[GyroNoise, DesignSpace]:
    """The GyroNoise and DesignSpace of a result's ``assumptions`` (as :func:`~gyroarray.design.recommend.assumptions` writes them)."""
    gm = a[GAUSS_MARKOV]["value"]
    rho = a["rho"]["value"]
    r0 = 0.0 if isinstance(rho, list) else float(rho)
    g = GyroNoise(arw_deg_rt_h=a[ARW]["value"], rrw_deg_h_rt_h=a[RRW]["value"],
                  bi_deg_h=a[BIAS_INSTABILITY]["value"], gm_sigma_deg_h=gm["sigma_deg_h"],
                  gm_tau_s=gm["tau_s"], rho_arw=r0, rho_rrw=r0)
    m = a["motion"]["value"]
    swing = None
    if isinstance(m, dict):
        swing = Swing(units.deg_s_to_rad_s(m["swing_amplitude_deg_s"]), m["swing_frequency_hz"])
    space = DesignSpace(rate_hz=a["rate_hz"]["value"], horizon_s=a["horizon_s"]["value"],
                        ns=tuple(a["n"]["value"]), failures=a["failures"]["value"], swing=swing,
                        settle_s=a["settle_s"]["value"])
    return g, space


def recommended_adev(res: dict, *, seed: int = ADEV_SEED, title: str = "") -> AdevFigure:
    """Simulate the recommended design once and compute its single-gyro and fused ADEV.

    Parameters
    ----------
    res : dict
        A ``design --recommend`` result (``recommended``, ``assumptions``).
    seed : int
        Seed of the record.
    title : str
        The figure's title.

    Returns
    -------
    AdevFigure
        One record of the design's horizon (at least 600 s), after the settling
        time, of the array as mounted (``axes``, reversed gyros included), with the
        motion of the result when it has one; ``rho`` the record's correlation
        (:func:`record_rho`: the design ρ the estimator is built for),
        ``predicted_arw_long_deg_rt_h`` the predictor's long-τ fused ARW per axis.
    """
    g, space = noise_and_space(res["assumptions"])
    d = res["recommended"]
    rho = record_rho(d, g.rho_arw)
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    n_g = d["n"]
    if d.get("axes") is not None:             # the array as mounted (reversed gyros included)
        layout = Layout(np.asarray(d["axes"], dtype=float))
    else:
        layout = Layout.conical(d["scheme"], n_g, math.radians(d["alpha_deg"]))
    model = gr.noise_model(n_g)
    dt = space.dt_s
    n = max(space.n_samples, int(round(600.0 / dt)))
    truth = swing_truth(space.swing, n, dt) if space.swing is not None else np.zeros((n, 3))
    t = np.arange(n) * dt
    z = simulate_readings(model, truth, layout, dt, np.random.default_rng(seed), time_s=t)
    est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], d["bandwidth_hz"], gr)
                                        ).fit(layout, model, dt)
    k0 = settle_start(n, dt, space.settle_s)
    fused = (est.estimate(z) - truth)[k0:]
    single = (z - truth @ layout.H.T)[k0:]
    p = d["predicted"]
    return single_vs_fused(single, fused, dt, title=title, estimator=d["estimator"], seed=seed,
                           rho=float(rho), record_s=n * dt,
                           predicted_arw_long_deg_rt_h=[p[a].get("arw_long_deg_rt_h", math.nan)
                                                        for a in AXES])


def record_rho(d: dict, default: float = 0.0) -> float:
    """The correlation the recommended design's ADEV record is simulated at [-].

    The design ρ its estimator is built for (``design_rho``, the typical case); a
    result without one: its ``rho``, else ``default``.
    """
    for v in (d.get("design_rho"), (d.get("typical") or {}).get("rho"), d.get("rho")):
        if v is not None:
            return float(v)
    return float(default)


def fused_single_ratio(a: AdevFigure, min_tau_s: float = 1.0) -> dict:
    """The plotted record's fused / single Allan deviation at long τ.

    Parameters
    ----------
    a : AdevFigure
    min_tau_s : float
        Only τ at or above this are compared [s] (above the filter's time constants).

    Returns
    -------
    dict
        ``per_axis`` (x, y, z: median over τ ≥ ``min_tau_s`` of fused ADEV / the mean
        single-gyro ADEV [-]), ``reference`` (√(3/N) [-]), ``min_tau_s``; per_axis
        empty when no τ qualifies.
    """
    singles = a.singles
    out: dict[str, Any] = {"per_axis": {}, "reference": float(a.reference_factor), "min_tau_s": float(min_tau_s)}
    if not singles:
        return out
    taus = singles[0].taus_s
    single = np.mean([c.adev_rad_s for c in singles if c.taus_s.shape == taus.shape], axis=0)
    for c, axis in zip(a.fused, AXES):
        m = (c.taus_s >= min_tau_s)
        if c.taus_s.shape != taus.shape or not m.any():
            continue
        r = c.adev_rad_s[m] / single[m]
        r = r[np.isfinite(r)]
        if r.size:
            out["per_axis"][axis] = float(np.median(r))
    return out


def _white_worst(axes: np.ndarray, design_rho: float, lo: float, hi: float, failures: int) -> dict:
    """Worst white-noise GDOP of the GLS with weights fixed for ``design_rho``, over ρ × failures."""
    n = axes.shape[0]
    worst: dict[str, Any] = {"gdop": -math.inf, "rho": None, "failed_gyros": []}
    for keep in kept_sets(n, failures):
        k = list(keep)
        H = axes[k]
        m = len(k)
        lo_ok = max(lo, -1.0 / (m - 1) + 1e-6) if m > 1 else lo
        c_d = (1.0 - design_rho) * np.eye(m) + design_rho * np.ones((m, m))
        M = fixed_weights("gls", H[None], c_d)[0]

        def g(r, M=M, m=m):
            C = (1.0 - r) * np.eye(m) + r * np.ones((m, m))
            return float(np.sqrt(max(np.trace(M @ C @ M.T), 0.0)))
        v, at = worst_over_interval(g, lo_ok, max(hi, lo_ok))
        if v > worst["gdop"]:
            worst = {"gdop": v, "rho": at, "failed_gyros": [j + 1 for j in range(n) if j not in keep]}
    return worst


def mirror_comparison(d: dict, rho_range, failures: int) -> dict | None:
    """A design against its mounting mirror under correlated noise.

    Both are scored the same way: least squares with weights fixed for the design's
    ``design_rho`` (recomputed on the gyros left after a failure), the white-noise
    GDOP √trace(M C(ρ) Mᵀ) [-] at its worst over ρ in ``rho_range`` and every set of
    ``failures`` failed gyros. The mirror is
    :func:`gyroarray.design.robust.mirror_pattern` of the design.

    Parameters
    ----------
    d : dict
        A design of a ``design --recommend`` result (``scheme``, ``n``, ``alpha_deg``,
        ``mounting_signs``, ``design_rho``).
    rho_range : (float, float)
        The correlations the gyros may have [-].
    failures : int
        Failed gyros to survive.

    Returns
    -------
    dict or None
        ``design`` and ``mirror`` ({gdop, rho, failed_gyros}), ``mirror_alpha_deg``,
        ``mirror_reversed`` (1-based gyros reversed in the mirror), ``ratio``
        (mirror / design); None when the design has no mounting signs.
    """
    signs = d.get("mounting_signs")
    if signs is None:
        return None
    lo, hi = (float(rho_range[0]), float(rho_range[-1])) if rho_range is not None else (0.0, 0.0)
    rd = d.get("design_rho")
    rd = 0.5 * (lo + hi) if rd is None else float(rd)
    s = np.asarray(signs, dtype=float)
    own = mounted_axes(d["scheme"], d["n"], np.array([math.radians(d["alpha_deg"])]), s)[0]
    m_alpha, m_signs = mirror_pattern(d["scheme"], d["alpha_deg"], s)
    mir = mounted_axes(d["scheme"], d["n"], np.array([math.radians(m_alpha)]), m_signs)[0]
    a = _white_worst(own, rd, lo, hi, failures)
    b = _white_worst(mir, rd, lo, hi, failures)
    return {"design": a, "mirror": b, "mirror_alpha_deg": float(m_alpha),
            "mirror_reversed": [k + 1 for k in range(len(m_signs)) if m_signs[k] < 0],
            "ratio": b["gdop"] / a["gdop"] if a["gdop"] > 0 else math.nan, "design_rho": rd}


def _objective_value(d: dict, objective: str) -> float | None:
    wc = d.get("worst_case") or {}
    v = wc.get("angle_deg" if objective == "angle" else "rms_3axis_deg_s")
    return None if v is None else float(v)


def what_would_change(res: dict) -> list[str]:
    """What would change the choice, from the ranked designs (for a result that does not say it).

    Returns
    -------
    list of str
        The runner-up's margin on the objective's worst case, and the best design
        with fewer gyros and its cost in accuracy; empty when the designs carry no
        worst case.
    """
    rec = res.get("recommended") or {}
    obj = res.get("objective") or rec.get("objective") or "rate"
    unit = "deg at the horizon" if obj == "angle" else "deg/s 3-axis RMS"
    v0 = _objective_value(rec, obj)
    if v0 is None:
        return []
    out = []
    ru = res.get("runner_up")
    v1 = _objective_value(ru, obj) if ru else None
    if v1 is not None and v0 > 0:
        out.append(f"the runner-up ({design_label(cast(dict, ru))}) is {100 * (v1 / v0 - 1):.3g} % worse in the worst "
                   f"case ({v1:.4g} against {v0:.4g} {unit}): a larger error in the inputs than that "
                   "(noise, ρ range) can reverse the order")
    fewer = [d for d in res.get("designs", []) if d.get("n", 0) < rec.get("n", 0)
             and _objective_value(d, obj) is not None]
    if fewer:
        b = min(fewer, key=lambda d: cast(float, _objective_value(d, obj)))    # fewer holds no None
        vb = cast(float, _objective_value(b, obj))
        out.append(f"fewer gyros: the best N = {b['n']} design ({design_label(b)}) has a worst case of "
                   f"{vb:.4g} {unit}, {100 * (vb / v0 - 1):.3g} % more")
    return out


def adev_file(design_path) -> Path:
    """Where the recommended design's ADEV curves are saved: ``<design stem>.adev.json`` beside it."""
    p = Path(design_path)
    return p.with_name(p.stem + ".adev.json")


def cached_recommended_adev(res: dict, cache: ResultCache | None, *, seed: int = ADEV_SEED,
                            title: str = "") -> AdevFigure:
    """:func:`recommended_adev`, read from ``cache`` when saved under the same inputs, else computed and added."""
    key = input_key("design_adev", res["recommended"], res["assumptions"], seed, title)
    hit = cache.get(key) if cache is not None else None
    if hit is not None:
        try:
            return AdevFigure.from_dict(hit)
        except (KeyError, TypeError, ValueError):
            pass                            # a damaged entry: simulate again and replace it
    fig = recommended_adev(res, seed=seed, title=title)
    if cache is not None:
        cache.put(key, fig.to_dict())
    return fig


@dataclass
class GdopRobustnessRow:
    """One scheme and N: the cone angle chosen for the largest ρ against the min-max one.

    Attributes
    ----------
    scheme, n : int
        The cone scheme and the number of gyros.
    chosen_for_rho : float
        The largest ρ of the range [-], the one the cone angle is optimal for.
    alpha_deg : float
        That optimal cone angle [deg].
    worst_rho : float
        Where over the range it is worst (largest excess over the best GDOP there) [-].
    gdop, gdop_best : float
        Its GDOP there and the best GDOP there [-].
    excess_percent : float
        (gdop / gdop_best − 1) × 100 [%].
    minmax_alpha_deg, minmax_gdop : float
        The min-max cone angle over the range [deg] and its worst GDOP [-].
    """

    scheme: int
    n: int
    chosen_for_rho: float
    alpha_deg: float
    worst_rho: float
    gdop: float
    gdop_best: float
    excess_percent: float
    minmax_alpha_deg: float
    minmax_gdop: float

    def to_dict(self) -> dict:
        """JSON-ready dict (the keys are the attributes)."""
        return {k: float(v) if isinstance(v, float) else v for k, v in asdict(self).items()}


def gdop_robustness_table(rhos, schemes=(1, 2), ns=(4, 5, 6, 8)) -> list[GdopRobustnessRow]:
    """GDOP alone over a ρ range: per scheme and N with at least two admissible ρ (ρ > −1/(N−1))."""
    rows = []
    for scheme in schemes:
        for n in ns:
            ok = [float(r) for r in rhos if r > -1.0 / (n - 1)]
            if len(ok) < 2:
                continue
            hi = max(ok)
            a_hi = optimal_alpha(scheme, n, hi).alpha_rad
            rob = gdop_robustness(scheme, n, ok, alpha_rad=a_hi)
            worst = max(rob, key=lambda r: r["excess"])
            mm = minmax_alpha(scheme, n, ok)
            rows.append(GdopRobustnessRow(
                scheme=scheme, n=n, chosen_for_rho=hi, alpha_deg=math.degrees(a_hi),
                worst_rho=worst["rho"], gdop=worst["gdop"], gdop_best=worst["gdop_opt"],
                excess_percent=100 * worst["excess"], minmax_alpha_deg=math.degrees(mm.alpha_rad),
                minmax_gdop=mm.gdop))
    return rows
