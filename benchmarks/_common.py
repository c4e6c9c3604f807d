"""Shared helpers for the benchmark scripts: machine record, analytic references, metrics, I/O.

Everything here is plain numpy/scipy so the peer runners (DustPy, PySDM) work without JAX and
the references are independent of :mod:`jaxcoag.analytic` (which the scripts cross-check
against when it is importable).

Conventions (cgs throughout):

* ``edges`` are bin edges in mass [g]; "mass per bin" is the mass density [g cm^-3] (or surface
  density [g cm^-2] for DustPy's vertically integrated boxes, the equations being identical)
  held by the particles whose mass lies in the bin.
* The accuracy metric is the relative L1 error of mass per bin,
  ``L1 = sum_b |M_b - M_b^ref| / sum_b M_b^ref`` (twice the total-variation distance when both
  totals agree; 0 is exact, 2 is disjoint).

References: Smoluchowski (1916) and Scott (1968) (constant kernel, exponential initial
condition); Golovin (1963) and Scott (1968) (sum kernel, exponential initial condition);
error metrics: docs/design_notes.md (Monte Carlo conventions).
"""

from __future__ import annotations

import datetime as _dt
import importlib
import json
import os
import pathlib
import platform
import subprocess
import sys
import time

import numpy as np
from scipy import special

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = pathlib.Path(__file__).resolve().parent / "results"

_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)

NOISE_NOTE = ("Timings were taken on a shared 2-core machine while other jobs were running; "
              "wall times are noisy (expect +-50 %), ratios between codes run in the same "
              "invocation are more reliable than absolute values.")


# ----------------------------------------------------------------------------------------------
# machine record
# ----------------------------------------------------------------------------------------------
def _version(mod):
    try:
        m = importlib.import_module(mod)
        return str(getattr(m, "__version__", "unknown"))
    except Exception as exc:  # noqa: BLE001 - record why a module is missing
        return f"not importable ({type(exc).__name__})"


def _cpu_model():
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info():
    """Dictionary describing the machine and the software versions of this run.

    Returns
    -------
    dict with cpu model, logical core count, load average at the time of the call, platform,
    python and package versions (jax, jaxlib, numpy, scipy, dustpy, PySDM, numba), UTC time and
    the git revision of the repository (read-only ``git rev-parse``).
    """
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                             capture_output=True, text=True, timeout=10).stdout.strip()
    except Exception:  # noqa: BLE001
        rev = "unknown"
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    return {
        "cpu": _cpu_model(),
        "logical_cores": os.cpu_count(),
        "load_average_1_5_15min": load,
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "versions": {m: _version(m) for m in
                     ("jax", "jaxlib", "numpy", "scipy", "dustpy", "PySDM", "numba", "diffrax")},
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "git_revision": rev,
        "timing_note": NOISE_NOTE,
    }


# ----------------------------------------------------------------------------------------------
# analytic references (exponential initial condition f(m,0) = n0/m0 exp(-m/m0))
# ----------------------------------------------------------------------------------------------
def _check_edges(edges):
    edges = np.asarray(edges, dtype=np.float64)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.diff(edges) > 0) or edges[0] <= 0:
        raise ValueError("edges must be a 1-D, strictly increasing array of positive masses [g]")
    return edges


def mass_per_bin_constant_exp(edges, t, *, coeff, n0, m0):
    """Exact mass per bin for K = coeff from an exponential initial condition.

    f(m, t) = n0 / (m0 s^2) exp(-m / (m0 s)), s = 1 + coeff n0 t / 2, so the mass in [a, b] is
    n0 m0 [Gamma(2, a/(m0 s)) - Gamma(2, b/(m0 s))] (regularised upper incomplete gamma).

    Parameters: edges [g] (nbins+1,), t [s], coeff [cm^3 s^-1], n0 [cm^-3], m0 [g] (mean mass
    at t = 0). Returns mass per bin [g cm^-3], shape (nbins,).
    References: Smoluchowski (1916); Scott (1968).
    """
    edges = _check_edges(edges)
    s = 1.0 + 0.5 * coeff * n0 * t
    y = edges / (m0 * s)
    upper = special.gammaincc(2.0, y)
    return n0 * m0 * (upper[:-1] - upper[1:])


