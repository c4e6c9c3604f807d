"""Bridge from monomer-contact collisions to the coagulation engines: a measured collision table as an outcome.

A sweep of aggregate collisions (:func:`sweep_collisions`, run with :func:`~jaxcoag.aggregates.contact.collision.collide`)
is summarised in a :class:`CollisionTable`: per aggregate size and impact speed, the impact energy E_imp and its
scaled forms x_roll = E_imp/(n_k E_roll) and x_break = E_imp/(n_k E_break) (n_k = N_total - 2 contacts of two
BCCAs before the impact), the mass fraction N_large/N_total of the largest remnant, the change of its gyration
radius relative to the unrestructured merger, the contact number n_con and the second-largest cluster.

:func:`outcome_from_collisions` turns the table into a collision outcome of both coagulation engines
(:class:`CollisionOutcome`, a :class:`jaxcoag.outcomes.RecipeOutcome` of the table recipe
:class:`CollisionRecipe`): a pair of masses m_1, m_2 [g] colliding at the engine's relative velocity dv
[cm s^-1] has E_imp = (1/2) mu dv^2 (mu the reduced mass) and x_break = E_imp/(n_k E_break) with
N_total = (m_1 + m_2)/m_1,mono; the table is interpolated linearly in ln x_break (which preserves the
monotonicity of the data: no overshoot) and linearly in ln N_total between the tabulated sizes. Outside the
table the nearest end is used, in energy and in size.

References: Wada, Tanaka, Suyama, Kimura & Yamamoto (2007, ApJ 661, 320) §4-5 (collision set-up, eqs. 44-45,
50-59, Figs. 7, 11, 14); Ormel (2008) thesis §6.5 (tabulated recipes in coagulation, eqs. 6.25-6.30).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._validate import JaxcoagInputError, is_traced
from ...outcomes import AbstractRecipe, Products, RecipeOutcome, Sticking
from ...physics import contact as pcontact
from ...physics.outcome import Outcome
from ...physics.porosity import _reduced_mass, psi_mass_average
from ...physics.safe import safe_sqrt

__all__ = ["CollisionTable", "CollisionRecipe", "CollisionOutcome", "sweep_collisions", "outcome_from_collisions",
           "n_contacts_before"]


# ---------------------------------------------------------------------------------------------
def n_contacts_before(n_total):
    """Contacts of two colliding BCCAs before the impact, n_k = max(N_total - 2, 1) [-].

    Two trees of N_1 and N_2 monomers hold N_1 - 1 + N_2 - 1 = N_total - 2 contacts (Wada et al. 2007 §5.1);
    the floor 1 [CHOICE] keeps x = E_imp/(n_k E) finite for a pair of single monomers (one new contact).

    Arguments: n_total: monomers in both aggregates [-] (> 0).
    Returns: n_k [-].
    References: Wada et al. (2007) §5.1 (n_k = N_total - 2 for BCCA pairs).
    """
    return jnp.maximum(jnp.asarray(n_total, jnp.float64) - 2.0, 1.0)


def _material_constants(material):
    """(m1 [g], r1 [cm], E_roll [erg], E_break [erg]) of a contact or a physics Material (Wada conventions)."""
    from .materials import Material as ContactMaterial

    if isinstance(material, ContactMaterial):
        return material.m1, material.r1, material.E_roll, material.E_break
    if isinstance(material, pcontact.Material):
        return material.m0, material.a0, material.e_roll(), material.e_break()
    raise JaxcoagInputError("material must be a contact material (jaxcoag.aggregates.contact.ice(), quartz(), "
                            f"material(...)) or a jaxcoag.physics.contact.Material; got {type(material).__name__}.")


def _physics_material(material):
    """The :class:`jaxcoag.physics.contact.Material` the coagulation outcomes take (m0, E_roll, E_break), built from
    a contact material with Wada's conventions (rolling energy eq. 44, JKR breaking energy eq. 45)."""
    from .materials import Material as ContactMaterial

    if isinstance(material, pcontact.Material):
        return material
    if isinstance(material, ContactMaterial):
        return pcontact.Material(a0=material.r1, rho_s=material.rho, gamma=material.gamma, E_star=material.E_star,
                                 xi_crit=material.xi_crit, A_br=pcontact.A_BR_WADA, roll="Wada")
    _material_constants(material)  # raises with the message
    raise AssertionError


