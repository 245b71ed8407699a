"""Every test's z after the right model is fitted, over scored cases: is each ≈ N(0, 1)?

    python benchmarks/null_z.py [--first-seed 106] [--seeds 3] [--json F]

For each case of :func:`gyroarray.sim.cases.single_effect_case` the hidden
effect is fitted (``ModelComparison.fit``), then every test of the analysis
after the fit is kept. A test of the effect that was set, on its gyro, is not
a null test and is left out. Per test kind the summary prints how many z
exceed 2 and 3 against a normal z's expectation, and the largest, with the
cases beyond 3. Not run by ``make``: about 6 min per 3 seeds on two cores
(run two seed ranges side by side).
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np
from scipy import stats

from gyroarray.chain.compare import ModelComparison
from gyroarray.sim.cases import EFFECTS, single_effect_case


def main(argv=None) -> list:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first-seed", type=int, default=106)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rows = []
    for eff in EFFECTS:
        for s in range(a.first_seed, a.first_seed + a.seeds):
            c = single_effect_case(eff, s)
            _, after = ModelComparison(c.measurement, n_runs=20).fit([(eff, c.gyro)])
            rows += [[eff, c.gyro, s, t.effect, t.gyro, float(t.z) if np.isfinite(t.z) else None]
                     for t in after.tests]
    by = collections.defaultdict(list)
    for eff, g, s, te, tg, z in rows:
        if z is not None and not (te == eff and (tg == g or g is None)):
            by[str(te)].append((z, eff, s, tg))
    for k, v in sorted(by.items()):
        z = np.array([x[0] for x in v])
        print(f"{k:<20} {z.size:5d} tests  z>2: {np.sum(z > 2):3d} (normal {z.size * stats.norm.sf(2):5.1f})  "
              f"z>3: {np.sum(z > 3):3d} (normal {z.size * stats.norm.sf(3):4.2f})  max {z.max():5.2f}  "
              + " ".join(f"[{e} s{s} g{g}]" for zz, e, s, g in v if zz > 3))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(rows, fh)
    return rows


if __name__ == "__main__":
    main()