def mass_density_sum_exp(m, t, *, coeff, n0, m0):
    """Mass density m f(m, t) [g cm^-3 g^-1] for K = coeff (m1 + m2), exponential start.

    With eps = exp(-coeff n0 m0 t), T = 1 - eps and x = m/m0:
    m f = n0 eps / sqrt(T) exp(-(1 - sqrt T)^2 x) ive(1, 2 sqrt(T) x)   (T > 0),
    m f = n0 x exp(-x)                                                  (T = 0).
    References: Golovin (1963); Scott (1968).
    """
    m = np.asarray(m, dtype=np.float64)
    x = m / m0
    eps = np.exp(-coeff * n0 * m0 * t)
    T = -np.expm1(-coeff * n0 * m0 * t)
    if T <= 0.0:
        return n0 * x * np.exp(-x)
    sT = np.sqrt(T)
    return n0 * eps / sT * np.exp(-((1.0 - sT) ** 2) * x) * _ive1(2.0 * sT * x)


def _ive1(z):
    """exp(-z) I_1(z) for z >= 0, finite for all z (scipy returns NaN above ~1e9)."""
    z = np.asarray(z, dtype=np.float64)
    big = z > 1e6
    zs = np.where(big, 1.0, z)
    zb = np.where(big, z, 1e6)
    asym = (1.0 - 3.0 / (8.0 * zb) - 15.0 / (128.0 * zb * zb)) / np.sqrt(2.0 * np.pi * zb)
    return np.where(big, asym, special.ive(1, zs))


def mass_per_bin_sum_exp(edges, t, *, coeff, n0, m0):
    """Exact mass per bin [g cm^-3] for the sum kernel from an exponential start.

    Gauss-Legendre (48 nodes per bin) in ln m of :func:`mass_density_sum_exp`; bins are
    narrower than a factor 2 in every benchmark so the quadrature error is below 1e-12.
    """
    edges = _check_edges(edges)
    lo, hi = np.log(edges[:-1]), np.log(edges[1:])
    half = 0.5 * (hi - lo)
    lnm = 0.5 * (hi + lo)[:, None] + half[:, None] * _GL_X[None, :]
    m = np.exp(lnm)
    integrand = mass_density_sum_exp(m, t, coeff=coeff, n0=n0, m0=m0) * m
    return np.sum(integrand * _GL_W[None, :], axis=1) * half


def reference_mass_per_bin(kind, edges, t, *, coeff, n0, m0):
    """Mass per bin [g cm^-3] for ``kind`` in ("constant", "sum", "product"), exponential start.

    Constant and sum use the closed forms of this module; the product kernel has no closed form
    here and is taken from :func:`jaxcoag.analytic.mass_per_bin` (ImportError if absent).
    """
    if kind == "constant":
        return mass_per_bin_constant_exp(edges, t, coeff=coeff, n0=n0, m0=m0)
    if kind == "sum":
        return mass_per_bin_sum_exp(edges, t, coeff=coeff, n0=n0, m0=m0)
    if kind == "product":
        from jaxcoag import analytic
        return np.asarray(analytic.mass_per_bin("product", edges, t, coeff=coeff, n0=n0, m0=m0,
                                                initial="exponential"))
    raise ValueError(f"unknown kernel kind {kind!r}; use 'constant', 'sum' or 'product'")


