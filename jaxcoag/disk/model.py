"""The radial disk model: grids, parameters and every coefficient of one step, as DustPy 1.0.9.

:class:`DiskModel` holds the structure (radial and mass grids, the coagulation tensors, which effects
are on, the drag convention) as static fields or constant arrays, and every number a user may
differentiate or vmap (alpha, the deltas, v_frag, rho_s, M_disk, r_c, dust-to-gas, the star) as a
float64 array leaf that is evaluated inside the step. :func:`dustpy_default` builds DustPy's default
model with any quantity overridable by keyword.

References: Stammler & Birnstiel (2022, ApJ 935, 35) §2 (equations) and §3 (the default model);
Lynden-Bell & Pringle (1974); Birnstiel, Dullemond & Brauer (2010, A&A 513, A79); Birnstiel, Klahr &
Ercolano (2012, A&A 539, A148).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError, is_traced, require_x64
from . import gas as _gas
from . import transport as _tr
from .grid import const_grad_row, const_grad_value, mass_grid, radial_grid

__all__ = ["DiskModel", "dustpy_default", "DUSTPY_DEFAULTS"]

_DP = _gas.DUSTPY_CONSTANTS

#: DustPy 1.0.9's default model (Stammler & Birnstiel 2022 §3; ``dustpy.Simulation.ini``), cgs
DUSTPY_DEFAULTS = dict(
    nr=100, r_min=1.0 * _DP["au"], r_max=1000.0 * _DP["au"], m_min=1e-12, m_max=1e5, bins_per_decade=7,
    alpha=1e-3, delta_rad=None, delta_turb=None, delta_vert=None, v_frag=100.0, m_disk=0.05 * _DP["M_sun"],
    r_c=60.0 * _DP["au"], rho_s=1.67, dust_to_gas=0.01, a_ini_max=1e-4, dist_exp=-3.5, m_star=1.0 * _DP["M_sun"],
    r_star=2.0 * _DP["R_sun"], t_star=5772.0, mu=2.3 * _DP["m_p"], erosion_mass_ratio=10.0, excavated_mass=1.0,
    fragment_slope=-11.0 / 6.0, stokes="dustpy", coagulation=True, dust_transport=True, gas_evolution=True,
    initial_cut="hard")

_PARAMS = ("alpha", "delta_rad", "delta_turb", "delta_vert", "v_frag", "rho_s", "m_disk", "r_c", "dust_to_gas",
           "a_ini_max", "m_star", "r_star", "t_star", "mu")


class DiskModel(eqx.Module):
    """A 1-D radial disk: viscous gas, dust drift + diffusion and coagulation/fragmentation in every cell.

    Build it with :func:`dustpy_default`. Array fields (leaves; differentiable):
        ri (nr+1,), r (nr,), area (nr,) [cm, cm^2]; m (nm,) [g]; tensors: the coagulation tensors (None
        without coagulation);
        alpha, delta_rad, delta_turb, delta_vert: viscosity and radial / turbulent / vertical mixing;
        v_frag [cm s^-1]; rho_s [g cm^-3]; m_disk [g]; r_c [cm]; dust_to_gas; a_ini_max [cm];
        m_star [g]; r_star [cm]; t_star [K]; mu: mean molecular mass [g].
    Static fields: stokes ("dustpy" | "jaxcoag"), coagulation, dust_transport, gas_evolution (bool),
    dist_exp (MRN exponent), initial_cut ("hard" as DustPy | "smooth": differentiable w.r.t. the
    parameters that set the largest initial grain).

    References: Stammler & Birnstiel (2022) §2-3.
    """

    ri: jax.Array
    r: jax.Array
    area: jax.Array
    m: jax.Array
    tensors: object
    alpha: jax.Array
    delta_rad: jax.Array
    delta_turb: jax.Array
    delta_vert: jax.Array
    v_frag: jax.Array
    rho_s: jax.Array
    m_disk: jax.Array
    r_c: jax.Array
    dust_to_gas: jax.Array
    a_ini_max: jax.Array
    m_star: jax.Array
    r_star: jax.Array
    t_star: jax.Array
    mu: jax.Array
    dist_exp: float = eqx.field(static=True, default=-3.5)
    stokes: str = eqx.field(static=True, default="dustpy")
    coagulation: bool = eqx.field(static=True, default=True)
    dust_transport: bool = eqx.field(static=True, default=True)
    gas_evolution: bool = eqx.field(static=True, default=True)
    initial_cut: str = eqx.field(static=True, default="hard")

    @property
    def nr(self) -> int:
        return int(self.r.shape[-1])

    @property
    def nm(self) -> int:
        return int(self.m.shape[-1])

    # ------------------------------------------------------------------ gas structure
    def temperature(self):
        """(nr,) passive midplane temperature [K] (DustPy ``std.gas.T_passive``)."""
        L = _gas.stellar_luminosity(self.r_star, self.t_star)
        return _gas.temperature_passive(self.r, L)

    def gas_structure(self, sigma_gas):
        """Midplane gas quantities of a gas profile (dict of (nr,) arrays, cgs): T, cs, omega, Hp, nu, rho, P,
        eta, n, mfp, v_gas (viscous radial velocity), and sigma_gas itself."""
        T = self.temperature()
        om = _gas.omega_k(self.r, self.m_star)
        cs = _gas.sound_speed(T, self.mu)
        hp = _gas.pressure_scale_height(cs, om)
        nu = _gas.viscosity(self.alpha, cs, hp)
        rho = _gas.rho_midplane(sigma_gas, hp)
        P = _gas.pressure_midplane(rho, cs)
        eta = _gas.eta_midplane(hp, P, self.r, self.ri)
        n = _gas.n_midplane(rho, self.mu)
        mfp = _gas.mean_free_path(n)
        v_gas = _gas.gas_velocity_visc(sigma_gas, nu, self.r, self.ri)
        return dict(sigma_gas=sigma_gas, T=T, cs=cs, omega=om, Hp=hp, nu=nu, rho=rho, P=P, eta=eta, n=n, mfp=mfp,
                    v_gas=v_gas)

    def particle_size(self):
        """(nm,) compact particle radii [cm]."""
        return _tr.particle_size(self.m, self.rho_s)

    def stokes_number(self, sigma_gas):
        """(nr, nm) midplane Stokes numbers for a gas profile (``stokes`` convention)."""
        g = self.gas_structure(sigma_gas)
        return _tr.stokes_number(self.particle_size(), self.rho_s, sigma_gas, g["mfp"], convention=self.stokes)

    def floor_dust(self):
        """(nr, nm) DustPy's dust floor [g cm^-2] (0.1 m / area)."""
        return _tr.sigma_floor(self.m, self.area)

    # ------------------------------------------------------------------ initial condition
    def initial(self):
        """The initial :class:`~jaxcoag.disk.engine.DiskProfile`: LBP gas (floored at 1e-100) and DustPy's MRN dust
        (largest size min(a_ini_max, drift limit)), with DustPy's boundary values and floors applied (as its
        ``initialize`` does)."""
        from .engine import DiskProfile

        sg = jnp.maximum(_gas.lbp_profile(self.r, self.r_c, self.m_disk), 1e-100)
        # DustPy's initialize() runs its finaliser once: gas boundary values (inner constant gradient, outer floor)
        sg = jnp.maximum(sg.at[0].set(const_grad_value(sg, self.r, self.ri)).at[-1].set(1e-100), 1e-100)
        g = self.gas_structure(sg)
        sd = _tr.mrn_initial(self.particle_size(), sg, g["P"], self.r, self.ri, g["omega"], g["cs"], self.rho_s,
                             a_max=self.a_ini_max, dist_exp=self.dist_exp, d2g=self.dust_to_gas,
                             cut=self.initial_cut)
        floor = self.floor_dust()
        sd = jnp.where(sd <= floor, 0.1 * floor, sd)
        sd = _tr.apply_dust_boundaries(sd, self.r, self.ri, floor)
        return DiskProfile(sigma_gas=sg, sigma_dust=sd)

    # ------------------------------------------------------------------ one step's coefficients
    def physics(self, sigma_gas, sigma_dust, v_rad):
        """Every coefficient of a step at the state (sigma_gas (nr,), sigma_dust (nr, nm), the lagged radial dust
        velocity v_rad (nr, nm)), as DustPy evaluates them at the start of its step. Returns a dict with the gas
        structure, St, D (nr, nm), the collision rates Rs, Rf (nr, nm, nm) [cm^2 s^-1], J_coag (nr, nm, nm)
        Picard matrices (zero in the first and last cells), hyd_A/B/C (nr, nm) transport diagonals,
        bc_in_K1/K2, bc_out_value (nm,), floor_dust (nr, nm)."""
        g = self.gas_structure(sigma_gas)
        a = self.particle_size()
        st = _tr.stokes_number(a, self.rho_s, sigma_gas, g["mfp"], convention=self.stokes)
        nr, nm = self.nr, self.nm
        floor = self.floor_dust()
        out = dict(g)
        D = _tr.dust_diffusivity(self.delta_rad, g["cs"], g["omega"], st)
        out.update(St=st, D=D, v_rad=v_rad, floor_dust=floor)
        if self.coagulation:
            from . import coagulation as _coag

            rs, rf = self.collision_rates(g, a, st, v_rad, sigma_dust, floor)
            jc = jax.vmap(lambda rs_, rf_, s_, f_: _coag.coagulation_jacobian(self.tensors, self.m, rs_, rf_, s_,
                                                                              f_))(rs, rf, sigma_dust, floor)
            interior = jnp.ones((nr,)).at[0].set(0.0).at[-1].set(0.0)
            out.update(Rs=rs, Rf=rf, J_coag=jc * interior[:, None, None])
        else:
            out["J_coag"] = jnp.zeros((nr, nm, nm))
        if self.dust_transport:
            A, B, Cc = _tr.hydro_coefficients(self.area, D, self.r, self.ri, sigma_gas, v_rad)
        else:
            A = B = Cc = jnp.zeros((nr, nm))
        K1, K2 = const_grad_row(self.r, self.ri)
        out.update(hyd_A=A, hyd_B=B, hyd_C=Cc, bc_in_K1=K1, bc_in_K2=K2, bc_out_value=0.1 * floor[-1])
        return out

    def collision_rates(self, g, a, st, v_rad, sigma_dust, floor):
        """Sticking and fragmenting collision rates Rs = K p_stick, Rf = K p_frag, each (nr, nm, nm) [cm^2 s^-1]:
        the vertically integrated kernel of DustPy's relative velocities (Brownian, Ormel & Cuzzi 2007
        turbulence, radial and azimuthal drift, settling, in quadrature) and its fragmentation probability."""
        from . import coagulation as _coag
        from . import velocities as _vel

        H = _tr.dust_scale_height(g["Hp"], st, self.delta_vert)
        vdm = _tr.drift_velocity_max(g["eta"], self.r, g["omega"])
        nr = self.nr
        # Materialise vrel once. XLA fuses the (expensive, where-branched) velocity formulae into each consumer
        # (kernel, p_frag, rs, rf) and stores a dozen (nr, nm, nm) intermediates; jax.lax.optimization_barrier
        # does not stop it on CPU (XLA removes the barrier before fusion). The pair array is therefore built in
        # a lax.map over two halves of the radial grid: the loop output must be materialised and each half is one
        # fused loop. Measured at nr = 100, nm = 120 (2 shared CPU cores): 0.02 s against 0.11-0.19 s per call.
        half = -(-nr // 2)
        cells = (g["T"], g["cs"], jnp.broadcast_to(self.mu, (nr,)), jnp.broadcast_to(self.delta_turb, (nr,)),
                 g["omega"], g["sigma_gas"], vdm, st, v_rad, H)
        cells = tuple(jnp.concatenate([x, jnp.broadcast_to(x[-1:], (2 * half - nr,) + x.shape[1:])])
                      .reshape((2, half) + x.shape[1:]) for x in cells)

        def _vrel(c):
            T_, cs_, mu_, al_, om_, sg_, vdm_, st_, v_, H_ = c
            return _vel.dv_total_dustpy(m=self.m, T=T_, cs=cs_, mu=mu_, alpha=al_, omega=om_, sigma_gas=sg_, St=st_,
                                        v_rad=v_, v_drift_max=vdm_, H=H_)

        vrel = jax.lax.map(_vrel, cells)
        vrel = vrel.reshape((2 * half,) + vrel.shape[2:])[:nr]
        K = _coag.vertical_kernel(a, H, vrel, sigma_dust, floor)
        rf = K * _coag.p_frag(vrel, self.v_frag)
        return K - rf, rf  # p_stick = 1 - p_frag (DustPy p_stick)

    def radial_velocity(self, st, sigma_gas_new, g_old):
        """DustPy's finaliser value of the radial dust velocity (nr, nm) [cm s^-1]: Stokes numbers and eta of the
        state before the step (``g_old``), gas velocity of the gas after it."""
        g_new_v = _gas.gas_velocity_visc(sigma_gas_new, g_old["nu"], self.r, self.ri)
        return _tr.dust_radial_velocity(st, g_new_v, g_old["eta"], self.r, g_old["omega"])

    def finalize_sources(self, phys, sigma_gas, sigma_dust):
        """DustPy's finaliser bookkeeping after a step to (sigma_gas, sigma_dust): the lagged radial dust velocity
        and the step-size limit min(Sigma/|S|) [s] (dust and gas; before the factor cfl) from the sources
        DustPy books there: S_coag with the collision rates of the step's start, S_hyd from the explicit fluxes
        with the new v_rad, the old D and St and the new gas, and the gas sources of the new gas.
        Returns (v_rad (nr, nm), rate [s])."""
        v_rad = self.radial_velocity(phys["St"], sigma_gas, phys)
        s = jnp.zeros_like(sigma_dust)
        if self.coagulation:
            from . import coagulation as _coag

            s = s + jax.vmap(lambda rs_, rf_, s_, f_: _coag.coagulation_source(self.tensors, self.m, rs_, rf_, s_,
                                                                               f_))(phys["Rs"], phys["Rf"], sigma_dust,
                                                                                    phys["floor_dust"])
        if self.dust_transport:
            u = jnp.sqrt(self.delta_rad) * phys["cs"]
            fa, fd = _tr.dust_fluxes(sigma_dust, v_rad, phys["D"], sigma_gas, phys["St"], u, self.r, self.ri)
            s = s + _tr.hydro_source(fa + fd, self.ri)
        rate = _tr.dust_dt(jax.lax.stop_gradient(s), jax.lax.stop_gradient(sigma_dust), phys["floor_dust"])
        if self.gas_evolution:
            sg = jax.lax.stop_gradient(sigma_gas)
            rate = jnp.minimum(rate, _gas.gas_dt(_gas.gas_source(sg, phys["nu"], self.r, self.ri), sg))
        return v_rad, jax.lax.stop_gradient(rate)

    def start(self, sigma_gas, sigma_dust):
        """(v_rad (nr, nm), step-size limit [s]) of an initial state, as DustPy's ``initialize`` books them."""
        g = self.gas_structure(sigma_gas)
        st = _tr.stokes_number(self.particle_size(), self.rho_s, sigma_gas, g["mfp"], convention=self.stokes)
        v0 = _tr.dust_radial_velocity(st, g["v_gas"], g["eta"], self.r, g["omega"])
        return self.finalize_sources(self.physics(sigma_gas, sigma_dust, v0), sigma_gas, sigma_dust)

    # ------------------------------------------------------------------ finalisers and gas step
    def dust_finalize(self, sigma_dust):
        """DustPy's dust finaliser: boundary values (inner constant gradient, outer 0.1 floor), then the floor."""
        return _tr.apply_dust_boundaries(sigma_dust, self.r, self.ri, self.floor_dust())

    def gas_step(self, sigma_gas, dt):
        """One implicit Euler step of the viscous gas. Returns (new (nr,), mass in through the inner edge [g],
        mass out through the outer edge [g])."""
        g = self.gas_structure(sigma_gas)
        new, info = _gas.gas_implicit_step(sigma_gas, g["nu"], self.r, self.ri, dt)
        return new, info.mass_in, info.mass_out

    # ------------------------------------------------------------------ diagnostics
    def size_limits(self, sigma_gas, sigma_dust):
        """(a_frag, a_drift) [cm], each (nr,): the fragmentation limit a_frag = f_f 2 Sigma_g v_frag^2 /
        (3 pi alpha rho_s c_s^2) with f_f = 0.37 and the drift limit a_drift = f_d (2/pi) (Sigma_d/rho_s)
        (v_K/c_s)^2 / |dln P/dln r| with f_d = 0.55 (Birnstiel, Klahr & Ercolano 2012, eqs. 8 and 18)."""
        g = self.gas_structure(sigma_gas)
        a_frag = 0.37 * 2.0 * sigma_gas * self.v_frag ** 2 / (3.0 * jnp.pi * self.delta_turb * self.rho_s * g["cs"] ** 2)
        lnp = jnp.log(g["P"])
        lnr = jnp.log(self.r)
        gam = jnp.gradient(lnp, lnr)
        vk = g["omega"] * self.r
        sd = jnp.sum(sigma_dust, axis=-1)
        a_drift = 0.55 * 2.0 / jnp.pi * sd / self.rho_s * (vk / g["cs"]) ** 2 / jnp.abs(gam)
        return a_frag, a_drift


def _check_scalar(name, v, *, positive=True):
    if is_traced(v):
        return jnp.asarray(v, jnp.float64)
    a = np.asarray(v, np.float64)
    if a.ndim != 0 or not np.isfinite(a) or (positive and not a > 0):
        raise JaxcoagInputError(f"dustpy_default({name}=...) must be a finite scalar{' > 0' if positive else ''}; "
                                f"got {v!r}.")
    return jnp.asarray(a)


def dustpy_default(**overrides) -> DiskModel:
    """DustPy's default disk model (Stammler & Birnstiel 2022 §3), any quantity overridable by keyword (cgs).

    Keywords (defaults in :data:`DUSTPY_DEFAULTS`): grid ``nr`` (100), ``r_min``, ``r_max`` [cm] (1, 1000 au),
    ``m_min``, ``m_max`` [g] (1e-12, 1e5), ``bins_per_decade`` (7); gas ``alpha`` (1e-3), ``delta_rad``,
    ``delta_turb``, ``delta_vert`` (default alpha), ``m_disk`` [g] (0.05 Msun), ``r_c`` [cm] (60 au), ``mu`` [g]
    (2.3 m_p); dust ``v_frag`` [cm s^-1] (100), ``rho_s`` [g cm^-3] (1.67), ``dust_to_gas`` (0.01), ``a_ini_max``
    [cm] (1e-4), ``dist_exp`` (-3.5), ``erosion_mass_ratio`` (10), ``excavated_mass`` (1), ``fragment_slope``
    (-11/6); star ``m_star`` [g] (1 Msun), ``r_star`` [cm] (2 Rsun), ``t_star`` [K] (5772); structure
    ``stokes`` ("dustpy" | "jaxcoag"), ``coagulation``, ``dust_transport``, ``gas_evolution`` (bool),
    ``initial_cut`` ("hard" | "smooth"). DustPy's constants (:data:`jaxcoag.disk.gas.DUSTPY_CONSTANTS`) set
    the au, Msun, Rsun and m_p of the defaults.

    Parameters may be traced (inside jit/vmap/grad); grid sizes and structure may not.

    References: Stammler & Birnstiel (2022) §3; Lynden-Bell & Pringle (1974).
    """
    require_x64("jaxcoag.disk.dustpy_default")
    unknown = sorted(set(overrides) - set(DUSTPY_DEFAULTS))
    if unknown:
        import difflib

        hint = "".join(f" Did you mean {difflib.get_close_matches(u, DUSTPY_DEFAULTS, 1)[0]!r} for {u!r}?"
                       for u in unknown if difflib.get_close_matches(u, DUSTPY_DEFAULTS, 1))
        raise JaxcoagInputError(f"dustpy_default got unknown keyword(s) {unknown}; allowed: "
                                f"{sorted(DUSTPY_DEFAULTS)}.{hint}")
    p = dict(DUSTPY_DEFAULTS)
    p.update(overrides)
    for k in ("delta_rad", "delta_turb", "delta_vert"):
        if p[k] is None:
            p[k] = p["alpha"]
    for k in ("coagulation", "dust_transport", "gas_evolution"):
        if not isinstance(p[k], (bool, np.bool_)):
            raise JaxcoagInputError(f"dustpy_default({k}=...) must be True or False (structure); got {p[k]!r}.")
    if p["stokes"] not in ("dustpy", "jaxcoag"):
        raise JaxcoagInputError(f"dustpy_default(stokes=...) must be 'dustpy' or 'jaxcoag'; got {p['stokes']!r}.")
    if p["initial_cut"] not in ("hard", "smooth"):
        raise JaxcoagInputError(f"dustpy_default(initial_cut=...) must be 'hard' or 'smooth'; got "
                                f"{p['initial_cut']!r}.")
    nr = p["nr"]
    if isinstance(nr, bool) or not isinstance(nr, (int, np.integer)) or nr < 5:
        raise JaxcoagInputError(f"dustpy_default(nr=...) must be an int >= 5 (DustPy's boundary rows use three "
                                f"cells at each end); got {nr!r}.")
    for k in ("r_min", "r_max", "m_min", "m_max"):
        if is_traced(p[k]):
            raise JaxcoagInputError(f"dustpy_default({k}=...) sets the grid (structure) and cannot be traced.")
    grid = radial_grid(p["r_min"], p["r_max"], nr)
    m = mass_grid(p["m_min"], p["m_max"], p["bins_per_decade"])
    nm = m.size
    # the largest arrays of a step: (nr, nm, nm) kernel, probabilities and Picard matrices (a few copies)
    need = 8.0 * nr * nm * nm * 8
    limit = 8.0 * 2 ** 30
    if need > limit:
        raise JaxcoagInputError(f"nr = {nr} cells x nm = {nm} mass bins needs about {need / 2**30:.1f} GiB per step "
                                f"(8 (nr, nm, nm) float64 arrays); reduce nr or bins_per_decade, or widen the "
                                f"steps of the mass grid.")
    for k in ("erosion_mass_ratio", "excavated_mass"):
        _check_scalar(k, p[k])
    tensors = None
    if p["coagulation"]:
        from . import coagulation as _coag

        tensors = _coag.coagulation_tensors(m, erosion_mass_ratio=float(p["erosion_mass_ratio"]),
                                            excavated_mass=float(p["excavated_mass"]),
                                            fragment_slope=float(p["fragment_slope"]))
    leaves = {k: _check_scalar(k, p[k]) for k in _PARAMS}
    if not is_traced(p["dist_exp"]) and not math.isfinite(float(p["dist_exp"])):
        raise JaxcoagInputError(f"dustpy_default(dist_exp=...) must be finite; got {p['dist_exp']!r}.")
    return DiskModel(ri=jnp.asarray(grid.ri), r=jnp.asarray(grid.r), area=jnp.asarray(grid.area), m=jnp.asarray(m),
                     tensors=tensors, dist_exp=float(p["dist_exp"]), stokes=p["stokes"],
                     coagulation=bool(p["coagulation"]), dust_transport=bool(p["dust_transport"]),
                     gas_evolution=bool(p["gas_evolution"]), initial_cut=p["initial_cut"], **leaves)