def _arr(x, name, shape=None, *, positive=False, unit="", allow_nan=False):
    a = np.asarray(x, np.float64)
    if shape is not None and a.shape != shape:
        raise JaxcoagInputError(f"CollisionTable.{name} must have shape {shape} ({unit}); got {a.shape}.")
    if not np.all(np.isfinite(a) | (allow_nan & np.isnan(a))):
        raise JaxcoagInputError(f"CollisionTable.{name} must be finite ({unit}).")
    if positive and not np.all(a > 0):
        raise JaxcoagInputError(f"CollisionTable.{name} must be > 0 ({unit}).")
    return a


class CollisionTable(eqx.Module):
    """Measured results of a sweep of aggregate collisions (S sizes x V impact speeds, averaged over structures).

    Fields (float64 arrays; rows = sizes, columns = impact energies, increasing along each row):
        n_total: (S,) monomers in both aggregates N_total [-], strictly increasing.
        e_imp: (S, V) impact energy in the centre-of-mass frame E_imp [erg] (Wada et al. 2007 §5.1:
            E_imp = N_total m_1 v_imp^2 / 8 for two halves at relative speed v_imp).
        x_roll: (S, V) E_imp/(n_k E_roll) [-].
        x_break: (S, V) E_imp/(n_k E_break) [-] (n_k = :func:`n_contacts_before`).
        f_large: (S, V) N_large/N_total, mass fraction of the largest remnant [-] in (0, 1].
        rg_ratio: (S, V) r_g of the largest remnant over r_g of the unrestructured merger (both aggregates
            stuck at the first contact) [-]; < 1 is compaction (0 when the largest remnant is a single monomer).
        n_con: (S, V) contacts per monomer of the largest remnant [-] (Wada's n_con; NaN = not measured).
        f_second: (S, V) N_second/N_total, the second-largest cluster [-] (0 without fragments).
        e_roll, e_break: the material's E_roll (Wada eq. 44) and E_break (eq. 45) [erg].
        m1: monomer mass [g]. r1: monomer radius [cm].
        v_imp: (V,) relative impact speeds [cm s^-1] of a sweep (NaN for a hand-built table).
        n_runs: (S, V) collisions averaged in each entry (failed runs are left out).
        r_g: (S, V) gyration radius of the largest remnant [cm] (Wada eq. 50; NaN = not measured).

    Build one with :func:`sweep_collisions` (measured) or :meth:`from_measurements` (any numbers).

    References: Wada et al. (2007) §5 (x_roll, x_break, N_large/N_total, r_g, n_con: Figs. 7, 11, 14).
    """

    n_total: jax.Array
    e_imp: jax.Array
    x_roll: jax.Array
    x_break: jax.Array
    f_large: jax.Array
    rg_ratio: jax.Array
    n_con: jax.Array
    f_second: jax.Array
    e_roll: jax.Array
    e_break: jax.Array
    m1: jax.Array
    r1: jax.Array
    v_imp: jax.Array
    n_runs: jax.Array
    r_g: jax.Array

    def __check_init__(self):
        if is_traced((self.n_total, self.e_imp, self.f_large)):
            return
        n = _arr(self.n_total, "n_total", positive=True, unit="monomers")
        if n.ndim != 1 or n.size < 1 or np.any(np.diff(n) <= 0):
            raise JaxcoagInputError("CollisionTable.n_total must be a 1-D strictly increasing array of monomer numbers "
                                    "(one row per aggregate size); sort the rows by size.")
        S = n.size
        e = _arr(self.e_imp, "e_imp", positive=True, unit="erg")
        if e.ndim != 2 or e.shape[0] != S or e.shape[1] < 1:
            raise JaxcoagInputError(f"CollisionTable.e_imp must have shape (S, V) = ({S}, V >= 1) [erg]; got {e.shape}.")
        if np.any(np.diff(e, axis=1) <= 0):
            raise JaxcoagInputError("CollisionTable.e_imp must increase strictly along each row (impact energies of "
                                    "one size, sorted); sort the columns by impact speed.")
        shp = e.shape
        f = _arr(self.f_large, "f_large", shp, unit="N_large/N_total")
        if np.any(f <= 0) or np.any(f > 1.0 + 1e-12):
            raise JaxcoagInputError("CollisionTable.f_large = N_large/N_total must lie in (0, 1].")
        if np.any(_arr(self.rg_ratio, "rg_ratio", shp, unit="r_g after / r_g of the merger") < 0):
            raise JaxcoagInputError("CollisionTable.rg_ratio must be >= 0 (0: the largest remnant is one monomer).")
        _arr(self.x_roll, "x_roll", shp, positive=True, unit="E_imp/(n_k E_roll)")
        _arr(self.x_break, "x_break", shp, positive=True, unit="E_imp/(n_k E_break)")
        _arr(self.n_con, "n_con", shp, unit="contacts per monomer; NaN = not measured", allow_nan=True)
        _arr(self.r_g, "r_g", shp, unit="cm; NaN = not measured", allow_nan=True)
        s = _arr(self.f_second, "f_second", shp, unit="N_second/N_total")
        if np.any(s < 0) or np.any(s > f + 1e-12):
            raise JaxcoagInputError("CollisionTable.f_second must lie in [0, f_large] (the second-largest cluster).")
        for name in ("e_roll", "e_break", "m1", "r1"):
            _arr(getattr(self, name), name, (), positive=True, unit="cgs")

    @property
    def shape(self) -> tuple[int, int]:
        """(S sizes, V impact energies)."""
        return tuple(np.shape(self.e_imp))

    @classmethod
    def from_measurements(cls, n_total, e_imp, f_large, rg_ratio, material, *, n_con=None, f_second=None,
                          v_imp=None, n_runs=None) -> "CollisionTable":
        """A table from measured (or hand-chosen) numbers; x_roll and x_break follow from ``material``.

        Arguments:
            n_total: (S,) monomers per collision [-]. e_imp: (S, V) or (V,) impact energies [erg] (a 1-D array is
                used for every size). f_large: (S, V) N_large/N_total [-]. rg_ratio: (S, V) r_g change [-].
            material: the contact material (:func:`~jaxcoag.aggregates.contact.materials.ice`, ...) or a
                :class:`jaxcoag.physics.contact.Material` with Wada's conventions (``wada_ice()``); gives m_1,
                r_1, E_roll and E_break.
            n_con: (S, V) contacts per monomer (default NaN: not measured). f_second: (S, V) second-largest
                cluster fraction (default 0). v_imp: (V,) speeds [cm s^-1] (default NaN). n_runs: (S, V) counts
                (default 1).
        Returns: :class:`CollisionTable`.
        References: Wada et al. (2007) §5.1 (x_roll, x_break with n_k = N_total - 2).
        """
        m1, r1, e_roll, e_break = _material_constants(material)
        n = jnp.atleast_1d(jnp.asarray(n_total, jnp.float64))
        e = jnp.asarray(e_imp, jnp.float64)
        if e.ndim == 1:
            e = jnp.broadcast_to(e[None, :], (n.shape[0], e.shape[0]))
        shp = e.shape
        full = lambda v, d: jnp.full(shp, d, jnp.float64) if v is None else jnp.broadcast_to(
            jnp.asarray(v, jnp.float64), shp)
        nk = n_contacts_before(n)[:, None]
        return cls(n_total=n, e_imp=e, x_roll=e / (nk * e_roll), x_break=e / (nk * e_break),
                   f_large=full(f_large, 1.0), rg_ratio=full(rg_ratio, 1.0), n_con=full(n_con, jnp.nan),
                   f_second=full(f_second, 0.0), e_roll=jnp.asarray(e_roll, jnp.float64),
                   e_break=jnp.asarray(e_break, jnp.float64), m1=jnp.asarray(m1, jnp.float64),
                   r1=jnp.asarray(r1, jnp.float64),
                   v_imp=jnp.full((shp[1],), jnp.nan) if v_imp is None else jnp.asarray(v_imp, jnp.float64),
                   n_runs=full(n_runs, 1.0), r_g=jnp.full(shp, jnp.nan))


