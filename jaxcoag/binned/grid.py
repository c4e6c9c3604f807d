"""Logarithmic mass grids for the binned engine.

The grid is *structure*: its edges decide the compiled index tensors, so it is a plain,
hashable Python object holding numpy arrays (not a pytree). Everything is built from
``log_edges`` (natural log of the edges in g), so grids spanning hundreds of decades
(1e-20 .. 1e140 g and beyond) are exact; ``edges``/``centers`` are the exponentials and
may be +inf only beyond 1e308 g (use the ``log_*`` attributes there).

References: Brauer, Dullemond & Henning (2008), A&A 480, 859 (log grid); DustPy
(Stammler & Birnstiel 2022, ApJ 935, 35) ``mmin, mmax, nm``.
"""

from __future__ import annotations

import math
import os

import numpy as np
import jax.numpy as jnp

from .._validate import JaxcoagInputError

__all__ = ["MassGrid", "monodisperse", "mrn", "exponential", "LOG_TOL", "memory_limit_bytes",
           "GRID_BYTES_PER_BIN"]

#: Tolerance [ln g] of every decision that compares a mass, a mass ratio or a mass sum built
#: from grid masses with a boundary (an edge, a threshold ratio such as a cratering ratio).
#: ``log_edges`` and ``log_centers`` carry an absolute round-off of a few ulp of |ln m|
#: (measured: at most 1.04e-13 for the factor-10 offsets of a 1e-20..1e140 g grid at 7 bins
#: per decade), so values that coincide mathematically (a pair of centres exactly a factor 10
#: apart, a mass exactly on an edge) land on either side of a bare ``>=`` by chance. A value
#: within LOG_TOL (a relative 1e-9 in mass) of a boundary counts as *on* the boundary; real
#: grid spacings (ln 10 / bins_per_decade ~ 0.1-1) are 8 orders of magnitude wider.
LOG_TOL = 1e-9


#: Bytes per bin of a MassGrid's own numpy arrays (log_edges, log_centers, edges, centers,
#: widths and their temporaries: 8 float64 arrays of nbins (+1) entries).
GRID_BYTES_PER_BIN = 64


