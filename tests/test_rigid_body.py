"""Rigid-body core of the aggregate box (Richardson 1995): inertia, free rotation, restitution, merging, impact times.

Oracles: exact inertia of spheres; the free symmetric top and the Landau-Lifshitz §37 asymmetric top
(Jacobi elliptic functions); the 1-D textbook inelastic collision; brute-force fine stepping for the
time of impact; angular-momentum bookkeeping done independently with numpy.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special

from jaxcoag._validate import JaxcoagInputError
from jaxcoag.aggregates.rigid import body as B


# jitted entry points (eager dispatch of many small ops is slow on a shared CPU)
inertia_tensor = jax.jit(B.inertia_tensor)
principal_axes = jax.jit(B.principal_axes)
quat_from_matrix = jax.jit(B.quat_from_matrix)
matrix_from_quat = jax.jit(B.matrix_from_quat)
quat_mul = jax.jit(B.quat_mul)
contact_frame = jax.jit(B.contact_frame)
restitution_system = jax.jit(B.restitution_system)
gamma_inverse_r24 = jax.jit(B.gamma_inverse_r24)
merge = jax.jit(B.merge)


def _rot(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(Q) < 0:
        Q[:, 2] *= -1
    return Q


def _skew(c):
    return np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])


# --------------------------------------------------------------------------- A10.1 inertia


def test_inertia_one_sphere_and_touching_pair_exact():
    m, R = 2.5, 0.3
    I1 = np.asarray(inertia_tensor(np.zeros((1, 3)), np.array([m]), np.array([R])))
    np.testing.assert_allclose(I1, 0.4 * m * R**2 * np.eye(3), rtol=0, atol=1e-15)
    # two touching equal spheres along x, COM at the origin
    off = np.array([[-R, 0.0, 0.0], [R, 0.0, 0.0]])
    I2 = np.asarray(inertia_tensor(off, np.full(2, m), np.full(2, R)))
    np.testing.assert_allclose(np.diag(I2), [0.8 * m * R**2, 0.8 * m * R**2 + 2 * m * R**2,
                                             0.8 * m * R**2 + 2 * m * R**2], rtol=1e-15)
    np.testing.assert_allclose(I2 - np.diag(np.diag(I2)), 0.0, atol=1e-16)
    # masked capacity: padding lanes (with junk values) add nothing
    offp = np.concatenate([off, [[5.0, 6.0, 7.0]]])
    Ip = inertia_tensor(offp, np.array([m, m, 9.0]), np.array([R, R, 4.0]), np.array([True, True, False]))
    np.testing.assert_allclose(np.asarray(Ip), I2, rtol=1e-15, atol=0)


def test_inertia_invariant_under_translation_and_rotation():
    rng = np.random.default_rng(11)
    x = rng.normal(size=(7, 3))
    m = rng.uniform(0.5, 2.0, 7)
    R = rng.uniform(0.1, 0.4, 7)

    def tensor(pos):
        com = (m[:, None] * pos).sum(0) / m.sum()
        return np.asarray(inertia_tensor(pos - com[None, :], m, R))

    I0 = tensor(x)
    np.testing.assert_allclose(tensor(x + np.array([3.0, -7.0, 11.0])[None, :]), I0, rtol=1e-13, atol=1e-13)
    Q = _rot(rng)
    np.testing.assert_allclose(tensor(x @ Q.T), Q @ I0 @ Q.T, rtol=1e-12, atol=1e-13)
    # independent formula: sum of sphere moments + m (r² 1 − r rᵀ)
    com = (m[:, None] * x).sum(0) / m.sum()
    ref = sum(0.4 * mi * Ri**2 * np.eye(3) + mi * (ri @ ri * np.eye(3) - np.outer(ri, ri))
              for mi, Ri, ri in zip(m, R, x - com))
    np.testing.assert_allclose(I0, ref, rtol=1e-13)


def test_principal_axes_proper_rotation_and_quaternion_roundtrip():
    rng = np.random.default_rng(5)
    for _ in range(20):
        Q = _rot(rng)
        mom = np.sort(rng.uniform(0.2, 3.0, 3))
        I = Q @ np.diag(mom) @ Q.T
        Ip, A = principal_axes(I)
        A = np.asarray(A)
        np.testing.assert_allclose(np.asarray(Ip), mom, rtol=1e-12)
        assert abs(np.linalg.det(A) - 1.0) < 1e-13
        np.testing.assert_allclose(A @ np.diag(np.asarray(Ip)) @ A.T, I, atol=1e-13)
        q = quat_from_matrix(A)
        assert abs(float(jnp.linalg.norm(q)) - 1.0) < 1e-15
        np.testing.assert_allclose(np.asarray(matrix_from_quat(q)), A, atol=2e-15)
    # R(p ⊗ q) = R(p) R(q), including the near-180° rotations where the w pivot vanishes
    for A in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]), _rot(rng)):
        p = quat_from_matrix(A)
        np.testing.assert_allclose(np.asarray(matrix_from_quat(p)), A, atol=2e-15)
        q = quat_from_matrix(_rot(rng))
        np.testing.assert_allclose(np.asarray(matrix_from_quat(quat_mul(p, q))),
                                   np.asarray(matrix_from_quat(p)) @ np.asarray(matrix_from_quat(q)), atol=1e-14)


# --------------------------------------------------------------------------- A10.2 free rotation


@pytest.fixture(scope="module")
def trajectory():
    """Jitted free-rotation trajectory: (q0, Pi0, Ip, h, n_out, n_per) -> body ω and A at each output."""

    def run(q0, Pi0, Ip, h, n_out, n_per):
        def seg(carry, _):
            q, Pi = B.rotate_free(carry[0], carry[1], Ip, h * n_per, n_per)
            return (q, Pi), (Pi / Ip, matrix_from_quat(q), B.angular_momentum_space(q, Pi),
                             B.kinetic_energy_rot(Pi, Ip))

        _, out = jax.lax.scan(seg, (q0, Pi0), None, length=n_out)
        return out

    return jax.jit(run, static_argnums=(4, 5))


def test_rotate_free_symmetric_top_analytic(trajectory):
    Ip = jnp.array([1.0, 1.0, 2.0])
    w0 = np.array([0.3, 0.1, 1.0])
    q0 = quat_from_matrix(_rot(np.random.default_rng(3)))
    A0 = np.asarray(matrix_from_quat(q0))
    Pi0 = Ip * w0
    h = 0.01 / np.linalg.norm(w0)
    n_out, n_per = 20, 100
    w, A, L, E = (np.asarray(a) for a in trajectory(q0, Pi0, Ip, h, n_out, n_per))
    t = h * n_per * np.arange(1, n_out + 1)
    Om = w0[2] * (2.0 - 1.0) / 1.0  # body-frame precession rate ω_3 (I_3 − I_1)/I_1
    w_ref = np.stack([w0[0] * np.cos(Om * t) - w0[1] * np.sin(Om * t),
                      w0[0] * np.sin(Om * t) + w0[1] * np.cos(Om * t), np.full_like(t, w0[2])], axis=1)
    # ω_3 is constant for the exact flow; the 1-2-3-2-1 splitting keeps it to O(h²) (3e-9 measured)
    assert np.abs(w[:, 2] - w0[2]).max() < 1e-8
    print("symmetric top: max |ω - ω_ref| =", np.abs(w - w_ref).max())
    assert np.abs(w - w_ref).max() < 3e-4  # O(h²) phase error, 1.5e-4 measured at t = 19
    # space motion: A(t) = R_L̂(|L| t / I_1) A0 R_e3(−Ω t)  (Landau & Lifshitz §33)
    L0 = A0 @ np.asarray(Pi0)
    Lh = L0 / np.linalg.norm(L0)

    def axis_rot(u, th):
        K = _skew(u)
        return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K

    A_ref = np.stack([axis_rot(Lh, np.linalg.norm(L0) * ti / 1.0) @ A0 @ axis_rot(np.array([0, 0, 1.0]), -Om * ti)
                      for ti in t])
    print("symmetric top: max |A - A_ref| =", np.abs(A - A_ref).max())
    assert np.abs(A - A_ref).max() < 2e-4
    assert np.abs(L - L0[None, :]).max() / np.linalg.norm(L0) < 1e-12


def _ll_top(I, w0, t):
    """Landau & Lifshitz §37 asymmetric top (I1 < I2 < I3, ω2(0) = 0, L² > 2 E I2), body ω(t)."""
    I1, I2, I3 = I
    E2 = float(np.sum(I * w0**2))  # 2E
    L2 = float(np.sum((I * w0) ** 2))
    tau = t * math.sqrt((I3 - I2) * (L2 - E2 * I1) / (I1 * I2 * I3))
    m = (I2 - I1) * (E2 * I3 - L2) / ((I3 - I2) * (L2 - E2 * I1))
    sn, cn, dn, _ = scipy.special.ellipj(tau, m)
    return np.stack([math.sqrt((E2 * I3 - L2) / (I1 * (I3 - I1))) * cn,
                     math.sqrt((E2 * I3 - L2) / (I2 * (I3 - I2))) * sn,
                     math.sqrt((L2 - E2 * I1) / (I3 * (I3 - I1))) * dn], axis=1)


def test_rotate_free_asymmetric_top_landau_lifshitz(trajectory):
    I = np.array([1.0, 2.0, 3.0])
    w0 = np.array([0.3, 0.0, 1.0])
    q0 = quat_from_matrix(_rot(np.random.default_rng(8)))
    Pi0 = jnp.asarray(I * w0)
    L0 = np.asarray(B.angular_momentum_space(q0, Pi0))
    E0 = float(B.kinetic_energy_rot(Pi0, I))
    h = 0.01 / np.linalg.norm(w0)  # |ω| h = 0.01
    errs = []
    for k, (n_out, n_per) in enumerate(((20, 100), (20, 200))):
        hk = h / 2**k
        w, _, L, E = (np.asarray(a) for a in trajectory(q0, Pi0, jnp.asarray(I), hk, n_out, n_per))
        t = hk * n_per * np.arange(1, n_out + 1)  # same output times for both runs (T ≈ 19.2)
        errs.append(np.abs(w - _ll_top(I, w0, t)).max())
        print("asymmetric top: |ΔL|/|L| =", np.abs(L - L0[None, :]).max() / np.linalg.norm(L0),
              "|ΔE/E| =", np.abs(E / E0 - 1.0).max())
        assert np.abs(L - L0[None, :]).max() / np.linalg.norm(L0) < 1e-12
        assert np.abs(E / E0 - 1.0).max() < 1e-6
    print("asymmetric top: max |ω - ω_LL| at h, h/2 =", errs)
    assert errs[0] < 1e-4
    # second order: halving h divides the error by ~4
    assert 3.5 < errs[0] / errs[1] < 4.5, errs


def test_rotate_free_masked_substeps_and_reversibility():
    I = jnp.array([0.7, 1.3, 1.9])
    q0 = quat_from_matrix(_rot(np.random.default_rng(1)))
    Pi0 = jnp.array([0.4, -0.9, 0.5])
    ns = (3, 7, 12)
    static = [B.rotate_free(q0, Pi0, I, 0.8, jnp.int32(n)) for n in ns]  # traced n_sub: one compilation
    qs7, Ps7 = B.rotate_free(q0, Pi0, I, 0.8, 7)  # static n_sub (a fori_loop with a fixed trip count)
    np.testing.assert_allclose(np.asarray(qs7), np.asarray(static[1][0]), atol=1e-15)
    np.testing.assert_allclose(np.asarray(Ps7), np.asarray(static[1][1]), atol=1e-15)
    # traced n_sub with a static maximum, vmapped over bodies with different substep counts == one by one
    qv, Pv = jax.jit(jax.vmap(lambda n: B.rotate_free(q0, Pi0, I, 0.8, n, n_max=12)))(jnp.array(ns))
    for i, (qs, Ps) in enumerate(static):
        np.testing.assert_allclose(np.asarray(qv[i]), np.asarray(qs), atol=1e-15)
        np.testing.assert_allclose(np.asarray(Pv[i]), np.asarray(Ps), atol=1e-15)
    # time reversibility of the symmetric splitting
    qa, Pa = static[1]
    qr, Pr = B.rotate_free(qa, Pa, I, -0.8, 7)
    np.testing.assert_allclose(np.asarray(Pr), np.asarray(Pi0), atol=1e-14)
    np.testing.assert_allclose(np.asarray(matrix_from_quat(qr)), np.asarray(matrix_from_quat(q0)), atol=1e-14)

    @jax.jit
    def conversions(q, Pi):
        w = B.omega_space(q, Pi, I)
        return (w, B.pi_from_omega_space(q, w, I), B.inertia_inv_space(q, I) @ B.angular_momentum_space(q, Pi),
                B.max_spin(Pi, I))

    w, Pi_back, w_from_L, om = (np.asarray(x) for x in conversions(q0, Pi0))
    np.testing.assert_allclose(Pi_back, np.asarray(Pi0), atol=1e-15)  # Π -> ω_space -> Π
    np.testing.assert_allclose(w_from_L, w, atol=1e-15)  # I⁻¹ L = ω
    np.testing.assert_allclose(w, np.asarray(matrix_from_quat(q0)) @ (np.asarray(Pi0) / np.asarray(I)), atol=1e-15)
    assert np.linalg.norm(w) <= om * (1 + 1e-15)  # |ω| <= sqrt(2T/I_min)
    with pytest.raises(JaxcoagInputError, match="n_sub"):
        B.rotate_free(q0, Pi0, I, 0.8, 0)


def test_sincos_small_is_sin_and_cos_to_round_off():
    x = np.linspace(-1.0, 1.0, 20001)
    s, c = jax.jit(B._sincos_small)(jnp.asarray(x))
    np.testing.assert_allclose(np.asarray(s), np.sin(x), rtol=0, atol=2.3e-16)
    np.testing.assert_allclose(np.asarray(c), np.cos(x), rtol=0, atol=2.3e-16)
    tiny = np.array([1e-300, 1e-12, -3e-7])
    np.testing.assert_allclose(np.asarray(jax.jit(B._sincos_small)(jnp.asarray(tiny))[0]), np.sin(tiny), rtol=2e-16)


@pytest.mark.parametrize("dt, n_sub, tol", [(0.3, 4, 4e-15), (0.05, "per body", 4e-15), (6.0, 1, 3e-13)])
def test_rotate_free_batch_equals_rotate_free_body_by_body(dt, n_sub, tol):
    """The (8, B)-row batch integrator is the same scheme as rotate_free, body by body, to round-off: one
    substep count, per-body counts (masked beyond each body's count), and half angles above 1 rad (dt = 6:
    XLA's sin/cos instead of the Taylor series; rotations of several radians, where cos θ = 1 - 2 sin²(θ/2) and
    rotate_free's cos θ round differently)."""
    rng = np.random.default_rng(11)
    n = 37
    q = jnp.asarray(rng.normal(size=(n, 4)))
    Pi = jnp.asarray(rng.normal(size=(n, 3)))
    Ip = jnp.asarray(rng.uniform(0.4, 2.5, size=(n, 3)))
    ns = jnp.asarray(rng.integers(1, 9, n)) if n_sub == "per body" else jnp.full(n, n_sub)
    ref = jax.jit(jax.vmap(lambda a, b, c, k: B.rotate_free(a, b, c, dt, k, n_max=8)))(q, Pi, Ip, ns)
    got = jax.jit(B.rotate_free_batch)(q, Pi, Ip, dt, ns if n_sub == "per body" else n_sub)
    np.testing.assert_allclose(np.asarray(got[0]), np.asarray(ref[0]), rtol=0, atol=tol)
    np.testing.assert_allclose(np.asarray(got[1]), np.asarray(ref[1]), rtol=0, atol=3 * tol)
    # |Π| and |q| = 1 are kept exactly by the rotations (to round-off)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(got[1]), axis=1), np.linalg.norm(np.asarray(Pi), axis=1),
                               rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(got[0]), axis=1), 1.0, rtol=1e-15)
    with pytest.raises(JaxcoagInputError, match="n_sub"):
        B.rotate_free_batch(q, Pi, Ip, dt, jnp.zeros(n, jnp.int32))
    with pytest.raises(JaxcoagInputError, match="shapes"):
        B.rotate_free_batch(q[0], Pi[0], Ip[0], dt, 1)


