"""Thesis ch. 6 tabulated collision recipe (O09): tables, interpolation and outcome assembly.

The recipe of Ormel, Paszun, Dominik & Tielens (2009) gives, for a *global* (similar-size or
shattering) and a *local* (cratering/erosion) recipe, six quantities tabulated on a grid of
normalised energy eps, initial filling factor phi_ini (a_out/a for f_miss) and impact
parameter b/b_max:

    fmiss  fraction of misses                         (column axis: a_out/a)
    Nf, Sf mean and std of the number of large fragments (0..2)
    fpwl   mass in the small-fragment power law: global = fraction of M_tot,
           local = in units of m_mu (erratum 13: NOT M_tot)
    q      slope dn/dm ∝ m^q of the small fragments
    Csig   C_phi = phi/phi_ini of the large remnant   (eps axis is eps_roll = E/(N_tot E_roll))

Only two of the 72 tables are printed in the thesis (T-Tab6.7 global b=0 fpwl, T-Tab6.9 local
b=0 fpwl); both ship here (:data:`TAB6_7`, :data:`TAB6_9`). :meth:`RecipeTables.from_cds`
loads the full published set (Ormel et al. 2009, CDS J/A+A/502/845, in the thesis App. 6.A
layout: one table per block headed ``# GLOBAL, b=0.0, Q=fpwl``). :meth:`RecipeTables.surrogate`
builds smooth surrogate tables from the thesis's verbal constraints; they are a [CHOICE], carry
``is_surrogate=True``, and any figure made with them must say so.

Interpolation (``expected`` mode, for gradients and binned engines) is multilinear in
(eps | log eps, phi, b), clamped to the edge nodes. ``sample`` mode picks one node per axis
with probability P(x1) = (x2 - x)/(x2 - x1) (erratum 14 fixed).

References: Ormel 2008 thesis §6.3-6.4, eqs. 6.22-6.30, Tabs. 6.2, 6.3, 6.7-6.9, Fig. 6.7,
App. 6.A; Ormel et al. 2009 (A&A 502, 845); errata 12-18 in docs/design_notes.md.
"""

from __future__ import annotations

import gzip
import pathlib
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._validate import JaxcoagInputError
from .contact import Material
from .outcome import Outcome, pair_inputs, mix_outcomes
from .porosity import (_chk, _outer_radius_ratio, _phi_hit_and_stick_o09, _reduced_mass,
                       smooth_step)
from .safe import safe_log

__all__ = [
    "QUANTITIES",
    "B_GRID",
    "GLOBAL_PHI",
    "LOCAL_PHI",
    "GLOBAL_EPS",
    "LOCAL_EPS",
    "TAB6_7",
    "TAB6_9",
    "RecipeTable",
    "RecipeTables",
    "interp_weights",
    "interpolate",
    "sample_nodes",
    "b_average_weights",
    "o09_outcome",
]

QUANTITIES = ("fmiss", "Nf", "Sf", "fpwl", "q", "Csig")
B_GRID = (0.0, 0.25, 0.5, 0.75, 0.875, 0.95)
GLOBAL_PHI = (0.121938, 0.155263, 0.189273, 0.250536)
LOCAL_PHI = (0.0700907, 0.0904748, 0.126801, 0.160992)
# eps grids of the printed tables: 0.228827 (v / 1 m s^-1)^2 (global), 0.228847 v^2 (local)
GLOBAL_EPS = (0.000572118, 0.0205945, 0.0572069, 0.128715, 0.228827, 0.915310, 3.66124, 8.23779, 14.6450)
LOCAL_EPS = (0.228847, 0.915388, 3.66124, 14.6450, 32.9511, 58.5798)