# ---------------------------------------------------------------------------------------------
def _interp_table(log_n_tab, log_x_tab, values, log_n, log_x):
    """Tabulated ``values`` (S, V) at (ln N_total, ln x_break) of any common shape: linear in ln x along each size
    (clamped to the nearest end), then linear in ln N between sizes (clamped)."""
    rows = jax.vmap(lambda xp, fp: jnp.interp(log_x, xp, fp))(log_x_tab, values)  # (S, *shape)
    S = log_n_tab.shape[0]
    if S == 1:
        return rows[0]
    ln = jnp.clip(log_n, log_n_tab[0], log_n_tab[-1])
    i = jnp.clip(jnp.searchsorted(log_n_tab, ln, side="right") - 1, 0, S - 2)
    t = (ln - log_n_tab[i]) / (log_n_tab[i + 1] - log_n_tab[i])
    lo = jnp.take_along_axis(rows, i[None, ...], axis=0)[0]
    hi = jnp.take_along_axis(rows, (i + 1)[None, ...], axis=0)[0]
    return lo + t * (hi - lo)


def _x_break(m_mono, e_break, m1, m2, dv):
    e_imp = 0.5 * _reduced_mass(m1, m2) * dv**2
    return e_imp / (n_contacts_before((m1 + m2) / m_mono) * e_break)