# --------------------------------------------------------------------------- A10.3 restitution


def _random_collision(rng, approach=True):
    m1, m2 = rng.uniform(0.3, 5.0, 2)
    X1, X2 = rng.normal(size=3), rng.normal(size=3) + np.array([2.0, 0, 0])
    rc = 0.5 * (X1 + X2) + 0.3 * rng.normal(size=3)
    c1, c2 = rc - X1, rc - X2
    Qa, Qb = _rot(rng), _rot(rng)
    I1 = Qa @ np.diag(rng.uniform(0.2, 3.0, 3)) @ Qa.T
    I2 = Qb @ np.diag(rng.uniform(0.2, 3.0, 3)) @ Qb.T
    V1, V2, w1, w2 = (rng.normal(size=3) for _ in range(4))
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    u = (V2 + np.cross(w2, c2)) - (V1 + np.cross(w1, c1))
    if (u @ n < 0) != approach:
        n = -n
    return dict(m1=m1, m2=m2, I1=I1, I2=I2, X1=X1, X2=X2, c1=c1, c2=c2, V1=V1, V2=V2, w1=w1, w2=w2, n=n)


def _args(c, eps, mu_t, mu_p):
    f = np.float64  # one dtype for every scalar: the jitted functions compile once
    return (f(c["m1"]), f(c["m2"]), np.linalg.inv(c["I1"]), np.linalg.inv(c["I2"]), c["c1"], c["c2"],
            c["V1"], c["V2"], c["w1"], c["w2"], c["n"], f(eps), f(mu_t), f(mu_p))


