"""Standard diagnostic panel of a run of any engine (after DustPy's ``dustpy.plot.panel``).

``panel(result_or_dataset, kernel=None, path=None)`` takes a result of ``jaxcoag.evolve``
(:class:`jaxcoag.BinnedResult`, :class:`jaxcoag.MCResult`; converted with ``.to_xarray(kernel=...)``)
or a dataset of the common layout (``jaxcoag run`` / :func:`jaxcoag.io.load_netcdf`: ``mass_per_bin``
on dims (``t``, ``m``), coords ``t`` [s], ``m`` [g], ``m_edge`` [g] and optionally ``St``), so binned
and Monte Carlo runs are drawn alike. Four axes:

(a) m^2 f(m) = d rho / d ln m [g cm^-3] against m [g] at every output time, coloured by time
    with a colour bar in years (log scale when the positive output times span more than a
    decade); with ``frag_limit`` a labelled vertical line marks the fragmentation-limited size
    (Birnstiel et al. 2012: St_frag = v_frag^2 / (3 alpha c_s^2), converted to a mass with the
    scene's drag law, :func:`jaxcoag.runner.frag_limited_size`);
(b) mass-peak history m_p(t) [g] (``diagnostics.mass_peak``) against t [yr] (t [s] for runs
    shorter than 0.01 yr, e.g. dimensionless analytic-kernel tests);
(c) Stokes number St(m) = tau_f / t_L of the bin centers (from a physical kernel's
    ``particles(m)``, e.g. ``scenes.nebula_ch4().kernel(gas, rho_s)``, or else from the dataset's
    ``St`` coordinate);
(d) relative-velocity map Delta v(m1, m2) [cm s^-1] on the bin centers (needs a kernel with
    ``relative_velocity2``).

Without that information, (c) and (d) say so instead of plotting. The figure is a plain
``matplotlib.figure.Figure`` (no pyplot state, no global backend change), so it works headless
and in notebooks; with ``path`` it is saved as PNG.

References: Stammler & Birnstiel (2022) DustPy ``plot.panel``; Ormel (2008) thesis Figs. 5.3-5.9
(m^2 f(m) plots).
"""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import constants as C
from . import diagnostics
from ._validate import JaxcoagInputError

__all__ = ["panel", "time_norm", "sweep_panel"]


def time_norm(t_s):
    """Colour normalisation for output times t_s [s] in the unit the panel uses.

    Returns (values, norm, label): the times in years (or seconds when t_s[-1] < 0.01 yr),
    a ``matplotlib.colors.LogNorm`` over the positive values when they span more than a decade
    (t = 0 is drawn in the lowest colour), a ``Normalize`` otherwise, and the axis label.
    """
    from matplotlib import colors

    t = np.asarray(t_s, np.float64)
    years = t.size > 0 and t[-1] >= 0.01 * C.yr
    v = t / C.yr if years else t
    label = "t [yr]" if years else "t [s]"
    pos = v[v > 0]
    if pos.size >= 2 and pos.max() > 10 * pos.min():
        return v, colors.LogNorm(vmin=pos.min(), vmax=pos.max(), clip=True), label
    hi = v.max() if v.size and v.max() > v.min() else (v.min() + 1.0 if v.size else 1.0)
    return v, colors.Normalize(vmin=v.min() if v.size else 0.0, vmax=hi), label