# T-Tab6.7: GLOBAL, b = 0, fpwl (fraction of M_tot); rows eps = GLOBAL_EPS, columns GLOBAL_PHI
TAB6_7 = (
    (0, 0, 0, 0),
    (0, 0.002500, 0, 0),
    (0.000833, 0, 0, 0),
    (0.092500, 0.030417, 0.008750, 0.0029167),
    (0.388750, 0.094167, 0.030417, 0.015000),
    (0.957500, 0.603333, 0.243750, 0.115833),
    (1, 1, 1, 0.727083),
    (1, 1, 1, 1),
    (1, 1, 1, 1),
)
# T-Tab6.9: LOCAL, b = 0, fpwl in units of m_mu; rows eps = LOCAL_EPS, columns LOCAL_PHI
TAB6_9 = (
    (0, 0, 0, 0),
    (1.00100, 0.333667, 0, 0),
    (4.00400, 46.5465, 6.33967, 0.667333),
    (7.00700, 67.0670, 35.2018, 9.00900),
    (7.50750, 148.315, 58.2248, 16.0160),
    (9.50950, 129.129, 62.3957, 30.0300),
)

_Q = {name: i for i, name in enumerate(QUANTITIES)}


class RecipeTable(eqx.Module):
    """All six quantities of one recipe (global or local) on one grid; float array leaves.

    Fields:
        eps: (6, n_eps) energy axis per quantity [-] (eps_roll for Csig), increasing.
        col: (6, n_col) column axis per quantity [-]: phi_ini (a_out/a for fmiss), increasing.
        b: (n_b,) b/b_max nodes [-], increasing.
        values: (6, n_b, n_eps, n_col) table values in QUANTITIES order.

    References: Ormel 2008 thesis Tab. 6.3, App. 6.A.
    """

    eps: jax.Array
    col: jax.Array
    b: jax.Array
    values: jax.Array

    def __check_init__(self):
        v = np.asarray(self.values) if not isinstance(self.values, jax.core.Tracer) else None
        if v is not None:
            if v.ndim != 4 or v.shape[0] != len(QUANTITIES):
                raise ValueError(f"RecipeTable.values must have shape (6, n_b, n_eps, n_col); got {v.shape}")
            if np.shape(self.eps) != (6, v.shape[2]) or np.shape(self.col) != (6, v.shape[3]) \
                    or np.shape(self.b) != (v.shape[1],):
                raise ValueError("RecipeTable axes do not match values: eps (6, n_eps), col (6, n_col), b (n_b,)")


