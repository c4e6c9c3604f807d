"""Monte Carlo set-ups of the paper figures: thesis ch. 2 porous vs compact growth until rain-out.

:func:`ch2_setup` bundles a T-Tab2.1 model (scene, gas, material, rain-out kernel, collision outcome and
the Monte Carlo engine settings); :func:`ch2_mc_run` runs it with a :class:`RainedFraction` stop,
vmapped over keys; :func:`ch2_pilot` measures the enlargement factor at the first rain-out that sets
the zoom mass of the full run. The published rows live in :mod:`jaxcoag.scenes.tables`.

References: Ormel (2008) thesis ch. 2 (§2.4, eq. 2.25, Tabs. 2.1, 2.2, Figs. 2.10, 2.12); Ormel,
Spaans & Tielens (2007) A&A 461, 215.
"""

from __future__ import annotations

from .._validate import JaxcoagInputError
from ..mc.state import AbstractStop as _AbstractStop
from . import tables as _tables
from .presets import ch2_compact, ch2_porous

__all__ = ["ch2_setup", "RainedFraction", "ch2_mc_run", "ch2_pilot"]


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
    """Everything a thesis ch. 2 run needs: scene, gas, material, kernel, outcome, Monte Carlo engine
    and initial condition, run as ``jaxcoag.evolve(st["kernel"], st["engine"], st["initial"], t_out,
    outcome=st["outcome"], key=key)`` (or :func:`ch2_mc_run`, vmapped over keys).

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
            n_particles = ns_target m_end/m0 (constant volume), so about 2 ns_target single particles
            carry the mass at rain-out; capacity = 16 ns_target + 64 slots (rained particles stay
            parked in their slots, see RainOutKernel). rain_out: wrap the kernel in RainOutKernel.
        n_frag: Monte Carlo fragment species of the RecipeOutcome (0: O07 without fragmentation, as in ch. 2).
        psi_est: porous only: the enlargement factor at rain-out that sets m_rain_est, from a
            simulation of the same setting: ``ch2_pilot(R_au, alpha, ...)["psi"]``. The published
            T-Tab2.2 <psi> is never read (it is what the run is compared with). A porous setup
            needs psi_est or m_end (JaxcoagInputError otherwise; the pilot is a ~10-60 s run, so
            it is not started implicitly). Compact runs use psi = 1 (definition of the 'C' models).
        n_small: O07 small-N treatment (thesis: Ossenkopf's psi for N <= 40, psi_add from N = 40):
            psi_add off for products of <= n_small monomers (``jaxcoag.outcomes.O07Recipe(n_small=...)``);
            None applies psi_add from N = 1.
        z_over_H: height of the simulated layer in gas scale heights (1 = the thesis text; 0 =
            midplane, a sensitivity knob: the published T-Tab2.2 rows imply a rho_g c_g ~1.75x
            that of the Hayashi gas at z = H_g).

    Returns:
        dict with ``scene``, ``gas``, ``material``, ``kernel`` (RainOutKernel-wrapped when
        rain_out), ``outcome`` (``RecipeOutcome(O07Recipe(n_small=...), material)`` or ``Sticking()``),
        ``tau_rain`` [s], ``rho_d`` [g cm^-3], ``m0`` [g], ``struct0`` (psi of the monomers: (1.,)
        porous, () compact), ``name`` (Tab. 2.1 id), ``reference`` (Tab. 2.2 row or None),
        ``m_rain_est`` [g] (None for porous with m_end but no psi_est), ``psi_est`` (the value used:
        psi_est, 1 for compact, None), ``m_end`` [g] (the zoom mass), ``engine`` (a
        :class:`jaxcoag.MonteCarlo`: equal-mass grouping, constant volume, ns_target, n_particles,
        f_eps = 1e-3, capacity) and ``initial`` (``jaxcoag.Monodisperse(m0, rho_d)``).
    """
    import math

    import jax.numpy as jnp

    from .. import constants as _C
    from .. import outcomes as _oc
    from .._engine import Monodisperse
    from ..mc import ConstantVolume, EqualMass, MonteCarlo, RainOutKernel
    from ..physics import gas as _gas
    from ..physics.contact import Material

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
                                    f"jaxcoag.scenes.mc_setups.ch2_pilot(R_au, alpha)['psi']); got {psi_est!r}")
    elif porous and m_end is None:
        raise JaxcoagInputError("ch2_setup: a porous setup needs the rain-out enlargement factor psi_est= (from a "
                                "run of the same setting: psi_est=jaxcoag.scenes.mc_setups.ch2_pilot(R_au, alpha, "
                                "ns_target=...)['psi']) or an explicit zoom mass m_end= [g]")
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
    kernel = RainOutKernel(base) if rain_out else base
    if porous:
        outcome = _oc.RecipeOutcome(_oc.O07Recipe(n_small=n_small), mat, n_frag=n_frag)
        struct0 = jnp.ones((1,))
    else:
        outcome = _oc.Sticking()
        struct0 = jnp.zeros((0,))
    name = _tables.ch2_model_name(R_au, alpha, porous)
    ref = _tables.CH2_TABLE_2_2.get(name)
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
    engine = MonteCarlo(grouping=EqualMass(), volume=ConstantVolume(), ns_target=ns_target, n_particles=n_particles,
                        f_eps=1e-3, capacity=int(16 * ns_target) + 64, struct0=struct0)
    return dict(scene=scene, gas=gas, material=mat, kernel=kernel, outcome=outcome,
                tau_rain=tau_rain, rho_d=float(rho_d), m0=m0, struct0=struct0, name=name,
                reference=ref, m_rain_est=m_rain_est, psi_est=psi_est, m_end=float(m_end), engine=engine,
                initial=Monodisperse(m0, float(rho_d)))