def cross_check_reference(kind, edges, t, *, coeff, n0, m0):
    """Relative L1 between this module's reference and :mod:`jaxcoag.analytic`'s.

    Returns a float, or None when ``jaxcoag.analytic`` cannot be imported or has a different
    signature (the reason is returned as a string then).
    """
    try:
        from jaxcoag import analytic
        theirs = np.asarray(analytic.mass_per_bin(kind, edges, t, coeff=coeff, n0=n0, m0=m0,
                                                  initial="exponential"))
    except Exception as exc:  # noqa: BLE001 - a cross-check must not abort the benchmark
        return f"unavailable: {type(exc).__name__}: {exc}"
    ours = reference_mass_per_bin(kind, edges, t, coeff=coeff, n0=n0, m0=m0)
    return rel_l1(theirs, ours)


# ----------------------------------------------------------------------------------------------
# metrics, grids
# ----------------------------------------------------------------------------------------------
def rel_l1(sim, ref):
    """Relative L1 error sum|sim - ref| / sum ref of two mass-per-bin arrays (same grid)."""
    sim = np.asarray(sim, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if sim.shape != ref.shape:
        raise ValueError(f"shape mismatch {sim.shape} vs {ref.shape}")
    return float(np.sum(np.abs(sim - ref)) / np.sum(ref))


def dustpy_edges(m):
    """Bin edges [g] that DustPy's own analytic-kernel notebook implies for its mass grid ``m``.

    The notebook converts Sigma_i = N(m_i) m_i (B m_i) with B = 2 (A - 1)/(A + 1), A the grid
    ratio, i.e. bin i spans [2 m_i/(A + 1), 2 A m_i/(A + 1)]: interior edges at the harmonic
    means 2 m_i m_{i+1}/(m_i + m_{i+1}).
    """
    m = np.asarray(m, dtype=np.float64)
    A = float(np.mean(m[1:] / m[:-1]))
    return np.concatenate([m * 2.0 / (A + 1.0), [m[-1] * 2.0 * A / (A + 1.0)]])


def log_edges(m_min, m_max, bins_per_decade):
    """Logarithmic bin edges [g] with ``bins_per_decade`` bins per decade from m_min to m_max."""
    n = int(round(np.log10(m_max / m_min) * bins_per_decade))
    return np.geomspace(m_min, m_max, n + 1)


# ----------------------------------------------------------------------------------------------
# timing and I/O
# ----------------------------------------------------------------------------------------------
class Timer:
    """Context manager measuring wall time with ``time.perf_counter`` (attribute ``.seconds``)."""

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._t0
        return False


def first_and_best(call, repeat=2):
    """(result, first_call_s, best_s): one compiling call of ``call()`` (blocked until ready), then the best
    wall time of ``repeat`` more calls (inf when repeat = 0; the result is the last call's)."""
    import jax

    t0 = time.perf_counter()
    r = call()
    jax.block_until_ready(r)
    first = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = call()
        jax.block_until_ready(r)
        best = min(best, time.perf_counter() - t0)
    return r, first, best


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return float(f"{v:.9g}") if np.isfinite(v) else None   # 9 digits keep files small
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def write_json(path, payload):
    """Write ``payload`` (dict) as indented JSON to ``path``, atomically (a temporary file in the same folder,
    then ``os.replace``: an interrupted run never leaves a truncated file).

    Floats are stored with 9 significant digits; non-finite floats become null; other objects as ``str``.
    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        json.dump(_jsonable(payload), fh, indent=1, default=str)
    os.replace(tmp, path)
    return path


def print_table(rows, columns, title=None):
    """Print ``rows`` (list of dicts) as a fixed-width text table with the given ``columns``."""
    def fmt(v):
        if isinstance(v, float):
            if v == 0.0 or 1e-3 <= abs(v) < 1e5:
                return f"{v:.4g}"
            return f"{v:.3e}"
        return "-" if v is None else str(v)

    cells = [[fmt(r.get(c)) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) if cells else len(c)
              for i, c in enumerate(columns)]
    if title:
        print(f"\n{title}")
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)))
    sys.stdout.flush()


def ensure_x64():
    """Turn on float64 in JAX for a benchmark process (scripts, not the library, may do this)."""
    import jax
    jax.config.update("jax_enable_x64", True)
