"""Results to labelled datasets and netCDF files (xarray + h5netcdf / netCDF4).

Every engine's result has ``.to_xarray()`` (:class:`jaxcoag.BinnedResult`,
:class:`jaxcoag.MCResult`) with one common layout:

* dims ``t`` (output times), ``m`` (mass bins), ``m_edge`` (bin edges);
* coords ``t`` [s] and ``t_yr`` [yr] on ``t`` (:func:`time_coords`; 1 yr = 365.25 d =
  3.15576e7 s, ``jaxcoag.constants.yr``), ``m`` [g] (geometric bin centres), ``m_edge`` [g], and
  where the physical state is known (a physical kernel such as ``scene.kernel(gas, rho_s)``;
  ``jaxcoag run`` passes its kernel) the grain radius ``a`` [cm] and Stokes number ``St`` [1] of
  the bin centres on ``m`` (:func:`particle_coords`; Ormel 2008 thesis eqs. 2.4, 4.5/4.6 and ch. 4
  footnote 5). An analytic kernel carries no material density or gas state, so its dataset has
  neither ``a`` nor ``St`` (left out rather than invented);
* variables ``mass_per_bin`` [g cm^-3] (t, m), ``number_per_bin`` [cm^-3] (t, m), ``gel_mass``
  [g cm^-3] (t), ``mass_drift`` [1] (t) and ``status`` (scalar int32 code of the shared
  :class:`jaxcoag.RESULTS`, attributes ``status_name`` / ``status_message``; :func:`result_table`);
* global attributes ``title``, ``Conventions`` (CF-1.10), ``engine`` ("binned" / "mc"),
  ``status`` (the RESULTS name) and the caller's ``attrs``.

Engines add their own variables beside these (binned: solver step counts; MC: per-species arrays
on (t, species)). Every variable carries ``units`` and ``long_name`` attributes (CF style).
netCDF attributes must be str / numbers / 1-D numeric arrays, so anything else is stored as its
``repr``.

``save_netcdf`` takes a dataset or any result and writes atomically (:func:`atomic_write`): the
dataset goes to a temporary file in the target's directory, is flushed and fsync'ed, then
``os.replace``'d onto the target. A failure at any point leaves no partial file at the target (a
previous file there stays intact) and removes the temporary file.

References: CF conventions 1.10 (units, long_name); xarray ``Dataset.to_netcdf``; Ormel (2008)
thesis eqs. 2.4, 4.5, 4.6 (grain radius, friction time).
"""

from __future__ import annotations

import os
import tempfile

import equinox as eqx
import numpy as np

from ._validate import JaxcoagInputError

__all__ = ["save_netcdf", "load_netcdf", "result_table", "time_coords", "particle_coords", "grain_size_stokes",
           "atomic_write"]


def _xr():
    try:
        import xarray as xr
    except ImportError as e:  # pragma: no cover - xarray is a dependency
        raise ImportError("jaxcoag.io needs xarray (pip install xarray h5netcdf).") from e
    return xr


def result_table():
    """Mapping RESULTS code (int, the position in :data:`jaxcoag.RESULT_NAMES`) -> (name, message)
    of the shared status enumeration :class:`jaxcoag.RESULTS` (both engines, files, sweeps)."""
    from . import _status

    return dict(enumerate(_status.result_table()))


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
    """CF-labelled time coordinates of output times ``t_s`` [s]: ``{"t": ... [s], "t_yr": ... [yr]}``
    on the dimension ``t`` (t_yr = t / ``jaxcoag.constants.yr``, the Julian year 3.15576e7 s)."""
    from . import constants as C

    t = np.asarray(t_s, np.float64)
    return {"t": ("t", t, {"units": "s", "long_name": "time"}),
            "t_yr": ("t", t / C.yr, {"units": "yr", "long_name": "time in years",
                                     "comment": f"Julian years: 1 yr = 365.25 d = {C.yr:.8g} s"})}