@jax.jit
def _lookup(log_n, log_x, f_large, rg_ratio, f_second, m_mono, e_break, m1, m2, dv):
    """(f_large, rg_ratio, f_second, x_break) at the pairs (m1, m2, dv) (one compiled program: the binned engine
    evaluates the recipe eagerly, where op-by-op dispatch would compile every primitive separately)."""
    x = _x_break(m_mono, e_break, m1, m2, dv)
    lx = jnp.log(jnp.maximum(x, 1e-300))
    ln = jnp.log((m1 + m2) / m_mono)
    lx, ln = jnp.broadcast_arrays(lx, ln)
    f = lambda v: _interp_table(log_n, log_x, v, ln, lx)  # noqa: E731
    return f(f_large), f(rg_ratio), f(f_second), x


class CollisionRecipe(AbstractRecipe):
    """Collision recipe interpolated from a :class:`CollisionTable` (shared-physics recipe of
    :class:`jaxcoag.outcomes.RecipeOutcome`).

    For a pair m_1, m_2 [g] at relative velocity dv [cm s^-1]: E_imp = (1/2) mu dv^2, N_total = (m_1 + m_2)/m_mono,
    x_break = E_imp/(n_k E_break) with n_k = :func:`n_contacts_before` (N_total); from the table (linear in
    ln x_break, then in ln N_total, nearest end outside): f_large (with the monomer granularity of
    :meth:`mass_fraction`), the r_g change c and f_second. The
    :class:`~jaxcoag.physics.outcome.Outcome`: one remnant of mass f_large M_tot with enlargement factor
    psi = max(1, <psi>_m c^psi_exponent) (<psi>_m the mass-weighted psi of the pair, i.e. hit-and-stick, times the
    measured volume change at fixed mass [CHOICE: volume ∝ r_g^3 for a 3-D aggregate; the paper's aggregates are
    2-D]) and (1 - f_large) M_tot in fragments dn/dm ∝ m^q on [m_mono, max(m_mono, f_second M_tot)] (the measured
    second-largest cluster bounds the fragments; q [CHOICE], default -11/6). ``weight`` is 0 (pure sticking, the
    engines' coagulation path) where the table gives f_large = 1 and c = 1, else 1.

    Fields: log_n (S,) ln N_total; log_x (S, V) ln x_break; f_large, rg_ratio, f_second (S, V) (as processed by
    :func:`outcome_from_collisions`); m_mono [g]; e_break [erg]; q [-]; psi_exponent [-]. Float leaves (gradients
    flow to the table and the material's E_break).

    References: Wada et al. (2007) §5 eqs. 44-45, Figs. 7, 14; Ormel (2008) thesis eqs. 2.14 (mass-weighted psi),
    6.29-6.30 (fragments).
    """

    log_n: jax.Array
    log_x: jax.Array
    f_large: jax.Array
    rg_ratio: jax.Array
    f_second: jax.Array
    m_mono: jax.Array
    e_break: jax.Array
    q: jax.Array
    psi_exponent: jax.Array

    needs_velocity: ClassVar[bool] = True

    @property
    def two_remnants(self) -> bool:
        return False

    def x_break(self, m1, m2, dv):
        """E_imp/(n_k E_break) [-] of a pair m1, m2 [g] at relative velocity dv [cm s^-1] (E_imp = mu dv^2/2)."""
        return _x_break(self.m_mono, self.e_break, *(jnp.asarray(v, jnp.float64) for v in (m1, m2, dv)))

    def lookup(self, m1, m2, dv):
        """(f_large, rg_ratio, f_second, x_break) of the pair, interpolated from the table (class docstring)."""
        return _lookup(self.log_n, self.log_x, self.f_large, self.rg_ratio, self.f_second, self.m_mono,
                       self.e_break, *(jnp.asarray(v, jnp.float64) for v in (m1, m2, dv)))

    def mass_fraction(self, m1, m2, dv):
        """(f_large, r_g change) of the pair with the monomer granularity [CHOICE]: the largest remnant keeps at least
        one monomer (f_large >= m_mono/M_tot: two monomers that bounce leave two monomers, not 0.9 of one), and a
        fragment mass below one monomer sticks instead ((1 - f_large) M_tot < m_mono -> f_large = 1)."""
        fL, c, _, _ = self.lookup(m1, m2, dv)
        m_tot = jnp.asarray(m1 + m2, jnp.float64)
        fL = jnp.clip(fL, jnp.minimum(self.m_mono / m_tot, 1.0), 1.0)
        fL = jnp.where((1.0 - fL) * m_tot < self.m_mono * (1.0 - 1e-9), 1.0, fL)
        return fL, c

    def __call__(self, m1, psi1, m2, psi2, dv, material=None, width=0.0) -> Outcome:
        _, _, fs, x = self.lookup(m1, m2, dv)
        fL, c = self.mass_fraction(m1, m2, dv)
        psi_st = psi_mass_average(m1, psi1, m2, psi2)
        psi = jnp.maximum(psi_st * c ** self.psi_exponent, 1.0)
        m_tot = m1 + m2
        m_hi = jnp.maximum(self.m_mono, fs * m_tot)
        return Outcome.build(f_pwl=1.0 - fL, q=self.q, m_lo=self.m_mono, m_hi=m_hi, psi_one=psi,
                             aux=dict(x_break=x, rg_ratio=c))

    def weight(self, m1, psi1, m2, psi2, dv, material=None, width=0.0):
        """0 where the table says pure sticking (f_large = 1 and r_g change 1), else 1 [-]."""
        fL, c = self.mass_fraction(m1, m2, dv)
        return jnp.where((fL >= 1.0) & (c == 1.0), 0.0, 1.0)