def _ke(c, V1, V2, w1, w2):
    return 0.5 * (c["m1"] * V1 @ V1 + c["m2"] * V2 @ V2 + w1 @ c["I1"] @ w1 + w2 @ c["I2"] @ w2)


def _L(c, V1, V2, w1, w2):
    return (c["m1"] * np.cross(c["X1"], V1) + c["m2"] * np.cross(c["X2"], V2) + c["I1"] @ w1 + c["I2"] @ w2)


@pytest.fixture(scope="module")
def restitute_jit():
    return jax.jit(B.restitute)


def test_restitution_fuzz_closed_form_conservation_and_energy(restitute_jit):
    rng = np.random.default_rng(2024)
    n_mu = 0
    for trial in range(40):
        c = _random_collision(rng)
        eps = rng.uniform(0.0, 1.0)
        mu_t, mu_p = (rng.uniform(-0.6, 0.6, 2) if trial % 2 else (0.0, 0.0))
        a = _args(c, eps, mu_t, mu_p)
        dV1, dV2, dw1, dw2 = (np.asarray(x) for x in restitute_jit(*a))
        V1, V2, w1, w2 = c["V1"] + dV1, c["V2"] + dV2, c["w1"] + dw1, c["w2"] + dw2
        n, t, p = (np.asarray(x) for x in contact_frame(c["n"]))
        u = (c["V2"] + np.cross(c["w2"], c["c2"])) - (c["V1"] + np.cross(c["w1"], c["c1"]))
        u_new = (V2 + np.cross(w2, c["c2"])) - (V1 + np.cross(w1, c["c1"]))
        scale_v = np.linalg.norm(u)
        # (R15) normal restitution
        assert abs(u_new @ n + eps * (u @ n)) < 1e-12 * scale_v
        # (R13) P conserved; (R14) L conserved about the origin
        P_scale = c["m1"] * np.linalg.norm(c["V1"]) + c["m2"] * np.linalg.norm(c["V2"]) + 1.0
        assert np.abs(c["m1"] * dV1 + c["m2"] * dV2).max() < 1e-12 * P_scale
        L0 = _L(c, c["V1"], c["V2"], c["w1"], c["w2"])
        assert np.abs(_L(c, V1, V2, w1, w2) - L0).max() < 1e-12 * (np.abs(L0).max() + P_scale)
        # independent K and the frictionless energy formula
        K = ((1 / c["m1"] + 1 / c["m2"]) * np.eye(3) + _skew(c["c1"]).T @ np.linalg.inv(c["I1"]) @ _skew(c["c1"])
             + _skew(c["c2"]).T @ np.linalg.inv(c["I2"]) @ _skew(c["c2"]))
        dKE = _ke(c, V1, V2, w1, w2) - _ke(c, c["V1"], c["V2"], c["w1"], c["w2"])
        assert dKE <= 1e-12 * _ke(c, c["V1"], c["V2"], c["w1"], c["w2"])
        P = c["m1"] * dV1
        # R95's 3x3 system (R20-R22) with the friction actually applied
        sys_mu = np.asarray(restitution_system(*a))
        sys_0 = np.asarray(restitution_system(*_args(c, eps, 0.0, 0.0)))
        ke_mu = _ke(c, c["V1"] + sys_mu, c["V2"] - c["m1"] / c["m2"] * sys_mu,
                    c["w1"] + c["m1"] * np.linalg.solve(c["I1"], np.cross(c["c1"], sys_mu)),
                    c["w2"] - c["m1"] * np.linalg.solve(c["I2"], np.cross(c["c2"], sys_mu)))
        friction_ok = ke_mu <= _ke(c, c["V1"], c["V2"], c["w1"], c["w2"])
        if friction_ok:
            n_mu += mu_t != 0.0
            np.testing.assert_allclose(dV1, sys_mu, rtol=1e-11, atol=1e-13 * scale_v)
            # (R16, R17) transverse impulses
            assert abs(P @ t - mu_t * (P @ n)) < 1e-12 * np.linalg.norm(P)
            assert abs(P @ p - mu_p * (P @ n)) < 1e-12 * np.linalg.norm(P)
        else:  # documented fallback to mu = 0 when friction would raise KE
            np.testing.assert_allclose(dV1, sys_0, rtol=1e-11, atol=1e-13 * scale_v)
        if mu_t == 0.0 or not friction_ok:
            nKn = n @ K @ n
            ref = -0.5 * (1 - eps**2) * (u @ n) ** 2 / nKn
            assert abs(dKE - ref) < 1e-12 * max(abs(ref), 1e-3 * _ke(c, c["V1"], c["V2"], c["w1"], c["w2"]))
            # (R24) written out in the ntp basis == mu n^T K n, and (R25) Δv_1 = γ(1+ε)(m2/M) u_n n̂
            mu = c["m1"] * c["m2"] / (c["m1"] + c["m2"])
            ginv = float(gamma_inverse_r24(*a[:6], c["n"]))
            assert abs(ginv - mu * nKn) < 1e-13 * ginv
            np.testing.assert_allclose(dV1, (1 + eps) * c["m2"] / (c["m1"] + c["m2"]) * (u @ n) / ginv * n,
                                       rtol=1e-12, atol=1e-14 * scale_v)
    assert n_mu >= 5  # the friction branch was actually exercised


