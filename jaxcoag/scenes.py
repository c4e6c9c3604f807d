"""Named scene presets: functions returning :class:`~jaxcoag.Scene` compositions.

Each preset names only the effects its setting needs (like optax's ``adam = chain(...)``).

``setup(name, **overrides)`` bundles a complete seed setting for the binned engine (scene, gas,
material, kernel, outcome model, grid, initial state, output times, published numbers): see
:data:`SETUPS` (ch2_compact_1au/_5au, ch4_nebula, ch6_cloud, ch5_constant/_sum/_product).

References: Ormel (2008) thesis ch. 2 (protoplanetary disk: Brownian + turbulence), ch. 4
(nebula with chondrules: Brownian + OC07 turbulence + radial drift, eqs. 4.4, 4.8, 4.10/ch. 3),
ch. 6 (molecular cloud cores: Brownian + OC07 turbulence); DustPy's default relative velocities
(Brownian, turbulence, radial and azimuthal drift, settling; Stammler & Birnstiel 2022).
"""

from __future__ import annotations

from .effects import AzimuthalDrift, Brownian, RadialDrift, Settling, TurbulenceOC07
from ._validate import JaxcoagInputError
from .scene import Scene

__all__ = ["brownian_only", "turbulence_only", "protoplanetary_disk", "nebula_ch4", "molecular_cloud",
           "dustpy_like", "ch2_porous", "ch2_compact", "ch2_setup", "ch2_pilot", "ch2_mc_run", "RainedFraction",
           "ch2_model_name", "CH2_TABLE_2_2",
           "PRESETS", "get",
           "Setup", "setup", "SETUPS", "CH6_TABLE_6_5_6_6"]


def brownian_only() -> Scene:
    """Brownian motion only (thesis eq. 4.4): the small-grain, laminar limit."""
    return Scene(velocities=(Brownian(),), name="brownian_only")


def turbulence_only(method: str = "exact") -> Scene:
    """OC07 turbulence only (thesis ch. 3)."""
    return Scene(velocities=(TurbulenceOC07(method=method),), name="turbulence_only")


def protoplanetary_disk(method: str = "exact") -> Scene:
    """Chapter-2 style disk scene: Brownian motion + OC07 turbulence (compact variant)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method)), name="protoplanetary_disk")


def nebula_ch4(method: str = "exact") -> Scene:
    """Chapter-4 nebula: thermal, turbulent and radial-drift velocities in quadrature (§4.3)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method), RadialDrift()), name="nebula_ch4")


def molecular_cloud(method: str = "exact") -> Scene:
    """Chapter-6 molecular-cloud core: Brownian + OC07 turbulence (use gas.molecular_cloud)."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method)), name="molecular_cloud")


def dustpy_like(method: str = "exact") -> Scene:
    """All five contributions DustPy adds in quadrature (azimuthal drift and settling are [EXT])."""
    return Scene(velocities=(Brownian(), TurbulenceOC07(method=method), RadialDrift(), AzimuthalDrift(),
                             Settling()), name="dustpy_like")


# ---- chapter 2 (porous vs compact growth until rain-out; thesis ch. 2 = Ormel+2007) ---- begin
def _ch2_turbulence(method):
    from .effects import TurbulenceW84
    return TurbulenceW84() if method in (None, "w84") else TurbulenceOC07(method=method)


def ch2_porous(method: str = "w84") -> Scene:
    """Chapter-2 porous disk scene: Brownian + Weidenschilling (1984) turbulence fits (eqs. 2.1,
    2.5a/b; ``method`` = an OC07 method name swaps in OC07) with the enlargement factor psi as
    structural parameter (``porosity="psi"``: a = a* psi^(1/3), tau_f from (m, psi), eq. 2.25).
    Drag: Epstein with the Stokes switch at a = 9 l_mfp/4 (library default; only R1Ta2-P reaches it)."""
    return Scene(velocities=(Brownian(), _ch2_turbulence(method)), porosity="psi", name="ch2_porous")


def ch2_compact(method: str = "w84") -> Scene:
    """Chapter-2 compact disk scene (psi = 1 by definition, thesis 'C' models): Brownian + W84 fits."""
    return Scene(velocities=(Brownian(), _ch2_turbulence(method)), name="ch2_compact")


# T-Tab2.2 (properties at rain-out; averages over 50 runs). Erratum 8 applied to the alphas.
CH2_TABLE_2_2 = {
    "R1Ta4-P": dict(R_au=1, alpha=1e-4, porous=True, a=2.1, m=1.4, psi=86.0, a_over_astar=4.4, t_rain=4.7e3, t_99=4.5e4),
    "R1Ta4-C": dict(R_au=1, alpha=1e-4, porous=False, a=2.4e-2, m=1.9e-4, psi=1.0, a_over_astar=1.0, t_rain=2.6e3, t_99=4.4e4),
    "R5Ta4-P": dict(R_au=5, alpha=1e-4, porous=True, a=0.72, m=1.4e-2, psi=110.0, a_over_astar=4.8, t_rain=1.9e4, t_99=2.2e5),
    "R5Ta4-C": dict(R_au=5, alpha=1e-4, porous=False, a=6.7e-3, m=1.2e-6, psi=1.0, a_over_astar=1.0, t_rain=8.1e3, t_99=2.1e5),
    "R1Ta2-P": dict(R_au=1, alpha=1e-2, porous=True, a=7.8, m=1.6e3, psi=3.9, a_over_astar=1.6, t_rain=2.6e2, t_99=4.0e5),
    "R5Ta2-P": dict(R_au=5, alpha=1e-2, porous=True, a=24.0, m=1.7e3, psi=36.0, a_over_astar=3.3, t_rain=1.4e3, t_99=4.5e3),
    "R1Ta6-P": dict(R_au=1, alpha=1e-6, porous=True, a=2.1e-2, m=1.3e-6, psi=87.0, a_over_astar=4.4, t_rain=1.3e3, t_99=2.3e6),
    "R5Ta6-P": dict(R_au=5, alpha=1e-6, porous=True, a=1.3e-3, m=4.6e-10, psi=20.0, a_over_astar=2.7, t_rain=61.0, t_99=1.1e5),
}


def ch2_model_name(R_au, alpha, porous) -> str:
    """Thesis Tab. 2.1 model id, e.g. (1, 1e-4, True) -> 'R1Ta4-P'."""
    import math
    return f"R{int(R_au)}Ta{int(round(-math.log10(alpha)))}-{'P' if porous else 'C'}"


def _ch2_m_rain(base, psi, tau_rain, m0):
    """Rain-out mass [g] for enlargement factor ``psi`` (None: compact): the first mass of a
    40-per-decade grid (m0 1e-2 .. m0 1e22) with tau_f(m, psi) > tau_rain (thesis eq. 2.25), so
    tau_f(m_rain / 10^(1/40), psi) <= tau_rain < tau_f(m_rain, psi); the grid's top if none."""
    import jax.numpy as jnp

    mg = jnp.logspace(-16, 8, 961) * m0 / 1e-14
    x = None if psi is None else jnp.full(mg.shape + (1,), float(psi))
    over = jnp.asarray(base.particles(mg, x).tau_f > tau_rain)
    return float(mg[jnp.argmax(over)]) if bool(jnp.any(over)) else float(mg[-1])


