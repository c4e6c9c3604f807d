"""Monte Carlo adapter of the shared physics :class:`~jaxcoag.physics.outcomes.Outcome`, and rain-out.

:class:`RecipeOutcome` plugs any collision recipe that returns the shared ``Outcome`` (thesis
ch. 2 O07 by default) into the grouped Monte Carlo engine with the enlargement factor psi as
structural parameter: for the colliding pair it evaluates Delta v from the kernel's own
``relative_velocity2(m_i, m_j, x_i, x_j)``, calls the recipe, draws one or two large remnants
(probability ``p_two``), draws power-law fragments (mass-exact, into ``n_frag`` product
species) and returns :class:`~jaxcoag.mc.Products` that conserve mass exactly.

:class:`RainOutKernel` is the chapter-2 settling sink [T2.25]: a particle whose friction time
exceeds tau_rain = alpha/Omega has left the turbulent layer; the wrapped kernel is zero for
every pair that involves it, so it never collides again, while it stays in the state (with
its mass, psi and multiplicity) so that the rain-out population can be measured afterwards
with :func:`rainout_summary` (rained mass vs time, t_rain, t_99%, <a>, <m>, <psi>, a/a*).

References: Ormel (2008) thesis ch. 2 (§2.2.3 recipe, §2.4 eq. 2.25 rain-out, Tab. 2.2),
§5.2.2 and App. 5.B step 5 (group events), eqs. 6.27-6.30 (fragments, at most one breakage
per group event); collision-outcome interface and errata in docs/design_notes.md.
"""

from __future__ import annotations

import functools
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from .._validate import JaxcoagInputError, check
from ..kernels import AbstractKernel
from ..physics.contact import Material
from ..physics.outcomes import Outcome, o07_outcome, psi_fragment, sample_fragment_masses
from ..physics.safe import safe_sqrt
from .outcomes import AbstractOutcome, Products

__all__ = ["RecipeOutcome", "o07_recipe", "RainOutKernel", "rainout_summary"]


def o07_recipe(*, n_small=None, **kw) -> Callable:
    """The thesis ch. 2 recipe O07 as ``recipe(m1, psi1, m2, psi2, dv, material) -> Outcome``.

    Keyword arguments are passed to :func:`jaxcoag.physics.outcomes.o07_outcome` (delta = 0.95,
    B = 1, mF_over_m0 = 10, restr_factor = 1 by default = the ch. 2 settings; frag_model,
    bounce_model, width for variants). Input validation is off (engine hot loop).

    n_small: small-N treatment (hook ``psi_small_N``, erratum 20 in docs/design_notes.md). The
        thesis takes psi from Ossenkopf's (1993) tables for N <= 40 and applies eq. 2.15 with
        psi_add only from N = 40 on ("zero point shifted from N = 1 to N = 40", T§2.2.3); the
        tables are not available. With ``n_small = 40`` collisions whose product has at most
        n_small monomers use the pure fractal hit-and-stick law (B = 0: the CCA/PCA limits,
        psi <= N^0.425) instead [CHOICE]; None (default) applies psi_add from N = 1 (the
        library default). Without it the early psi_add term makes CCA aggregates very fluffy
        (psi(64) = 62 instead of 64^0.425 = 5.9).
    """
    B = kw.pop("B", 1.0)
    if n_small is None:
        return functools.partial(o07_outcome, validate=False, B=B, **kw)
    n_small = float(n_small)

    def recipe(m1, psi1, m2, psi2, dv, mat):
        # N = (m1 + m2)/m0 of a product of exactly n_small monomers rounds to n_small (1 +- 1e-16)
        # (sums of m0 in float64); decide "at most n_small" to a relative 1e-9, not by round-off
        small = (m1 + m2) / mat.m0 <= n_small * (1.0 + 1e-9)
        return o07_outcome(m1, psi1, m2, psi2, dv, mat, validate=False, B=jnp.where(small, 0.0, B), **kw)

    return recipe


def _log1p_neg_pow(n, f):
    """(r^n, (1 - r^n)/(1 - r)) for r = 1 - f, n >= 1 real, 0 <= f <= 1, stable at f -> 0."""
    lr = jnp.log1p(-jnp.minimum(f, 1.0))
    rn = jnp.exp(n * lr)
    small = f < 1e-12
    f_safe = jnp.where(small, 1.0, f)
    geo = jnp.where(small, n * (1.0 - 0.5 * (n - 1.0) * f), -jnp.expm1(n * lr) / f_safe)
    return rn, geo