def _m2f_axes(ax, y, ylabel, title):
    """Log-log axes of m^2 f(m) against m [g], the y range spanning 8 decades below the maximum
    of the finite positive values of ``y``."""
    pos = y[np.isfinite(y) & (y > 0)]
    ax.set_xscale("log")
    ax.set_yscale("log")
    if pos.size:
        ax.set_ylim(max(pos.min(), pos.max() * 1e-8), pos.max() * 3)
    ax.set_xlabel("m [g]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)


def _dataset(result_or_dataset, kernel):
    """The common-layout dataset of a result (``.to_xarray(kernel=...)``) or a dataset, checked."""
    import xarray as xr

    ds = result_or_dataset
    if not isinstance(ds, xr.Dataset):
        if not callable(getattr(ds, "to_xarray", None)):
            raise JaxcoagInputError(f"panel needs a result of jaxcoag.evolve (BinnedResult, MCResult) or its dataset "
                                    f"(result.to_xarray(), jaxcoag.io.load_netcdf); got {type(ds).__name__}.")
        if np.ndim(ds.t) != 1:
            raise JaxcoagInputError(f"panel draws one run (t of shape (T,)); got t of shape {np.shape(ds.t)} (a vmapped "
                                    "batch?). Index one member first.")
        ds = ds.to_xarray(kernel=kernel)
    need = ("mass_per_bin", "t", "m", "m_edge")
    miss = [k for k in need if k not in ds.variables]
    if miss:
        raise JaxcoagInputError(f"panel needs a dataset of the jaxcoag result layout (missing {miss}); write it with "
                                "result.to_xarray() or `jaxcoag run`.")
    if ds["mass_per_bin"].dims != ("t", "m"):
        raise JaxcoagInputError(f"panel draws one run (mass_per_bin on dims ('t', 'm')); got dims "
                                f"{ds['mass_per_bin'].dims} (a sweep? select one member first, e.g. ds.isel(alpha=0), "
                                "or draw it with sweep_panel).")
    return ds


@eqx.filter_jit
def _kernel_maps(kernel, m, want_st, want_dv):
    """St(m) and the Delta v map [cm s^-1] of a kernel in one compiled call (eager evaluation of a
    scene kernel's velocity sources ran ~100 small programs, ~3 s of a `jaxcoag run`'s first figure)."""
    st = kernel.particles(m).st if want_st else None
    dv = jnp.sqrt(jnp.maximum(kernel.relative_velocity2(m[:, None], m[None, :]), 0.0)) if want_dv else None
    return st, dv


def panel(result_or_dataset, kernel=None, path=None, *, dpi=110, title=None, frag_limit=None):
    """Four-panel overview of one run of any engine.

    Arguments:
        result_or_dataset: a result of ``jaxcoag.evolve`` (one run; converted with
            ``.to_xarray(kernel=kernel)``, Monte Carlo results on their automatic bins) or a dataset
            of the common layout (``mass_per_bin`` (t, m) [g cm^-3], ``m_edge`` [g], ``t`` [s]).
        kernel: optional physical kernel (``SceneKernel``) for the Stokes-number and
            relative-velocity panels; analytic kernels with ``relative_velocity2`` draw (d) only.
            Without a kernel, (c) uses the dataset's ``St`` coordinate when it has one.
        path: optional PNG path; the directory must exist.
        dpi: resolution of the saved PNG; title: figure title.
        frag_limit: optional (m_frag [g], a_frag [cm], St_frag) of the fragmentation barrier
            (``jaxcoag run`` passes St_frag = v_frag^2 / (3 alpha c_s^2) and its size from
            :func:`jaxcoag.runner.frag_limited_size`): a dashed vertical line at m_frag on (a),
            labelled with a_frag and St_frag, and a horizontal line at St_frag on (c).

    Returns:
        matplotlib.figure.Figure with axes [m2f, peak, stokes, dv, then colour bars: time (of
        axis 0) and, with a kernel, Delta v]; the first ``T`` lines of axis 0 are the m^2 f
        curves in time order (xdata = ``ds.m``, ydata = ``diagnostics.m2f(ds.mass_per_bin[i],
        ds.m_edge)``), the fragmentation line (gid ``"frag_limit"``) comes after them.
    """
    from matplotlib.figure import Figure
    from matplotlib import cm, colors
    from matplotlib.cm import ScalarMappable

    if path is not None:
        d = os.path.dirname(os.path.abspath(os.fspath(path)))
        if not os.path.isdir(d):
            raise JaxcoagInputError(f"directory {d!r} for the PNG does not exist.")
    ds = _dataset(result_or_dataset, kernel)
    rho = np.asarray(ds["mass_per_bin"].values, np.float64)
    edges = np.asarray(ds["m_edge"].values, np.float64)
    m = np.asarray(ds["m"].values, np.float64)
    t = np.asarray(ds["t"].values, np.float64)
    # all output times at once, in numpy (diagnostics computes numpy input with numpy)
    y = np.asarray(diagnostics.m2f(rho, edges), np.float64)
    mp = np.asarray(diagnostics.mass_peak(rho, edges), np.float64).reshape(-1)

    # fixed margins, not layout="constrained": that engine measures every tick label's extent before the
    # draw, ~0.5-1 s of a `jaxcoag run` for this figure (the labels here have fixed forms)
    fig = Figure(figsize=(11, 8.5))
    ax = fig.subplots(2, 2, gridspec_kw=dict(left=0.075, right=0.955, bottom=0.06, top=0.905 if title else 0.95,
                                             wspace=0.3, hspace=0.26)).ravel()
    ax_f, ax_p, ax_s, ax_v = ax

    if frag_limit is not None:
        try:
            m_fr, a_fr, st_fr = (float(v) for v in frag_limit)
        except (TypeError, ValueError):
            raise JaxcoagInputError("frag_limit must be (m_frag [g], a_frag [cm], St_frag), three numbers.") from None
        if not (m_fr > 0 and np.isfinite(m_fr)):
            raise JaxcoagInputError(f"frag_limit mass must be a positive finite number of grams, got {m_fr!r}.")

    # (a) m^2 f over time, coloured by time with a colour bar
    tv, tnorm, tlabel = time_norm(t)
    cmap = cm.viridis
    unit = tlabel[3:-1]
    pos_t = tv[tv > 0]
    floor = pos_t.min() if isinstance(tnorm, colors.LogNorm) else tv.min()
    for i in range(len(t)):
        ax_f.plot(m, y[i], color=cmap(tnorm(max(tv[i], floor))), lw=1.3, label=f"t = {tv[i]:.3g} {unit}")
    sm = ScalarMappable(norm=tnorm, cmap=cmap)
    sm.set_array(tv)
    fig.colorbar(sm, ax=ax_f, label=tlabel + (" (log scale)" if isinstance(tnorm, colors.LogNorm) else ""))
    _m2f_axes(ax_f, y, r"$m^2 f(m)$ = d$\rho$/d ln m [g cm$^{-3}$]", "(a) mass distribution")
    if frag_limit is not None:
        ax_f.axvline(m_fr, color="C3", ls="--", lw=1.2, gid="frag_limit",
                     label=f"fragmentation limit a = {a_fr:.3g} cm (St = {st_fr:.3g})")
        # the label on the side of the line with more room (the axis spans the bin centres in log m)
        lm = np.log(m[m > 0]) if np.any(m > 0) else np.zeros(1)
        right = np.ptp(lm) > 0 and (np.log(m_fr) - lm.min()) / np.ptp(lm) > 0.6
        pad = lambda s: "\n".join(f"{ln} " if right else f" {ln}" for ln in s.split("\n"))
        ax_f.text(m_fr, 0.97, pad(f"fragmentation limit\na = {a_fr:.3g} cm\nSt = {st_fr:.3g}"), color="C3",
                  fontsize=8, ha="right" if right else "left", va="top", transform=ax_f.get_xaxis_transform())
    if len(t) <= 8:
        ax_f.legend(fontsize=7)

    # (b) mass-peak history
    ax_p.plot(tv, mp, "o-", color="C3")
    ax_p.set_yscale("log")
    if np.all(tv > 0) or (len(tv) > 2 and tv[1] > 0 and tv[0] == 0 and tv[-1] / tv[1] > 30):
        ax_p.set_xscale("symlog", linthresh=tv[1] if tv[0] == 0 else tv[0])
        if tv[0] >= 0:
            ax_p.set_xlim(left=0.0)  # symlog would otherwise show negative times
    if frag_limit is not None:
        ax_p.axhline(m_fr, color="C3", ls="--", lw=1.0, label="fragmentation limit")
        good = mp[np.isfinite(mp) & (mp > 0)]
        if good.size:
            ax_p.set_ylim(min(good.min(), m_fr) / 3, max(good.max(), m_fr) * 3)
        ax_p.legend(fontsize=7)
    ax_p.set_xlabel(tlabel)
    ax_p.set_ylabel(r"mass peak $m_p$ [g]")
    ax_p.set_title("(b) mass-peak history")

    # (c) Stokes number
    st = None
    want_st = kernel is not None and hasattr(kernel, "particles") and int(getattr(kernel, "n_struct", 0) or 0) == 0
    want_dv = kernel is not None and hasattr(kernel, "relative_velocity2")
    st_k, dv = _kernel_maps(kernel, jnp.asarray(m), want_st, want_dv) if (want_st or want_dv) else (None, None)
    if want_st:
        st = np.asarray(st_k)
    elif "St" in ds.coords and ds["St"].dims == ("m",):
        st = np.asarray(ds["St"].values, np.float64)
    if st is not None:
        ax_s.loglog(m, st, color="C0")
        ax_s.axhline(1.0, color="0.6", ls=":")
        if frag_limit is not None:
            ax_s.axhline(st_fr, color="C3", ls="--", lw=1.0, label=r"St$_{\rm frag}$ = " + f"{st_fr:.3g}")
            ax_s.axvline(m_fr, color="C3", ls="--", lw=1.0)
            ax_s.legend(fontsize=7)
        ax_s.set_ylabel("Stokes number St")
    else:
        ax_s.text(0.5, 0.5, "pass a physical kernel\n(scene.kernel(gas, rho_s))\nfor St(m)", ha="center",
                  va="center", transform=ax_s.transAxes)
    ax_s.set_xlabel("m [g]")
    ax_s.set_title("(c) Stokes number")

    # (d) relative velocity map
    if want_dv:
        dv = np.asarray(dv)
        pc = ax_v.pcolormesh(edges, edges, dv.T, norm=colors.LogNorm(vmin=max(dv[dv > 0].min(), dv.max() * 1e-10)
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


def sweep_panel(ds, path=None, *, dpi=110, title=None):
    """Figure of a parameter sweep written by :func:`jaxcoag.runner.sweep_config` (``jaxcoag sweep``).

    Axes:
        (a) the mass peak at the last output time [g] (``mass_peak``) against the first swept
            parameter, one line per combination of the others (log axes where the values are
            positive and span a decade or more); failed members (status one of
            :data:`jaxcoag.FAILURES`) are marked x;
        (b) the final m^2 f(m) = d rho / d ln m [g cm^-3] of every member against m [g],
            coloured by the first swept parameter with a colour bar (LogNorm over a span of a
            decade or more, else Normalize), line style cycling over the other parameters;
        (c) with exactly two swept parameters: a colour map of log10 m_peak over both.

    Arguments:
        ds: the sweep dataset (coords = swept parameters in ``attrs["swept"]`` order, then
            ``t``, ``m``, ``m_edge``; variables ``mass_per_bin`` (..., t, m), ``mass_peak``, ``status``).
        path: optional PNG path (its directory must exist); dpi: PNG resolution; title: suptitle.

    Returns:
        matplotlib.figure.Figure; ``fig.axes[0].lines`` are the m_peak curves (ydata =
        ``ds.mass_peak`` along the first parameter), ``fig.axes[1].lines`` the final m^2 f curves
        in member order (C order over the swept parameters), then empty line-style key handles.
    """
    from matplotlib.figure import Figure
    from matplotlib import cm, colors
    from matplotlib.cm import ScalarMappable

    swept = [k for k in str(ds.attrs.get("swept", "")).split(",") if k]
    need = ("mass_per_bin", "mass_peak", "status", "m_edge")
    if not swept or any(k not in ds.variables for k in need + tuple(swept)):
        raise JaxcoagInputError("sweep_panel needs a dataset written by jaxcoag.runner.sweep_config / `jaxcoag sweep` "
                                f"(swept parameters in attrs['swept'] and variables {list(need)}).")
    if path is not None:
        d = os.path.dirname(os.path.abspath(os.fspath(path)))
        if not os.path.isdir(d):
            raise JaxcoagInputError(f"directory {d!r} for the PNG does not exist.")
    p0, rest = swept[0], swept[1:]
    x = np.asarray(ds[p0].values, np.float64)
    mp = np.asarray(ds["mass_peak"].transpose(*swept).values, np.float64).reshape(x.size, -1)
    from ._status import FAILURES, RESULT_NAMES

    st = np.asarray(ds["status"].transpose(*swept).values).reshape(x.size, -1)
    failed = np.isin(st, [RESULT_NAMES.index(n) for n in FAILURES])
    rho = np.asarray(ds["mass_per_bin"].isel(t=-1).transpose(*swept, "m").values, np.float64)
    rho = rho.reshape(x.size, -1, rho.shape[-1])
    e = np.asarray(ds["m_edge"].values, np.float64)
    m = np.sqrt(e[:-1] * e[1:])
    y = rho / np.diff(np.log(e))
    combos = [dict(zip(rest, v)) for v in np.array(np.meshgrid(*[ds[k].values for k in rest],
                                                              indexing="ij")).reshape(len(rest), -1).T] if rest else [{}]

    def _log_ok(v):
        v = v[np.isfinite(v)]
        return v.size > 1 and np.all(v > 0) and v.max() >= 10 * v.min()

    fig = Figure(figsize=(13 if len(swept) == 2 else 11, 4.6), layout="constrained")
    ax = fig.subplots(1, 3 if len(swept) == 2 else 2)
    ax_m, ax_f = ax[0], ax[1]
    for j, c in enumerate(combos):
        lab = ", ".join(f"{k} = {v:.3g}" for k, v in c.items()) or None
        line, = ax_m.plot(x, mp[:, j], "o-", label=lab if j < 10 else None)
        bad = failed[:, j]
        if np.any(bad):
            ax_m.plot(x[bad], np.where(np.isfinite(mp[bad, j]), mp[bad, j], np.nanmin(mp)), "x", color="k", ms=9,
                      label="failed" if j == 0 else None)
    if _log_ok(x):
        ax_m.set_xscale("log")
    if _log_ok(mp.ravel()) or np.all(mp[np.isfinite(mp)] > 0):
        ax_m.set_yscale("log")
    ax_m.set_xlabel(p0)
    ax_m.set_ylabel(r"mass peak $m_p$ at $t_{\rm end}$ [g]")
    ax_m.set_title(f"(a) mass peak vs {p0}")
    if rest or np.any(failed):
        ax_m.legend(fontsize=7)

    norm = colors.LogNorm(vmin=x.min(), vmax=x.max()) if _log_ok(x) else \
        colors.Normalize(vmin=x.min(), vmax=x.max() if x.max() > x.min() else x.min() + 1.0)
    cmap = cm.viridis
    styles = ["-", "--", ":", "-."]
    for i in range(x.size):
        for j in range(len(combos)):
            ax_f.plot(m, y[i, j], color=cmap(norm(x[i])), ls=styles[j % len(styles)], lw=1.2)
    if rest:  # line-style key for the other parameters (empty handles, after the member curves)
        for j, c in enumerate(combos[:len(styles)]):
            ax_f.plot([], [], color="0.3", ls=styles[j], label=", ".join(f"{k} = {v:.3g}" for k, v in c.items()))
        ax_f.legend(fontsize=7)
    sm = ScalarMappable(norm=norm, cmap=cmap)
    sm.set_array(x)
    fig.colorbar(sm, ax=ax_f, label=p0)
    _m2f_axes(ax_f, y, r"$m^2 f(m)$ at $t_{\rm end}$ [g cm$^{-3}$]", "(b) final mass distributions")

    if len(swept) == 2:
        ax_c = ax[2]
        x1 = np.asarray(ds[rest[0]].values, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.log10(mp)
        pc = ax_c.pcolormesh(np.arange(x.size + 1) - 0.5, np.arange(x1.size + 1) - 0.5, z.T, cmap="viridis",
                             shading="flat")
        ax_c.set_xticks(np.arange(x.size), [f"{v:.3g}" for v in x], rotation=45, fontsize=7)
        ax_c.set_yticks(np.arange(x1.size), [f"{v:.3g}" for v in x1], fontsize=7)
        ax_c.set_xlabel(p0)
        ax_c.set_ylabel(rest[0])
        fig.colorbar(pc, ax=ax_c, label=r"log$_{10}$ $m_p$ [g]")
        ax_c.set_title("(c) mass peak map")
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(os.fspath(path), dpi=dpi, format="png")
    return fig