def test_restitution_head_on_spheres_is_1d_textbook(restitute_jit):
    m1, m2, R1, R2, eps = 2.0, 3.0, 0.4, 0.7, 0.6
    n = np.array([1.0, 2.0, -2.0]) / 3.0
    v1, v2 = 1.5, -0.5  # velocities along n: approaching (u_n = v2 - v1 < 0)
    t_perp = np.cross(n, [0.0, 0.0, 1.0])
    V1, V2 = v1 * n + 0.3 * t_perp, v2 * n - 0.2 * t_perp  # tangential parts must be untouched
    w1, w2 = np.array([0.1, 0.2, 0.3]), np.array([-0.3, 0.0, 0.5])
    Iinv1, Iinv2 = np.eye(3) / (0.4 * m1 * R1**2), np.eye(3) / (0.4 * m2 * R2**2)
    dV1, dV2, dw1, dw2 = (np.asarray(x) for x in
                          restitute_jit(m1, m2, Iinv1, Iinv2, R1 * n, -R2 * n, V1, V2, w1, w2, n, eps, 0.0, 0.0))
    M = m1 + m2
    v1p = (m1 * v1 + m2 * v2 + m2 * eps * (v2 - v1)) / M
    v2p = (m1 * v1 + m2 * v2 + m1 * eps * (v1 - v2)) / M
    np.testing.assert_allclose(dV1, (v1p - v1) * n, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dV2, (v2p - v2) * n, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dw1, 0.0, atol=1e-15)
    np.testing.assert_allclose(dw2, 0.0, atol=1e-15)
    # separating bodies: nothing happens
    out = restitute_jit(m1, m2, Iinv1, Iinv2, R1 * n, -R2 * n, V2, V1, w1, w2, n, eps, 0.0, 0.0)
    assert all(float(jnp.abs(x).max()) == 0.0 for x in out)
    with pytest.raises(JaxcoagInputError, match="eps_n"):
        B.restitute(m1, m2, Iinv1, Iinv2, R1 * n, -R2 * n, V1, V2, w1, w2, n, 1.2)