def memory_limit_bytes() -> float:
    """Largest memory estimate [bytes] a binned run may need before it is refused up front.

    The environment variable ``JAXCOAG_MEMORY_LIMIT_GB`` (GiB, > 0) sets it; otherwise it is half
    the physical memory of this machine (``os.sysconf("SC_PHYS_PAGES") * SC_PAGE_SIZE``) and, on an
    accelerator whose JAX device reports a ``bytes_limit``, at most that. inf where neither is
    known (no refusal).
    """
    env = os.environ.get("JAXCOAG_MEMORY_LIMIT_GB", "").strip()
    if env:
        try:
            v = float(env)
        except ValueError:
            v = float("nan")
        if not (math.isfinite(v) and v > 0):
            raise JaxcoagInputError(f"JAXCOAG_MEMORY_LIMIT_GB must be a number of GiB > 0, got {env!r}; "
                                    "unset it to use half the physical memory.")
        return v * 2.0 ** 30
    limit = float("inf")
    try:
        limit = 0.5 * float(os.sysconf("SC_PAGE_SIZE")) * float(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - non-POSIX
        pass
    try:
        import jax

        dev = jax.devices()[0]
        if dev.platform != "cpu":
            stats = dev.memory_stats() or {}
            if stats.get("bytes_limit"):
                limit = min(limit, float(stats["bytes_limit"]))
    except Exception:  # pragma: no cover - a backend without memory statistics
        pass
    return limit


def _gib(nbytes) -> str:
    return f"{nbytes / 2.0 ** 30:.3g} GiB"


class MassGrid:
    """A mass grid: ``nbins`` bins between ``nbins + 1`` strictly increasing edges [g].

    Attributes:
        log_edges: ln of the edges [ln g], shape (nbins+1,).
        edges: edges [g], shape (nbins+1,).
        log_centers: ln of the geometric centers, (log_edges[:-1] + log_edges[1:]) / 2.
        centers: geometric bin centers sqrt(m_lo m_hi) [g], shape (nbins,).
        widths: edges[1:] - edges[:-1] [g].
        nbins: number of bins (int).

    Build with :meth:`log` (uniform in log m) or :meth:`from_edges`.
    """

    def __init__(self, log_edges):
        le = np.asarray(log_edges, dtype=np.float64)
        if le.ndim != 1 or le.size < 3:
            raise JaxcoagInputError(
                f"a MassGrid needs at least 2 bins (3 edges); got {max(le.size - 1, 0)} bins. "
                "Increase bins_per_decade or widen [m_min, m_max].")
        if not np.all(np.isfinite(le)):
            raise JaxcoagInputError("MassGrid edges must be finite positive masses in g (got a NaN/inf/0 edge).")
        if not np.all(np.diff(le) > 0):
            raise JaxcoagInputError("MassGrid edges must be strictly increasing; sort them and drop duplicates.")
        le.setflags(write=False)
        self.log_edges = le
        self.nbins = int(le.size - 1)
        lc = 0.5 * (le[:-1] + le[1:])
        lc.setflags(write=False)
        self.log_centers = lc
        with np.errstate(over="ignore"):
            self.edges = np.exp(le)
            self.centers = np.exp(lc)
            # width = m_lo (exp(dlog) - 1) without cancellation
            self.widths = np.exp(le[:-1]) * np.expm1(np.diff(le))
        for a in (self.edges, self.centers, self.widths):
            a.setflags(write=False)

    # ---------------------------------------------------------------- constructors
    @classmethod
    def log(cls, m_min, m_max, bins_per_decade):
        """Grid uniform in log m.

        Arguments:
            m_min: lowest edge [g] (> 0).
            m_max: highest edge [g] (> m_min). The number of bins is
                ``round(log10(m_max/m_min) * bins_per_decade)`` (at least 2) and the top edge is
                adjusted to keep the spacing uniform.
            bins_per_decade: bins per factor 10 in mass (> 0, float allowed).

        Returns: MassGrid.

        References: Brauer et al. (2008) §2; DustPy grid.
        """
        m_min = float(m_min)
        m_max = float(m_max)
        bpd = float(bins_per_decade)
        if not (np.isfinite(m_min) and m_min > 0):
            raise JaxcoagInputError(f"m_min must be a finite mass > 0 g (got {m_min!r}).")
        if not (np.isfinite(m_max) and m_max > m_min):
            raise JaxcoagInputError(f"m_max must be finite and > m_min = {m_min!r} g (got {m_max!r}).")
        if not (np.isfinite(bpd) and bpd > 0):
            raise JaxcoagInputError(f"bins_per_decade must be > 0 (got {bins_per_decade!r}).")
        return cls.log_from_log10(np.log10(m_min), np.log10(m_max), bpd)

    @classmethod
    def log_from_log10(cls, log10_min, log10_max, bins_per_decade):
        """Grid uniform in log m given log10 of the edges (for grids beyond 1e308 g).

        Arguments: log10_min, log10_max [log10 g]; bins_per_decade (> 0).
        Returns: MassGrid. References: as :meth:`log`.
        """
        log10_min, log10_max, bpd = float(log10_min), float(log10_max), float(bins_per_decade)
        if not (np.isfinite(log10_min) and np.isfinite(log10_max)):
            raise JaxcoagInputError(f"log10_min and log10_max must be finite log10 masses [log10 g] "
                                    f"(got {log10_min!r}, {log10_max!r}).")
        if not (np.isfinite(bpd) and bpd > 0):
            raise JaxcoagInputError(f"bins_per_decade must be > 0 (got {bins_per_decade!r}).")
        decades = log10_max - log10_min
        if not decades > 0:
            raise JaxcoagInputError(f"log10_max must exceed log10_min (got {log10_min!r} .. {log10_max!r}).")
        n = int(round(decades * float(bins_per_decade)))
        if n < 2:
            raise JaxcoagInputError(
                f"[m_min, m_max] at {bins_per_decade} bins/decade gives {n} bin(s); need at least 2. "
                "Increase bins_per_decade or widen the range.")
        need = (n + 1.0) * GRID_BYTES_PER_BIN
        if need > memory_limit_bytes():  # before any allocation (e.g. bins_per_decade = 1e12)
            raise JaxcoagInputError(
                f"{decades:.4g} decades at {bins_per_decade:g} bins/decade give {n:.4g} bins, whose grid arrays "
                f"alone need {_gib(need)} (limit {_gib(memory_limit_bytes())}); lower bins_per_decade.")
        le = np.log(10.0) * (float(log10_min) + np.arange(n + 1) / float(bins_per_decade))
        return cls(le)

    @classmethod
    def from_edges(cls, edges):
        """Grid from explicit strictly increasing edges [g] (all > 0, at least 3)."""
        e = np.asarray(edges, dtype=np.float64)
        if e.ndim != 1 or e.size < 3:
            raise JaxcoagInputError("edges must be a 1-D array of at least 3 masses (2 bins).")
        if not np.all(np.isfinite(e)) or not np.all(e > 0):
            raise JaxcoagInputError("edges must be finite masses > 0 g.")
        if not np.all(np.diff(e) > 0):
            raise JaxcoagInputError("edges must be strictly increasing; sort them and drop duplicates.")
        return cls(np.log(e))

    # ---------------------------------------------------------------- helpers
    @property
    def dlog(self):
        """ln(m_hi/m_lo) per bin, shape (nbins,)."""
        return np.diff(self.log_edges)

    @property
    def is_uniform_log(self) -> bool:
        """True if the spacing in log m is uniform (to 1e-10 relative)."""
        d = self.dlog
        return bool(np.all(np.abs(d - d[0]) <= 1e-10 * d[0]))

    def __len__(self):
        return self.nbins

    def __repr__(self):
        return (f"MassGrid(nbins={self.nbins}, m_min={np.exp(self.log_edges[0]):.3g} g, "
                f"m_max={np.exp(self.log_edges[-1]):.3g} g)")

    def __hash__(self):
        return hash(("MassGrid", self.log_edges.tobytes()))

    def __eq__(self, other):
        return isinstance(other, MassGrid) and np.array_equal(self.log_edges, other.log_edges)


# ---------------------------------------------------------------------- initial conditions
def monodisperse(grid: MassGrid, m0, rho_d):
    """Number density per bin [cm^-3] for all mass rho_d in the bin containing m0.

    Arguments: grid; m0: monomer mass [g] (inside the grid); rho_d: dust mass density [g cm^-3].
    Returns: numpy (nbins,) array, rho_d / m_b in the bin b holding m0 (so the bin's mass is
    exactly rho_d; the particles carry the bin's center mass m_b - put m0 at a bin center,
    e.g. ``MassGrid.log(m0 / 10**(0.5/bpd), ...)``, for analytic comparisons). Bins are
    [m_lo, m_hi): an m0 on an edge to a relative :data:`LOG_TOL` goes to the bin above that
    edge (e.g. ``MassGrid.log(2.0, ...)`` has ln m_lo = ln 10 log10(2) > ln 2 by 1.1e-16, and m0 =
    2 g is its first bin, not "outside the grid").
    References: Ormel (2008) thesis Table 5.1 (monodisperse start).
    """
    m0, rho_d = float(m0), float(rho_d)
    if not (np.isfinite(rho_d) and rho_d > 0):
        raise JaxcoagInputError(f"rho_d must be a finite dust density > 0 g cm^-3 (got {rho_d!r}).")
    if not (np.isfinite(m0) and m0 > 0):
        raise JaxcoagInputError(f"m0 must be a finite mass > 0 g (got {m0!r}).")
    lm = np.log(m0)
    if not (grid.log_edges[0] - LOG_TOL <= lm < grid.log_edges[-1] - LOG_TOL):
        raise JaxcoagInputError(f"m0 = {m0!r} g lies outside the grid [{grid.edges[0]:.3g}, {grid.edges[-1]:.3g}) g.")
    # bins are [m_lo, m_hi): an m0 on an edge (to LOG_TOL) belongs to the bin above it
    b = int(np.clip(np.searchsorted(grid.log_edges, lm + LOG_TOL, side="right") - 1, 0, grid.nbins - 1))
    n = np.zeros(grid.nbins)
    n[b] = rho_d * np.exp(-grid.log_centers[b])
    return n


def mrn(grid: MassGrid, a_min, a_max, rho_s, rho_d, q=3.5):
    """MRN-like size distribution n(a) da ~ a^-q da between a_min and a_max, as number per bin.

    Arguments: grid; a_min, a_max: radii [cm] (0 < a_min < a_max); rho_s: material density
    [g cm^-3]; rho_d: total dust density [g cm^-3]; q: size exponent (3.5, MRN).
    Returns: numpy (nbins,) number density per bin [cm^-3] = (mass in the bin)/m_b, with the
    mass in each bin the exact integral of m n(a) da over the bin's radius range, normalised
    to rho_d (mass conserving).
    References: Mathis, Rumpl & Nordsieck (1977), ApJ 217, 425.
    """
    a_min, a_max, rho_s, rho_d, q = map(float, (a_min, a_max, rho_s, rho_d, q))
    if not (0 < a_min < a_max and np.isfinite(a_max)):
        raise JaxcoagInputError(f"need 0 < a_min < a_max, finite radii in cm (got a_min={a_min!r}, a_max={a_max!r}).")
    for name, v in (("rho_s", rho_s), ("rho_d", rho_d)):
        if not (np.isfinite(v) and v > 0):
            raise JaxcoagInputError(f"{name} must be finite and > 0 g cm^-3 (got {v!r}).")
    if not np.isfinite(q):
        raise JaxcoagInputError(f"q must be finite (the size exponent, 3.5 for MRN); got {q!r}.")
    c = np.log(4.0 * np.pi / 3.0 * rho_s)
    lmlo, lmhi = c + 3.0 * np.log(a_min), c + 3.0 * np.log(a_max)
    if lmlo < grid.log_edges[0] or lmhi > grid.log_edges[-1]:
        raise JaxcoagInputError(
            f"the MRN mass range [{np.exp(lmlo):.3g}, {np.exp(lmhi):.3g}] g must lie inside the grid "
            f"[{grid.edges[0]:.3g}, {grid.edges[-1]:.3g}] g; widen the grid or change a_min/a_max.")
    lo = np.clip(grid.log_edges[:-1], lmlo, lmhi)
    hi = np.clip(grid.log_edges[1:], lmlo, lmhi)
    # mass per bin ~ int a^{3-q} da = int m^{(4-q)/3} d ln m / 3 ;  s = (4-q)/3
    s = (4.0 - q) / 3.0
    if abs(s) < 1e-12:
        w = hi - lo
    else:
        ref = lmhi if s > 0 else lmlo
        w = (np.exp(s * (hi - ref)) - np.exp(s * (lo - ref))) / s
    w = np.maximum(w, 0.0)
    mass = rho_d * w / w.sum()
    return mass * np.exp(-grid.log_centers)


def exponential(m0, n0):
    """Callable f(m) = (n0/m0) exp(-m/m0) [cm^-3 g^-1] (the classic exponential start).

    Arguments: m0: e-folding mass [g]; n0: total number density [cm^-3].
    Returns: a function of m [g] (numpy or JAX arrays).
    References: Scott (1968); Golovin (1963).
    """
    m0, n0 = float(m0), float(n0)
    if not (m0 > 0 and n0 > 0 and np.isfinite(m0) and np.isfinite(n0)):
        raise JaxcoagInputError(f"exponential(m0, n0) needs finite m0 > 0 g and n0 > 0 cm^-3 (got {m0!r}, {n0!r}).")

    def f(m):
        return (n0 / m0) * jnp.exp(-jnp.asarray(m) / m0)

    return f
