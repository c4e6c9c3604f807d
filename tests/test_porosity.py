"""Porosity recipes and geometry: thesis eqs. 2.4-2.19, 2.25 (ch. 2) and 6.22, 6.24 (ch. 6), smooth switches."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import porosity as P


def test_geometry_G1_and_tab22():
    np.testing.assert_allclose(float(P.geometric_radius(1.4, 86.0, 3.0)), 2.12392, rtol=1e-5)
    np.testing.assert_allclose(float(P.compact_radius_of(1.4, 3.0)), 0.481178, rtol=1e-5)
    # T-Tab2.2 rows (computed; the table lists 0.72, 7.8, 2.4e-2 cm)
    for m, psi, rho, a in ((1.4e-2, 110.0, 1.0, 0.716), (1.6e3, 3.9, 3.0, 7.92), (1.9e-4, 1.0, 3.0, 0.02473)):
        np.testing.assert_allclose(float(P.geometric_radius(m, psi, rho)), a, rtol=1e-3)
    # a/a* = psi^(1/3) (T-Tab2.2 a/a* = 4.4 for psi = 86)
    assert round(86.0 ** (1 / 3), 1) == 4.4
    A = P.geometric_area(1.4, 86.0, 3.0)
    np.testing.assert_allclose(float(A), np.pi * 2.12392**2, rtol=1e-5)
    np.testing.assert_allclose(float(P.enlargement_factor(1.4, 2.1239235, 3.0)), 86.0, rtol=1e-6)
    np.testing.assert_allclose(float(P.filling_factor(4.0)), 0.25, rtol=1e-15)


def test_outer_radius_G2():
    N = jnp.array([1000.0, 1000.0, 1e6, 100.0, 10.0])
    phi = jnp.array([0.05, 0.2, 0.01, 0.5, 0.3])
    want = [20.5456, 1.14508, 2.20099, 1.09458, 8.29622]
    np.testing.assert_allclose(np.asarray(P.outer_radius_ratio(N, phi)), want, rtol=1e-5)
    # forward check of the fit [T6.22] on both branches
    r = P.outer_radius_ratio(N, phi)
    fl = 1.21 * r**-0.3 * N**-0.33
    cp = r ** (0.75 - 4.21 * jnp.log10(N))
    np.testing.assert_allclose(np.where(np.asarray(r) >= 1.2, fl, cp), np.asarray(phi), rtol=1e-10)
    # guards: N < 1.6 -> a_out = a; compact aggregate -> a_out >= a
    assert float(P.outer_radius_ratio(1.0, 1.0)) == 1.0
    assert float(P.outer_radius_ratio(1e4, 1.0)) >= 1.0
    # smooth mode: tiny width equals the hard switch away from the junction
    np.testing.assert_allclose(np.asarray(P.outer_radius_ratio(N, phi, width=1e-4)), want, rtol=1e-5)
    a_out = P.outer_radius(1000 * 1.11e-14, 20.0, 2.65, 1.11e-14)
    np.testing.assert_allclose(float(a_out), float(P.geometric_radius(1000 * 1.11e-14, 20.0, 2.65) * 20.5456), rtol=1e-5)


def test_single_collisions_R4():
    h = lambda *a, **k: float(P.psi_hit_and_stick(*a, m0=1.0, **k))
    np.testing.assert_allclose(h(100.0, 10.0, 10.0, 2.0), 9.75399, rtol=1e-6)
    np.testing.assert_allclose(h(100.0, 10.0, 10.0, 2.0, B=0.0), 9.35110, rtol=1e-6)
    np.testing.assert_allclose(h(1000.0, 5.0, 1000.0, 5.0), 6.71286, rtol=1e-6)
    np.testing.assert_allclose(h(1e4, 30.0, 1.0, 1.0), 29.99986, rtol=1e-6)
    np.testing.assert_allclose(h(1e4, 3.0, 1e4, 3.0), 4.027718, rtol=1e-6)
    # psi_add ordered by MASS (volume ordering would give 53.6)
    np.testing.assert_allclose(float(P.psi_add(5.0, 20.0, 20.0, 2.0, m0=1.0)), 0.335, rtol=1e-3)
    np.testing.assert_allclose(h(5.0, 20.0, 20.0, 2.0), 6.79605, rtol=1e-6)


def test_symmetry_R6():
    key = jax.random.PRNGKey(3)
    k1, k2, k3, k4 = jax.random.split(key, 4)
    m1 = 10 ** jax.random.uniform(k1, (50,), minval=0, maxval=8)
    m2 = 10 ** jax.random.uniform(k2, (50,), minval=0, maxval=8)
    p1 = 1 + 10 ** jax.random.uniform(k3, (50,), minval=-2, maxval=3)
    p2 = 1 + 10 ** jax.random.uniform(k4, (50,), minval=-2, maxval=3)
    a = P.psi_hit_and_stick(m1, p1, m2, p2, m0=1.0)
    b = P.psi_hit_and_stick(m2, p2, m1, p1, m0=1.0)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    e = 10 ** jax.random.uniform(k1, (50,), minval=-2, maxval=9)
    c1 = P.psi_compaction(m1, p1, m2, p2, e, e_roll=1.0, m0=1.0)
    c2 = P.psi_compaction(m2, p2, m1, p1, e, e_roll=1.0, m0=1.0)
    np.testing.assert_allclose(np.asarray(c1), np.asarray(c2), rtol=1e-14)
    # hit-and-stick never lowers psi below <psi>_m; compaction keeps psi in [1, <psi>_m]
    pm = P.psi_mass_average(m1, p1, m2, p2)
    assert bool(jnp.all(a >= pm * (1 - 1e-14)))
    assert bool(jnp.all((c1 >= 1.0) & (c1 <= pm * (1 + 1e-14))))


def _pca(B, n_steps):
    def body(psi, N):
        return P._psi_hit_and_stick(N, psi, 1.0, 1.0, 1.0, 0.95, B, 10.0), psi

    return jax.jit(lambda: jax.lax.scan(body, 1.0, jnp.arange(1.0, n_steps))[1])()


def test_pca_limits_R1_R2():
    traj0 = _pca(0.0, 200001)  # traj[k] = psi at N = k + 1
    np.testing.assert_allclose(float(traj0[-1]), 1.42501, rtol=1e-5)
    np.testing.assert_allclose(float(P.psi_pca_limit(B=0.0)), 1.425, rtol=1e-14)
    traj = _pca(1.0, 100001)
    for N, want in ((10, 5.1391), (40, 6.7315), (100, 7.5162), (1000, 9.0442), (10000, 10.218), (100000, 11.155)):
        np.testing.assert_allclose(float(traj[N - 1]), want, rtol=1e-4)
    np.testing.assert_allclose(float(P.psi_pca_limit()), 14.974, rtol=1e-4)


def test_cca_R3():
    np.testing.assert_allclose(float(P.psi_cca_ratio()), 1.342573, rtol=1e-6)
    for B, checks in ((0.0, {20: 362.039}), (1.0, {1: 2.29380, 6: 62.068, 11: 279.31, 16: 1218.35})):
        psi, m = 1.0, 1.0
        vals = {}
        for k in range(1, 41):
            psi = float(P.psi_hit_and_stick(m, psi, m, psi, m0=1.0, B=B))
            m *= 2
            vals[k] = psi
        for k, want in checks.items():
            np.testing.assert_allclose(vals[k], want, rtol=1e-5)
        # psi ∝ m^0.425 at large m
        np.testing.assert_allclose(vals[40] / vals[39], 1.342573, rtol=1e-6)
    np.testing.assert_allclose(float(P.psi_fractal(2.0**20, 1.0)), 362.039, rtol=1e-6)


def test_compaction_R5():
    c = lambda *a, **k: float(P.psi_compaction(*a, **k))
    np.testing.assert_allclose(c(100.0, 10.0, 100.0, 10.0, 50.0, e_roll=1.0, m0=1.0), 7.75, rtol=1e-12)
    np.testing.assert_allclose(c(1000.0, 20.0, 10.0, 1.0, 500.0, e_roll=1.0, m0=1.0), 10.49907, rtol=1e-6)
    assert c(1000.0, 20.0, 10.0, 1.0, 1010.0, e_roll=1.0, m0=1.0) == 1.0
    assert c(1000.0, 20.0, 10.0, 1.0, 1e9, e_roll=1.0, m0=1.0) == 1.0
    np.testing.assert_allclose(c(1000.0, 20.0, 10.0, 1.0, 1e9, e_roll=1.0, m0=1.0, psi_min=1 / 0.33),
                               1 / 0.33, rtol=1e-12)
    # the floor never raises psi above <psi>_m
    np.testing.assert_allclose(c(10.0, 2.0, 10.0, 2.0, 1e9, e_roll=1.0, m0=1.0, psi_min=1 / 0.33), 2.0, rtol=1e-12)
    # porous volume bookkeeping (eq. 2.16): (V1*+V2*)(psi-1) = (1-f_C)[V1*(psi1-1)+V2*(psi2-1)]
    m1, p1, m2, p2, E = 300.0, 7.0, 40.0, 3.0, 85.0
    f_C = E / (m1 + m2)
    psi = c(m1, p1, m2, p2, E, e_roll=1.0, m0=1.0)
    np.testing.assert_allclose((m1 + m2) * (psi - 1), (1 - f_C) * (m1 * (p1 - 1) + m2 * (p2 - 1)), rtol=1e-13)
    # O07 switch at restr_factor E_roll
    ho = float(P.psi_o07(100.0, 10.0, 100.0, 10.0, 0.99, e_roll=1.0, m0=1.0))
    co = float(P.psi_o07(100.0, 10.0, 100.0, 10.0, 1.0, e_roll=1.0, m0=1.0))
    np.testing.assert_allclose(ho, float(P.psi_hit_and_stick(100.0, 10.0, 100.0, 10.0, m0=1.0)), rtol=1e-14)
    np.testing.assert_allclose(co, 1 + (1 - 1 / 200) * 9, rtol=1e-14)


def test_phi_dust_and_o09_hit_and_stick_R9():
    np.testing.assert_allclose(float(P.phi_dust(10 ** (2 / 0.95))), 0.12743, rtol=1e-4)
    np.testing.assert_allclose(float(P.phi_dust(100 ** (2 / 0.95))), 0.016238, rtol=1e-4)
    v = lambda *a, **k: float(P.void_volume_o09(*a, **k))
    np.testing.assert_allclose(v(1000.0, 10.0, 5.0, 0.5, form="A"), 61.6886, rtol=1e-5)
    np.testing.assert_allclose(v(1000.0, 10.0, 5.0, 0.5), 4.28022, rtol=1e-5)
    np.testing.assert_allclose(v(100.0, 100.0, 20.0, 0.2, form="A"), 160.618, rtol=1e-5)
    np.testing.assert_allclose(v(100.0, 100.0, 20.0, 0.2), 68.5145, rtol=1e-5)
    # form B CCA slope -0.425: equal partners
    phi, N = 1.0, 1.0
    logs = []
    for _ in range(30):
        phi = float(P.phi_hit_and_stick_o09(N, phi, N, phi))
        N *= 2
        logs.append((np.log(N), np.log(phi)))
    slope = (logs[-1][1] - logs[-6][1]) / (logs[-1][0] - logs[-6][0])
    np.testing.assert_allclose(slope, -0.425, atol=1e-3)

    # form B monomer PCA
    def body(phi, N):
        return P._phi_hit_and_stick_o09(N, phi, 1.0, 1.0), phi

    traj = jax.jit(lambda: jax.lax.scan(body, 1.0, jnp.arange(1.0, 100001.0))[1])()
    np.testing.assert_allclose(float(traj[-1]), 0.1517, rtol=2e-3)
    np.testing.assert_allclose(float(traj[999]), 0.596, rtol=2e-3)


def test_gradients_vs_fd_log_params():
    """Autodiff vs central FD in log-parameters, all in one compiled function."""

    def f(lx):  # lx = log(m1, p1, m2, p2, E, e_roll, phi)
        m1, p1, m2, p2, E, er, phi = jnp.exp(lx)
        return jnp.stack([
            jnp.log(P.psi_hit_and_stick(m1, p1, m2, p2, m0=1.0)),
            jnp.log(P.psi_compaction(m1, p1, m2, p2, E, e_roll=er, m0=1.0)),
            jnp.log(P.outer_radius_ratio(1000.0, phi)),
            jnp.log(P.outer_radius_ratio(1000.0, 10 * phi)),
        ])

    h = 1e-5
    x0 = jnp.log(jnp.array([300.0, 7.0, 17.0, 2.5, 40.0, 0.9, 0.05]))
    steps = jnp.concatenate([h * jnp.eye(7), -h * jnp.eye(7)])

    @jax.jit
    def both(x):
        return jax.jacfwd(f)(x), jax.vmap(lambda e: f(x + e))(steps)

    jac, vals = both(x0)
    fd = ((vals[:7] - vals[7:]) / (2 * h)).T
    np.testing.assert_allclose(np.asarray(jac), np.asarray(fd), rtol=1e-6, atol=1e-10)
    assert np.all(np.abs(np.asarray(jac[0, :4])) > 1e-4)  # psi depends on every input
    # reverse mode agrees with forward mode
    g = jax.jit(jax.grad(lambda x: f(x)[1]))(x0)
    np.testing.assert_allclose(np.asarray(g), np.asarray(jac[1]), rtol=1e-10, atol=1e-14)


def test_smooth_mode_S1():
    args = (300.0, 7.0, 17.0, 2.5)
    for E in (0.3, 3.0, 30.0, 3e4):
        hard = float(P.psi_o07(*args, E, e_roll=1.0, m0=1.0))
        soft = float(P.psi_o07(*args, E, e_roll=1.0, m0=1.0, width=1e-3))
        np.testing.assert_allclose(soft, hard, rtol=2e-3)

    @jax.jit
    def f(lg):  # E_roll ∝ gamma: gradient wrt log gamma is 0 a.e. in hard mode, finite & nonzero smooth
        return P.psi_o07(*args, 1.0, e_roll=jnp.exp(lg), m0=1.0, width=0.3)

    gr = float(jax.grad(f)(0.0))
    fd = float((f(1e-5) - f(-1e-5)) / 2e-5)
    assert np.isfinite(gr) and abs(gr) > 1e-3
    np.testing.assert_allclose(gr, fd, rtol=1e-6)
    # smooth f_C -> clip as width -> 0; finite gradient at E = 0
    x = jnp.array([0.0, 0.2, 0.5, 2.0])
    np.testing.assert_allclose(np.asarray(P.compaction_fraction(x, 1.0, 1.0, width=1e-3)), [0, 0.2, 0.5, 1.0], atol=2e-3)
    assert np.isfinite(float(jax.grad(lambda e: P.compaction_fraction(e, 1.0, 1.0, width=0.3))(0.0)))


def test_jit_vmap_broadcast():
    m = jnp.logspace(0, 6, 7)
    psi = 1 + jnp.linspace(0, 30, 7)
    grid = P.psi_hit_and_stick(m[:, None], psi[:, None], m[None, :], psi[None, :], m0=1.0)
    assert grid.shape == (7, 7)
    jg = jax.jit(lambda a, b, c, d: P.psi_hit_and_stick(a, b, c, d, m0=1.0))(m[:, None], psi[:, None], m[None, :], psi[None, :])
    np.testing.assert_allclose(np.asarray(jg), np.asarray(grid), rtol=1e-14)  # XLA fusion: ULPs
    vm = jax.vmap(lambda a, b: P.psi_hit_and_stick(a, b, m, psi, m0=1.0))(m, psi)
    loop = jnp.stack([P.psi_hit_and_stick(m[i], psi[i], m, psi, m0=1.0) for i in (0, 3, 6)])
    np.testing.assert_allclose(np.asarray(vm[jnp.array([0, 3, 6])]), np.asarray(loop), rtol=1e-15)
    np.testing.assert_allclose(np.asarray(vm), np.asarray(grid), rtol=1e-15)
    # huge masses: no overflow of m1*m2, psi_add -> 0
    big = float(P.psi_hit_and_stick(1e300, 2.0, 1e299, 2.0, m0=1e-14))
    assert np.isfinite(big)


def test_bad_input_errors():
    with pytest.raises(JaxcoagInputError, match="psi1"):
        P.psi_hit_and_stick(1.0, -2.0, 1.0, 1.0, m0=1.0)
    with pytest.raises(JaxcoagInputError, match="m0"):
        P.psi_hit_and_stick(1.0, 2.0, 1.0, 1.0, m0=0.0)
    with pytest.raises(JaxcoagInputError, match="energy"):
        P.psi_compaction(1.0, 2.0, 1.0, 1.0, -1.0, e_roll=1.0, m0=1.0)
    with pytest.raises(JaxcoagInputError, match="m2"):
        P.psi_hit_and_stick(1.0, 2.0, jnp.array([1.0, jnp.nan]), 1.0, m0=1.0)
    with pytest.raises(ValueError, match="form"):
        P.void_volume_o09(10.0, 1.0, 1.0, 1.0, form="C")
    # traced bad input: runtime error with the same message, not a silent NaN
    # the equinox runtime check surfaces through XLA's host callback: a JaxRuntimeError on a first
    # dispatch, a ValueError ("INTERNAL: CpuCallback error") from an already-compiled executable
    with pytest.raises((jax.errors.JaxRuntimeError, ValueError), match="psi1") as err:
        jax.jit(lambda p: P.psi_hit_and_stick(1.0, p, 1.0, 1.0, m0=1.0))(-1.0).block_until_ready()
    assert "EquinoxRuntimeError" in str(err.value)  # the runtime check, not an eager one