class RecipeTables(eqx.Module):
    """The global and local recipe tables.

    Fields: glob, loc: :class:`RecipeTable`; is_surrogate: static bool (True for
    :meth:`surrogate` tables: label every figure made with them).

    Constructors: :meth:`surrogate` (no download needed; [CHOICE] surrogates that contain the
    printed T-Tab6.7/6.9), :meth:`from_cds` (the published tables).

    References: Ormel 2008 thesis §6.3.9, App. 6.A, Tabs. 6.3, 6.7-6.9.
    """

    glob: RecipeTable
    loc: RecipeTable
    is_surrogate: bool = eqx.field(static=True, default=False)

    @classmethod
    def surrogate(cls) -> "RecipeTables":
        """Smooth surrogate tables from the thesis's verbal constraints ([CHOICE], labelled).

        - fpwl: b = 0 equals the printed T-Tab6.7 (global) / T-Tab6.9 (local); for b > 0 it is
          scaled down: at b = 0.75 to 25 % (the recipe's most compact phi column: 0.2505
          global, 0.1610 local) ... 6 % (its least compact one: 0.1219 global, 0.0701 local),
          linearly in phi and in b below 0.75, and by (1 - b)/0.25 above;
        - q: global b = 0 from -2.0 at eps <= 0.1 to -3.7 at eps >= 20 (linear in ln eps);
          offset impacts q = -2.0 + 0.4 b (shallower than -2); local from -1.3 to -2.0
          across the local eps range;
        - Nf = 1 at b = 0, rising to 2 for b >= 0.75 between eps = 0.3 and 1; Sf = 0;
        - Csig: 0.95 below eps_roll = 0.1 (hit-and-stick decompaction), 1 at 0.2, rising to
          max(1, 0.33/phi) at eps_roll = 1; 1 for b >= 0.75 above 1 m/s (eps >= 0.2288);
        - fmiss = 0.

        References: Ormel 2008 thesis §6.3.3-6.3.8, Figs. 6.3-6.5.
        """
        return cls(glob=_surrogate_table("global"), loc=_surrogate_table("local"), is_surrogate=True)

    @classmethod
    def from_cds(cls, path) -> "RecipeTables":
        """Load the published tables (Ormel et al. 2009, CDS J/A+A/502/845) from a file or a directory.

        Format (thesis App. 6.A): 72 tables, each headed ``# GLOBAL, b=0.0, Q=fpwl`` (recipe
        GLOBAL|LOCAL, case-insensitive; b/b_max; Q one of fmiss, Nf, Sf, fpwl, q, Csig, or the
        CDS catalogue's names Nfk = Nf and Cphi = Csig). Inside a table:

        - optional column-title lines that do not start with a number (the printed tables
          carry ``ε  φ^ini``) are skipped;
        - the first numeric row is the column axis (phi_ini, or a_out/a for fmiss), either
          as printed (only the n_col axis values, the corner cell left blank) or with a
          placeholder in the corner cell (as :meth:`to_text` writes it);
        - every following row is eps (eps_roll for Csig) then the n_col values.

        Fields may be separated by tabs or runs of blanks (fixed-width columns). Other lines
        starting with ``#`` are comments. In a directory every regular file is read except the
        catalogue's ``ReadMe`` (its byte-by-byte description is not table data); ``*.gz``
        files are decompressed.

        Arguments: path: file or directory.
        Returns: :class:`RecipeTables` with is_surrogate = False.
        Raises: JaxcoagInputError naming the table and line that does not fit the format.
        References: Ormel 2008 thesis App. 6.A (Tabs. 6.7-6.9); Ormel et al. 2009, A&A 502, 845.
        """
        p = pathlib.Path(path)
        if p.is_dir():
            files = sorted(f for f in p.iterdir() if f.is_file() and not f.name.lower().startswith("readme"))
        else:
            files = [p]
        if not files:
            raise FileNotFoundError(f"no table files found in {p} (a CDS ReadMe alone holds no tables)")
        blocks = {}
        for f in files:
            raw = f.read_bytes()
            if f.suffix == ".gz":
                raw = gzip.decompress(raw)
            new = _parse_cds(raw.decode("utf-8"), source=str(f))
            twice = sorted(set(new) & set(blocks))
            if twice:
                r, bb, q = twice[0]
                raise JaxcoagInputError(f"table {r}, b={bb:g}, Q={q} appears in more than one file (again in {f}); "
                                        "keep one copy")
            blocks.update(new)
        return cls(glob=_assemble(blocks, "GLOBAL"), loc=_assemble(blocks, "LOCAL"), is_surrogate=False)

    def to_text(self) -> str:
        """Serialise in the :meth:`from_cds` format (round-trip)."""
        out = []
        for name, t in (("GLOBAL", self.glob), ("LOCAL", self.loc)):
            for iq, q in enumerate(QUANTITIES):
                for ib, b in enumerate(np.asarray(t.b)):
                    out.append(f"# {name}, b={b:g}, Q={q}")
                    out.append("0 " + " ".join(f"{c:.17g}" for c in np.asarray(t.col[iq])))
                    for ie, e in enumerate(np.asarray(t.eps[iq])):
                        out.append(f"{e:.17g} " + " ".join(f"{v:.17g}" for v in np.asarray(t.values[iq, ib, ie])))
        return "\n".join(out) + "\n"


_HEADER = re.compile(r"#\s*(GLOBAL|LOCAL)\s*,\s*b\s*=\s*([0-9.eE+-]+)\s*,\s*Q\s*=\s*(\w+)", re.I)
# quantity keywords: thesis App. 6.A names, and the CDS catalogue's names (Nfk, Cphi)
_QNAMES = {**{k.lower(): k for k in QUANTITIES}, "nfk": "Nf", "cphi": "Csig"}


