"""``--plugin`` files are checked when they load (issue 29): estimators as well as effects.

An estimator of the user's own, in a file named with ``--plugin``, runs in
``gyroarray run`` like a built-in once it passes the conformance suite; one
that breaks the contract is refused in one line naming the class and the
failed check, and is not left registered. The worked effect plugin
(``examples/plugins/thermostat_bias.py``) still loads (its checks pass).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hostile import assert_contract, run_cli, write_scenario

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "plugins" / "thermostat_bias.py"

ESTIMATOR = '''
import numpy as np
from gyroarray.estimators import Estimator


class FirstGyros(Estimator):
    """Least squares on the readings, written out: (HᵀH)⁻¹Hᵀ z."""
    name = "{name}"
    description = "least squares written in a plugin file"

    def __init__(self):
        pass

    def _fit(self, H, noise, dt_s):
        self.weights_ = np.linalg.solve(H.T @ H, H.T){broken}
        R = noise.R(dt_s)
        self.covariance_ = self.weights_ @ R @ self.weights_.T

    def _estimate(self, z):
        return np.ascontiguousarray(z @ self.weights_.T)
'''


def _plugin(tmp_path, name="my_ls", broken=""):
    p = tmp_path / f"{name or 'nameless'}.py"
    p.write_text(ESTIMATOR.format(name=name, broken=broken))
    return p


def test_an_estimator_plugin_runs_like_a_builtin(tmp_path):
    scen = write_scenario(tmp_path, "sc", rate=20.0)
    plugin = _plugin(tmp_path)
    o = run_cli(["run", scen, "--plugin", plugin, "--estimators", "my_ls,ols", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    rows = o.json["rows"] if "rows" in o.json else o.json["estimators"]
    text = str(rows)
    assert "my_ls" in text and "ols" in text
    # the plugin's plain least squares equals the built-in OLS on the same run (same noise draw)
    from gyroarray.chain.run import run_scenario
    from gyroarray.sim.scenario import load_scenario
    res = run_scenario(load_scenario(scen), ["my_ls", "ols"])
    df = res.table if hasattr(res, "table") else None
    if df is not None:
        a = df[df.estimator == "my_ls"].sort_values("axis")["sigma_1_deg_s"].to_numpy()
        b = df[df.estimator == "ols"].sort_values("axis")["sigma_1_deg_s"].to_numpy()
        np.testing.assert_allclose(a, b, rtol=1e-12)


def test_an_estimator_that_breaks_the_contract_is_refused_and_not_registered(tmp_path):
    scen = write_scenario(tmp_path, "sc", rate=20.0)
    # estimate changes with every call: fails the "same output for the same input" check
    plugin = _plugin(tmp_path, name="my_noisy", broken="\n        self.calls_ = 0")
    text = plugin.read_text().replace(
        "return np.ascontiguousarray(z @ self.weights_.T)",
        "return np.ascontiguousarray(z @ self.weights_.T + np.random.default_rng().normal(size=3))")
    plugin.write_text(text)
    o = run_cli(["run", scen, "--plugin", plugin, "--estimators", "my_noisy", "--json"])
    assert_contract(o, "my_noisy.py")
    assert o.code == 2 and "FirstGyros fails the conformance check" in o.err, o.err
    from gyroarray.estimators import available
    assert "my_noisy" not in available()


def test_a_nameless_estimator_is_refused_with_the_way_out(tmp_path):
    plugin = _plugin(tmp_path, name="")
    scen = write_scenario(tmp_path, "sc", rate=20.0)
    o = run_cli(["run", scen, "--plugin", plugin, "--json"])
    assert_contract(o)
    assert o.code == 2 and "name = 'my_name'" in o.err, o.err


def test_the_example_effect_plugin_passes_its_load_checks(tmp_path):
    from gyroarray.chain.plugins import load_plugin
    assert load_plugin(EXAMPLE) == ["thermostat_bias"]


def test_a_file_with_neither_effect_nor_estimator_is_refused(tmp_path):
    p = tmp_path / "empty_plugin.py"
    p.write_text("x = 1\n")
    scen = write_scenario(tmp_path, "sc", rate=20.0)
    o = run_cli(["run", scen, "--plugin", p, "--json"])
    assert_contract(o, "empty_plugin.py")
    assert o.code == 2 and "no estimator" in o.err, o.err