def test_restitute_jit_equals_eager_and_vmap_equals_stack(restitute_jit):
    rng = np.random.default_rng(99)
    cases = [_args(_random_collision(rng, approach=i != 2), 0.3 + 0.1 * i, 0.2 * (i % 2), -0.1 * i)
             for i in range(4)]
    eager = [B.restitute(*a) for a in cases]
    for a, e in zip(cases, eager):
        for x, y in zip(restitute_jit(*a), e):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-14, atol=1e-15)
    stacked = [np.stack([np.asarray(a[k]) for a in cases]) for k in range(14)]
    batched = jax.vmap(B.restitute)(*stacked)
    for j in range(4):
        for k in range(4):
            np.testing.assert_allclose(np.asarray(batched[j][k]), np.asarray(eager[k][j]), rtol=1e-14, atol=1e-15)
    assert float(jnp.abs(eager[2][0]).max()) == 0.0  # the separating case


def test_contact_frame_right_handed():
    rng = np.random.default_rng(4)
    for v in list(rng.normal(size=(10, 3))) + [np.array([0, 0, 3.0]), np.array([1.0, 1.0, 1.0])]:
        n, t, p = (np.asarray(x) for x in contact_frame(v))
        Bm = np.stack([n, t, p], axis=1)
        np.testing.assert_allclose(Bm.T @ Bm, np.eye(3), atol=1e-15)
        assert abs(np.linalg.det(Bm) - 1.0) < 1e-14
        np.testing.assert_allclose(n, v / np.linalg.norm(v), atol=1e-15)
        np.testing.assert_allclose(np.cross(n, t), p, atol=1e-15)


