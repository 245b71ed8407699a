"""Song et al. 2018 (paper 000), Table 1: DAVAR-400, DAVAR-600 and A-DAVAR on the paper's
simulated signal, over several seeds, beside the printed values.

Run: ``python benchmarks/davar_paper.py [--seeds N] [--json]`` (about 1 s per seed).
tests/test_davar.py imports :func:`paper_signal` and :func:`paper_table1` from here.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gyroarray.core import units
from gyroarray.analysis.davar import (AdaptiveWindow, DavarResult, finite_float, change_nodes,
                                      davar)
from gyroarray.core.errors import InputError

__all__ = ["PAPER_TABLE1", "PaperTable1", "paper_signal", "paper_table1", "format_paper_table1"]


#: Song et al. 2018, Table 1: DAVAR-400, DAVAR-600, A-DAVAR on the simulated
#: signal (one realisation).  ARW in 1e-3 deg/√h, nodes in s.
PAPER_TABLE1 = {
    "arw_0_2000": (4.03, 3.87, 3.83),
    "arw_3000_4000": (10.97, 10.32, 9.45),
    "beginning_3000": (2800.0, 2702.0, 2703.0),
    "end_3000": (3200.0, 3300.0, 3156.0),
    "beginning_4000": (3800.0, 3700.0, 3740.0),
    "end_4000": (4200.0, 4300.0, 4200.0),
}

_PAPER_METHODS = ("DAVAR-400", "DAVAR-600", "A-DAVAR")
_PAPER_N = 6000            # samples at tau0 = 1 s
_PAPER_TAU0 = 1.0
_PAPER_CHANGE = (3000, 4000)   # variance 3 on samples [3000, 4000)
_PAPER_VARIANCE = 3.0

# rows of the comparison: key, label, unit
_ROWS = (
    ("arw_0_2000", "ARW (0-2000 s)", "1e-3 deg/rt-h"),
    ("arw_3000_4000", "ARW (3000-4000 s)", "1e-3 deg/rt-h"),
    ("arw_ratio", "ARW ratio (3000-4000)/(0-2000)", "-"),
    ("beginning_3000", "Beginning (3000 s)", "s"),
    ("end_3000", "End (3000 s)", "s"),
    ("restore_3000", "Restore 600 (3000 s)", "s"),
    ("beginning_4000", "Beginning (4000 s)", "s"),
    ("end_4000", "End (4000 s)", "s"),
    ("restore_4000", "Restore 600 (4000 s)", "s"),
)


def paper_signal(rng: np.random.Generator, *,
                 sigma_rad_s: float = units.deg_h_to_rad_s(1.0)
                 ) -> np.ndarray:
    """The paper's simulated gyro: white noise with a variance step.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the noise.
    sigma_rad_s : float, default 1 deg/h
        Standard deviation of the stable parts [rad/s].  The paper gives
        "variance 1" without a unit; 1 (deg/h)^2 is assumed, so that the
        ARW is ``1/60 deg/√h = 16.7e-3 deg/√h`` at 1 s sampling.

    Returns
    -------
    numpy.ndarray, shape (6000,)
        Rate [rad/s] sampled at 1 s; samples 3000-3999 (3000-4000 s) have
        variance ``3 sigma^2``.

    References
    ----------
    .. [1] J. Song, Z. Shi, L. Wang, H. Wang, Micromachines 9(8), 373,
       2018, sec. 2.2.
    """
    if not isinstance(rng, np.random.Generator):
        raise InputError("rng must be a numpy.random.Generator")
    scale = np.full(_PAPER_N, finite_float(sigma_rad_s, "sigma_rad_s"))
    scale[_PAPER_CHANGE[0]:_PAPER_CHANGE[1]] *= math.sqrt(_PAPER_VARIANCE)
    return scale * rng.standard_normal(_PAPER_N)


@dataclass(frozen=True)
class PaperTable1:
    """The paper's Table 1 beside ours over several seeds.

    Parameters
    ----------
    rows : tuple of str
        Row keys: ``arw_0_2000``, ``arw_3000_4000`` (mean ARW of the window
        centres in that interval [1e-3 deg/√h]), ``arw_ratio`` [-],
        ``beginning_3000``, ``end_3000``, ``restore_3000``,
        ``beginning_4000``, ``end_4000``, ``restore_4000`` [s] (see
        :func:`change_nodes`).
    labels, units : tuple of str
        Row labels and units for printing.
    methods : tuple of str
        ``("DAVAR-400", "DAVAR-600", "A-DAVAR")``.
    paper : numpy.ndarray, shape (rows, methods)
        Table 1 of the paper (NaN where it has no value; the ratio row is
        computed from its ARW rows).
    values : numpy.ndarray, shape (seeds, rows, methods)
        Ours per seed (NaN: node not found).
    seeds : tuple of int
        Seeds of ``numpy.random.default_rng`` used for the signals.
    sigma_rad_s : float
        Noise level of the stable parts [rad/s] (:func:`paper_signal`).
    """

    rows: tuple
    labels: tuple
    units: tuple
    methods: tuple
    paper: np.ndarray = field(repr=False)
    values: np.ndarray = field(repr=False)
    seeds: tuple
    sigma_rad_s: float

    @property
    def mean(self) -> np.ndarray:
        """Mean over the seeds where the value exists, (rows, methods)."""
        found = self.found
        total = np.nansum(self.values, axis=0)
        return np.where(found > 0, total / np.maximum(found, 1), np.nan)

    @property
    def sd(self) -> np.ndarray:
        """Sample standard deviation over the seeds where the value exists
        (ddof 1; NaN with fewer than two), (rows, methods)."""
        found = self.found
        dev = np.where(np.isfinite(self.values), self.values - self.mean, 0.0)
        ss = np.sum(dev * dev, axis=0)
        return np.where(found > 1, np.sqrt(ss / np.maximum(found - 1, 1)),
                        np.nan)

    @property
    def found(self) -> np.ndarray:
        """Number of seeds with a value, (rows, methods)."""
        return np.sum(np.isfinite(self.values), axis=0)

    def to_json_dict(self) -> dict:
        """JSON-ready dict: per row and method, paper, mean, sd, found, values.

        Returns
        -------
        dict
            ``{"seeds": [...], "sigma_deg_h": float, "rows": {key: {"label",
            "unit", "methods": {name: {"paper", "mean", "sd", "found",
            "values"}}}}}``; NaN becomes ``None``.
        """
        def num(v):
            return None if not math.isfinite(v) else float(v)
        mean, sd, found = self.mean, self.sd, self.found
        rows = {}
        for r, key in enumerate(self.rows):
            rows[key] = {
                "label": self.labels[r], "unit": self.units[r],
                "methods": {
                    name: {"paper": num(self.paper[r, c]),
                           "mean": num(mean[r, c]), "sd": num(sd[r, c]),
                           "found": int(found[r, c]),
                           "values": [num(v) for v in self.values[:, r, c]]}
                    for c, name in enumerate(self.methods)},
            }
        return {"seeds": list(self.seeds),
                "sigma_deg_h": float(units.rad_s_to_deg_h(self.sigma_rad_s)),
                "rows": rows}


def _mean_arw_in(result: DavarResult, t0: float, t1: float) -> float:
    """Mean ARW [rad/√s] of the windows centred in ``[t0, t1)``."""
    sel = (result.time_s >= t0) & (result.time_s < t1)
    return float(np.mean(result.arw_rad_rt_s[sel]))


def paper_table1(seeds: Sequence[int] = tuple(range(20)), *,
                 sigma_rad_s: float = units.deg_h_to_rad_s(1.0),
                 params: AdaptiveWindow | None = None) -> PaperTable1:
    """Reproduce the paper's Table 1 over several noise realisations.

    Parameters
    ----------
    seeds : sequence of int, default 0..19
        One ``numpy.random.default_rng(seed)`` signal (:func:`paper_signal`)
        per seed, analysed by all three methods.
    sigma_rad_s : float, default 1 deg/h
        Noise level of the stable parts [rad/s].
    params : AdaptiveWindow or None
        A-DAVAR parameters (default: the paper's).

    Returns
    -------
    PaperTable1

    Notes
    -----
    DAVAR-400 and DAVAR-600: fixed windows of 400 and 600 samples; A-DAVAR
    with ``params``; all with step 1, mirror extension, octave taus up to
    L/3 and ``arw="tau0"``.  ARW rows: mean over the window centres in
    [0, 2000) s and [3000, 4000) s, in 1e-3 deg/√h; nodes from
    :func:`change_nodes` at 3000 s and 4000 s.  About 1 s per seed.

    References
    ----------
    .. [1] J. Song, Z. Shi, L. Wang, H. Wang, Micromachines 9(8), 373,
       2018, sec. 5, Table 1.
    """
    seeds = tuple(int(s) for s in seeds)
    if not seeds:
        raise InputError("paper_table1 needs at least one seed")
    keys = [r[0] for r in _ROWS]
    paper = np.full((len(keys), len(_PAPER_METHODS)), np.nan)
    for key, vals in PAPER_TABLE1.items():
        paper[keys.index(key)] = vals
    paper[keys.index("arw_ratio")] = (paper[keys.index("arw_3000_4000")]
                                      / paper[keys.index("arw_0_2000")])
    values = np.full((len(seeds), len(keys), len(_PAPER_METHODS)), np.nan)
    to_table = 1e3 * units.arw_rad_rt_s_to_deg_rt_h(1.0)
    for s, seed in enumerate(seeds):
        y = paper_signal(np.random.default_rng(seed), sigma_rad_s=sigma_rad_s)
        results = (davar(y, _PAPER_TAU0, window=400, step=1),
                   davar(y, _PAPER_TAU0, window=600, step=1),
                   davar(y, _PAPER_TAU0, adaptive=True, params=params))
        for c, res in enumerate(results):
            quiet = _mean_arw_in(res, 0.0, 2000.0) * to_table
            loud = _mean_arw_in(res, 3000.0, 4000.0) * to_table
            cell = {"arw_0_2000": quiet, "arw_3000_4000": loud,
                    "arw_ratio": loud / quiet}
            for change in _PAPER_CHANGE:
                nodes = change_nodes(res, change * _PAPER_TAU0)
                cell[f"beginning_{change}"] = nodes.beginning_s
                cell[f"end_{change}"] = nodes.end_s
                cell[f"restore_{change}"] = nodes.restore_s
            values[s, :, c] = [cell[k] for k in keys]
    return PaperTable1(rows=tuple(keys), labels=tuple(r[1] for r in _ROWS),
                       units=tuple(r[2] for r in _ROWS),
                       methods=_PAPER_METHODS, paper=paper, values=values,
                       seeds=seeds, sigma_rad_s=float(sigma_rad_s))


def format_paper_table1(table: PaperTable1) -> str:
    """The comparison as a text table (paper | ours mean ± sd [found/seeds]).

    Parameters
    ----------
    table : PaperTable1
        From :func:`paper_table1`.

    Returns
    -------
    str
        One line per row, one column group per method; ``-`` where the paper
        has no value or the node does not exist (restore of a fixed window),
        ``[k/n]`` where only ``k`` of ``n`` seeds have the node.
    """
    mean, sd, found = table.mean, table.sd, table.found
    n = len(table.seeds)
    width = 32
    lines = [(f"Song et al. 2018, Table 1 vs gyroarray ({n} seeds, sigma = "
              f"{units.rad_s_to_deg_h(table.sigma_rad_s):g} deg/h)"),
             f"{'node':<36}" + "".join(f"{m:>{width}}" for m in table.methods),
             f"{'':<36}" + f"{'paper | ours mean ± sd':>{width}}"
             * len(table.methods)]
    for r in range(len(table.rows)):
        nodes = table.units[r] == "s"
        cells = []
        for c in range(len(table.methods)):
            p = table.paper[r, c]
            text = "-" if not math.isfinite(p) else (
                f"{p:.0f}" if nodes else f"{p:.4g}")
            if found[r, c] == 0:
                text += " | -"
            else:
                m, s = mean[r, c], sd[r, c]
                text += (f" | {m:.0f} ± {s:.0f}" if nodes
                         else f" | {m:.4g} ± {s:.2g}")
                if found[r, c] < n:
                    text += f" [{found[r, c]}/{n}]"
            cells.append(f"{text:>{width}}")
        label = f"{table.labels[r]} [{table.units[r]}]"
        lines.append(f"{label:<36}" + "".join(cells))
    return "\n".join(lines)



def main(argv: Sequence[str] | None = None) -> PaperTable1:
    """Print the paper's Table 1 beside ours (20 seeds by default) and return it."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20, metavar="N", help="realisations (seeds 0..N-1)")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error("--seeds must be at least 1")
    table = paper_table1(tuple(range(args.seeds)))
    print(json.dumps(table.to_json_dict(), allow_nan=False) if args.json
          else format_paper_table1(table))
    return table


if __name__ == "__main__":
    main()