def _is_number(tok):
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _parse_cds(text, source="<text>"):
    """Tables of one text in the App. 6.A layout -> {(recipe, b, Q): (eps, col, values)}."""
    blocks, key, rows = {}, None, []

    def flush():
        if key is None:
            return
        where = f"table {key[0]}, b={key[1]:g}, Q={key[2]} in {source}"
        if len(rows) < 2:
            raise JaxcoagInputError(f"{where} has no data rows: after the header give the column-axis "
                                    "row (phi_ini, or a_out/a for fmiss) and then rows of eps and values")
        axis, data = rows[0][1], rows[1:]
        n = len(data[0][1])
        if n < 2:
            raise JaxcoagInputError(f"{where}, line {data[0][0]}: a data row needs eps and at least one value")
        for ln, r in data:
            if len(r) != n:
                raise JaxcoagInputError(f"{where}, line {ln}: {len(r)} numbers, but the first data row has "
                                        f"{n} (eps and {n - 1} values); every row needs the same columns")
        if len(axis) == n:  # placeholder in the corner cell
            axis = axis[1:]
        elif len(axis) != n - 1:
            raise JaxcoagInputError(f"{where}, line {rows[0][0]}: the column-axis row has {len(axis)} numbers "
                                    f"but the data rows have {n - 1} values; give the {n - 1} axis values "
                                    "(optionally after a corner placeholder)")
        d = np.array([r for _, r in data], dtype=float)
        blocks[key] = (d[:, 0], np.array(axis, dtype=float), d[:, 1:])

    for ln, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s:
            continue
        m = _HEADER.match(s)
        if m:
            flush()
            q = m.group(3)
            qn = _QNAMES.get(q.lower())
            if qn is None:
                raise JaxcoagInputError(f"unknown quantity {q!r} in header {s!r} ({source}, line {ln}); expected "
                                        f"one of {QUANTITIES} (CDS names Nfk, Cphi also accepted)")
            key, rows = (m.group(1).upper(), round(float(m.group(2)), 6), qn), []
            if key in blocks:
                raise JaxcoagInputError(f"table {key[0]}, b={key[1]:g}, Q={qn} appears twice ({source}, line {ln}); "
                                        "keep one copy")
            continue
        if s.startswith("#"):
            continue
        toks = s.split()
        if not _is_number(toks[0]):
            continue  # column-title line of the printed layout (e.g. "ε  φ^ini")
        if key is None:
            raise JaxcoagInputError(f"numbers before any '# GLOBAL|LOCAL, b=..., Q=...' header ({source}, "
                                    f"line {ln}): {s!r}; every table starts with such a header")
        bad = [t for t in toks if not _is_number(t)]
        if bad:
            raise JaxcoagInputError(f"table {key[0]}, b={key[1]:g}, Q={key[2]} ({source}, line {ln}): "
                                    f"{bad[0]!r} is not a number; a table row holds numbers only")
        rows.append((ln, [float(t) for t in toks]))
    flush()
    return blocks


def _assemble(blocks, recipe):
    bs = sorted({k[1] for k in blocks if k[0] == recipe})
    if not bs:
        raise JaxcoagInputError(f"no {recipe} tables found; the file(s) need '# {recipe}, b=..., Q=...' tables")
    eps, col, vals = [], [], []
    for q in QUANTITIES:
        per_b = []
        for b in bs:
            arr = blocks.get((recipe, b, q))
            if arr is None:
                raise JaxcoagInputError(f"missing table {recipe}, b={b}, Q={q}; all 72 tables (2 recipes x 6 "
                                        "quantities x the same b values) are needed")
            per_b.append(arr)
        e0, c0 = per_b[0][0], per_b[0][1]
        for e, c, _ in per_b:
            if not (np.array_equal(e, e0) and np.array_equal(c, c0)):
                raise JaxcoagInputError(f"{recipe} Q={q}: eps/phi axes differ between b values; every b "
                                        "table of one quantity must use the same eps and phi_ini nodes")
        if np.any(np.diff(e0) <= 0) or np.any(np.diff(c0) <= 0):
            raise JaxcoagInputError(f"{recipe} Q={q}: the eps column and the axis row must increase")
        eps.append(e0)
        col.append(c0)
        vals.append(np.stack([v for _, _, v in per_b]))
    shapes = {v.shape for v in vals}
    if len(shapes) != 1:
        raise JaxcoagInputError(f"{recipe}: quantities have different grid shapes {shapes}")
    return RecipeTable(eps=jnp.asarray(np.stack(eps)), col=jnp.asarray(np.stack(col)),
                       b=jnp.asarray(np.array(bs)), values=jnp.asarray(np.stack(vals)))