def ch2_setup(R_au: int = 1, alpha: float = 1e-4, porous: bool = True, *, method: str = "w84",
              ns_target: int = 200, m_end=None, psi_est=None, rain_out: bool = True, n_frag: int = 0,
              z_over_H: float = 1.0, n_small=40):
    """Everything a thesis ch. 2 run needs: scene, gas, material, kernel, outcome and MC settings.

    Setting (thesis §2.4, Tab. 2.1; Ormel, Spaans & Tielens 2007): Hayashi MMSN (Sigma = 1700
    (R/AU)^-3/2 g cm^-2, T = 280 (R/AU)^-1/2 K; the thesis does not print its normalisation,
    erratum 21) evaluated at z = H_g (rho_g = e^-1/2 of the midplane); t_L = 2 pi/Omega,
    v_L = alpha^1/2 c_g, Re = nu_T/nu_m with nu_m = c_g l_mfp/2; a0 = 0.1 um monomers;
    1 AU: quartz (rho_s = 3, gamma = 25), rho_g/rho_d = 240; 5 AU: ice (rho_s = 1, gamma = 370,
    erratum 7), rho_g/rho_d = 57 (solids enhanced x4.2). Velocities Brownian + W84 fits.
    Porous: O07 recipe (restr_factor 1, rolling-force E_roll, B = 1, m_F = 10 m0, delta = 0.95,
    psi_add from N = 40 on, B = 0 below: a surrogate for Ossenkopf's small-N psi), psi0 = 1; compact: perfect sticking with psi = 1. Rain-out at tau_f > alpha/Omega (eq. 2.25).

    Arguments:
        R_au: 1 (quartz) or 5 (ice). alpha: turbulence parameter. porous: O07 vs compact.
        method: "w84" (thesis) or an OC07 method name. ns_target: Ns* of the MC settings.
        m_end: equal-mass zoom mass m* [g]; default 2 m_rain_est, where m_rain_est solves
            tau_f(m, psi_est) = tau_rain (eq. 2.25; compact: psi = 1). Sets
            n_particles = ns_target m_end/m0 (const_v), so about 2 ns_target single particles
            carry the mass at rain-out; capacity = 16 ns_target + 64 slots (rained particles stay
            parked in their slots, see RainOutKernel). rain_out: wrap the kernel in RainOutKernel. n_frag: passed to
            RecipeOutcome (0: O07 without fragmentation, as in ch. 2).
        psi_est: porous only: the enlargement factor at rain-out that sets m_rain_est, from a
            simulation of the same setting: ``ch2_pilot(R_au, alpha, ...)["psi"]``. The published
            T-Tab2.2 <psi> is never read (it is what the run is compared with). A porous setup
            needs psi_est or m_end (JaxcoagInputError otherwise; the pilot is a ~10-60 s run, so
            it is not started implicitly). Compact runs use psi = 1 (definition of the 'C' models).
        n_small: O07 small-N treatment (thesis: Ossenkopf's psi for N <= 40, psi_add from N = 40):
            psi_add off for products of <= n_small monomers (see mc.recipe_outcome.o07_recipe);
            None applies psi_add from N = 1.
        z_over_H: height of the simulated layer in gas scale heights (1 = the thesis text; 0 =
            midplane, a sensitivity knob: the published T-Tab2.2 rows imply a rho_g c_g ~1.75x
            that of the Hayashi gas at z = H_g).

    Returns:
        dict with ``scene``, ``gas``, ``material``, ``kernel`` (RainOutKernel-wrapped when
        rain_out), ``outcome`` (RecipeOutcome or PerfectSticking), ``tau_rain`` [s], ``rho_d``
        [g cm^-3], ``m0`` [g], ``struct0``, ``name`` (Tab. 2.1 id), ``reference`` (Tab. 2.2 row or
        None), ``m_rain_est`` [g] (None for porous with m_end but no psi_est), ``psi_est`` (the
        value used: psi_est, 1 for compact, None) and ``mc`` (keyword arguments for
        :func:`jaxcoag.mc.run` except t_out and key).
    """
    import math

    import jax.numpy as jnp

    from . import constants as _C
    from .mc import outcomes as _mco
    from .mc import recipe_outcome as _ro
    from .physics import gas as _gas
    from .physics.contact import Material

    if R_au not in (1, 5):
        raise JaxcoagInputError(f"ch2_setup: R_au must be 1 (quartz, rho_g/rho_d = 240) or 5 (ice, 57); got {R_au!r}")
    if not (alpha > 0):
        raise JaxcoagInputError(f"ch2_setup: alpha must be > 0 (thesis range 1e-6..1e-2); got {alpha!r}")
    if psi_est is not None:
        if not porous:
            raise JaxcoagInputError("ch2_setup: psi_est applies to porous runs only (compact runs have psi = 1); "
                                    "drop psi_est or set porous=True")
        try:
            psi_ok = math.isfinite(float(psi_est)) and float(psi_est) >= 1.0
        except (TypeError, ValueError):
            psi_ok = False
        if not psi_ok:
            raise JaxcoagInputError(f"ch2_setup: psi_est must be a finite enlargement factor >= 1 (e.g. "
                                    f"scenes.ch2_pilot(R_au, alpha)['psi']); got {psi_est!r}")
    elif porous and m_end is None:
        raise JaxcoagInputError("ch2_setup: a porous setup needs the rain-out enlargement factor psi_est= (from a "
                                "run of the same setting: psi_est=scenes.ch2_pilot(R_au, alpha, ns_target=...)['psi']) "
                                "or an explicit zoom mass m_end= [g]")
    if m_end is not None:
        try:
            m_ok = float(m_end) > 0 and math.isfinite(float(m_end))
        except (TypeError, ValueError):
            m_ok = False
        if not m_ok:
            raise JaxcoagInputError(f"ch2_setup: m_end must be a finite zoom mass > 0 g; got {m_end!r}")
    R = R_au * _C.AU
    H = _gas.mmsn_hayashi81(R, alpha).H_g
    gas = _gas.mmsn_hayashi81(R, alpha, z=float(z_over_H) * H, tL_factor=2.0 * math.pi)
    mat = Material.ch2_quartz() if R_au == 1 else Material.ch2_ice()
    rho_d = gas.rho_g / (240.0 if R_au == 1 else 57.0)
    scene = ch2_porous(method) if porous else ch2_compact(method)
    base = scene.kernel(gas, material=mat)
    kernel = _ro.RainOutKernel(base) if rain_out else base
    if porous:
        outcome = _ro.RecipeOutcome(kernel, mat, _ro.o07_recipe(n_small=n_small), n_frag=n_frag)
        struct0 = jnp.ones((1,))
    else:
        outcome = _mco.PerfectSticking()
        struct0 = jnp.zeros((0,))
    name = ch2_model_name(R_au, alpha, porous)
    ref = CH2_TABLE_2_2.get(name)
    m0 = float(mat.m0)
    tau_rain = float(alpha / gas.Omega)
    # rain-out mass estimate: tau_f(m, psi_est) = tau_rain (eq. 2.25) on a fine grid; psi_est comes
    # from a run (ch2_pilot) or the caller, never from the published table
    if not porous:
        psi_est = 1.0
        m_rain_est = _ch2_m_rain(base, None, tau_rain, m0)
    elif psi_est is not None:
        psi_est = float(psi_est)
        m_rain_est = _ch2_m_rain(base, psi_est, tau_rain, m0)
    else:
        m_rain_est = None
    if m_end is None:
        m_end = 2.0 * m_rain_est
    n_particles = float(ns_target) * float(m_end) / m0
    mc = dict(n_particles=n_particles, m0=m0, rho_d=float(rho_d), mode="const_v", grouping="equal_mass",
              ns_target=ns_target, f_eps=1e-3, outcome=outcome, struct0=struct0,
              capacity=int(16 * ns_target) + 64)
    return dict(scene=scene, gas=gas, material=mat, kernel=kernel, outcome=outcome,
                tau_rain=tau_rain, rho_d=float(rho_d), m0=m0, struct0=struct0, name=name,
                reference=ref, m_rain_est=m_rain_est, psi_est=psi_est, mc=mc)