class RecipeOutcome(AbstractOutcome):
    """Grouped-MC collision module driven by a shared-physics recipe (psi as structural parameter).

    For the pair (i, j) (masses [g], structure vectors x with ``x[index] = psi``):

    1. Delta v = sqrt(kernel.relative_velocity2(m_i, m_j, x_i, x_j)) [cm/s] (the same velocity
       field that sets the rate), then ``out = recipe(m_i, psi_i, m_j, psi_j, dv, material)``.
    2. Misses (``remnants=2`` only): with probability 1 - out.eff the pair separates unchanged.
    3. One or two large remnants: with probability p_two the large remnant mass M_L splits into
       split M_L (psi_a) and (1 - split) M_L (psi_b); else one remnant with psi_one.
    4. Fragments (``n_frag > 0``): the mass f_pwl M_tot is drawn from dn/dm ∝ m^q on
       [m_lo, m_hi] (:func:`~jaxcoag.physics.outcomes.sample_fragment_masses`, eq. 6.29, the
       last fragment takes the remainder and multiplicities are rescaled to make the total
       exact), at most ``n_frag`` distinct masses; psi = psi_fragment(m/m0, c_f).

    Group events (the i-particle meets n_c > 1 j-particles, thesis App. 5.B step 5). Reading
    implemented [own]: the recipe is evaluated ONCE for the physical single pair (so the regime,
    e.g. hit-and-stick vs compaction, is decided by the single-collision energy (1/2) m_mu dv^2,
    not by a lumped energy n_c times larger), and the n_c sequential accretions are compounded
    in closed form with the per-collision change held fixed (first order in n_c m_j/m_i, which
    the engine bounds by f_eps):

    * mass: a constant fragment fraction f per collision leaves M_L = r^n m_i + r m_j (1-r^n)/(1-r),
      r = 1 - f (exact for f = 0: M_L = m_i + n_c m_j); the rest is fragments;
    * psi: with g = n_c (m_i + m_j)/(m_i + n_c m_j), psi = psi_i + g (psi_one - psi_i) when the
      collision increases psi (mass-weighted mixing with a fixed accreted psi: exact for
      sequential mixing), and psi - 1 = (psi_i - 1)((psi_one - 1)/(psi_i - 1))^g when it
      compacts (the multiplicative compaction of eq. 2.17 compounded n_c times). Both equal
      psi_one for n_c = 1 and agree to first order; psi >= 1 always;
    * two remnants: at most one two-remnant event per group event, with probability
      1 - (1 - p_two)^n_c (the ch. 6 rule, eq. 6.27); misses: n_c (1 - eff) j-particles (the
      expected number) are returned unchanged.

    Arguments:
        kernel: the physical kernel of the run (``Scene(...).kernel(gas, ...)``, optionally
            wrapped in :class:`RainOutKernel`); must implement ``relative_velocity2``.
        material: :class:`~jaxcoag.physics.contact.Material` (m0, E_roll, E_br), e.g.
            ``Material.ch2_quartz()``.
        recipe: callable ``(m1, psi1, m2, psi2, dv, material) -> Outcome``; default
            :func:`o07_recipe` () (thesis ch. 2 settings).
        remnants: static, 1 or 2 product slots for large remnants. 1 (default, enough for O07
            without bounce) ignores p_two and eff (the recipe must give p_two = 0, eff = 1);
            2 enables bounce/breakage and misses.
        n_frag: static, number of product species for fragments (0: the recipe must not
            fragment; f_pwl is then ignored). ``n_products = remnants + n_frag``.
        index: static, which structural parameter is psi (default 0).
        c_f: prefactor of the fragments' psi(N) law (1, [CHOICE], erratum 18).

    Returns (``__call__``): :class:`~jaxcoag.mc.Products` with counts per i-particle; mass is
    conserved to rounding: sum(count m) = m_i + n_c m_j.

    References: Ormel (2008) thesis §2.2.3 (eqs. 2.9-2.19), eqs. 6.27-6.30, App. 5.B step 5;
    errata 5, 6, 18, 20 in docs/design_notes.md.
    """

    kernel: AbstractKernel
    material: Material
    recipe: Callable = eqx.field(static=True)
    c_f: jax.Array
    remnants: int = eqx.field(static=True)
    n_frag: int = eqx.field(static=True)
    index: int = eqx.field(static=True)

    def __init__(self, kernel, material, recipe=None, *, remnants=1, n_frag=0, index=0, c_f=1.0):
        if not isinstance(kernel, AbstractKernel):
            raise JaxcoagInputError("RecipeOutcome(kernel=...) must be a jaxcoag kernel built from a Scene, "
                                    "e.g. jaxcoag.Scene(velocities=..., porosity='psi').kernel(gas, material=mat)")
        if type(kernel).relative_velocity2 is AbstractKernel.relative_velocity2:
            raise JaxcoagInputError(f"RecipeOutcome needs a physical kernel with a relative velocity; "
                                    f"{type(kernel).__name__} has none (use Scene(...).kernel(gas, ...))")
        if not isinstance(material, Material):
            raise JaxcoagInputError("RecipeOutcome(material=...) must be a jaxcoag.physics.contact.Material, "
                                    "e.g. Material.ch2_quartz()")
        if remnants not in (1, 2):
            raise JaxcoagInputError(f"remnants must be 1 or 2 (product slots for large remnants); got {remnants!r}")
        if not isinstance(n_frag, int) or n_frag < 0:
            raise JaxcoagInputError(f"n_frag must be a non-negative int (fragment product species); got {n_frag!r}")
        if not isinstance(index, int) or index < 0:
            raise JaxcoagInputError(f"index must be a non-negative int (position of psi in x); got {index!r}")
        self.kernel = kernel
        self.material = material
        self.recipe = o07_recipe() if recipe is None else recipe
        self.remnants = remnants
        self.n_frag = n_frag
        self.index = index
        self.c_f = check(c_f, "c_f", positive=True, hint="fragment psi(N) prefactor, 1 by default")

    @property
    def n_products(self) -> int:  # type: ignore[override]
        return self.remnants + self.n_frag

    def __call__(self, m_i, logm_i, psi_i, m_j, logm_j, psi_j, n_c, log_nc, key):
        """Products of the i-particle meeting n_c j-particles (masses in g, psi vectors (P,))."""
        k = self.index
        dt = jnp.result_type(float)
        x_i, x_j = psi_i, psi_j
        ps_i, ps_j = x_i[k], x_j[k]
        dv = safe_sqrt(self.kernel.relative_velocity2(m_i, m_j, x_i, x_j))
        out: Outcome = self.recipe(m_i, ps_i, m_j, ps_j, dv, self.material)
        ku, kf = jax.random.split(key)
        u = jax.random.uniform(ku, (2,), dtype=dt)
        one = n_c <= 1.0

        # misses and two-remnant events (remnants = 2 only): n_c = 1 -> drawn; n_c > 1 -> the
        # expected number of hits n_c eff, and at most one two-remnant event (probability
        # 1 - (1 - p_two)^(n_c eff), eq. 6.27), in which all n_c j-particles take part [CHOICE]
        if self.remnants == 2:
            eff = jnp.clip(out.eff, 0.0, 1.0)
            p2 = jnp.clip(out.p_two, 0.0, 1.0)
            n_exp = jnp.where(one, jnp.where(u[0] < eff, 1.0, 0.0), n_c * eff)
            P2 = jnp.where(one, p2, -jnp.expm1(n_exp * jnp.log1p(-jnp.minimum(p2, 1.0 - 1e-16))))
            two = (n_exp > 0) & (u[1] < P2)
            n_hit = jnp.where(two, n_c, n_exp)
        else:
            n_hit = n_c
            two = jnp.zeros((), bool)
        n_miss = n_c - n_hit
        hit = n_hit > 0
        n_eff = jnp.where(hit, n_hit, 1.0)

        # large remnant after n_hit sequential collisions with constant fragment fraction f
        f = jnp.clip(out.f_pwl, 0.0, 1.0) if self.n_frag > 0 else jnp.zeros((), dt)
        rn, geo = _log1p_neg_pow(n_eff, f)
        M_L = rn * m_i + (1.0 - f) * m_j * geo
        M_tot = m_i + n_hit * m_j
        M_pwl = jnp.where(hit, jnp.maximum(M_tot - M_L, 0.0), 0.0)
        M_L = M_tot - M_pwl

        # psi of the large remnant (closed-form compounding, see class docstring)
        g = n_eff * (m_i + m_j) / (m_i + n_eff * m_j)
        e_i = jnp.maximum(ps_i - 1.0, 0.0)
        e_one = jnp.maximum(out.psi_one - 1.0, 0.0)
        grow = out.psi_one >= ps_i
        lin = ps_i + g * (out.psi_one - ps_i)
        ratio = jnp.where(e_i > 0, e_one / jnp.where(e_i > 0, e_i, 1.0), 0.0)
        comp = 1.0 + e_i * jnp.where(ratio > 0, jnp.exp(g * jnp.log(jnp.where(ratio > 0, ratio, 1.0))), 0.0)
        psi_L = jnp.where(n_eff <= 1.0, out.psi_one, jnp.where(grow, lin, comp))
        psi_L = jnp.maximum(psi_L, 1.0)

        # other structural columns (if any): mass-weighted mix of i and the accreted j's
        wi = m_i / M_tot
        x_mix = wi * x_i + (1.0 - wi) * x_j

        def vec(p):
            return x_mix.at[k].set(p)

        if self.remnants == 2:
            sp = jnp.clip(out.split, 0.0, 1.0)
            # slot a: the (first) large remnant, or the unchanged i-particle on a miss
            m_a = jnp.where(hit, jnp.where(two, sp * M_L, M_L), m_i)
            x_a = jnp.where(hit, vec(jnp.maximum(jnp.where(two, out.psi_a, psi_L), 1.0)), x_i)
            # slot b: the second remnant, or the missed j-particles (count n_miss)
            m_b = jnp.where(two, (1.0 - sp) * M_L, m_j)
            x_b = jnp.where(two, vec(jnp.maximum(out.psi_b, 1.0)), x_j)
            ms, xs = [m_a, m_b], [x_a, x_b]
            cnts = [jnp.ones((), dt), jnp.where(two, 1.0, n_miss)]
            oks = [m_a > 0, jnp.where(two, m_b > 0, n_miss > 0)]
        else:
            ms, xs, cnts, oks = [M_L], [vec(psi_L)], [jnp.ones((), dt)], [M_L > 0]

        if self.n_frag > 0:
            fm, mult = sample_fragment_masses(kf, out.q, out.m_lo, jnp.maximum(out.m_hi, out.m_lo), M_pwl, self.n_frag)
            m0 = self.material.m0
            psi_fr = psi_fragment(fm / m0, self.c_f)
            for q in range(self.n_frag):
                ms.append(fm[q])
                xs.append(vec(psi_fr[q]))
                cnts.append(mult[q])
                oks.append((mult[q] > 0) & (fm[q] > 0))

        m = jnp.stack([jnp.asarray(v, dt) for v in ms])
        m_safe = jnp.where(m > 0, m, 1.0)
        return Products(m=m_safe, logm=jnp.log(m_safe), psi=jnp.stack(xs),
                        count=jnp.stack([jnp.asarray(c, dt) for c in cnts]),
                        valid=jnp.stack(oks) & (m > 0))