def _surrogate_table(recipe):
    glob = recipe == "global"
    eps = np.array(GLOBAL_EPS if glob else LOCAL_EPS)
    phi = np.array(GLOBAL_PHI if glob else LOCAL_PHI)
    b = np.array(B_GRID)
    nb, ne, nc = len(b), len(eps), len(phi)
    E = eps[None, :, None] * np.ones((nb, ne, nc))
    Bg = b[:, None, None] * np.ones((nb, ne, nc))
    Ph = phi[None, None, :] * np.ones((nb, ne, nc))
    # fpwl
    base = np.array(TAB6_7 if glob else TAB6_9, dtype=float)[None] * np.ones((nb, 1, 1))
    # b = 0.75 scale: 6 % at the table's least compact phi column, 25 % at its most compact one
    # (each recipe on its own phi grid: 0.122..0.251 global, 0.070..0.161 local)
    f75 = np.interp(Ph, [phi[0], phi[-1]], [0.06, 0.25])
    scale = np.where(Bg <= 0.75, 1.0 - (1.0 - f75) * Bg / 0.75, f75 * (1.0 - Bg) / 0.25)
    fpwl = base * scale
    # q
    if glob:
        t = np.clip(np.log(E / 0.1) / np.log(20.0 / 0.1), 0.0, 1.0)
        q = np.where(Bg == 0.0, -2.0 - 1.7 * t, -2.0 + 0.4 * Bg)
    else:
        t = np.clip(np.log(E / eps[0]) / np.log(eps[-1] / eps[0]), 0.0, 1.0)
        q = -1.3 - 0.7 * t
    # Nf, Sf, fmiss
    ramp = np.clip(np.log(E / 0.3) / np.log(1.0 / 0.3), 0.0, 1.0)
    nf = 1.0 + np.clip((Bg - 0.5) / 0.25, 0.0, 1.0) * ramp
    sf = np.zeros_like(E)
    fmiss = np.zeros_like(E)
    # Csig on the eps_roll axis (same numbers)
    cmax = np.maximum(1.0, 0.33 / Ph)
    lo = np.interp(np.log(E), np.log([0.1, 0.2]), [0.95, 1.0])
    up = 1.0 + (cmax - 1.0) * np.clip(np.log(E / 0.2) / np.log(1.0 / 0.2), 0.0, 1.0)
    csig = np.where(E < 0.2, lo, up)
    csig = np.where((Bg >= 0.75) & (E >= 0.2288), 1.0, csig)
    values = np.stack([fmiss, nf, sf, fpwl, q, csig])
    # fmiss column axis is a_out/a: use a representative 1..2 range (values are 0 anyway)
    col = np.stack([np.linspace(1.0, 2.0, nc)] + [phi] * 5)
    return RecipeTable(eps=jnp.asarray(np.stack([eps] * 6)), col=jnp.asarray(col), b=jnp.asarray(b),
                       values=jnp.asarray(values))


# ---------------------------------------------------------------------------------------------
def interp_weights(grid, x, log: bool = False):
    """Index and linear weight of x on an increasing 1D grid (clamped to the end nodes).

    Returns (i, w) with x ≈ (1 - w) grid[i] + w grid[i + 1]; the lower node gets
    P(x1) = 1 - w = (x2 - x)/(x2 - x1) (thesis Fig. 6.7 erratum fixed). log: weights in ln x.

    Arguments: grid: (n,) increasing [-]; x: query (any shape); log: static.
    Returns: (i int array, w float array) of x's shape.
    References: Ormel 2008 thesis §6.4.1, Fig. 6.7 (erratum 14 in docs/design_notes.md).
    """
    g = jnp.log(grid) if log else jnp.asarray(grid)
    xx = safe_log(x, fill=-1e300) if log else jnp.asarray(x)
    n = g.shape[-1]
    i = jnp.clip(jnp.searchsorted(g, xx, side="right") - 1, 0, n - 2)
    g0, g1 = g[i], g[i + 1]
    w = jnp.clip((xx - g0) / (g1 - g0), 0.0, 1.0)
    return i, w