from .mc.state import AbstractStop as _AbstractStop  # noqa: E402


class RainedFraction(_AbstractStop):
    """Stop predicate for ``mc.run(stop=...)``: true once the rained-out mass exceeds ``fraction``
    of the simulated mass (rain-out: tau_f > tau_rain, thesis eq. 2.25, as marked by
    :class:`~jaxcoag.mc.RainOutKernel`).

    ``fraction = 0`` stops at the first rain-out event (the :func:`ch2_pilot`); ``fraction = 1``
    never stops (the rained mass cannot exceed the simulated mass): the full run uses it so that it
    has the pilot's program structure and reuses its compilation. ``fraction`` is an array leaf
    (other values reuse the compiled run).

    Arguments:
        kernel: the run's :class:`~jaxcoag.mc.RainOutKernel`. fraction: rained mass fraction in [0, 1].
    """

    kernel: object
    fraction: object

    def __init__(self, kernel, fraction=0.0):
        import jax.numpy as jnp

        if not hasattr(kernel, "rained"):
            raise JaxcoagInputError("RainedFraction needs the run's RainOutKernel (ch2_setup(...)['kernel'] with "
                                    "rain_out=True)")
        if not (0.0 <= float(fraction) <= 1.0):
            raise JaxcoagInputError(f"RainedFraction: fraction must be in [0, 1] (0: first rain-out); got {fraction!r}")
        self.kernel = kernel
        self.fraction = jnp.asarray(float(fraction), jnp.float64)

    def __call__(self, state):
        """True where sum(g m | rained) > fraction * sum(g m | valid)."""
        import jax.numpy as jnp

        g = state.w * jnp.exp2(state.z.astype(state.m.dtype))
        gm = jnp.where(state.valid, g * state.m, 0.0)
        gone = state.valid & self.kernel.rained(state.m, state.psi)
        return jnp.sum(jnp.where(gone, gm, 0.0)) > self.fraction * jnp.sum(gm)


def ch2_mc_run(st, t_out, keys, *, stop_fraction=1.0, max_events=3_000_000, **overrides):
    """Run a :func:`ch2_setup` setting with :func:`jaxcoag.mc.run`, vmapped over ``keys``.

    Every ch. 2 run goes through here with a :class:`RainedFraction` stop, so :func:`ch2_pilot`
    (``stop_fraction = 0``) and the full run (``1``: never stops) share one compiled program when
    their static shapes agree (ns_target, capacity, len(t_out), number of keys).

    Arguments:
        st: ``ch2_setup(...)`` dict (rain_out=True). t_out: output times [s]. keys: (runs,) jax keys.
        stop_fraction: rained mass fraction that stops a run. max_events: event budget per run.
        overrides: replace entries of ``st["mc"]`` (e.g. ``f_eps``).
    Returns:
        ``MCResult`` with a leading runs axis.
    """
    import jax

    from . import mc as _mc

    K = st["kernel"]
    kw = dict(st["mc"])
    kw.update(overrides)
    stop = RainedFraction(K, stop_fraction)
    return jax.vmap(lambda k: _mc.run(K, t_out=t_out, key=k, max_events=max_events, stop=stop, **kw))(keys)