def _pad_products(p: Products, n: int) -> Products:
    k = n - p.m.shape[0]
    pad = lambda a, v: jnp.concatenate([a, jnp.full((k,) + a.shape[1:], v, a.dtype)], axis=0)
    return Products(m=pad(p.m, 1.0), logm=pad(p.logm, 0.0), psi=pad(p.psi, 1.0), count=pad(p.count, 0.0),
                    valid=pad(p.valid, False))


class CollisionOutcome(RecipeOutcome):
    """Collision outcome of both engines from a measured :class:`CollisionTable` (:func:`outcome_from_collisions`).

    A :class:`jaxcoag.outcomes.RecipeOutcome` of the :class:`CollisionRecipe`, so the binned redistribution and the
    Monte Carlo products (remnant compounding for group events, mass-exact fragment draws) are the shared ones:

    * binned engine (compact particles, psi = 1): the pair's fragment fraction 1 - f_large goes to fragments
      dn/dm ∝ m^q on [m_mono, f_second M_tot]; the r_g change is NOT used (the binned engine tracks no porosity);
    * Monte Carlo engine: the same masses; the r_g change sets the remnant's enlargement factor where the kernel
      tracks one (structure column ``index``); compact runs (no structure column) do not use it.

    Where the table says pure sticking (below the table when its lowest row has f_large = 1 and no r_g change),
    the products are exactly those of :class:`jaxcoag.outcomes.Sticking` (also for Monte Carlo group events) and
    the binned engine uses its coagulation tensors.

    References: Wada et al. (2007) §5; Ormel (2008) thesis §6.5, App. 5.B step 5.
    """

    def products(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key) -> Products:
        """Recipe products, replaced by the :class:`~jaxcoag.outcomes.Sticking` products in the pure-sticking regime."""
        pr = super().products(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key)
        st = _pad_products(Sticking().products(m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key),
                           self.n_products)
        dv = safe_sqrt(self.kernel.relative_velocity2(m_i, m_j, psi_i, psi_j))
        stick = self.recipe.weight(m_i, 1.0, m_j, 1.0, dv) == 0.0
        pick = lambda a, b: jnp.where(stick.reshape((1,) * a.ndim) if a.ndim else stick, a, b)
        return Products(*(pick(a, b) for a, b in zip(st, pr)))