def _interp_raw(eps_grid, col_grid, b_grid, V, eps, col, b, log_eps=False):
    """Multilinear interpolation of one (n_b, n_eps, n_col) table (arguments broadcast)."""
    ie, we = interp_weights(eps_grid, eps, log_eps)
    ic, wc = interp_weights(col_grid, col)
    ib, wb = interp_weights(b_grid, b)
    out = 0.0
    for db, fb in ((0, 1.0 - wb), (1, wb)):
        for de, fe in ((0, 1.0 - we), (1, we)):
            for dc, fc in ((0, 1.0 - wc), (1, wc)):
                out = out + fb * fe * fc * V[ib + db, ie + de, ic + dc]
    return out


_interp_jit = jax.jit(_interp_raw, static_argnames=("log_eps",))


def interpolate(table: RecipeTable, quantity: str, eps, col, b, *, log_eps: bool = False):
    """Multilinear (expected-mode) interpolation of one tabulated quantity.

    Arguments:
        table: :class:`RecipeTable`; quantity: static name in QUANTITIES.
        eps: normalised energy [-] (eps_roll for Csig); col: phi_ini (a_out/a for fmiss) [-];
        b: b/b_max [-]. Broadcast against each other; outside the grid: clamped to edges.
        log_eps: static; interpolate in ln eps instead of eps ([CHOICE] option "log_eps").

    Returns:
        interpolated values [-] (the table's units; local fpwl in units of m_mu).

    References: Ormel 2008 thesis §6.4.1.
    """
    iq = _Q[quantity]
    eps, col, b = jnp.broadcast_arrays(jnp.asarray(eps, float), jnp.asarray(col, float), jnp.asarray(b, float))
    return _interp_jit(table.eps[iq], table.col[iq], table.b, table.values[iq], eps, col, b, log_eps=log_eps)


def _interp_all(table: RecipeTable, eps_q, col_q, b, log_eps):
    """All six quantities at once: eps_q, col_q of shape (6, *shape); b scalar or (*shape)."""
    f = lambda eg, cg, V, e, c: _interp_raw(eg, cg, table.b, V, e, c, b, log_eps)
    return jax.vmap(f)(table.eps, table.col, table.values, eps_q, col_q)


def sample_nodes(key, table: RecipeTable, quantity: str, eps, col, b, *, log_eps: bool = False):
    """Sample-mode lookup: pick one of the 8 surrounding nodes, independently per axis, with
    linear weights (lower node probability (x2 - x)/(x2 - x1)); returns the node's value.

    Arguments: key: PRNG key; others as :func:`interpolate` (scalars or arrays).
    Returns: tabulated value at the drawn node [-]; its expectation equals :func:`interpolate`.
    References: Ormel 2008 thesis §6.4.1, Fig. 6.7 (erratum 14 fixed).
    """
    iq = _Q[quantity]
    eps, col, b = jnp.broadcast_arrays(jnp.asarray(eps, float), jnp.asarray(col, float), jnp.asarray(b, float))
    ie, we = interp_weights(table.eps[iq], eps, log_eps)
    ic, wc = interp_weights(table.col[iq], col)
    ib, wb = interp_weights(table.b, b)
    u = jax.random.uniform(key, (3,) + eps.shape, dtype=jnp.result_type(float))
    return table.values[iq][ib + (u[0] < wb), ie + (u[1] < we), ic + (u[2] < wc)]


def _b_weights(b_nodes, n_quad=4000):
    """Node weights of the p(b) = 2b average with the interpolation's hat functions (midpoint rule)."""
    x = (jnp.arange(n_quad) + 0.5) / n_quad
    i, t = interp_weights(b_nodes, x)
    dens = 2.0 * x / n_quad
    w = jnp.zeros(b_nodes.shape[0]).at[i].add((1.0 - t) * dens).at[i + 1].add(t * dens)
    return w / jnp.sum(w)


def b_average_weights(b_nodes=B_GRID):
    """Weights of the b nodes for averaging over impact parameters with p(b) ∝ b on [0, 1].

    Uses the same piecewise-linear interpolation in b as :func:`interpolate` (clamped above
    the last node). Arguments: b_nodes: increasing (n_b,) [-]. Returns: (n_b,) weights, sum 1.
    References: Ormel 2008 thesis §6.3-6.5 (b_frac = None: expected mode over p(b) ∝ b).
    """
    return _b_weights(jnp.asarray(b_nodes, dtype=float))


