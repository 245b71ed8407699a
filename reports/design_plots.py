"""GDOP design figures (paper 003 Figs. 8–10)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..design import correlation_matrix, gdop, gdop_vs_alpha, optimal_alpha
from ..errors import InputError
from ..layout import Layout
from ..units import deg_to_rad, rad_to_deg

NS = (4, 5, 6, 8)


def _rho_grid(n: int, count: int = 200) -> np.ndarray:
    """ρ strictly inside (−1/(N−1), 1), where the correlation matrix is PD."""
    lo = -1.0 / (n - 1)
    eps = 1e-3
    return np.linspace(lo + eps, 1.0 - eps, count)


def design_figure(path, *, force: bool = True) -> Path:
    """Write the design figure to ``path`` (see :func:`design_fig`).

    Parameters
    ----------
    path : path-like
        Output image; the format follows the suffix (``.png``, ``.svg``, ``.pdf``).

    Returns
    -------
    Path
        The file written.
    """
    from gyroarray.outputs import PLOT_SUFFIXES, check_output_dir, save_figure
    path = Path(path)
    if path.suffix.lower() not in PLOT_SUFFIXES:
        raise InputError(f"plot must end in .png, .svg or .pdf, got {path.name!r}", file=str(path))
    check_output_dir(path.parent, what="the plot's folder")
    return save_figure(design_fig(), path, force=force, dpi=110)


def design_fig():
    """The figure: GDOP vs α (both schemes, N = 4, 5, 6, 8, ρ = 0), GDOP vs α
    for several ρ (Scheme 1, N = 6), GDOP vs ρ at the ρ = 0 optimal α and the
    optimal α vs ρ (a matplotlib Figure on an Agg canvas; no pyplot state).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    alphas_deg = np.linspace(5.0, 175.0, 341)
    alphas = deg_to_rad(alphas_deg)
    fig = Figure(figsize=(15, 8.5), layout="constrained")
    FigureCanvasAgg(fig)
    axs = fig.subplots(2, 3)
    for col, scheme in enumerate((1, 2)):
        ax = axs[0, col]
        for n in NS:
            g = gdop_vs_alpha(scheme, n, alphas, 0.0)
            line, = ax.plot(alphas_deg, g, label=f"N = {n}")
            opt = optimal_alpha(scheme, n, 0.0)
            ax.plot(rad_to_deg(opt.alpha_rad), opt.gdop, "o", color=line.get_color())
        ax.set(title=f"Scheme {scheme}: GDOP vs cone angle (ρ = 0)  [Fig. 8{'ab'[col]}]",
               xlabel="cone angle α [deg]", ylabel="GDOP [-]", ylim=(0.8, 3.5))
        ax.legend(loc="upper center")
        ax.grid(alpha=0.3)

    ax = axs[0, 2]
    for rho in (-0.18, -0.1, 0.0, 0.2, 0.5):
        g = gdop_vs_alpha(1, 6, alphas, rho)
        ax.plot(alphas_deg, g, label=f"ρ = {rho:g}")
    ax.set(title="Scheme 1, N = 6: GDOP vs α for several ρ  [Fig. 9]",
           xlabel="cone angle α [deg]", ylabel="GDOP [-]", xlim=(5, 90), ylim=(0.8, 3.0))
    ax.legend()
    ax.grid(alpha=0.3)

    for col, scheme in enumerate((1, 2)):
        ax = axs[1, col]
        for n in NS:
            alpha = optimal_alpha(scheme, n, 0.0).alpha_rad
            rhos = _rho_grid(n)
            layout = Layout.conical(scheme, n, alpha)
            ax.plot(rhos, [gdop(layout, correlation_matrix(n, r)) for r in rhos],
                    label=f"N = {n}, α = {rad_to_deg(alpha):.2f}°")
        ax.set(title=f"Scheme {scheme}: GDOP vs ρ at the ρ = 0 optimum  [Fig. 10{'ab'[col]}]",
               xlabel="ARW correlation ρ [-]", ylabel="GDOP [-]")
        ax.legend()
        ax.grid(alpha=0.3)

    ax = axs[1, 2]
    for scheme, style in ((1, "-"), (2, "--")):
        for n in NS:
            rhos = _rho_grid(n, 60)
            ax.plot(rhos, [rad_to_deg(optimal_alpha(scheme, n, r).alpha_rad)
                           for r in rhos], style, label=f"scheme {scheme}, N = {n}")
    ax.set(title="Optimal cone angle vs ρ  [Table 2]", xlabel="ARW correlation ρ [-]",
           ylabel="optimal α [deg]")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)

    fig.suptitle("gyroarray design analysis: GDOP = sqrt(trace((Hᵀ C⁻¹ H)⁻¹))")
    return fig
