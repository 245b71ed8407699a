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
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gyroarray.analysis.adev_curves import AdevFigure, single_vs_fused
from gyroarray.core import units
from gyroarray.core.gdop import gdop_robustness, minmax_alpha, optimal_alpha
from gyroarray.core.layout import Layout
from gyroarray.core.result_cache import ResultCache, input_key
from gyroarray.design.predict import Swing, settle_start, swing_truth
from gyroarray.design.recommend import DesignSpace, GyroNoise, estimator_kwargs
from gyroarray.estimators import get_estimator
from gyroarray.sim.effects import simulate_readings

__all__ = ["ADEV_SEED", "GdopRobustnessRow", "noise_and_space", "recommended_adev",
           "cached_recommended_adev", "adev_file", "gdop_robustness_table"]

#: Seed of the recommended design's simulated record.
ADEV_SEED = 20260413
AXES = ("x", "y", "z")


def noise_and_space(a: dict) -> tuple[GyroNoise, DesignSpace]:
    """The GyroNoise and DesignSpace of a result's ``assumptions`` (as :func:`~gyroarray.design.recommend.assumptions` writes them)."""
    gm = a["gauss_markov"]["value"]
    rho = a["rho"]["value"]
    r0 = 0.0 if isinstance(rho, list) else float(rho)
    g = GyroNoise(arw_deg_rt_h=a["arw"]["value"], rrw_deg_h_rt_h=a["rrw"]["value"],
                  bi_deg_h=a["bias_instability"]["value"], gm_sigma_deg_h=gm["sigma_deg_h"],
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
        time; ``rho`` the design's correlation, ``predicted_arw_long_deg_rt_h``
        the predictor's long-τ fused ARW per axis.
    """
    g, space = noise_and_space(res["assumptions"])
    d = res["recommended"]
    gr = g.with_rho(d.get("rho", g.rho_arw)) if g.rho_arw == g.rho_rrw else g
    n_g = d["n"]
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
                           rho=float(d.get("rho", g.rho_arw)), record_s=n * dt,
                           predicted_arw_long_deg_rt_h=[p[a].get("arw_long_deg_rt_h", math.nan)
                                                        for a in AXES])


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