class RainOutKernel(AbstractKernel):
    """Kernel wrapper: pairs involving a particle with tau_f > tau_rain have zero rate [T2.25].

    In the thesis ch. 2 runs a particle whose friction time exceeds tau_rain = alpha/Omega has a
    scale height below the gas scale height, settles to the midplane and "is removed from the
    simulation" (T§2.4). Here it is parked: it never collides again (log K = -inf), keeps its
    slot, mass, psi and multiplicity, and the spatial density of the colliding population drops
    accordingly; :func:`rainout_summary` measures the parked (rained-out) population.

    Arguments:
        kernel: a physical kernel with ``particles(m, x).tau_f`` (a :class:`~jaxcoag.SceneKernel`).
        tau_rain: rain-out friction time [s]; default alpha/Omega of the kernel's gas (eq. 2.25).

    References: Ormel (2008) thesis eq. 2.25 and §2.4, Tab. 2.2.
    """

    base: AbstractKernel
    tau_rain: jax.Array

    def __init__(self, kernel, tau_rain=None):
        if not hasattr(kernel, "particles") or not hasattr(kernel, "gas"):
            raise JaxcoagInputError("RainOutKernel needs a physical kernel with particles(m, x).tau_f "
                                    "(jaxcoag.Scene(...).kernel(gas, ...))")
        self.base = kernel
        if tau_rain is None:
            tau_rain = kernel.gas.alpha / kernel.gas.Omega
        self.tau_rain = check(tau_rain, "tau_rain", positive=True,
                              hint="rain-out friction time in s, alpha/Omega in thesis eq. 2.25")

    @property
    def n_struct(self) -> int:  # type: ignore[override]
        return self.base.n_struct

    @property
    def gas(self):
        return self.base.gas

    def particles(self, m, x=None):
        return self.base.particles(m, x)

    def rained(self, m, x=None):
        """True where tau_f(m, x) > tau_rain (the particle has rained out)."""
        x = x if self.base.n_struct else None
        return self.base.particles(m, x).tau_f > self.tau_rain

    def __call__(self, m1, m2, x1=None, x2=None):
        gone = self.rained(m1, x1) | self.rained(m2, x2)
        return jnp.where(gone, 0.0, self.base(m1, m2, x1, x2))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        m1, m2 = jnp.exp(logm1), jnp.exp(logm2)
        gone = self.rained(m1, x1) | self.rained(m2, x2)
        return jnp.where(gone, -jnp.inf, self.base.log_kernel_from_log_mass(logm1, logm2, x1, x2))

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return self.base.relative_velocity2(m1, m2, x1, x2)


