"""The common ``xarray.Dataset`` layout every engine's ``to_xarray`` writes (one place, so that a
binned run and a Monte Carlo run have the same coordinates and variable names).

Layout: dims ``t``, ``m``, ``m_edge`` (plus engine extras such as ``species``); coords ``t`` [s],
``t_yr`` [yr] on ``t``, ``m`` [g] (geometric bin centres), ``m_edge`` [g], and with a physical kernel
``a`` [cm] and ``St`` [1] on ``m``; variables ``mass_per_bin`` [g cm^-3] and ``number_per_bin``
[cm^-3] on (t, m), ``gel_mass`` [g cm^-3] and ``mass_drift`` [1] on t, ``status`` (the
:class:`jaxcoag.RESULTS` code, attributes ``status_name`` and ``status_message``); attributes
``title``, ``Conventions``, ``engine``, ``status``.

References: CF conventions 1.10 (units, long_name).
"""

from __future__ import annotations

import numpy as np

from ._status import result_table
from ._validate import JaxcoagInputError

__all__ = ["common_dataset", "COMMON_COORDS", "COMMON_VARIABLES"]

#: Coordinates every engine's dataset has (``a`` and ``St`` too when a physical kernel is given).
COMMON_COORDS = ("t", "t_yr", "m", "m_edge")
#: Variables every engine's dataset has.
COMMON_VARIABLES = ("mass_per_bin", "number_per_bin", "gel_mass", "mass_drift", "status")


def common_dataset(*, engine, title, t, edges, mass_per_bin, number_per_bin, gel_mass, mass_drift, code,
                   extra=None, extra_coords=None, kernel=None, attrs=None, centres=None):
    """Build the common dataset (module docstring) plus engine-specific ``extra`` variables
    ({name: (dims, values, attrs)}) and ``extra_coords``; ``code`` is the RESULTS integer code;
    ``centres`` [g]: the bin centres when the engine has its own (default sqrt(m_lo m_hi))."""
    from .io import _attr_value, _xr, particle_coords, time_coords

    xr = _xr()
    if attrs is not None and not isinstance(attrs, dict):
        raise JaxcoagInputError("attrs must be a dict of str -> value (scene name, parameters).")
    e = np.asarray(edges, np.float64)
    centres = np.sqrt(e[:-1] * e[1:]) if centres is None else np.asarray(centres, np.float64)
    name, message = result_table()[int(code)]
    data = {
        "mass_per_bin": (("t", "m"), np.asarray(mass_per_bin, np.float64),
                         {"units": "g cm-3", "long_name": "dust mass density per mass bin"}),
        "number_per_bin": (("t", "m"), np.asarray(number_per_bin, np.float64),
                           {"units": "cm-3", "long_name": "dust number density per mass bin"}),
        "gel_mass": (("t",), np.asarray(gel_mass, np.float64),
                     {"units": "g cm-3", "long_name": "mass density above the top mass-bin edge"}),
        "mass_drift": (("t",), np.asarray(mass_drift, np.float64),
                       {"units": "1", "long_name": "relative total-mass change (M(t) - M(t0)) / M(t0)"}),
        "status": ((), np.int32(code), {"units": "1", "long_name": "jaxcoag.RESULTS code (0 = successful)",
                                        "status_name": name, "status_message": message}),
    }
    data.update(extra or {})
    coords = {
        **time_coords(np.asarray(t, np.float64)),
        "m": ("m", centres, {"units": "g", "long_name": "geometric bin-centre mass sqrt(m_lo m_hi)"}),
        "m_edge": ("m_edge", e, {"units": "g", "long_name": "mass-bin edges"}),
        **particle_coords(kernel, centres, dim="m"),
    }
    coords.update(extra_coords or {})
    ds = xr.Dataset(data_vars=data, coords=coords)
    ds.attrs["title"] = title
    ds.attrs["Conventions"] = "CF-1.10"
    ds.attrs["engine"] = engine
    ds.attrs["status"] = name
    for k, v in (attrs or {}).items():
        if not isinstance(k, str):
            raise JaxcoagInputError(f"attrs keys must be strings (got {k!r}).")
        ds.attrs[k] = _attr_value(v)
    return ds
