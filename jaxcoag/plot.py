"""Standard diagnostic panel of a binned solution (after DustPy's ``dustpy.plot.panel``).

``panel(solution, kernel=None, path=None)`` draws four axes:

(a) m^2 f(m) = d rho / d ln m [g cm^-3] against m [g] at every output time (colour = time);
(b) mass-peak history m_p(t) [g] (``diagnostics.mass_peak``) against t [s];
(c) Stokes number St(m) = tau_f / t_L of the bin centers (needs a physical kernel with
    ``particles(m)``, e.g. ``scenes.nebula_ch4().kernel(gas, rho_s)``);
(d) relative-velocity map Delta v(m1, m2) [cm s^-1] on the bin centers (needs a kernel with
    ``relative_velocity2``).

Without a kernel, (c) and (d) say so instead of plotting. The figure is a plain
``matplotlib.figure.Figure`` (no pyplot state, no global backend change), so it works headless
and in notebooks; with ``path`` it is saved as PNG.

References: Stammler & Birnstiel (2022) DustPy ``plot.panel``; Ormel (2008) thesis Figs. 5.3-5.9
(m^2 f(m) plots).
"""

from __future__ import annotations

import os

import numpy as np

from . import diagnostics
from ._validate import JaxcoagInputError

__all__ = ["panel"]




def panel(solution, kernel=None, path=None, *, dpi=110, title=None):
    """Four-panel overview of a :class:`~jaxcoag.binned.BinnedSolution`.

    Arguments:
        solution: BinnedSolution (one solve, mass_per_bin (nt, nbins) [g cm^-3]).
        kernel: optional physical kernel (``SceneKernel``) for the Stokes-number and
            relative-velocity panels; analytic kernels with ``relative_velocity2`` draw (d) only.
        path: optional PNG path; the directory must exist.
        dpi: resolution of the saved PNG; title: figure title.

    Returns:
        matplotlib.figure.Figure with axes [m2f, peak, stokes, dv]; the m^2 f lines of axis 0
        are in time order (ydata = ``diagnostics.m2f(solution.mass_per_bin, grid)[i]``).
    """
    from matplotlib.figure import Figure
    from matplotlib import cm, colors
    from .binned import BinnedSolution

    if not isinstance(solution, BinnedSolution):
        raise JaxcoagInputError(f"panel needs a jaxcoag.binned.BinnedSolution, got {type(solution).__name__}.")
    rho = np.asarray(solution.mass_per_bin, np.float64)
    if rho.ndim != 2:
        raise JaxcoagInputError(f"panel draws one solution (mass_per_bin of shape (nt, nbins)); got {rho.shape}.")
    if path is not None:
        d = os.path.dirname(os.path.abspath(os.fspath(path)))
        if not os.path.isdir(d):
            raise JaxcoagInputError(f"directory {d!r} for the PNG does not exist.")
    grid = solution.grid
    m = np.asarray(grid.centers)
    t = np.asarray(solution.ts, np.float64)
    # per time row: diagnostics.m2f / mass_peak broadcast 1-D edges against (nt, nbins), which
    # jax_numpy_rank_promotion='raise' rejects
    y = np.stack([np.asarray(diagnostics.m2f(r, grid)) for r in rho])

    fig = Figure(figsize=(11, 8.5), layout="constrained")
    ax = fig.subplots(2, 2).ravel()
    ax_f, ax_p, ax_s, ax_v = ax

    # (a) m^2 f over time
    norm = colors.Normalize(vmin=0, vmax=max(len(t) - 1, 1))
    cmap = cm.viridis
    for i in range(len(t)):
        ax_f.plot(m, y[i], color=cmap(norm(i)), lw=1.3, label=f"t = {t[i]:.3g} s")
    pos = y[y > 0]
    ax_f.set_xscale("log")
    ax_f.set_yscale("log")
    if pos.size:
        ax_f.set_ylim(max(pos.min(), pos.max() * 1e-8), pos.max() * 3)
    ax_f.set_xlabel("m [g]")
    ax_f.set_ylabel(r"$m^2 f(m)$ = d$\rho$/d ln m [g cm$^{-3}$]")
    ax_f.set_title("(a) mass distribution")
    if len(t) <= 8:
        ax_f.legend(fontsize=7)

    # (b) mass-peak history
    mp = np.array([float(diagnostics.mass_peak(r, grid)) for r in rho])
    ax_p.plot(t, mp, "o-", color="C3")
    ax_p.set_yscale("log")
    if np.all(t > 0) or (len(t) > 2 and t[1] > 0 and t[0] == 0 and t[-1] / t[1] > 30):
        ax_p.set_xscale("symlog", linthresh=t[1] if t[0] == 0 else t[0])
        if t[0] >= 0:
            ax_p.set_xlim(left=0.0)  # symlog would otherwise show negative times
    ax_p.set_xlabel("t [s]")
    ax_p.set_ylabel(r"mass peak $m_p$ [g]")
    ax_p.set_title("(b) mass-peak history")

    # (c) Stokes number
    if kernel is not None and hasattr(kernel, "particles"):
        st = np.asarray(kernel.particles(m).st)
        ax_s.loglog(m, st, color="C0")
        ax_s.axhline(1.0, color="0.6", ls=":")
        ax_s.set_ylabel("Stokes number St")
    else:
        ax_s.text(0.5, 0.5, "pass a physical kernel\n(scene.kernel(gas, rho_s))\nfor St(m)", ha="center",
                  va="center", transform=ax_s.transAxes)
    ax_s.set_xlabel("m [g]")
    ax_s.set_title("(c) Stokes number")

    # (d) relative velocity map
    if kernel is not None and hasattr(kernel, "relative_velocity2"):
        dv = np.sqrt(np.maximum(np.asarray(kernel.relative_velocity2(m[:, None], m[None, :])), 0.0))
        e = np.asarray(grid.edges)
        pc = ax_v.pcolormesh(e, e, dv.T, norm=colors.LogNorm(vmin=max(dv[dv > 0].min(), dv.max() * 1e-10)
                                                             if np.any(dv > 0) else 1e-10, vmax=max(dv.max(), 1e-10)),
                             cmap="magma", shading="flat")
        ax_v.set_xscale("log")
        ax_v.set_yscale("log")
        fig.colorbar(pc, ax=ax_v, label=r"$\Delta v$ [cm s$^{-1}$]")
        ax_v.set_ylabel("m2 [g]")
    else:
        ax_v.text(0.5, 0.5, "pass a kernel with\nrelative_velocity2\nfor the Δv map", ha="center", va="center",
                  transform=ax_v.transAxes)
    ax_v.set_xlabel("m1 [g]")
    ax_v.set_title("(d) relative velocity")
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(os.fspath(path), dpi=dpi, format="png")
    return fig