def ch2_pilot(R_au: int = 1, alpha: float = 1e-4, *, ns_target: int = 200, runs: int = 1, seed: int = 0,
              f_eps: float = 1e-3, t_end_yr: float = 1e6, n_out: int = 40, psi_start: float = 1e3,
              n_pass: int = 2, max_events: int = 3_000_000, **setup_kw):
    """Enlargement factor at rain-out from a run of the porous ch. 2 setting (zoom for :func:`ch2_setup`).

    Runs the porous setting of ``ch2_setup(R_au, alpha, porous=True, ...)`` with the Monte Carlo
    until the first particle rains out (tau_f > tau_rain = alpha/Omega, thesis eq. 2.25) and measures

        psi_pilot = <psi>_m over the particles with tau_f >= tau_rain / 2 at that moment

    (mass-weighted, weights g m; the rained particle and the ones within a factor 2 of rain-out in
    friction time: the particles that rain out next, thesis Fig. 2.10's 'distribution at the first
    rain-out'), averaged over ``runs`` runs. After compaction psi stalls (thesis Fig. 2.12, §2.4:
    <a>_m/<a*>_m is flat from the compaction stage to rain-out), so this psi is the rain-out <psi>
    of T-Tab2.2 and m_rain = the root of tau_f(m, psi_pilot) = tau_rain gives the zoom mass.

    Zoom of the pilot itself: pass 1 uses m* = 2 m_rain(psi_start) with a generous psi_start
    (default 1e3, a/a* = 10: too coarse rather than too fine: a zoom mass below the rain-out mass
    leaves too little simulated mass to reach rain-out); each further pass uses the previous
    pass's psi (the zoom the full run will use). Measured (R1Ta4-P, Ns* = 16, f_eps 1e-2, one run
    each, seeds 2007/11/12): psi_start 86 -> 89, 88, 82; psi_start 1e3 -> 78, 81, 98: the result does
    not depend on the zoom beyond the run-to-run scatter (~10 % at Ns* = 16).

    Arguments:
        R_au, alpha: the setting (thesis Tab. 2.1). ns_target: Ns* (use the full run's: same
        compiled program). runs: runs per pass (vmapped; use the full run's). seed: PRNG seed.
        f_eps: fractional mass gain per group event. t_end_yr, n_out: output grid (log from
        0.1 yr; use the full run's); the first rain-out must happen before t_end_yr.
        psi_start: pass-1 enlargement factor for the zoom (>= 1). n_pass: passes (>= 1).
        max_events: per run. setup_kw: passed to ch2_setup (method, n_small, z_over_H, ...).

    Returns:
        dict: ``psi`` (last pass, mean over runs), ``psi_runs`` (last pass, per run), ``psi_passes``
        (mean per pass), ``m_rain_est`` [g] (tau_f(m, psi) = tau_rain, as ch2_setup), ``m_first``
        [g] and ``t_first`` [s] (first rained particle per run, last pass), ``n_events``, ``status``.

    Raises:
        JaxcoagInputError: a run did not rain out by t_end_yr / max_events (message says what to raise).

    References: Ormel (2008) thesis §2.4, eq. 2.25, Figs. 2.10, 2.12, Tab. 2.2; Ormel, Spaans &
    Tielens (2007) A&A 461, 215.
    """
    import math

    import jax
    import jax.numpy as jnp
    import numpy as np

    from . import mc as _mc

    if not (math.isfinite(float(psi_start)) and float(psi_start) >= 1.0):
        raise JaxcoagInputError(f"ch2_pilot: psi_start must be a finite enlargement factor >= 1; got {psi_start!r}")
    for nm, v in (("n_pass", n_pass), ("runs", runs), ("n_out", n_out)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise JaxcoagInputError(f"ch2_pilot: {nm} must be an integer >= 1; got {v!r}")
    if "porous" in setup_kw or "psi_est" in setup_kw or "m_end" in setup_kw or "rain_out" in setup_kw:
        raise JaxcoagInputError("ch2_pilot: porous, psi_est, m_end and rain_out are set by the pilot (porous, "
                                "rain-out on, zoom from psi_start / the previous pass)")
    yr = 3.15576e7
    t_out = jnp.logspace(-1.0, math.log10(float(t_end_yr)), int(n_out)) * yr
    keys = jax.random.split(jax.random.key(int(seed)), int(runs))
    psi, passes = float(psi_start), []
    for _ in range(int(n_pass)):
        st = ch2_setup(R_au, alpha, True, ns_target=ns_target, psi_est=psi, **setup_kw)
        K = st["kernel"]
        res = ch2_mc_run(st, t_out, keys, stop_fraction=0.0, max_events=max_events, f_eps=f_eps)
        fs = res.final_state
        stopped = (np.asarray(res.status) & int(_mc.STATUS.STOPPED)) != 0
        if not np.all(stopped):
            names = [_mc.status_names(int(c)) for c in np.asarray(res.status)]
            raise JaxcoagInputError(
                f"ch2_pilot: {int((~stopped).sum())} of {runs} run(s) did not rain out (status {names}, zoom mass "
                f"{st['mc']['n_particles'] * st['m0'] / ns_target:.3g} g): raise t_end_yr (now {t_end_yr:g} yr), "
                f"max_events (now {max_events}) or psi_start (now {psi_start:g}, sets the pass-1 zoom mass)")
        g = fs.w * jnp.exp2(fs.z.astype(fs.m.dtype))
        tau = K.base.particles(fs.m, fs.psi).tau_f
        near = fs.valid & (tau >= 0.5 * st["tau_rain"])
        wgt = jnp.where(near, g * fs.m, 0.0)
        psi_runs = np.asarray(jnp.sum(wgt * fs.psi[..., 0], -1) / jnp.sum(wgt, -1))
        gone = fs.valid & K.rained(fs.m, fs.psi)
        m_first = np.asarray(jnp.max(jnp.where(gone, fs.m, 0.0), -1))
        psi = float(np.mean(psi_runs))
        passes.append(psi)
    m_rain = _ch2_m_rain(st["kernel"].base, psi, st["tau_rain"], st["m0"])
    return dict(psi=psi, psi_runs=psi_runs, psi_passes=passes, m_rain_est=m_rain, m_first=m_first,
                t_first=np.asarray(res.t_stop), n_events=np.asarray(res.n_events),
                status=[_mc.status_names(int(c)) for c in np.asarray(res.status)])
# ---- chapter 2 ---- end


# ---- setups: complete settings of the seeds for the binned engine ---- begin
import equinox as _eqx  # noqa: E402

from ._validate import JaxcoagInputError as _JIE  # noqa: E402


# A Scene holds structure only; a Setup bundles everything one run of a seed's setting needs
# (scene, gas, material, kernel, outcome model, grid, initial state, output times, the numbers
# used and the published ones to compare with). ``setup(name, **overrides)``.
class Setup(_eqx.Module):
    """A complete binned-engine setting: ``setup.solve(**kw)`` runs it.

    Attributes:
        name: setup name. kernel: collision kernel [cm^3 s^-1]. grid: MassGrid. n0: number
        density per bin [cm^-3] (numpy). ts: output times [s] (numpy, ts[0] = 0).
        scene: the Scene (None for the ch. 5 analytic test kernels). gas: GasState or None.
        material: contact.Material or None. fragmentation: binned outcome model or None
        (perfect sticking). params: dict of the numbers used and derived [cgs; times also in yr].
        reference: dict of published numbers (empty if none). notes: what differs from the source.
    """

    name: str = _eqx.field(static=True)
    kernel: object
    grid: object = _eqx.field(static=True)
    n0: object
    ts: object
    scene: object = None
    gas: object = None
    material: object = None
    fragmentation: object = None
    params: dict = _eqx.field(default_factory=dict)
    reference: dict = _eqx.field(default_factory=dict)
    notes: str = _eqx.field(static=True, default="")

    @property
    def effect_names(self) -> tuple:
        """Names of the velocity effects the setting simulates (() for analytic kernels)."""
        return () if self.scene is None else self.scene.effect_names

    def solve(self, **kw):
        """:func:`jaxcoag.binned.solve_binned` on this setting (keywords passed through;
        ``fragmentation`` defaults to the setup's)."""
        from .binned import solve_binned
        kw.setdefault("fragmentation", self.fragmentation)
        return solve_binned(self.kernel, self.grid, self.n0, self.ts, **kw)


_YR = 3.15576e7

# T-Tab6.5 (<a>_m [cm]) and T-Tab6.6 (kappa = sum(pi a^2)/sum(m) [cm^2 g^-1]) at 1e4, 1e5, 1e6,
# 1e7 yr, t_ff, t_ad; keys (n [cm^-3], material, a0 [cm], variant)
CH6_TABLE_6_5_6_6 = {
    (1e3, "ice", 1e-5, "standard"): ((1.0e-5, 1.0e-5, 1.2e-5, 8.3e-5, 1.2e-5, 8.3e-5), (2.8e4, 2.8e4, 2.7e4, 1.5e4, 2.7e4, 1.5e4)),
    (1e4, "silicate", 1e-5, "standard"): ((1.0e-5, 1.1e-5, 1.4e-5, 1.4e-5, 1.2e-5, 1.4e-5), (2.8e4, 2.8e4, 2.7e4, 2.6e4, 2.7e4, 2.6e4)),
    (1e4, "ice", 1e-5, "standard"): ((1.0e-5, 1.1e-5, 4.6e-5, 8.5e-4, 1.5e-5, 8.5e-4), (2.8e4, 2.8e4, 2.0e4, 2.5e3, 2.6e4, 2.5e3)),
    (1e5, "silicate", 1e-5, "standard"): ((1.0e-5, 1.9e-5, 4.0e-5, 4.0e-5, 2.0e-5, 4.0e-5), (2.8e4, 2.5e4, 2.0e4, 2.0e4, 2.5e4, 2.0e4)),
    (1e5, "silicate", 1e-4, "standard"): ((1.0e-4,) * 6, (2.8e3,) * 6),
    (1e5, "ice", 1e-5, "standard"): ((1.0e-5, 2.2e-5, 6.4e-4, 7.4e-3, 2.3e-5, 3.2e-3), (2.8e4, 2.4e4, 5.1e3, 2.3e3, 2.4e4, 8.4e2)),
    (1e5, "ice", 1e-4, "standard"): ((1.0e-4, 1.1e-4, 2.2e-4, 2.3e-4, 1.1e-4, 2.3e-4), (2.8e3, 2.8e3, 2.4e3, 2.4e3, 2.8e3, 2.4e3)),
    (1e5, "ice", 3e-6, "standard"): ((3.2e-6, 1.1e-5, 1.3e-3, 4.3, 1.2e-5, 2.4e-1), (9.3e4, 7.1e4, 1.4e4, 4.4e2, 6.9e4, 1.7e3)),
    (1e5, "ice", 1e-5, "compact"): ((1.0e-5, 1.5e-5, 1.4e-4, 5.8e-3, 1.6e-5, 1.3e-3), (2.8e4, 2.6e4, 8.0e3, 1.9e3, 2.6e4, 1.0e3)),
    (1e5, "ice", 1e-5, "head-on"): ((1.0e-5, 2.2e-5, 3.6e-4, 7.5e-3, 2.4e-5, 3.1e-3), (2.8e4, 2.4e4, 4.9e3, 3.1e3, 2.4e4, 9.3e2)),
    (1e6, "silicate", 1e-5, "standard"): ((1.4e-5, 1.2e-4, 1.3e-4, 1.3e-4, 4.4e-5, 1.3e-4), (2.7e4, 1.4e4, 1.4e4, 1.4e4, 2.0e4, 1.4e4)),
    (1e6, "ice", 1e-5, "standard"): ((1.4e-5, 2.7e-4, 3.7e-2, 2.0e-2, 4.6e-5, 2.9e-2), (2.7e4, 1.2e4, 6.7e2, 2.2e3, 2.0e4, 1.5e3)),
    (1e7, "ice", 1e-5, "standard"): ((7.9e-5, 3.7e-2, 5.2e-2, 6.1e-2, 8.6e-5, 7.8e-1), (1.7e4, 1.8e3, 1.4e3, 1.7e3, 1.6e4, 6.4e2)),
}
CH6_EPOCHS = ("1e4 yr", "1e5 yr", "1e6 yr", "1e7 yr", "t_ff", "t_ad")


def _log_grid(m_first, decades, bins_per_decade):
    """Log grid whose first bin centre is m_first [g]."""
    from .binned import MassGrid
    lo = float(m_first) * 10.0 ** (-0.5 / bins_per_decade)
    return MassGrid.log(lo, lo * 10.0 ** decades, bins_per_decade)


def _setup_ch6(n=1e5, material="ice", T=10.0, a0=1e-5, R_gd=100.0, bins_per_decade=2, decades=16,
               outcome="o09", width=0.3, method="exact", t_end_yr=1e7):
    """Thesis ch. 6 molecular-cloud core (thesis §6.2, eqs. 6.1-6.16; Ormel et al. 2009):
    homogeneous Jeans core of density n [cm^-3] (1e3..1e7) at T [K]; ice-coated (gamma = 370,
    E* = 3.7e10) or bare silicate (gamma = 25, E* = 2.8e11) monomers of radius a0 (rho0 = 2.65,
    xi = 2e-7, A_br = 2.8e3); R_gd = 100; Brownian + OC07 turbulence with v_L = c_g,
    t_L = L_J/c_g. Compact particles (psi = 1: the thesis's 'compact' run 9 is the like-for-like
    row). Outcome: "o09" (tabulated recipe with the SURROGATE tables unless CDS tables are
    loaded; smooth regime switches of ``width``), "o07_dt" (DT thresholds, restr_factor 5) or
    "sticking". Outputs at 1e4..1e7 yr, t_ff and t_ad = 3.7e6 yr (n/1e5)^-1/2 (T-Tab6.5)."""
    import numpy as np

    from .binned import monodisperse
    from .binned.outcome import O07Recipe, O09Recipe, OutcomeFragmentation
    from .physics import gas as _gas
    from .physics.contact import Material

    if material not in ("ice", "silicate"):
        raise _JIE(f"ch6_cloud: material must be 'ice' (ice-coated silicate) or 'silicate'; got {material!r}")
    if not (float(n) > 0):
        raise _JIE(f"ch6_cloud: n must be a gas number density > 0 cm^-3 (thesis 1e3..1e7); got {n!r}")
    if outcome not in ("o09", "o07_dt", "sticking"):
        raise _JIE(f"ch6_cloud: outcome must be 'o09', 'o07_dt' or 'sticking'; got {outcome!r}")
    mat = Material.ch6_ice(a0) if material == "ice" else Material.ch6_silicate(a0)
    gas = _gas.molecular_cloud(n, T)
    scene = molecular_cloud(method)
    kernel = scene.kernel(gas, material=mat)
    m0 = float(mat.m0)
    rho_g = float(gas.rho_g)
    rho_d = rho_g / float(R_gd)
    grid = _log_grid(m0, decades, bins_per_decade)
    n0 = monodisperse(grid, m0, rho_d)
    jq = _gas.jeans_quantities(gas)
    t_ff = float(jq["t_ff"])
    t_ad = 3.7e6 * _YR * (float(n) / 1e5) ** -0.5
    epochs = np.array([1e4 * _YR, 1e5 * _YR, 1e6 * _YR, 1e7 * _YR, t_ff, t_ad])
    ts = np.unique(np.concatenate([[0.0], epochs[epochs <= t_end_yr * _YR * (1 + 1e-12)], [t_end_yr * _YR]]))
    if outcome == "o09":
        frag = OutcomeFragmentation(O09Recipe(), mat, width=width)
    elif outcome == "o07_dt":
        frag = OutcomeFragmentation(O07Recipe(restr_factor=5.0), mat, width=width)
    else:
        frag = None
    # monomer numbers of §11.4 (eqs. 6.13-6.16)
    rho0, a0f = float(mat.rho_s), float(mat.a0)
    c_g = float(gas.c_g)
    tau0 = rho0 * a0f / (c_g * rho_g)                                  # eq. 6.13
    St_s = tau0 / float(gas.t_s)
    dv0 = 3.0 ** 0.5 * float(gas.v_s) * St_s ** 0.5                    # eq. 6.15
    t_coll0 = rho0 * a0f * float(R_gd) / (3.0 * rho_g * dv0)           # eq. 6.16
    e_roll, e_br = float(mat.e_roll()), float(mat.e_break())
    params = dict(n=float(n), T=float(T), material=material, a0=a0f, rho0=rho0, R_gd=float(R_gd), rho_g=rho_g,
                  rho_d=rho_d, m0=m0, f_monomer0=rho_d / m0, c_g=c_g, Re=float(gas.Re), t_s=float(gas.t_s),
                  v_s=float(gas.v_s), tau0=tau0, tau0_yr=tau0 / _YR, St_s=St_s, dv0=dv0, t_coll0=t_coll0,
                  t_coll0_yr=t_coll0 / _YR, t_ff=t_ff, t_ad=t_ad, e_roll=e_roll, e_break=e_br,
                  kappa0=3.0 / (4.0 * rho0 * a0f), outcome=outcome, width=float(width))
    variant = "compact"
    ref = CH6_TABLE_6_5_6_6.get((float(n), material, a0f, variant)) or CH6_TABLE_6_5_6_6.get(
        (float(n), material, a0f, "standard"))
    reference = {}
    if ref is not None:
        row = "compact" if (float(n), material, a0f, "compact") in CH6_TABLE_6_5_6_6 else "standard (porous)"
        reference = dict(row=row, epochs=CH6_EPOCHS, a_m=ref[0], kappa=ref[1],
                         source="Ormel 2008 thesis Tabs. 6.5, 6.6")
    notes = ("compact particles (psi = 1); " + ("O09 recipe with SURROGATE tables (thesis prints only Tabs. 6.7/6.9) "
             if outcome == "o09" else "") + "homogeneous static core, no collapse (as the thesis).")
    return Setup(name="ch6_cloud", kernel=kernel, grid=grid, n0=n0, ts=ts, scene=scene, gas=gas, material=mat,
                 fragmentation=frag, params=params, reference=reference, notes=notes)


def _setup_ch4(alpha=1e-4, rho_X=1.0, R_au=3.0, R_gc=100.0, R_cd=1.0, a_dust=1e-3, a_chondrule=3e-2,
               sigma_chondrule=0.5, bins_per_decade=4, decades=12, t_end_yr=1e4, method="exact"):
    """Thesis ch. 4 nebula with chondrules and dust (thesis §4.4; Ormel, Cuzzi & Tielens 2008): Takeuchi & Lin
    disk (T-Tab4.1) at R_au = 3 AU with gas enhancement rho_X; Brownian + OC07 turbulence +
    radial drift (eqs. 4.4, 4.8, ch. 3); chondrules lognormal in radius (median a_chondrule =
    300 um, width sigma = 0.5: <a>_m = 720 um) with density rho_g/R_gc, dust of radius a_dust =
    10 um with rho_chondrules/R_cd; ch4-silicate material (rho = 3). The binned engine treats
    compounds as compact spheres that stick (the O08 stick/bounce rule needs the compound
    phases: use the MC engine); this bundle gives the gas/velocity setting and initial state."""
    import numpy as np

    from . import constants as _C
    from .physics import gas as _gas
    from .physics.contact import Material

    for nm, v in (("alpha", alpha), ("rho_X", rho_X), ("R_au", R_au), ("R_gc", R_gc), ("R_cd", R_cd),
                  ("a_dust", a_dust), ("a_chondrule", a_chondrule), ("sigma_chondrule", sigma_chondrule)):
        if not (float(v) > 0):
            raise _JIE(f"ch4_nebula: {nm} must be > 0 (got {v!r})")
    mat = Material.ch4_silicate()
    gas = _gas.ch4_disk(float(R_au) * _C.AU, alpha, rho_X=rho_X)
    scene = nebula_ch4(method)
    kernel = scene.kernel(gas, material=mat)
    rho_s = float(mat.rho_s)
    mass = lambda a: 4.0 / 3.0 * np.pi * rho_s * a ** 3
    m_dust = mass(a_dust)
    grid = _log_grid(m_dust, decades, bins_per_decade)  # 1.3e-8 g .. 1.3e4 g (a ~ 10 cm)
    rho_g = float(gas.rho_g)
    rho_c = rho_g / float(R_gc)
    rho_dd = rho_c / float(R_cd)
    # chondrule mass per bin: n(a) ∝ lognormal(ln a; ln a_ch, sigma); mass weight ∝ a^3 n(a)
    le = np.asarray(grid.log_edges)
    la_edges = (le - np.log(4.0 / 3.0 * np.pi * rho_s)) / 3.0
    from math import erf, sqrt
    mu3 = np.log(a_chondrule) + 3.0 * sigma_chondrule ** 2   # mass-weighted lognormal shifts by 3 sigma^2
    cdf = np.array([0.5 * (1.0 + erf((x - mu3) / (sqrt(2.0) * sigma_chondrule))) for x in la_edges])
    w = np.diff(cdf)
    w = w / w.sum()
    n0 = rho_c * w / grid.centers
    kd = int(np.searchsorted(le, np.log(m_dust), side="right") - 1)
    n0[kd] += rho_dd / grid.centers[kd]
    ts = np.concatenate([[0.0], np.logspace(0, np.log10(t_end_yr), 9) * _YR])
    a_m0 = float(a_chondrule * np.exp(3.5 * sigma_chondrule ** 2))
    params = dict(alpha=float(alpha), rho_X=float(rho_X), R_au=float(R_au), rho_g=rho_g, T=float(gas.T),
                  c_g=float(gas.c_g), l_mfp=float(gas.l_mfp), eta=float(gas.eta), t_L=float(gas.t_L),
                  t_L_yr=float(gas.t_L) / _YR, t_s=float(gas.t_s), rho_chondrules=rho_c, rho_dust=rho_dd,
                  m_dust=m_dust, a_m_chondrules=a_m0)
    key = {1e-7: 0, 1e-6: 1, 1e-5: 2, 1e-4: 3, 1e-3: 4, 1e-2: 5}.get(float(alpha))
    tab = {10.0: (8.5, 8.0, 4.8, 0.6, 0.1, 0.1), 1.0: (0.8, 0.7, 0.5, 0.1, 0.1, 0.1)}.get(float(rho_X))
    reference = dict(gas=dict(rho_g=2.4e-11, c_g=7.6e4, l_mfp=82.0, T=162.0, eta=2.7e-3, t_L_yr=0.82, t_s=1.2e4),
                     a_m_chondrules=0.072, source="Ormel 2008 thesis §4.3, Tab. 4.1, Tab. 4.5")
    if key is not None and tab is not None and float(R_au) == 3.0:
        reference["a_m_final"] = tab[key]
    notes = "compact sticking spheres (no O08 stick/bounce, no porous dust phase) in the binned engine."
    return Setup(name="ch4_nebula", kernel=kernel, grid=grid, n0=n0, ts=ts, scene=scene, gas=gas, material=mat,
                 fragmentation=None, params=params, reference=reference, notes=notes)


def _setup_ch2_compact(R_au=1, alpha=1e-4, bins_per_decade=4, decades=14, t_end_yr=None, method="w84"):
    """Thesis ch. 2 compact model ('C' rows of T-Tab2.2) for the binned engine: the setting of
    :func:`ch2_setup` (MMSN at z = H_g, t_L = 2 pi/Omega, quartz at 1 AU / ice at 5 AU,
    Brownian + W84 turbulence) with perfect sticking of compact spheres; rain-out (removal at
    tau_f > alpha/Omega) is an MC-engine feature and is not applied here."""
    import numpy as np

    from .binned import monodisperse

    if R_au not in (1, 5):
        raise _JIE(f"ch2_compact: R_au must be 1 or 5; got {R_au!r}")
    base = ch2_setup(R_au, alpha, porous=False, method=method, rain_out=False)
    mat, gas, kernel = base["material"], base["gas"], base["kernel"]
    m0 = float(mat.m0)
    grid = _log_grid(m0, decades, bins_per_decade)
    n0 = monodisperse(grid, m0, base["rho_d"])
    ref = base["reference"] or {}
    if t_end_yr is None:
        t_end_yr = float(ref.get("t_99", 1e5))
    ts = np.concatenate([[0.0], np.logspace(1, np.log10(t_end_yr), 9) * _YR])
    params = dict(R_au=R_au, alpha=float(alpha), rho_g=float(gas.rho_g), rho_d=float(base["rho_d"]), m0=m0,
                  tau_rain=float(base["tau_rain"]), m_rain_est=float(base["m_rain_est"]))
    reference = dict(ref, model=base["name"], source="Ormel 2008 thesis Tab. 2.2") if ref else {}
    return Setup(name=f"ch2_compact_{R_au}au", kernel=kernel, grid=grid, n0=n0, ts=ts, scene=base["scene"],
                 gas=gas, material=mat, fragmentation=None, params=params, reference=reference,
                 notes="no rain-out sink in the binned engine (the MC engine's RainOutKernel does it).")


def _setup_ch5(kind, bins_per_decade=8, m_frag=None):
    """Thesis ch. 5 test kernels (Tab. 5.1): K = 1, K = (m_i + m_j)/2, K = m_i m_j as analytic kernels,
    monodisperse start m0 = 1, n0 = 1 (dimensionless units); ``m_frag``: shatter products
    heavier than m_frag into monomers (thesis §5.3.4; constant and sum kernels)."""
    import numpy as np

    from .binned import ShatterToMonomers, monodisperse
    from . import kernels as _k

    kern = {"constant": _k.Constant(1.0), "sum": _k.Sum(0.5), "product": _k.Product(1.0)}[kind]
    t_end = {"constant": 1e4, "sum": 10.0, "product": 0.9}[kind]
    decades = {"constant": 7, "sum": 8, "product": 6}[kind] if m_frag is None else int(np.ceil(np.log10(m_frag))) + 1
    grid = _log_grid(1.0, decades, bins_per_decade)
    n0 = monodisperse(grid, 1.0, 1.0)
    ts = np.concatenate([[0.0], np.logspace(-1 if kind != "constant" else 0, np.log10(t_end), 7)])
    frag = None if m_frag is None else ShatterToMonomers(m_frag)
    reference = dict(analytic=f"jaxcoag.analytic.number_density('{kind}', m, t)") if m_frag is None else dict(
        steady_state="m^2 f ∝ m^(1/2) (constant) / bath tub n0 m0 = n_f m_f (sum) [T§5.3.4]")
    return Setup(name=f"ch5_{kind}", kernel=kern, grid=grid, n0=n0, ts=ts, fragmentation=frag,
                 params=dict(m0=1.0, n0=1.0, t_end=t_end, m_frag=m_frag), reference=reference,
                 notes="dimensionless units (m0 = n0 = 1).")


# name -> (builder, fixed arguments that are not overridable)
SETUPS = {
    "ch2_compact_1au": (_setup_ch2_compact, dict(R_au=1)),
    "ch2_compact_5au": (_setup_ch2_compact, dict(R_au=5)),
    "ch4_nebula": (_setup_ch4, {}),
    "ch6_cloud": (_setup_ch6, {}),
    "ch5_constant": (_setup_ch5, dict(kind="constant")),
    "ch5_sum": (_setup_ch5, dict(kind="sum")),
    "ch5_product": (_setup_ch5, dict(kind="product")),
}


def setup(name: str, **overrides) -> Setup:
    """A complete setting of the seeds by name (see :data:`SETUPS`), with keyword overrides.

    Names: ``ch2_compact_1au``/``_5au`` (thesis ch. 2 compact), ``ch4_nebula`` (chondrules +
    dust at 3 AU), ``ch6_cloud`` (molecular-cloud core; n, material = "ice"|"silicate", a0,
    outcome ...), ``ch5_constant``/``ch5_sum``/``ch5_product`` (test kernels; m_frag).
    Raises JaxcoagInputError for an unknown name or override (listing the valid ones).
    """
    import inspect

    if name not in SETUPS:
        raise _JIE(f"unknown setup {name!r}; available: {sorted(SETUPS)}")
    builder, fixed = SETUPS[name]
    allowed = [p for p in inspect.signature(builder).parameters if p not in fixed]
    bad = sorted(set(overrides) - set(allowed))
    if bad:
        raise _JIE(f"setup {name!r} has no parameter(s) {bad}; valid overrides: {allowed}")
    return builder(**fixed, **overrides)
# ---- setups ---- end


PRESETS = {f.__name__: f for f in (brownian_only, turbulence_only, protoplanetary_disk, nebula_ch4,
                                   molecular_cloud, dustpy_like, ch2_porous, ch2_compact)}


def get(name: str, **kw) -> Scene:
    """Preset by name, with a clear error for an unknown one."""
    if name not in PRESETS:
        raise JaxcoagInputError(f"unknown scene preset {name!r}; available: {sorted(PRESETS)}")
    return PRESETS[name](**kw)