def sweep_collisions(sizes, v_imps, material, key, n_structures: int = 3, *, dim: int = 2, copy: bool = True,
                     dt=None, t_end=None, quiet_steps: int = 10_000, workers=None, **collide_kwargs) -> CollisionTable:
    """Run head-on collisions of BCCA pairs over sizes x impact speeds and tabulate their outcomes.

    For every size n (monomers per aggregate, a power of 2) and structure k < ``n_structures`` a BCCA is built
    (:func:`~jaxcoag.aggregates.contact.structures.bcca`); it collides with a copy of itself (``copy=True``, the
    default of Wada et al. 2007 §4: "the same BCCA", both copies independently rotated by ``collide``'s key) or
    with an independent BCCA (``copy=False``) at every speed of ``v_imps``. The collisions run one after another
    (``collide`` runs until the outcome settles, a run length that depends on the speed, so a vmap over speeds
    would run every lane to the slowest one), ``workers`` of them at a time in host threads: a collision's step
    loop is sequential and keeps one core busy, so ``workers=os.cpu_count()`` uses the machine. The table does not
    depend on ``workers`` (every collision has its own key; the averages are summed in one fixed order). Runs
    whose status is a failure are left out of the averages.

    Arguments:
        sizes: monomers per aggregate (ints, powers of 2, >= 2); N_total = 2 n.
        v_imps: relative impact speeds [cm s^-1] (> 0), increasing.
        material: contact material (:func:`~jaxcoag.aggregates.contact.materials.ice`, ...).
        key: ``jax.random`` key (structures and rotations).
        n_structures: structures per size (default 3, as in the paper).
        dim: 2 (planar, the paper) or 3.
        copy: collide each BCCA with a rotated copy of itself (True) or with an independent one.
        dt: time step [s] (None: 0.014 t_c; sweeps may use up to 0.112 t_c, Wada et al. §4).
        t_end, quiet_steps, collide_kwargs: passed to ``collide``.
        workers: collisions run at once in host threads (default None = 1, one after another). ``checkpoint``
            and ``progress`` (collide_kwargs) are refused with workers > 1 (one file and one bar per collision).

    Returns:
        :class:`CollisionTable` (rows: sizes, columns: speeds; structure averages).

    References: Wada et al. (2007) §4-5 (BCCA pairs, 3 structures per size; N_large, r_g, n_con).
    """
    from .collision import collide
    from .structures import bcca

    sizes = [int(n) for n in np.atleast_1d(sizes)]
    v = np.asarray(v_imps, np.float64).ravel()
    if not sizes or any(n < 2 for n in sizes) or any(np.diff(sizes) <= 0):
        raise JaxcoagInputError(f"sizes must be increasing monomer numbers per aggregate (powers of 2, >= 2); "
                                f"got {sizes}.")
    if v.size < 1 or not np.all(np.isfinite(v) & (v > 0)) or np.any(np.diff(v) <= 0):
        raise JaxcoagInputError("v_imps must be increasing impact speeds > 0 in cm/s.")
    if isinstance(n_structures, bool) or not isinstance(n_structures, (int, np.integer)) or n_structures < 1:
        raise JaxcoagInputError(f"n_structures must be an int >= 1; got {n_structures!r}.")
    from ..._status import is_failure

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise JaxcoagInputError(f"workers must be a positive int (host threads) or None; got {workers!r}.")
    workers = 1 if workers is None else int(workers)
    if workers > 1 and (collide_kwargs.get("checkpoint") is not None or collide_kwargs.get("progress")):
        raise JaxcoagInputError("checkpoint= and progress= name one file and one bar per collide call; give them "
                                "with workers=1 only.")

    S, V = len(sizes), v.size
    tasks = []   # (size index, speed index, a, b, speed, key), in the order of the sums below
    for i, n in enumerate(sizes):
        for k in range(n_structures):
            kk = jax.random.fold_in(jax.random.fold_in(key, i), k)
            ka, kb, kr = jax.random.split(kk, 3)
            a = bcca(n, ka, dim, material=material)
            b = a if copy else bcca(n, kb, dim, material=material)
            tasks.extend((i, j, a, b, float(vj), jax.random.fold_in(kr, j)) for j, vj in enumerate(v))

    def run(task):
        _, _, a, b, vj, kj = task
        return collide(a, b, vj, material, key=kj, dt=dt, t_end=t_end, quiet_steps=quiet_steps, throw=False,
                       **collide_kwargs)

    if workers == 1:
        results = map(run, tasks)
    else:
        from concurrent.futures import ThreadPoolExecutor
        ex = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="jaxcoag-collide")
        try:
            results = [f.result() for f in [ex.submit(run, t) for t in tasks]]
        finally:   # Ctrl-C or a failed collision: the collisions not yet started are dropped
            ex.shutdown(wait=True, cancel_futures=True)
    acc = {k: np.zeros((S, V)) for k in ("f_large", "rg_ratio", "n_con", "f_second", "r_g", "n")}
    for (i, j, *_), res in zip(tasks, results):
        if bool(is_failure(res.status)):
            continue
        cs = np.asarray(res.cluster_sizes, np.float64)
        nt = float(2 * sizes[i])
        acc["f_large"][i, j] += cs[0] / nt
        acc["f_second"][i, j] += (cs[1] if cs.size > 1 else 0.0) / nt
        acc["rg_ratio"][i, j] += float(res.r_g) / float(res.final_state.r_g0)
        acc["n_con"][i, j] += float(res.n_contacts)
        acc["r_g"][i, j] += float(res.r_g)
        acc["n"][i, j] += 1.0
    cnt = acc["n"]
    if np.any(cnt == 0):
        raise JaxcoagInputError("sweep_collisions: every structure failed for some (size, speed); check dt, the "
                                "capacities and max_steps (collide(..., throw=True) shows the failure).")
    mean = {k: acc[k] / cnt for k in acc if k != "n"}
    n_total = 2.0 * np.asarray(sizes, np.float64)
    m1 = float(_material_constants(material)[0])
    e_imp = n_total[:, None] * m1 * v[None, :] ** 2 / 8.0   # (1/2) mu v^2 with mu = N_total m1 / 4
    tab = CollisionTable.from_measurements(n_total, e_imp, mean["f_large"], mean["rg_ratio"], material,
                                           n_con=mean["n_con"], f_second=mean["f_second"], v_imp=v, n_runs=cnt)
    return eqx.tree_at(lambda t: t.r_g, tab, jnp.asarray(mean["r_g"]))