# --------------------------------------------------------------------------- A10.4 coagulation


def _body(pos, m, R):
    """State of a rigid body made of spheres (numpy): X, q, Ip, body offsets."""
    X = (m[:, None] * pos).sum(0) / m.sum()
    Ip, A = principal_axes(inertia_tensor(pos - X[None, :], m, R))
    q = quat_from_matrix(A)
    return X, q, np.asarray(Ip)


def test_merge_conserves_momentum_angular_momentum_and_dissipates():
    rng = np.random.default_rng(7)
    R = 0.1
    for trial in range(4):
        pos1 = np.array([[0, 0, 0], [2 * R, 0, 0], [2 * R, 2 * R, 0.0]]) + 0.01 * rng.normal(size=(3, 3))
        pos2 = np.array([[0, 0, 0], [0, 2 * R, 0], [0, 2 * R, 2 * R], [2 * R, 2 * R, 2 * R]]) @ _rot(rng).T
        pos2 = pos2 + np.array([5 * R, 0.3 * R, -0.2 * R])[None, :]
        m = rng.uniform(0.5, 1.5, 7)
        Rs = np.full(7, R)
        X1, q1, Ip1 = _body(pos1, m[:3], Rs[:3])
        X2, q2, Ip2 = _body(pos2, m[3:], Rs[3:])
        m1, m2 = m[:3].sum(), m[3:].sum()
        V1, V2 = rng.normal(size=3), rng.normal(size=3)
        Pi1, Pi2 = rng.normal(size=3) * Ip1, rng.normal(size=3) * Ip2
        # fixed capacity 9 with two dead lanes
        sph_x = np.concatenate([pos1, pos2, 99 * np.ones((2, 3))])
        sph_m = np.concatenate([m, [7.0, 7.0]])
        sph_R = np.concatenate([Rs, [3.0, 3.0]])
        mask = np.array([True] * 7 + [False] * 2)
        X, V, q, Pi, Ip, b, Rmax = jax.jit(B.merge)(X1, V1, q1, Pi1, Ip1, m1, X2, V2, q2, Pi2, Ip2, m2,
                                                   sph_x, sph_m, sph_R, mask)
        X, V, Pi, Ip, b = (np.asarray(a) for a in (X, V, Pi, Ip, b))
        M = m1 + m2
        P0 = m1 * V1 + m2 * V2
        assert np.abs(M * V - P0).max() < 1e-14 * np.abs(P0).max() + 1e-15
        np.testing.assert_allclose(X, (m[:, None] * sph_x[:7]).sum(0) / M, atol=1e-14)
        L0 = (m1 * np.cross(X1, V1) + m2 * np.cross(X2, V2) + np.asarray(B.angular_momentum_space(q1, Pi1))
              + np.asarray(B.angular_momentum_space(q2, Pi2)))
        L1 = M * np.cross(X, V) + np.asarray(B.angular_momentum_space(q, Pi))
        assert np.abs(L1 - L0).max() < 1e-13 * np.abs(L0).max()
        ke0 = 0.5 * (m1 * V1 @ V1 + m2 * V2 @ V2) + float(B.kinetic_energy_rot(Pi1, Ip1) + B.kinetic_energy_rot(Pi2, Ip2))
        ke1 = 0.5 * M * V @ V + float(B.kinetic_energy_rot(Pi, Ip))
        assert ke1 <= ke0 * (1 + 1e-14)
        # geometry: spheres keep their space positions; Ip is the spectrum of the (R1) tensor; R_max (R7)
        A = np.asarray(matrix_from_quat(q))
        np.testing.assert_allclose(X[None, :] + b[:7] @ A.T, sph_x[:7], atol=1e-14)
        np.testing.assert_allclose(b[7:], 0.0, atol=0)
        Iref = np.asarray(inertia_tensor(sph_x[:7] - X[None, :], m, Rs))
        np.testing.assert_allclose(Ip, np.linalg.eigvalsh(Iref), rtol=1e-12)
        assert abs(float(Rmax) - (np.linalg.norm(sph_x[:7] - X[None, :], axis=1) + R).max()) < 1e-14


