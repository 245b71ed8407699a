"""Allan deviation of one sweep scenario, re-simulated once and saved in the sweep's folder.

The design report shows, for a sweep's best static design and for paper 003's
Figs. 14 and 22, the Allan deviation of the single gyros against the fused
output. Those curves need the record, which a sweep does not keep: this module
re-simulates the scenario from the sweep's own file (only while that file is
unchanged since the run: its SHA-256 is in the manifest), computes the curves
(:func:`gyroarray.analysis.adev_curves.single_vs_fused`) and saves them in
``<sweep folder>/adev.json`` (:data:`ADEV_FILE`), keyed by a hash of the sweep
file's digest, the scenario id and the estimator. A report reads them from
there: it re-renders without simulating.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.analysis.adev_curves import AdevFigure, single_vs_fused
from gyroarray.chain.run import SETTLE_S
from gyroarray.core.errors import InputError
from gyroarray.core.result_cache import ResultCache, input_key
from gyroarray.estimators import get_estimator
from gyroarray.sweep.sweep import load_sweep

__all__ = ["ADEV_FILE", "SweepAdev", "scenario_adev"]

#: The saved curves in a sweep's folder.
ADEV_FILE = "adev.json"


def scenario_adev(spec, estimator: str, title: str) -> AdevFigure:
    """Simulate one sweep scenario and compute the ADEV of its single gyros and fused axes.

    Parameters
    ----------
    spec : gyroarray.sweep.sweep.ScenarioSpec
        The scenario (its seed included).
    estimator : str
        The estimator that fuses the readings.
    title : str
        The figure's title.

    Returns
    -------
    AdevFigure
        Errors after the chain's settling time :data:`gyroarray.chain.run.SETTLE_S`.
    """
    from gyroarray.sim.scenario import simulate  # lazy: loads mujoco only when a record is needed
    sc = spec.build()
    res = simulate(sc)
    dt = 1.0 / sc.sample_rate_hz
    est = get_estimator(estimator)().fit(sc.layout, sc.model, dt).estimate(res.readings_rad_s)
    t = res.truth.time_s
    keep = t >= t[0] + SETTLE_S
    truth = res.truth.omega_body_rad_s
    gyro_err = (res.readings_rad_s - truth @ sc.layout.H.T)[keep]
    fused_err = (est - truth)[keep]
    return single_vs_fused(gyro_err, fused_err, dt, title=title, estimator=estimator,
                           seed=spec.seed, record_s=float(t[keep][-1] - t[keep][0]))


class SweepAdev:
    """The ADEV figures of one sweep folder: read from ``adev.json``, else simulated and saved.

    Parameters
    ----------
    path : path-like
        The sweep's ``--out`` folder.
    manifest : dict
        Its ``sweep.json`` (``source``: the sweep file, ``sweep_sha256``: its digest at the run).
    """

    def __init__(self, path, manifest: dict):
        self.path = Path(path)
        self.manifest = manifest
        self.cache = ResultCache(self.path / ADEV_FILE, "adev")
        self._specs: dict | None = None
        self._why = ""

    def _find_spec(self, scenario_id: str):
        if self._specs is None:
            self._specs = {}
            src = self.manifest.get("source")
            if not src or not Path(src).is_file():
                self._why = f"the sweep file {src} is not available to re-simulate from"
            else:
                try:
                    sweep = load_sweep(src)
                except InputError as err:
                    self._why = f"the sweep file no longer loads: {err}"
                else:
                    if sweep.sha256 != self.manifest.get("sweep_sha256"):
                        self._why = f"the sweep file {src} changed since the run"
                    else:
                        self._specs = {s.id: s for s in sweep.scenarios}
        return self._specs.get(scenario_id), self._why

    def figure(self, scenario_id: str, estimator: str, title: str) -> tuple[AdevFigure | None, str]:
        """(the figure, "") from the saved curves or a new simulation; (None, why not) otherwise.

        A saved figure is used only under the key of this sweep file's digest (as
        recorded at the run), this scenario, estimator and title.
        """
        key = input_key("sweep_adev", self.manifest.get("sweep_sha256"), scenario_id, estimator, title)
        hit = self.cache.get(key)
        if hit is not None:
            try:
                return AdevFigure.from_dict(hit), ""
            except (KeyError, TypeError, ValueError):
                pass                        # a damaged entry: simulate again and replace it
        spec, why = self._find_spec(scenario_id)
        if spec is None:
            return None, why
        fig = scenario_adev(spec, estimator, title)
        self.cache.put(key, fig.to_dict())
        return fig, ""

    def save(self) -> str:
        """Write the new curves to ``adev.json``; returns why not ("" when written or nothing new)."""
        self.cache.save()
        return self.cache.why_not