def outcome_from_collisions(table: CollisionTable, material, *, q=-11.0 / 6.0, psi_exponent=3.0,
                            monotone: bool = True, n_frag: int = 4, index: int = 0, c_f=1.0) -> CollisionOutcome:
    """A collision outcome of the binned and Monte Carlo engines from a measured collision table.

    Pass the result as ``jaxcoag.evolve(kernel, engine, initial, t_out, outcome=...)``; the kernel must provide
    relative velocities (``relative_velocity2``), which set each pair's impact energy.

    Arguments:
        table: :class:`CollisionTable` (from :func:`sweep_collisions` or :meth:`CollisionTable.from_measurements`).
        material: the material the table was measured for (contact material or
            :class:`jaxcoag.physics.contact.Material`); its monomer mass and E_break must match the table's.
        q: number slope of the fragments, dn/dm ∝ m^q [-] ([CHOICE] -11/6, Dohnanyi; the paper measures no
            fragment distribution).
        psi_exponent: exponent of the r_g change in the remnant's volume [-] (3: V ∝ r_g^3 at fixed mass).
        monotone: static; True replaces f_large by its running minimum along increasing energy (more impact energy
            never leaves a larger remnant: Wada et al. 2007 Fig. 14; removes the scatter of few structures),
            False uses the measured values.
        n_frag: Monte Carlo fragment product species (static int >= 1).
        index: position of psi in the Monte Carlo structure vector (static).
        c_f: prefactor of the fragments' psi(N) law (Monte Carlo porosity runs).

    Returns: :class:`CollisionOutcome`.

    Outside the table the nearest end is used: below the lowest energy the lowest row (pure sticking when that
    row has f_large = 1 and rg_ratio = 1), above the highest the highest row; sizes outside the tabulated range
    take the nearest size.

    References: Wada et al. (2007) §5 (eqs. 44-45, Figs. 7, 11, 14); Ormel (2008) thesis §6.5.
    """
    if not isinstance(table, CollisionTable):
        raise JaxcoagInputError(f"table must be a CollisionTable (from sweep_collisions); got {type(table).__name__}.")
    pmat = _physics_material(material)
    m1, _, _, e_break = _material_constants(material)
    if not is_traced((m1, e_break, table.m1, table.e_break)):
        for name, a, b in (("monomer mass", m1, table.m1), ("E_break", e_break, table.e_break)):
            if not np.isclose(float(a), float(b), rtol=1e-9, atol=0.0):
                raise JaxcoagInputError(f"the material's {name} ({float(a):.6g}) differs from the table's "
                                        f"({float(b):.6g}): pass the material the collisions were run with.")
    if isinstance(n_frag, bool) or not isinstance(n_frag, (int, np.integer)) or n_frag < 1:
        raise JaxcoagInputError(f"n_frag must be an int >= 1 (Monte Carlo fragment species); got {n_frag!r}.")
    f_large = jnp.asarray(table.f_large, jnp.float64)
    if monotone:
        f_large = jax.lax.cummin(f_large, axis=1)
    f_second = jnp.minimum(jnp.asarray(table.f_second, jnp.float64), f_large)
    recipe = CollisionRecipe(log_n=jnp.log(table.n_total), log_x=jnp.log(table.x_break), f_large=f_large,
                             rg_ratio=jnp.asarray(table.rg_ratio, jnp.float64), f_second=f_second,
                             m_mono=jnp.asarray(table.m1, jnp.float64), e_break=jnp.asarray(table.e_break, jnp.float64),
                             q=jnp.asarray(q, jnp.float64), psi_exponent=jnp.asarray(psi_exponent, jnp.float64))
    return CollisionOutcome(recipe, pmat, remnants=1, n_frag=int(n_frag), index=index, c_f=c_f)