def o09_outcome(m1, psi1, m2, psi2, dv, tables: RecipeTables, mat: Material, *, b_frac=None,
                hs_form: str = "B", log_eps: bool = False, kappa_glob=3.0, mass_ratio_glob=0.1,
                hs_factor=5.0, phi_max=0.33, width: float = 0.0,
                validate: bool = True) -> Outcome:
    """Thesis ch. 6 (O09) collision outcome in expected mode (deterministic, differentiable).

    Regimes [T§6.3.9]: hit-and-stick if E < hs_factor E_roll (eq. 6.24 filling factor); else
    *global* if N_s/N_b >= mass_ratio_glob or E >= kappa_glob N_tot E_br ([CHOICE] kappa = 3),
    else *local*. Table quantities are interpolated at eps = E/(N E_br) (N = N_tot global,
    N_mu local), eps_roll = E/(N_tot E_roll) for C_phi, phi_ini = <phi>_m (global) or the
    target's phi (local), a_out/a of the target for f_miss. Then [T6.25-6.28]:
    eff = 1 - f_miss; M_pwl = fpwl M_tot (global) or min(fpwl m_mu, M_tot) (local), all mass
    to the power law if M_pwl >= the target mass (local); P_2 = clip(N_f - 1, 0, 1) two equal
    remnants; P_0 = clip(1 - N_f, 0, 1) of M_large also to the power law ([CHOICE]);
    phi_large = C_phi <phi>_m, capped at max(phi_max, <phi>_m) when C_phi > 1; fragments
    q from the table on [m0, 0.25 M_tot]. With width > 0 the regimes mix smoothly.

    Arguments:
        m1, m2 [g], psi1, psi2 [-], dv [cm s^-1]: the pair (broadcast).
        tables: :class:`RecipeTables`; mat: :class:`Material` (E_roll, E_br of a monomer
            pair, R = a0/2, as in ch. 6).
        b_frac: b/b_max in [0, 1], or None to average over p(b) ∝ b.
        hs_form: static "B"/"A" (eq. 6.24 reading); log_eps: static interpolation option.
        kappa_glob, mass_ratio_glob, hs_factor, phi_max: recipe constants (see above).
            Fragment structure psi(N) = 1/min(1, c_f N^-0.33) is applied by the consumer
            (:func:`jaxcoag.physics.outcome.psi_fragment`).
        width: static regime-switch width in e-folds (0 = sources).
        validate: static; False skips input checks.

    Returns:
        :class:`Outcome`; aux: energy [erg], w_hs, w_glob (regime weights), is_surrogate.

    References: Ormel 2008 thesis §6.3-6.5, eqs. 6.17-6.30; errata 12-18 in docs/design_notes.md.
    """
    m1, psi1, m2, psi2, dv = pair_inputs(m1, psi1, m2, psi2, dv, validate)
    if b_frac is not None:
        b_frac = _chk(b_frac, "b_frac", nonnegative=True, hint="b_frac = b/b_max in [0, 1], or None to average")
    kappa_glob, mass_ratio_glob, hs_factor, phi_max = (
        jnp.asarray(x, dtype=jnp.result_type(float)) for x in (kappa_glob, mass_ratio_glob, hs_factor, phi_max))
    return _o09_jit(m1, psi1, m2, psi2, dv, tables, mat, b_frac, hs_form, log_eps, kappa_glob,
                    mass_ratio_glob, hs_factor, phi_max, width)


