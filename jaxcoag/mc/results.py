"""Result of the Monte Carlo engine with binned, moment and largest-particle diagnostics, and its
conversion to the common ``xarray.Dataset`` layout of every engine.

References: Ormel (2008) thesis ch. 5, Table 5.1 units (densities from a simulation:
n_b = Σ_{i∈b} g_i/V, ρ_b = Σ_{i∈b} g_i m_i/V); log-moments and M_L1, M_L2 as in the Monte Carlo
conventions of docs/design_notes.md.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._engine import AbstractResult
from .._status import RESULTS, result_code
from .._validate import JaxcoagInputError, is_traced
from .state import MCState, flag_names, largest_two, log_n_particles

__all__ = ["MCResult", "auto_edges"]

LN2 = 0.6931471805599453
_LN10 = math.log(10.0)


def auto_edges(logm, valid, per_decade=10):
    """Automatic mass-bin edges [g]: ``per_decade`` log-spaced bins per decade on the grid
    10^(k/per_decade), covering every valid species mass (any leading axes) with the largest mass
    strictly below the top edge. Needs concrete (not traced) arrays.

    Arguments: logm: ln species masses [ln g]; valid: which slots hold a species.
    Returns: numpy (nbins + 1,) edges [g] (one decade around 1 g when no species is valid).
    """
    lm = np.asarray(logm, np.float64)[np.asarray(valid, bool)]
    lm = lm[np.isfinite(lm)]
    if lm.size == 0:
        return 10.0 ** (np.arange(-per_decade // 2, per_decade // 2 + 1) / per_decade)
    lo, hi = float(lm.min()), float(min(lm.max(), math.log(1e300)))
    k_lo = math.floor(lo / _LN10 * per_decade)
    while math.log(10.0 ** (k_lo / per_decade)) > lo:
        k_lo -= 1
    k_hi = math.floor(hi / _LN10 * per_decade) + 1
    while math.log(10.0 ** (k_hi / per_decade)) <= hi:
        k_hi += 1
    return 10.0 ** (np.arange(k_lo, k_hi + 1) / per_decade)


class MCResult(AbstractResult):
    """Snapshots of one Monte Carlo run (add a leading batch axis under ``jax.vmap``).

    Fields (T = number of output times, S = capacity, P = structural parameters):
        t: (T,) output times [s].
        m, logm: (T, S) species particle masses [g] and their natural logs.
        psi: (T, S, P) structural parameters.
        w, z: (T, S) group number (float) and zoom number (int); multiplicity g = w 2^z.
        valid: (T, S) which slots hold a species.
        V, logV: (T,) simulated volume [cm^3] and its log.
        M_tot: (T,) total simulated mass [g].
        n_events_snap: (T,) events executed before each snapshot.
        status: a :class:`jaxcoag.RESULTS` item (successful, max_steps_reached = event budget spent,
            nonfinite, capacity_exceeded, stopped, zero_rate).
        flags: int32 raw bit flags of the run (``jaxcoag.mc.state.STATUS``; diagnostics only:
            several may be set where ``status`` names the most important one).
        n_events, n_dup, n_merge: totals of events, duplications and species merges.
        t_stop: time [s] of the event after which the stop predicate fired (``MonteCarlo(stop=...)``);
            NaN when the run did not stop that way.
        rho_d: dust mass density M_tot / V at the start of the run [g cm^-3] (reference of
            ``mass_drift``; None for hand-built results).
        final_state: the complete end state (``MCState`` without snapshot buffers): pass the result
            itself as ``initial`` to ``jaxcoag.evolve`` to continue the run; the continuation is
            bitwise the same as one uninterrupted run (same backend).
        config: static run configuration as (name, value) pairs (mode, grouping, capacity,
            kernel and outcome class, ...), used for dataset attributes.

    References: Ormel (2008) thesis Table 5.4; snapshots in docs/design_notes.md (MC conventions).
    """

    t: jax.Array
    m: jax.Array
    logm: jax.Array
    psi: jax.Array
    w: jax.Array
    z: jax.Array
    valid: jax.Array
    V: jax.Array
    logV: jax.Array
    M_tot: jax.Array
    n_events_snap: jax.Array
    status: RESULTS
    flags: jax.Array
    n_events: jax.Array
    n_dup: jax.Array
    n_merge: jax.Array
    t_stop: jax.Array | None = None
    rho_d: jax.Array | None = None
    final_state: MCState | None = None
    config: tuple = eqx.field(static=True, default=())

    @property
    def log_g(self):
        """(T, S) ln multiplicity ln g = ln w + z ln 2 (−inf on invalid slots)."""
        pos = self.valid & (self.w > 0)
        return jnp.where(pos, jnp.log(jnp.where(pos, self.w, 1.0)) + self.z * LN2, -jnp.inf)

    @property
    def g(self):
        """(T, S) multiplicity g = w 2^z (number of physical particles per species; may be inf
        beyond 1.8e308, use ``log_g``)."""
        return jnp.where(self.valid, jnp.ldexp(self.w, self.z), 0.0)

    @property
    def n_species(self):
        """(T,) number of valid species Ns."""
        return jnp.sum(self.valid, axis=-1)

    @property
    def n_groups(self):
        """(T,) number of groups Ng = Σ w."""
        return jnp.sum(jnp.where(self.valid, self.w, 0.0), axis=-1)

    def flag_names(self):
        """Names of the raw flags set in ``flags`` (only for a single, concrete run; ``[]`` = none)."""
        return flag_names(self.flags)

    def log_moments(self, p):
        """(T,) ln M_p = ln(Σ_i g_i m_i^p / V) [ln(g^p cm^-3)] via logsumexp (overflow-free).

        References: Ormel (2008) Table 5.1 (moments); log-moments (docs/design_notes.md).
        """
        x = jnp.where(self.valid, self.log_g + p * self.logm, -jnp.inf)
        return jax.nn.logsumexp(x, axis=-1) - self.logV

    def moments(self, p):
        """(T,) moments M_p = Σ_i g_i m_i^p / V [g^p cm^-3] (M0 number, M1 mass density).

        References: Ormel (2008) eq. (5.4) and Table 5.1.
        """
        return jnp.exp(self.log_moments(p))

    def _per_bin(self, edges, p):
        edges = jnp.asarray(edges, jnp.float64)
        le = jnp.log(edges)
        nb = edges.shape[-1] - 1
        b = jnp.searchsorted(le, self.logm, side="right") - 1
        inside = self.valid & (b >= 0) & (b < nb)
        bc = jnp.clip(b, 0, nb - 1)
        val = jnp.where(inside, jnp.exp(self.log_g + p * self.logm - self.logV[..., None]), 0.0)
        onehot = (bc[..., None] == jnp.arange(nb).reshape((1,) * bc.ndim + (nb,))) & inside[..., None]
        return jnp.sum(jnp.where(onehot, val[..., None], 0.0), axis=-2)

    def bin_edges(self, edges=None):
        """Mass-bin edges [g] of the binned accessors: ``edges`` (checked) or, for None, automatic edges
        with 10 log-spaced bins per decade over the valid species masses of all snapshots
        (:func:`auto_edges`; needs a concrete result, give ``edges`` inside jit/vmap)."""
        if edges is None:
            return auto_edges(self.logm, self.valid)
        e = np.asarray(getattr(edges, "edges", edges), np.float64)
        if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or np.any(e <= 0) or np.any(np.diff(e) <= 0):
            raise JaxcoagInputError("edges must be a 1-D, positive, strictly increasing array of >= 2 mass-bin edges in g.")
        return e

    def mass_per_bin(self, edges=None):
        """(T, nbins) mass density per mass bin [g cm^-3]: Σ_{edges[b] ≤ m_i < edges[b+1]} g_i m_i / V.

        Arguments: edges: (nbins+1,) increasing bin edges [g] (e.g. 2.0**arange(...)); None: automatic
            edges (:meth:`bin_edges`). Species outside the edges are not counted.
        References: Ormel (2008) thesis §5.3 (factor-2 bins, m^2 f(m) plots).
        """
        return self._per_bin(self._edges_arg(edges), 1.0)

    def number_per_bin(self, edges=None):
        """(T, nbins) number density per mass bin [cm^-3]: Σ_{i in bin} g_i / V (edges as :meth:`mass_per_bin`).

        References: Ormel (2008) thesis §5.3 (factor-2 bins).
        """
        return self._per_bin(self._edges_arg(edges), 0.0)

    def _edges_arg(self, edges):
        # traced edges (inside jit/vmap) are used as given; concrete ones are checked
        return edges if is_traced(edges) else self.bin_edges(edges)

    def _gel_mass(self, edges=None):
        """(T,) mass density of the species at or above the top edge [g cm^-3] (0 with automatic edges)."""
        e = self._edges_arg(edges)
        top = jnp.log(jnp.asarray(e, jnp.float64)[-1])
        x = jnp.where(self.valid & (self.logm >= top), self.log_g + self.logm, -jnp.inf)
        return jnp.exp(jax.nn.logsumexp(x, axis=-1) - self.logV)

    @property
    def mass_drift(self):
        """(T,) relative change of the simulated mass density, Σ g m / V / rho_d - 1 [1] (0 to rounding
        in constant-V runs; fluctuates with ``leftover="stochastic"``). Hand-built results without
        ``rho_d`` use the first snapshot as reference."""
        ref = jnp.log(self.rho_d)[..., None] if self.rho_d is not None else self.log_M1[..., :1]
        return jnp.expm1(self.log_M1 - ref)

    def largest_mass(self):
        """(T,) mass of the largest particle M_L1 [g].

        References: Ormel (2008) thesis §5.3.2 (M_L1); M_L1 in docs/design_notes.md (MC conventions).
        """
        return jnp.exp(jnp.max(jnp.where(self.valid, self.logm, -jnp.inf), axis=-1))

    # ------------------------------------------------------------------ statistics

    def largest_two(self, kind="particle"):
        """(T,) masses (M_L1, M_L2) of the largest and second-largest particle [g].

        Arguments: kind: "particle" (default; if the largest species has g ≥ 2 then
            M_L2 = M_L1) or "species" (second-largest species mass).
        Returns: two (T,) arrays (0 where no such particle exists).
        References: Ormel (2008) thesis §5.3.2-5.3.3, Figs. 5.6/5.7; MC hazard 12 in
        docs/design_notes.md.
        """
        l1, l2 = largest_two(self.logm, self.w, self.z, self.valid, kind)
        return jnp.exp(l1), jnp.exp(l2)

    def log_largest_two(self, kind="particle"):
        """(T,) (ln M_L1, ln M_L2) [ln g]; overflow-free form of :meth:`largest_two`."""
        return largest_two(self.logm, self.w, self.z, self.valid, kind)

    @property
    def M_L1(self):
        """(T,) mass of the largest particle [g] (same as :meth:`largest_mass`)."""
        return self.largest_two("particle")[0]

    @property
    def M_L2(self):
        """(T,) mass of the second-largest particle [g] (= M_L1 if the largest species has g ≥ 2)."""
        return self.largest_two("particle")[1]

    @property
    def log_n_particles(self):
        """(T,) ln Np = ln Σ g_i, the number of simulated physical particles (eq. 5.9)."""
        return log_n_particles(self.w, self.z, self.valid)

    @property
    def Ns(self):
        """(T,) number of species (alias of ``n_species``)."""
        return self.n_species

    @property
    def Ng(self):
        """(T,) number of groups Σ w (alias of ``n_groups``)."""
        return self.n_groups

    @property
    def log_M0(self):
        """(T,) ln M0 = ln(Np / V) [ln cm^-3]."""
        return self.log_moments(0.0)

    @property
    def log_M1(self):
        """(T,) ln M1 = ln(M_tot / V) [ln(g cm^-3)]."""
        return self.log_moments(1.0)

    @property
    def log_M2(self):
        """(T,) ln M2 = ln(Σ g m^2 / V) [ln(g^2 cm^-3)] (M2 itself overflows beyond m ~ 1e154)."""
        return self.log_moments(2.0)

    # ------------------------------------------------------------------ xarray

    def to_xarray(self, *, attrs=None, kernel=None, edges=None):
        """Labelled ``xarray.Dataset`` of one run in the common layout of every engine (index a
        vmapped result first).

        Arguments:
            attrs: optional dict of extra global attributes (scene, seed, ...); values netCDF
                cannot hold are stored as their ``repr``.
            kernel: optional physical kernel the run used (``scene.kernel(gas, rho_s)``, compact
                or porous): adds the grain radius ``a`` [cm] and Stokes number ``St`` [1] of the
                bin-centre masses on ``m`` (compact kernels) and ``a_species`` / ``St_species`` of
                every species slot on (t, species) from ``kernel.particles(m, psi)`` (NaN on free
                slots). Analytic kernels (no material density or gas state) add nothing.
            edges: mass-bin edges [g] of the binned view, or a ``jaxcoag.MassGrid`` (its edges and
                centres, the coordinates of a binned run on that grid); default: automatic edges, 10 per
                decade over the valid species masses of all snapshots (:meth:`bin_edges`).

        Returns:
            Dataset with dims ``t``, ``m``, ``m_edge``, ``species`` (capacity slots), ``struct`` (P);
            coords ``t`` [s], ``t_yr`` [yr], ``m`` [g] (bin centres), ``m_edge`` [g] (and ``a``, ``St``);
            common variables ``mass_per_bin`` [g cm^-3], ``number_per_bin`` [cm^-3] (t, m),
            ``gel_mass`` [g cm^-3] (species at or above the top edge), ``mass_drift`` [1] (t),
            ``status`` (RESULTS code with ``status_name``/``status_message``); MC extras
            ``m_species`` [g], ``log_g``, ``w``, ``z``, ``psi``, ``valid`` (t, species[, struct]);
            ``V`` [cm^3], ``M_tot`` [g], ``n_events``, ``n_species``, ``n_groups``,
            ``log_n_particles``, ``M_L1``, ``M_L2`` [g], ``log_M0``, ``log_M1``, ``log_M2`` (t);
            scalars ``flags``, ``n_events_total``, ``n_dup``, ``n_merge``, ``t_stop`` [s].
            Attributes: title, Conventions, engine = "mc", status, the static run configuration
            (``run_mode``, ``run_grouping``, ``run_capacity``, ``run_kernel``, ...) and ``attrs``.
            Save it with :func:`jaxcoag.io.save_netcdf` (atomic).

        References: CF conventions 1.10 (units, long_name).
        """
        from .._dataset import common_dataset
        from ..io import _attr_value

        if np.ndim(self.t) != 1:
            raise JaxcoagInputError(
                f"to_xarray takes one run (t of shape (T,)); got t of shape {np.shape(self.t)} (a vmapped batch?). "
                "Index one member first, e.g. jax.tree_util.tree_map(lambda x: x[0], result).")
        if attrs is not None and not isinstance(attrs, dict):
            raise JaxcoagInputError("attrs must be a dict of str -> value (scene name, parameters).")
        e = self.bin_edges(edges)
        d = _derived(self, jnp.asarray(e, jnp.float64))  # one compiled call, not each operation eagerly per shape

        def a(x, dt=np.float64):
            return np.asarray(x).astype(dt)

        l1, l2 = d["l1"], d["l2"]
        T = ("t",)
        TS = ("t", "species")
        flags = int(np.asarray(self.flags))
        extra = {
            "m_species": (TS, a(self.m), {"units": "g", "long_name": "particle mass of each species slot"}),
            "log_g": (TS, a(d["log_g"]), {"units": "1", "long_name": "ln multiplicity ln(w 2^z) (-inf on free slots)"}),
            "w": (TS, a(self.w), {"units": "1", "long_name": "group number w (g = w 2^z)"}),
            "z": (TS, a(self.z, np.int32), {"units": "1", "long_name": "zoom number z"}),
            "psi": (TS + ("struct",), a(self.psi), {"units": "1", "long_name": "structural parameters"}),
            "valid": (TS, a(self.valid, np.int8), {"units": "1", "long_name": "slot holds a species (1) or is free (0)"}),
            "V": (T, a(self.V), {"units": "cm3", "long_name": "simulated volume"}),
            "M_tot": (T, a(self.M_tot), {"units": "g", "long_name": "total simulated mass"}),
            "n_events": (T, a(self.n_events_snap, np.int64), {"units": "1", "long_name": "events executed before the snapshot"}),
            "n_species": (T, a(d["n_species"], np.int64), {"units": "1", "long_name": "number of species Ns"}),
            "n_groups": (T, a(d["n_groups"]), {"units": "1", "long_name": "number of groups Ng = sum w"}),
            "log_n_particles": (T, a(d["log_n_particles"]), {"units": "1", "long_name": "ln of the number of physical particles Np"}),
            "M_L1": (T, a(l1), {"units": "g", "long_name": "mass of the largest particle"}),
            "M_L2": (T, a(l2), {"units": "g", "long_name": "mass of the second-largest particle (= M_L1 if the largest species has g >= 2)"}),
            "log_M0": (T, a(d["log_M0"]), {"units": "1", "long_name": "ln number density ln M0 [ln cm-3]"}),
            "log_M1": (T, a(d["log_M1"]), {"units": "1", "long_name": "ln mass density ln M1 [ln(g cm-3)]"}),
            "log_M2": (T, a(d["log_M2"]), {"units": "1", "long_name": "ln second moment ln M2 [ln(g2 cm-3)]"}),
            "flags": ((), np.int32(flags), {"units": "1", "long_name": "raw Monte Carlo flags (diagnostics; status is the result)",
                                            "flag_names": ",".join(flag_names(flags)) or "none",
                                            "flag_values": "CAPACITY=1, ZERO_RATE=2, NONFINITE=4, MAX_EVENTS=8, STOPPED=16"}),
            "n_events_total": ((), np.int64(np.asarray(self.n_events)), {"units": "1", "long_name": "events executed"}),
            "n_dup": ((), np.int64(np.asarray(self.n_dup)), {"units": "1", "long_name": "duplications"}),
            "n_merge": ((), np.int64(np.asarray(self.n_merge)), {"units": "1", "long_name": "species merges"}),
            "t_stop": ((), np.float64(np.nan if self.t_stop is None else np.asarray(self.t_stop)),
                       {"units": "s", "long_name": "time the stop predicate fired (NaN: not stopped)"}),
        }
        extra_coords = {"species": ("species", np.arange(np.shape(self.m)[-1], dtype=np.int32),
                                    {"units": "1", "long_name": "species slot index"})}
        if kernel is not None and hasattr(kernel, "particles"):
            ns = int(getattr(kernel, "n_struct", 0))
            valid = np.asarray(self.valid, bool)
            m_safe = np.where(valid, np.asarray(self.m, np.float64), 1.0)
            if ns == 0:  # one jitted call (io.grain_size_stokes), not the eager operations for this shape
                from ..io import grain_size_stokes

                p_a, p_st = grain_size_stokes(kernel, m_safe)
            else:
                psi = np.asarray(self.psi, np.float64)[..., :ns]
                p = kernel.particles(jnp.asarray(m_safe), jnp.asarray(np.where(valid[..., None], psi, 1.0)))
                p_a, p_st = p.a, p.st
            extra["a_species"] = (TS, np.where(valid, np.asarray(p_a, np.float64), np.nan),
                                  {"units": "cm", "long_name": "grain radius of each species slot (NaN on free slots)"})
            extra["St_species"] = (TS, np.where(valid, np.asarray(p_st, np.float64), np.nan),
                                   {"units": "1", "long_name": "Stokes number tau_f / t_L of each species slot in the "
                                                               "run's gas (NaN on free slots)"})
        ds = common_dataset(engine="mc", title="jaxcoag grouped Monte Carlo run", t=a(self.t), edges=e,
                            mass_per_bin=a(d["mass_per_bin"]), number_per_bin=a(d["number_per_bin"]),
                            gel_mass=a(d["gel_mass"]), mass_drift=a(d["mass_drift"]),
                            code=int(np.asarray(result_code(self.status))), extra=extra, extra_coords=extra_coords,
                            kernel=kernel, centres=getattr(edges, "centers", None))
        for k, v in self.config:
            ds.attrs[f"run_{k}"] = _attr_value(v)
        for k, v in (attrs or {}).items():
            if not isinstance(k, str):
                raise JaxcoagInputError(f"attrs keys must be strings (got {k!r}).")
            ds.attrs[k] = _attr_value(v)
        return ds


@eqx.filter_jit
def _derived(res, edges):
    """The derived arrays :meth:`MCResult.to_xarray` writes, in one compiled call (evaluated eagerly, each of their
    operations was compiled on its own for the run's shapes: ~0.5-0.8 s of a Monte Carlo ``jaxcoag run``'s output)."""
    l1, l2 = res.largest_two("particle")
    return dict(log_g=res.log_g, n_species=res.n_species, n_groups=res.n_groups, log_n_particles=res.log_n_particles,
                l1=l1, l2=l2, log_M0=res.log_M0, log_M1=res.log_M1, log_M2=res.log_M2,
                mass_per_bin=res.mass_per_bin(edges), number_per_bin=res.number_per_bin(edges),
                gel_mass=res._gel_mass(edges), mass_drift=res.mass_drift)
