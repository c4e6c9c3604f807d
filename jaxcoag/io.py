"""Solutions to labelled datasets and netCDF files (xarray + h5netcdf / netCDF4).

``to_xarray(solution)`` turns a :class:`~jaxcoag.binned.BinnedSolution` into an
``xarray.Dataset`` with coordinates

* ``time`` [s] (nt,), with ``t_yr`` [yr] (time) beside it: the same times in Julian years
  (1 yr = 365.25 d = 3.15576e7 s, ``jaxcoag.constants.yr``),
* ``mass`` [g] (nbins,) - geometric bin centers, and ``mass_edge`` [g] (nbins+1,) - edges,
* where the physical state is known (``to_xarray(..., kernel=K)`` with a physical kernel such as
  ``scene.kernel(gas, rho_s)``; ``jaxcoag run`` passes its kernel): the grain radius ``a`` [cm]
  (mass) of the bin centers and their Stokes number ``St`` [1] (mass) = tau_f Omega_L in the run's
  gas state (Ormel 2008 thesis eqs. 2.4, 4.5/4.6; ch. 4 footnote 5). An analytic kernel carries
  no material density or gas state, so its dataset has neither ``a`` nor ``St`` (they are left
  out rather than invented),

and data variables ``mass_per_bin`` [g cm^-3] (time, mass), ``number_per_bin`` [cm^-3]
(time, mass), ``gel_mass`` [g cm^-3] (time), ``mass_drift`` [-] (time), ``result_code`` (int,
a :class:`~jaxcoag.binned.RESULTS` index) with attributes ``result_name``/``result_message``, and
the solver step counts. Every variable carries ``units`` and ``long_name`` attributes (CF style).
Caller-supplied ``attrs`` (scene name, alpha, rho_g, ...) are stored as global attributes;
netCDF attributes must be str / numbers / 1-D numeric arrays, so anything else is stored as
its ``repr``.

``save_netcdf`` writes atomically: the dataset goes to a temporary file in the target's
directory, is flushed and fsync'ed, then ``os.replace``'d onto the target. A failure at any
point leaves no partial file at the target (a previous file there stays intact) and removes
the temporary file.

References: CF conventions 1.10 (units, long_name); xarray ``Dataset.to_netcdf``;
docs/design_notes.md, house style (results -> io -> plot).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ._validate import JaxcoagInputError

__all__ = ["to_xarray", "save_netcdf", "load_netcdf", "result_table", "time_coords", "particle_coords"]


def _xr():
    try:
        import xarray as xr
    except ImportError as e:  # pragma: no cover - xarray is a dependency
        raise ImportError("jaxcoag.io needs xarray (pip install xarray h5netcdf).") from e
    return xr


def result_table():
    """Mapping RESULTS index (int) -> (name, message) for :class:`jaxcoag.binned.RESULTS`."""
    from .binned import RESULT_NAMES, RESULTS

    return {code: (name, RESULTS[getattr(RESULTS, name)]) for code, name in enumerate(RESULT_NAMES)}


def _attr_value(v):
    """Coerce a caller attribute to something netCDF can store."""
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (str, int, float, np.integer, np.floating)):
        return v
    try:
        a = np.asarray(v)
    except Exception:  # noqa: BLE001 - anything not array-like is stored as its repr
        return repr(v)
    if a.dtype.kind in "iuf" and a.ndim <= 1:
        return a.item() if a.ndim == 0 else a
    if a.dtype.kind == "b" and a.ndim <= 1:
        return a.astype(np.int8).item() if a.ndim == 0 else a.astype(np.int8)
    return repr(v)


def time_coords(t_s):
    """CF-labelled time coordinates of output times ``t_s`` [s]: ``{"time": ... [s], "t_yr": ... [yr]}``
    on the dimension ``time`` (t_yr = t / ``jaxcoag.constants.yr``, the Julian year 3.15576e7 s)."""
    from . import constants as C

    t = np.asarray(t_s, np.float64)
    return {"time": ("time", t, {"units": "s", "long_name": "time"}),
            "t_yr": ("time", t / C.yr, {"units": "yr", "long_name": "time in years",
                                         "comment": f"Julian years: 1 yr = 365.25 d = {C.yr:.8g} s"})}


def particle_coords(kernel, m, dim="mass"):
    """Grain radius ``a`` [cm] and Stokes number ``St`` [1] of masses ``m`` [g] as coordinates on
    ``dim``, from a physical kernel's ``particles(m)`` (its material density, drag law and gas
    state: a = (3 m / (4 pi rho_s))^(1/3) for compact grains, St = tau_f / t_L with the Epstein /
    Stokes friction time, Ormel 2008 thesis eqs. 2.4, 4.5, 4.6 and ch. 4 footnote 5).
    Returns {} for kernels without ``particles`` (analytic kernels: no rho_s, no gas state)."""
    if kernel is None or not hasattr(kernel, "particles"):
        return {}
    import jax.numpy as jnp

    p = kernel.particles(jnp.asarray(np.asarray(m, np.float64)))
    return {"a": (dim, np.asarray(p.a, np.float64),
                  {"units": "cm", "long_name": "grain radius of the bin-center mass"}),
            "St": (dim, np.asarray(p.st, np.float64),
                   {"units": "1", "long_name": "Stokes number tau_f / t_L of the bin-center mass in the run's gas"})}


def to_xarray(solution, *, attrs=None, kernel=None):
    """Labelled dataset of a binned solution.

    Arguments:
        solution: a :class:`jaxcoag.binned.BinnedSolution` (not vmapped: ``mass_per_bin`` of
            shape (nt, nbins); index a batched solution first, or use :func:`jaxcoag.sweep.sweep`).
        attrs: optional dict of global attributes (scene name, parameters such as
            ``alpha``, ``rho_g`` [g cm^-3], ``T`` [K], ``rho_s`` [g cm^-3], ...). Keys must be
            strings; values that netCDF cannot hold are stored as their ``repr``.
        kernel: optional physical kernel (``scene.kernel(gas, rho_s)``, compact grains) that
            the solution was computed with; adds the coordinates ``a`` [cm] and ``St`` [1] on
            ``mass``. Kernels without ``particles`` (analytic kernels) add nothing.

    Returns:
        xarray.Dataset with coords ``time`` [s], ``t_yr`` [yr] (time), ``mass`` [g],
        ``mass_edge`` [g], and with a physical kernel ``a`` [cm] and ``St`` [1] (mass);
        variables ``mass_per_bin`` [g cm^-3], ``number_per_bin`` [cm^-3], ``gel_mass``
        [g cm^-3], ``mass_drift`` [-], ``result_code`` [-], ``steps``, ``rejected_steps``.

    References: CF conventions (units / long_name attributes).
    """
    xr = _xr()
    from .binned import BinnedSolution

    if not isinstance(solution, BinnedSolution):
        raise JaxcoagInputError(f"to_xarray needs a jaxcoag.binned.BinnedSolution, got {type(solution).__name__}.")
    rho = np.asarray(solution.mass_per_bin, dtype=np.float64)
    if rho.ndim != 2:
        raise JaxcoagInputError(
            f"to_xarray takes one solution with mass_per_bin of shape (nt, nbins); got shape {rho.shape} "
            "(a vmapped batch?). Index one member first, or build the dataset with jaxcoag.sweep.sweep.")
    if attrs is not None and not isinstance(attrs, dict):
        raise JaxcoagInputError("attrs must be a dict of str -> value (scene name, parameters).")
    grid = solution.grid
    from .binned import result_code

    code = int(np.asarray(result_code(solution.result)))
    name, message = result_table()[code]
    stats = solution.stats
    ds = xr.Dataset(
        data_vars={
            "mass_per_bin": (("time", "mass"), rho,
                             {"units": "g cm-3", "long_name": "dust mass density per mass bin"}),
            "number_per_bin": (("time", "mass"), np.asarray(solution.number_per_bin, np.float64),
                               {"units": "cm-3", "long_name": "dust number density per mass bin"}),
            "gel_mass": (("time",), np.asarray(solution.gel_mass, np.float64),
                         {"units": "g cm-3", "long_name": "mass density that left through the top of the grid"}),
            "mass_drift": (("time",), np.asarray(solution.mass_drift, np.float64),
                           {"units": "1", "long_name": "relative total-mass change (M(t) - M(t0)) / M(t0) incl. gel"}),
            "result_code": ((), np.int32(code),
                            {"units": "1", "long_name": "jaxcoag.binned.RESULTS index (0 = successful)",
                             "result_name": name, "result_message": message}),
            "steps": ((), np.int64(np.asarray(stats["steps"])), {"units": "1", "long_name": "accepted solver steps"}),
            "rejected_steps": ((), np.int64(np.asarray(stats["rejected"])),
                               {"units": "1", "long_name": "rejected solver steps"}),
        },
        coords={
            **time_coords(solution.ts),
            "mass": ("mass", np.asarray(grid.centers, np.float64),
                     {"units": "g", "long_name": "geometric bin-center mass sqrt(m_lo m_hi)"}),
            "mass_edge": ("mass_edge", np.asarray(grid.edges, np.float64),
                          {"units": "g", "long_name": "mass-bin edges"}),
            **particle_coords(kernel, grid.centers),
        },
    )
    ds.attrs["title"] = "jaxcoag binned coagulation solution"
    ds.attrs["Conventions"] = "CF-1.10"
    ds.attrs["result"] = name
    for k, v in (attrs or {}).items():
        if not isinstance(k, str):
            raise JaxcoagInputError(f"attrs keys must be strings (got {k!r}).")
        ds.attrs[k] = _attr_value(v)
    return ds


def _pick_engine():
    for eng, mod in (("h5netcdf", "h5netcdf"), ("netcdf4", "netCDF4"), ("scipy", "scipy")):
        try:
            __import__(mod)
            return eng
        except ImportError:  # pragma: no cover - depends on the environment
            continue
    raise ImportError("saving netCDF needs h5netcdf, netCDF4 or scipy.")  # pragma: no cover



def atomic_write(path, write, *, what="output file"):
    """Write ``path`` atomically: ``write(tmp)`` fills a temporary file in the same directory,
    which is fsync'ed, given the usual permissions (0666 & ~umask; ``mkstemp`` makes 0600)
    and renamed over ``path`` with ``os.replace`` (atomic on POSIX and Windows). On any
    exception the temporary file is removed and an existing ``path`` is left untouched.

    Arguments:
        path: target file path (str or PathLike); its directory must exist.
        write: callable taking the temporary file path (str) and writing the content there.
        what: name used in the error message when the directory is missing.

    Returns:
        the target path (str).
    """
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise JaxcoagInputError(f"directory {d!r} for the {what} does not exist; create it first.")
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=d)
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.remove(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def save_netcdf(ds_or_solution, path, *, attrs=None, engine=None, kernel=None):
    """Write a dataset (or a BinnedSolution, via :func:`to_xarray`) to netCDF atomically.

    Arguments:
        ds_or_solution: xarray.Dataset or BinnedSolution.
        path: target file path (str or PathLike); its directory must exist.
        attrs: global attributes, only used when a solution is given.
        kernel: the solution's physical kernel (adds ``a`` [cm] and ``St``; see :func:`to_xarray`),
            only used when a solution is given.
        engine: xarray netCDF engine; default h5netcdf (then netcdf4, scipy).

    Returns:
        the target path (str).

    The data go to a temporary file next to the target (same filesystem), which is fsync'ed
    and then renamed over the target with ``os.replace`` (atomic on POSIX and Windows). On any
    exception the temporary file is removed and an existing target is left untouched.
    """
    xr = _xr()
    if isinstance(ds_or_solution, xr.Dataset):
        if attrs is not None:
            raise JaxcoagInputError("attrs is only used when saving a solution; set ds.attrs on a Dataset instead.")
        if kernel is not None:
            raise JaxcoagInputError("kernel is only used when saving a solution; build the Dataset with "
                                    "to_xarray(solution, kernel=K) instead.")
        ds = ds_or_solution
    else:
        ds = to_xarray(ds_or_solution, attrs=attrs, kernel=kernel)
    path = os.fspath(path)
    if os.path.isdir(path):
        raise JaxcoagInputError(f"{path!r} is a directory; give a file path such as {os.path.join(path, 'run.nc')!r}.")
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise JaxcoagInputError(f"directory {d!r} for the netCDF file does not exist; create it first.")
    engine = engine or _pick_engine()
    atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine=engine))
    return path


def load_netcdf(path, *, engine=None):
    """Read a dataset written by :func:`save_netcdf` fully into memory (the file is closed).

    Arguments: path: netCDF file; engine: xarray engine (default as in save_netcdf).
    Returns: xarray.Dataset.
    """
    xr = _xr()
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no netCDF file at {path!r}.")
    with xr.open_dataset(path, engine=engine or _pick_engine()) as ds:
        return ds.load()