def _o09_impl(m1, psi1, m2, psi2, dv, tables, mat, b_frac, hs_form, log_eps, kappa_glob,
              mass_ratio_glob, hs_factor, phi_max, width):
    """Unvalidated O09 outcome (see :func:`o09_outcome`)."""
    m0, e_roll, e_br = mat.m0, mat.e_roll(), mat.e_break()
    first = (m1 > m2) | ((m1 == m2) & (psi1 >= psi2))
    mt, pt = jnp.where(first, m1, m2), jnp.where(first, psi1, psi2)  # target (heavier)
    mp, pp = jnp.where(first, m2, m1), jnp.where(first, psi2, psi1)
    M_tot = mt + mp
    m_mu = _reduced_mass(mt, mp)
    energy = 0.5 * m_mu * dv**2
    N_tot, N_t, N_mu = M_tot / m0, mt / m0, m_mu / m0
    phi_t, phi_p = 1.0 / pt, 1.0 / pp
    w_t = 1.0 / (1.0 + mp / mt)
    phi_m = w_t * phi_t + (1.0 - w_t) * phi_p  # mass-weighted phi
    lE = safe_log(energy, fill=-1e3)
    # hit-and-stick
    phi_hs = _phi_hit_and_stick_o09(N_t, phi_t, mp / m0, phi_p, form=hs_form)
    hs = Outcome.build(m_lo=m0, m_hi=m0, psi_one=1.0 / phi_hs)
    aout_t = _outer_radius_ratio(N_t, phi_t)
    eps_roll = energy / (N_tot * e_roll)

    def fragmenting(t, eps, phi_ini, local):
        shape = jnp.broadcast_shapes(eps.shape, phi_ini.shape, aout_t.shape, eps_roll.shape)
        bc = lambda x: jnp.broadcast_to(x, shape)
        eps_q = jnp.stack([bc(eps)] * 5 + [bc(eps_roll)])
        col_q = jnp.stack([bc(aout_t)] + [bc(phi_ini)] * 4 + [bc(phi_ini)])
        if b_frac is None:
            w_b = _b_weights(t.b)
            per_b = jax.vmap(lambda bb: _interp_all(t, eps_q, col_q, bb, log_eps))(t.b)
            vals = jnp.tensordot(w_b, per_b, axes=1)
        else:
            vals = _interp_all(t, eps_q, col_q, b_frac, log_eps)
        fmiss = jnp.clip(vals[0], 0.0, 1.0)
        nf = vals[1]
        fp = jnp.maximum(vals[3], 0.0)
        q = vals[4]
        c_phi = vals[5]
        if local:
            M_pwl = jnp.minimum(fp * m_mu, M_tot)
            M_pwl = jnp.where(M_pwl >= mt, M_tot, M_pwl)
        else:
            M_pwl = jnp.minimum(fp, 1.0) * M_tot
        f_pwl = M_pwl / M_tot
        p0 = jnp.clip(1.0 - nf, 0.0, 1.0)
        f_pwl = f_pwl + (1.0 - f_pwl) * p0
        p_two = jnp.clip(nf - 1.0, 0.0, 1.0)
        phi_l = c_phi * phi_m
        phi_l = jnp.where(c_phi > 1.0, jnp.minimum(phi_l, jnp.maximum(phi_max, phi_m)), phi_l)
        psi_l = 1.0 / jnp.minimum(phi_l, 1.0)
        m_hi = jnp.maximum(0.25 * M_tot, m0)
        return Outcome.build(eff=1.0 - fmiss, p_two=p_two, split=0.5, f_pwl=jnp.clip(f_pwl, 0.0, 1.0),
                             q=q, m_lo=m0, m_hi=m_hi, psi_one=psi_l)

    glob = fragmenting(tables.glob, energy / (N_tot * e_br), phi_m, False)
    loc = fragmenting(tables.loc, energy / (N_mu * e_br), phi_t, True)
    w_ratio = smooth_step(jnp.log(mp / mt) - jnp.log(mass_ratio_glob), width)
    w_energy = smooth_step(lE - jnp.log(kappa_glob * N_tot * e_br), width)
    w_glob = 1.0 - (1.0 - w_ratio) * (1.0 - w_energy)
    frag = mix_outcomes(w_glob, loc, glob, mt, mp)
    w_hs = 1.0 - smooth_step(lE - jnp.log(hs_factor * e_roll), width)
    out = mix_outcomes(1.0 - w_hs, hs, frag, mt, mp)
    shape = out.eff.shape
    aux = dict(energy=jnp.broadcast_to(energy, shape), w_hs=jnp.broadcast_to(w_hs, shape),
               w_glob=jnp.broadcast_to(w_glob, shape),
               is_surrogate=jnp.full(shape, 1.0 if tables.is_surrogate else 0.0))
    return eqx.tree_at(lambda o: o.aux, out, aux)


_o09_jit = eqx.filter_jit(_o09_impl)