def test_merge_stationary_pair_and_grazing_spin():
    m, R, v = 1.3, 0.1, 2.0
    Ip1 = np.full(3, 0.4 * m * R**2)
    q0 = np.array([1.0, 0, 0, 0])
    X1, X2 = np.zeros(3), np.array([2 * R, 0.0, 0.0])
    sph_x = np.stack([X1, X2])
    mask = np.array([True, True])
    # stationary pair: no spin
    out = merge(X1, np.zeros(3), q0, np.zeros(3), Ip1, m, X2, np.zeros(3), q0, np.zeros(3), Ip1, m,
                  sph_x, np.full(2, m), np.full(2, R), mask)
    assert float(jnp.abs(out[3]).max()) == 0.0 and float(jnp.abs(out[1]).max()) == 0.0
    # grazing: sphere 1 moves along +y past sphere 2 at rest -> L about the COM = -m R v ẑ, I_zz = 2.8 m R²
    X, V, q, Pi, Ip, b, Rmax = merge(X1, np.array([0.0, v, 0.0]), q0, np.zeros(3), Ip1, m, X2, np.zeros(3), q0,
                                       np.zeros(3), Ip1, m, sph_x, np.full(2, m), np.full(2, R), mask)
    w = np.asarray(B.omega_space(q, Pi, Ip))
    np.testing.assert_allclose(w, [0.0, 0.0, -v / (2.8 * R)], atol=1e-12)
    np.testing.assert_allclose(np.asarray(V), [0.0, v / 2, 0.0], atol=1e-15)
    np.testing.assert_allclose(np.sort(np.asarray(Ip)), [0.8 * m * R**2, 2.8 * m * R**2, 2.8 * m * R**2], rtol=1e-13)
    assert abs(float(Rmax) - 2 * R) < 1e-15
    # the same with the spheres' own spins added: ω = (L_orb + I_s ω1 + I_s ω2)/I_zz about z
    s1, s2 = 3.0, -1.0
    X, V, q, Pi, Ip, b, Rmax = merge(X1, np.array([0.0, v, 0.0]), q0, Ip1 * np.array([0, 0, s1]), Ip1, m, X2,
                                       np.zeros(3), q0, Ip1 * np.array([0, 0, s2]), Ip1, m, sph_x, np.full(2, m),
                                       np.full(2, R), mask)
    w = np.asarray(B.omega_space(q, Pi, Ip))
    np.testing.assert_allclose(w[2], (-m * R * v + 0.4 * m * R**2 * (s1 + s2)) / (2.8 * m * R**2), rtol=1e-12)


# --------------------------------------------------------------------------- A10.5 impact times, ε_n(v)


def test_sphere_toi_matches_brute_force_stepping():
    rng = np.random.default_rng(31)
    n = 60
    d = rng.normal(size=(n, 3)) * 3.0
    Rc = rng.uniform(0.3, 1.5, n)
    # velocities aimed roughly back at the partner, so that some pairs hit and some miss
    u = -d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.5, 2.0, (n, 1)) + 0.6 * rng.normal(size=(n, 3))
    ok = np.linalg.norm(d, axis=1) > Rc  # start apart
    d, u, Rc = d[ok], u[ok], Rc[ok]
    tc = np.asarray(jax.jit(B.sphere_toi)(d, u, Rc))
    ts = np.linspace(0.0, 20.0, 20001)
    dist = np.linalg.norm(d[:, None, :] + u[:, None, :] * ts[None, :, None], axis=2)
    touch = dist <= Rc[:, None]
    first = np.where(touch.any(1), ts[np.argmax(touch, axis=1)], np.inf)
    hit = np.isfinite(first)
    assert 10 < hit.sum() < len(d) - 5  # both hits and misses in the sample
    dt = ts[1] - ts[0]
    assert np.all((tc[hit] <= first[hit] + 1e-12) & (tc[hit] > first[hit] - dt))
    assert np.all(~np.isfinite(tc[~hit]) | (tc[~hit] > 20.0))
    # overlapping and approaching -> 0; receding -> inf
    assert float(B.sphere_toi(np.array([0.5, 0, 0]), np.array([-1.0, 0, 0]), 1.0)) == 0.0
    assert float(B.sphere_toi(np.array([3.0, 0, 0]), np.array([1.0, 0, 0]), 1.0)) == np.inf


def test_safe_time_never_overshoots_the_bound():
    rng = np.random.default_rng(17)
    n = 4000
    g = np.where(rng.uniform(size=n) < 0.1, -rng.uniform(0, 1e-6, n), rng.lognormal(-2, 2, n))
    gd = rng.normal(size=n) * rng.lognormal(0, 2, n)
    A = np.where(rng.uniform(size=n) < 0.2, 0.0, rng.lognormal(0, 3, n))
    ts = np.asarray(jax.jit(B.safe_time)(g, gd, A))
    assert np.all(ts >= 0)
    g0 = np.maximum(g, 0)
    fin = np.isfinite(ts)
    # the worst-case gap g + ġ t − ½ A t² is >= 0 on [0, t*] and reaches 0 at t* (a tight bound)
    f = np.linspace(0, 1, 101)
    tt = ts[fin, None] * f[None, :]
    lb = g0[fin, None] + gd[fin, None] * tt - 0.5 * A[fin, None] * tt**2
    scale = g0[fin, None] + np.abs(gd[fin, None]) * tt + 0.5 * A[fin, None] * tt**2
    assert np.all(lb >= -1e-12 * scale)
    assert np.all(np.abs(lb[:, -1]) <= 1e-11 * scale[:, -1])
    # infinite only when the gap can never close: A = 0 and ġ >= 0
    assert np.array_equal(~fin, (A == 0) & (gd >= 0))
    # exact A = 0 case and the just-bounced pair (g = 0, ġ > 0): t* = 2ġ/A
    assert float(B.safe_time(2.0, -0.5, 0.0)) == 4.0
    assert float(B.safe_time(-1e-9, 0.3, 1.5)) == pytest.approx(0.4, rel=1e-15)