def rainout_summary(res, kernel: RainOutKernel, *, rho_s=None) -> dict[str, Any]:
    """Rain-out accounting of an MC result run with a :class:`RainOutKernel` (thesis Tab. 2.2).

    Arguments:
        res: ``MCResult`` (optionally batched over runs: leading axes before (T, S)).
        kernel: the :class:`RainOutKernel` of the run (tau_f and tau_rain).
        rho_s: material density for a* [g cm^-3]; default the kernel's ``rho_s``.

    Returns:
        dict of arrays (leading batch axes kept): ``t`` [s]; ``M_rain`` (rained mass per
        snapshot [g]) and ``f_rain`` (fraction of the simulated mass); ``t_rain`` = first output
        time with rained mass > 0 and ``t_99`` = first with f_rain >= 0.99 [s] (inf if never:
        resolution = the output grid); number means over the rained population at the last
        snapshot: ``m`` [g], ``a`` [cm] (geometric), ``a_star`` [cm], ``psi``, ``a_over_astar`` =
        <a>/<a*>; and ``n_rain`` (number of rained physical particles).

    References: Ormel (2008) thesis Tab. 2.2 (columns <a>, <m>, <psi>, a/a*, t_rain, t_99%).
    """
    base = kernel.base
    rho_s = base.rho_s if rho_s is None else rho_s
    m, psi, valid = res.m, res.psi, res.valid
    g = res.w * jnp.exp2(res.z.astype(m.dtype))
    x = psi if base.n_struct else None
    gone = valid & kernel.rained(m, x)
    gm = jnp.where(gone, g * m, 0.0)
    M_rain = jnp.sum(gm, axis=-1)
    f_rain = M_rain / res.M_tot
    t = res.t
    big = jnp.inf

    def first(cond):
        idx = jnp.argmax(cond, axis=-1)
        tb = jnp.broadcast_to(t, cond.shape)
        val = jnp.take_along_axis(tb, idx[..., None], axis=-1)[..., 0]
        return jnp.where(jnp.any(cond, axis=-1), val, big)

    t_rain = first(M_rain > 0)
    t_99 = first(f_rain >= 0.99)
    gl = jnp.where(gone[..., -1, :], g[..., -1, :], 0.0)
    ml = m[..., -1, :]
    ps = psi[..., -1, :, base.scene.porosity.index] if base.n_struct else jnp.ones_like(ml)
    a_star = jnp.cbrt(3.0 * ml / (4.0 * jnp.pi * rho_s))
    a = a_star * jnp.cbrt(ps)
    n = jnp.sum(gl, axis=-1)
    n_safe = jnp.where(n > 0, n, 1.0)
    mean = lambda v: jnp.where(n > 0, jnp.sum(gl * v, axis=-1) / n_safe, jnp.nan)
    out = dict(t=t, M_rain=M_rain, f_rain=f_rain, t_rain=t_rain, t_99=t_99, n_rain=n,
               m=mean(ml), a=mean(a), a_star=mean(a_star), psi=mean(ps))
    out["a_over_astar"] = out["a"] / out["a_star"]
    return out