class RainedFraction(_AbstractStop):
    """Stop predicate for ``MonteCarlo(stop=...)``: true once the rained-out mass exceeds ``fraction``
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
    """Run a :func:`ch2_setup` setting with ``jaxcoag.evolve`` (its Monte Carlo engine), vmapped over ``keys``.

    Every ch. 2 run goes through here with a :class:`RainedFraction` stop, so :func:`ch2_pilot`
    (``stop_fraction = 0``) and the full run (``1``: never stops) share one compiled program when
    their static shapes agree (ns_target, capacity, len(t_out), number of keys).

    Arguments:
        st: ``ch2_setup(...)`` dict (rain_out=True). t_out: output times [s] (the run starts at t0 = 0).
        keys: (runs,) jax keys. stop_fraction: rained mass fraction that stops a run. max_events:
        event budget per run. overrides: replace fields of ``st["engine"]`` (e.g. ``f_eps``).
    Returns:
        ``MCResult`` with a leading runs axis (``throw=False``: read ``.status``).
    """
    import dataclasses

    import jax

    from .._engine import evolve

    K = st["kernel"]
    engine = dataclasses.replace(st["engine"], max_events=max_events, stop=RainedFraction(K, stop_fraction),
                                 **overrides)
    return jax.vmap(lambda k: evolve(K, engine, st["initial"], t_out, outcome=st["outcome"], key=k,
                                     throw=False))(keys)


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
        stopped = np.isfinite(np.asarray(res.t_stop))  # the RainedFraction stop fired: rained out
        if not np.all(stopped):
            raise JaxcoagInputError(
                f"ch2_pilot: {int((~stopped).sum())} of {runs} run(s) did not rain out (status {_status_list(res)}, "
                f"zoom mass {st['m_end']:.3g} g): raise t_end_yr (now {t_end_yr:g} yr), "
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
                status=_status_list(res))


def _status_list(res):
    """Name of the :class:`jaxcoag.RESULTS` item of each run of a (vmapped) Monte Carlo result."""
    from .._status import status_names

    names = status_names(res.status)
    return [names] if isinstance(names, str) else names