def particle_coords(kernel, m, dim="m"):
    """Grain radius ``a`` [cm] and Stokes number ``St`` [1] of masses ``m`` [g] as coordinates on
    ``dim``, from a physical kernel's ``particles(m)`` (its material density, drag law and gas
    state: a = (3 m / (4 pi rho_s))^(1/3) for compact grains, St = tau_f / t_L with the Epstein /
    Stokes friction time, Ormel 2008 thesis eqs. 2.4, 4.5, 4.6 and ch. 4 footnote 5).
    Returns {} for kernels without ``particles`` (analytic kernels: no rho_s, no gas state) and for
    kernels of porous grains (``n_struct > 0``: a bin-centre mass alone does not fix the size)."""
    if kernel is None or not hasattr(kernel, "particles") or int(getattr(kernel, "n_struct", 0) or 0) > 0:
        return {}
    a, st = grain_size_stokes(kernel, m)
    return {"a": (dim, a, {"units": "cm", "long_name": "grain radius of the bin-center mass"}),
            "St": (dim, st,
                   {"units": "1", "long_name": "Stokes number tau_f / t_L of the bin-center mass in the run's gas"})}


#: Length the masses of :func:`grain_size_stokes` are padded to (a multiple of it): one compiled program serves
#: the bin centres, the output times' mass peaks and the fragmentation-limit search of a run.
GRAIN_BATCH = 2048


@eqx.filter_jit
def _grains(kernel, m):
    p = kernel.particles(m)
    return p.a, p.st


def grain_size_stokes(kernel, m):
    """Radius a [cm] and Stokes number St [1] of compact grains of masses ``m`` [g] (any shape) in a
    physical kernel's gas, from its ``particles`` (drag law: Ormel 2008 thesis eqs. 2.4, 4.5, 4.6).

    One jitted call on the masses padded to a multiple of :data:`GRAIN_BATCH` (with the first mass):
    evaluated eagerly, ``particles`` compiles each of its operations again for every new array length,
    ~0.3-0.5 s per length, which made up a good part of a ``jaxcoag run``'s output phase. Returns two
    float64 numpy arrays of the shape of ``m``.
    """
    import jax.numpy as jnp

    m = np.asarray(m, np.float64)
    flat = m.reshape(-1)
    n = flat.size
    if n == 0:
        return np.zeros(m.shape), np.zeros(m.shape)
    buf = np.full(-(-n // GRAIN_BATCH) * GRAIN_BATCH, flat[0])
    buf[:n] = flat
    a, st = _grains(kernel, jnp.asarray(buf))
    return (np.asarray(a, np.float64)[:n].reshape(m.shape).copy(),
            np.asarray(st, np.float64)[:n].reshape(m.shape).copy())


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


def save_netcdf(result_or_dataset, path, *, attrs=None, kernel=None, edges=None, engine=None):
    """Write a dataset, or any result with ``.to_xarray`` (BinnedResult, MCResult), to netCDF atomically.

    Arguments:
        result_or_dataset: xarray.Dataset, or a result: it is converted with
            ``result.to_xarray(attrs=attrs, kernel=kernel, edges=edges)``.
        path: target file path (str or PathLike); its directory must exist.
        attrs: global attributes; kernel: the run's physical kernel (adds ``a`` [cm] and ``St``
            on ``m``); edges: mass-bin edges [g] of the binned view (default: the binned grid /
            automatic MC edges) - these three only for a result (set them on a Dataset yourself).
        engine: xarray netCDF engine; default h5netcdf (then netcdf4, scipy).

    Returns:
        the target path (str).

    The data go to a temporary file next to the target (same filesystem), which is fsync'ed
    and then renamed over the target with ``os.replace`` (atomic on POSIX and Windows). On any
    exception the temporary file is removed and an existing target is left untouched.
    """
    xr = _xr()
    if isinstance(result_or_dataset, xr.Dataset):
        given = [k for k, v in (("attrs", attrs), ("kernel", kernel), ("edges", edges)) if v is not None]
        if given:
            raise JaxcoagInputError(f"save_netcdf({', '.join(k + '=...' for k in given)}) is only for saving a result; "
                                    "on a Dataset set ds.attrs yourself, or build it with "
                                    "result.to_xarray(attrs=..., kernel=..., edges=...).")
        ds = result_or_dataset
    elif callable(getattr(result_or_dataset, "to_xarray", None)):
        ds = result_or_dataset.to_xarray(attrs=attrs, kernel=kernel, edges=edges)
    else:
        raise JaxcoagInputError(f"save_netcdf needs an xarray.Dataset or a result with .to_xarray() (the return value of "
                                f"jaxcoag.evolve); got {type(result_or_dataset).__name__}.")
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