def test_conservative_advancement_rotating_dumbbells_no_tunnelling():
    """Two fast-spinning dumbbells fired at each other; steps of 0.9 t* never overlap beyond tol."""
    R = 0.1
    b = np.array([[-R, 0, 0], [R, 0, 0.0]])  # body offsets along the long axis
    m = np.ones(2)
    Ip = np.asarray(principal_axes(inertia_tensor(b, m, np.full(2, R)))[0])
    Rmax = 2 * R
    tol = 1e-6 * R

    def spheres(X, V, q, Pi):
        A = matrix_from_quat(q)
        r = b @ A.T
        w = B.omega_space(q, Pi, Ip)
        return X[None, :] + r, V[None, :] + jnp.cross(jnp.broadcast_to(w, r.shape), r)

    def step(s):
        X, V, q, Pi = s
        x1, u1 = spheres(X[0], V[0], q[0], Pi[0])
        x2, u2 = spheres(X[1], V[1], q[1], Pi[1])
        d = x2[None, :, :] - x1[:, None, :]
        du = u2[None, :, :] - u1[:, None, :]
        dist = jnp.linalg.norm(d, axis=-1)
        g = dist - 2 * R
        gd = jnp.sum(d * du, axis=-1) / dist
        Om = jax.vmap(B.max_spin, in_axes=(0, None))(Pi, Ip)
        A = 2 * (Om[0] ** 2 + Om[1] ** 2) * Rmax
        dt = jnp.minimum(0.9 * jnp.min(B.safe_time(g, gd, A)), 1.0)
        n_sub = jnp.maximum(jnp.ceil(jnp.max(Om) * dt / 0.02).astype(jnp.int32), 1)
        qn, Pn = jax.vmap(lambda qq, pp: B.rotate_free(qq, pp, Ip, dt, n_sub, n_max=64))(q, Pi)
        event = jnp.any((g <= tol) & (gd < 0))
        return (X + V * dt, V, qn, Pn), jnp.min(g), event

    @jax.jit
    @jax.vmap
    def advance(X, V, q, Pi):
        """Step until an event (g <= tol, approaching) or 400 steps; track the smallest gap seen."""

        def cond(c):
            return (~c[3]) & (c[1] < 400)

        def body(c):
            s, it, worst, _ = c
            s2, gmin, event = step(s)
            s2 = jax.tree_util.tree_map(lambda a, b2: jnp.where(event, a, b2), s, s2)  # stop at the event
            return s2, it + 1, jnp.minimum(worst, gmin), event

        s0 = (X, V, q, Pi)
        _, it, worst, event = jax.lax.while_loop(cond, body, (s0, 0, jnp.inf, False))
        return worst, event, it

    rng = np.random.default_rng(123)
    n_tr = 8
    q = jnp.asarray([[quat_from_matrix(_rot(rng)) for _ in range(2)] for _ in range(n_tr)])
    Pi = jnp.asarray(rng.normal(size=(n_tr, 2, 3)) * 20.0) * Ip[None, None, :]  # |ω| ~ 35 rad/s
    off = rng.uniform(-0.15, 0.15, (n_tr, 2))  # impact parameters up to ~R_max
    X = jnp.asarray(np.stack([np.zeros((n_tr, 3)), np.stack([np.ones(n_tr), off[:, 0], off[:, 1]], 1)], 1))
    V = jnp.broadcast_to(jnp.array([[3.0, 0.0, 0.0], [-3.0, 0.0, 0.0]]), (n_tr, 2, 3))  # 6 cm/s closing
    worst, event, iters = (np.asarray(a) for a in advance(X, V, q, Pi))
    assert event.all(), "the dumbbells must meet"
    print("dumbbells: smallest gap / R =", worst.min() / R, "steps to contact:", iters)
    assert np.all(worst > -tol), worst
    assert np.all(iters < 400)


def test_bridges_epsilon_values():
    v = np.array([0.0, 0.0077, 0.5 * 0.0077, 1.0, 10.0, 100.0])
    eps = np.asarray(jax.jit(B.bridges_epsilon)(v))
    np.testing.assert_allclose(eps[:3], 1.0, rtol=0, atol=0)  # elastic below v_c
    np.testing.assert_allclose(eps[3:], (v[3:] / 0.0077) ** -0.234, rtol=1e-14)
    assert abs(eps[3] - 0.32) < 5e-4  # the "0.32 (v / 1 cm/s)^-0.234" form of Bridges et al. (1984)
    np.testing.assert_allclose(float(B.bridges_epsilon(1.0, v_unit=10.0)), eps[4], rtol=1e-15)
    with pytest.raises(JaxcoagInputError, match="v_c"):
        B.bridges_epsilon(1.0, v_c=0.0)
