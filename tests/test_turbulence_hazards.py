"""OC07 turbulence at the numerical hazard points (velocity hazards, docs/design_notes.md):
values AND gradients.

Every hazard point of velocity hazard 7 (equal St in the tightly coupled and intermediate regimes, St -> 0 for one
and both particles, St = (1e25, 1e24) and (1e20, 1e19), Re = 0.5, 1, 1e30, (1, 1), (1e-30, 1e-31)),
for methods exact / ya / ch03 and accurate=True, plus a dense log grid and float32.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import turbulence as T
from jaxcoag.physics.safe import safe_sqrt

HAZARDS = [  # (St1, St2, Re)
    (1e-6, 1e-6, 1e8),     # equal, tightly coupled (Dv = 0 exactly)
    (1e-7, 1e-7, 1e12),
    (1e-2, 1e-2, 1e8),     # equal, intermediate
    (0.3, 0.3, 1e30),
    (1e-30, 1e-3, 1e8),    # St -> 0 for one
    (0.5, 1e-30, 1e8),
    (1e-30, 1e-30, 1e8),   # both
    (1e-30, 1e-31, 1e8),
    (1e25, 1e24, 1e8),     # overflow candidates
    (1e20, 1e19, 1e8),
    (1e25, 1e-30, 1e30),
    (0.1, 0.01, 0.5),      # Re < 1: no inertial range
    (0.1, 0.01, 1.0),
    (1.0, 1.0, 1.0),
    (0.1, 0.01, 1e30),     # Re -> inf surrogate
    (1.0, 1.0, 1e8),       # (1, 1): kink of the St* upper clip
    (1.0, 0.3, 1e8),
    (6.248706e-5, 1e-9, 1e8),  # lower clip kink
]
COMBOS = [("exact", False), ("ya", False), ("ch03", False),
          ("exact", True), ("ya", True), ("ch03", True)]


def _coarse_grid():
    st = 10.0 ** np.arange(-30.0, 26.0, 5.0)
    re = np.array([0.5, 1.0, 1e4, 1e8, 1e12, 1e20, 1e30])
    A, B, R = np.meshgrid(st, st, re, indexing="ij")
    return A.ravel(), B.ravel(), R.ravel()


@pytest.mark.parametrize("method,accurate", COMBOS)
def test_values_and_grads_finite_f64(method, accurate):
    h = np.array(HAZARDS)
    ga, gb, gr = _coarse_grid()
    a = jnp.asarray(np.concatenate([h[:, 0], ga]))
    b = jnp.asarray(np.concatenate([h[:, 1], gb]))
    lnre = jnp.log(jnp.asarray(np.concatenate([h[:, 2], gr])))

    def f(a, b, lnre):
        return T.dv_turbulent_oc07(a, b, jnp.exp(lnre), method=method, accurate=accurate)

    val, grads = jax.jit(jax.vmap(jax.value_and_grad(f, argnums=(0, 1, 2))))(a, b, lnre)
    val = np.asarray(val)
    assert np.all(np.isfinite(val)) and np.all(val >= 0)
    for g in grads:
        assert np.all(np.isfinite(np.asarray(g)))
    n = len(HAZARDS)
    # exact zeros: identical tightly coupled particles and Re <= 1, with zero gradient
    for i, (s1, s2, re) in enumerate(HAZARDS):
        if re <= 1.0 or (s1 == s2 and s1 < 1e-5):
            assert val[i] == 0.0
            assert all(float(g[i]) == 0.0 for g in grads)
    # physically sensible magnitudes at the extreme points (heavy limit, eq. 3.26)
    i = HAZARDS.index((1e25, 1e24, 1e8))
    assert accurate or abs(val[i] ** 2 / (1.0 / (1 + 1e25) + 1.0 / (1 + 1e24)) - 1.0) < 1e-3
    assert val[n:].shape == ga.shape


@pytest.mark.parametrize("method", ["exact", "ya", "ch03"])
def test_st_exactly_zero_internal(method):
    # the hot-path dv2 accepts St = 0 (clamped to 1e-30); sqrt of the total is the safe one
    def f(a, b):
        return safe_sqrt(T.dv2_turbulent_oc07(a, b, 1e8, method=method))
    for a, b in [(0.0, 0.0), (0.0, 1e-3), (0.3, 0.0)]:
        v, (g1, g2) = jax.value_and_grad(f, argnums=(0, 1))(a, b)
        assert np.isfinite(float(v)) and np.isfinite(float(g1)) and np.isfinite(float(g2))
    assert float(f(0.0, 0.0)) == 0.0
    assert float(f(0.0, 1e-30)) == 0.0


@pytest.mark.parametrize("method", ["exact", "ya", "ch03"])
@pytest.mark.parametrize("accurate", [False, True])
def test_dense_grid_f64(method, accurate):
    st = jnp.logspace(-30, 25, 56)
    re = jnp.array([1.0, 10.0, 1e4, 1e8, 1e12, 1e20, 1e30])
    a, b, re = jnp.broadcast_arrays(st[:, None, None], st[None, :, None], re[None, None, :])
    v = np.asarray(T.dv2_turbulent_oc07(a, b, re, method=method, accurate=accurate))
    assert np.all(np.isfinite(v))
    assert np.all(v >= 0.0)
    np.testing.assert_array_equal(v, np.transpose(v, (1, 0, 2)))  # bitwise symmetric
    # Re = 1: no turbulence cascade at all
    assert np.all(v[:, :, 0] == 0.0)
    # bounded by the largest possible value (two independent particles fully coupled to v_g)
    assert np.max(v) < 2.0


def test_float32_dtype_and_values():
    f32 = jnp.float32
    a = jnp.array([1e6, 1e20, 1e25, 1e-18, 0.1, 1e-2, 1e-6], f32)
    b = jnp.array([1e5, 1e19, 1e24, 1e-18, 1e-3, 1e-2, 1e-6], f32)
    re = jnp.array([1e8] * 7, f32)
    for method in ("exact", "ya", "ch03"):
        for accurate in (False, True):
            v32 = T.dv2_turbulent_oc07(a, b, re, method=method, accurate=accurate)
            assert v32.dtype == f32
            v64 = np.asarray(T.dv2_turbulent_oc07(a.astype(jnp.float64), b.astype(jnp.float64),
                                                  re.astype(jnp.float64), method=method, accurate=accurate))
            v32 = np.asarray(v32)
            assert np.all(np.isfinite(v32)) and np.all(v32 >= 0)
            nz = v64 > 0
            np.testing.assert_allclose(v32[nz], v64[nz], rtol=2e-5)
            assert np.all(v32[~nz] == 0)
    s32 = T.st_star(jnp.array([1e-3, 0.5, 2.0], f32), jnp.array(1e8, f32))
    assert s32.dtype == f32
    np.testing.assert_allclose(s32, np.asarray(T.st_star(jnp.array([1e-3, 0.5, 2.0]), 1e8)), rtol=3e-7)


def test_30_float32_spec_points():
    f32 = jnp.float32
    for (a, b), ref in [((1e6, 1e5), 1.099990e-5), ((1e20, 1e19), 1.100000e-19)]:
        v = T.dv2_turbulent_oc07(jnp.array(a, f32), jnp.array(b, f32), jnp.array(1e8, f32))
        assert v.dtype == f32
        assert abs(float(v) - ref) / ref < 1e-6


def test_float32_grads_finite():
    f32 = jnp.float32
    h = np.array(HAZARDS)
    a = jnp.asarray(np.maximum(h[:, 0], 1e-18), f32)
    b = jnp.asarray(np.maximum(h[:, 1], 1e-18), f32)
    lnre = jnp.log(jnp.asarray(h[:, 2], f32))

    def f(a, b, lnre):
        return T.dv_turbulent_oc07(a, b, jnp.exp(lnre))

    val, grads = jax.vmap(jax.value_and_grad(f, argnums=(0, 1, 2)))(a, b, lnre)
    assert val.dtype == f32
    assert np.all(np.isfinite(np.asarray(val)))
    for g in grads:
        assert g.dtype == f32
        assert np.all(np.isfinite(np.asarray(g)))


def test_bad_input_raises():
    cases = [dict(st1=0.0), dict(st1=-1e-3), dict(st1=np.nan), dict(st2=0.0), dict(st2=np.inf),
             dict(reynolds=0.0), dict(reynolds=-1.0), dict(reynolds=np.nan),
             dict(beta_over_alpha=-1.0)]
    for bad in cases:
        kw = dict(st1=0.1, st2=0.01, reynolds=1e8)
        boa = bad.pop("beta_over_alpha", 0.0)
        kw.update(bad)
        with pytest.raises(JaxcoagInputError, match="must be"):
            T.dv_turbulent_oc07(kw["st1"], kw["st2"], kw["reynolds"], beta_over_alpha=boa)
    # array input: the message counts the offending entries
    with pytest.raises(JaxcoagInputError, match="st1"):
        T.dv_turbulent_oc07(jnp.array([0.1, 0.0]), 0.1, 1e8)
    # traced input: runtime error with the same message (no silent NaN)
    # the equinox runtime check surfaces through XLA's host callback: a JaxRuntimeError on a first
    # dispatch, a ValueError ("INTERNAL: CpuCallback error") from an already-compiled executable
    with pytest.raises((jax.errors.JaxRuntimeError, ValueError), match="must be") as err:
        jax.jit(T.dv_turbulent_oc07)(jnp.array(-0.1), 0.1, 1e8)
    assert "EquinoxRuntimeError" in str(err.value)  # the runtime check, not an eager one
    with pytest.raises(ValueError, match="valid methods"):
        T.dv2_turbulent_oc07(0.1, 0.1, 1e8, method="CH03")
