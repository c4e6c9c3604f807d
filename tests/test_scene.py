"""Scenes and the physical kernel: composition, trace economy, values, gradients, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcoag.physics.drift as drift
import jaxcoag.physics.turbulence as turb
from jaxcoag import constants as C
from jaxcoag import effects as E
from jaxcoag import scenes
from jaxcoag._validate import JaxcoagInputError
from jaxcoag.physics import gas as G
from jaxcoag.scene import Scene

RHO_S = 3.0
A = np.logspace(-5, 2, 8)  # radii [cm]
M = jnp.asarray(4 / 3 * np.pi * RHO_S * A ** 3)


def _gas(alpha=1e-4):
    return G.ch4_disk(3 * C.AU, alpha=alpha)


def test_brownian_kernel_matches_hand_formula():
    gas = _gas()
    K = scenes.brownian_only().kernel(gas, rho_s=RHO_S).matrix(M)
    a1, a2 = A[:, None], A[None, :]
    m1, m2 = np.asarray(M)[:, None], np.asarray(M)[None, :]
    dv = np.sqrt(8 * C.k_B * float(gas.T) / np.pi * (1 / m1 + 1 / m2))
    np.testing.assert_allclose(K, np.pi * (a1 + a2) ** 2 * dv, rtol=1e-12)


def test_quadrature_sum_of_components_equals_physics_functions():
    gas = _gas()
    kern = scenes.nebula_ch4().kernel(gas, rho_s=RHO_S)
    p = kern.particles(M)
    st = np.asarray(p.st)
    dv2 = np.asarray(kern.relative_velocity2(M[:, None], M[None, :]))
    turb_dv = np.asarray(turb.dv_turbulent_oc07(st[:, None], st[None, :], float(gas.Re))) * float(gas.v_g)
    bm = np.asarray(drift.dv_brownian(M[:, None], M[None, :], gas.T))
    rd = 2 * float(gas.eta * gas.v_K) * np.abs(st[:, None] / (1 + st[:, None] ** 2) - st[None, :] / (1 + st[None, :] ** 2))
    np.testing.assert_allclose(dv2, bm ** 2 + turb_dv ** 2 + rd ** 2, rtol=1e-10)
    comps = kern.components_matrix(M)
    assert set(comps) == {"brownian", "turbulence", "radial_drift"}
    np.testing.assert_allclose(sum(comps.values()), dv2, rtol=1e-14)
    # matrix == broadcasting __call__ and symmetric
    Kmat = np.asarray(kern.matrix(M))
    np.testing.assert_allclose(Kmat, np.asarray(kern(M[:, None], M[None, :])), rtol=1e-14)
    np.testing.assert_allclose(Kmat, Kmat.T, rtol=1e-14)
    Km2, dv2b = kern.matrix_and_dv2(M)
    np.testing.assert_allclose(Km2, Kmat, rtol=1e-14)
    np.testing.assert_allclose(dv2b, dv2, rtol=1e-14)


def test_scene_traces_only_named_effects(monkeypatch):
    calls = []

    def spy(name, fn):
        def wrapped(*a, **k):
            calls.append(name)
            return fn(*a, **k)
        return wrapped

    monkeypatch.setattr(turb, "st_star", spy("st_star", turb.st_star))
    monkeypatch.setattr(turb, "dv2_terms_oc07", spy("oc07", turb.dv2_terms_oc07))
    for nm in ("_dv2_brownian", "_dv2_radial_drift", "_dv2_azimuthal_drift", "_dv2_settling"):
        monkeypatch.setattr(drift, nm, spy(nm, getattr(drift, nm)))
    gas = _gas()
    jax.make_jaxpr(scenes.brownian_only().kernel(gas, rho_s=RHO_S).matrix)(M)
    assert calls == ["_dv2_brownian"]
    calls.clear()
    jax.make_jaxpr(scenes.nebula_ch4().kernel(gas, rho_s=RHO_S).matrix)(M)
    assert sorted(calls) == sorted(["st_star", "oc07", "_dv2_brownian", "_dv2_radial_drift"])
    assert calls.count("st_star") == 1  # one per-particle root solve for the whole N x N matrix


def _count_eqns(jaxpr):
    """Equations in a jaxpr including every nested sub-jaxpr (pjit, custom_jvp, cond...)."""
    n = 0
    for eq in jaxpr.eqns:
        n += 1
        for v in eq.params.values():
            for sub in (v if isinstance(v, (tuple, list)) else (v,)):
                inner = getattr(sub, "jaxpr", None)
                if inner is not None and hasattr(inner, "eqns"):
                    n += _count_eqns(inner)
                elif hasattr(sub, "eqns"):
                    n += _count_eqns(sub)
    return n


def _n_eqns(*effects):
    jp = jax.make_jaxpr(Scene(velocities=tuple(effects)).kernel(_gas(), rho_s=RHO_S).matrix)(M)
    return _count_eqns(jp.jaxpr)


def test_op_counts_are_additive_in_named_effects():
    B, T, R, Z = E.Brownian(), E.TurbulenceOC07(), E.RadialDrift(), E.Settling()
    n_b, n_bt, n_br, n_btr, n_btrz = _n_eqns(B), _n_eqns(B, T), _n_eqns(B, R), _n_eqns(B, T, R), _n_eqns(B, T, R, Z)
    assert n_b < n_br < n_bt < n_btr < n_btrz
    # each effect costs the same ops whatever else the scene holds: nothing unnamed is traced
    assert n_btr - n_bt == n_br - n_b
    assert n_btr - n_br == n_bt - n_b
    # the turbulence model (root solve + OC07 closed form) costs more ops than the drift term
    assert n_bt - n_b > n_br - n_b


def test_gradients_wrt_log_disk_parameters_vs_fd():
    m1, m2 = M[2], M[4]
    base = dict(rho_g=2.4e-11, T=162.0, alpha=1e-4, rho_s=RHO_S)
    Omega = 3.83e-8

    def logk(lp):
        p = {k: jnp.exp(v) for k, v in lp.items()}
        gas = G.midplane_state(p["rho_g"], p["T"], p["alpha"], Omega)
        return jnp.log(scenes.nebula_ch4().kernel(gas, rho_s=p["rho_s"])(m1, m2))

    lp0 = {k: jnp.log(v) for k, v in base.items()}
    g = jax.grad(logk)(lp0)
    h = 1e-5
    for k in base:
        up = dict(lp0); up[k] = lp0[k] + h
        dn = dict(lp0); dn[k] = lp0[k] - h
        fd = (logk(up) - logk(dn)) / (2 * h)
        np.testing.assert_allclose(g[k], fd, rtol=1e-5, atol=1e-9, err_msg=k)
    assert float(g["alpha"]) > 0  # turbulence dominates for these sizes: more alpha, faster growth


def test_jit_and_vmap_over_alpha():
    alphas = jnp.array([1e-6, 1e-4, 1e-2])

    def kmat(alpha):
        gas = G.midplane_state(2.4e-11, 162.0, alpha, 3.83e-8)
        return scenes.nebula_ch4().kernel(gas, rho_s=RHO_S).matrix(M)

    loop = jnp.stack([kmat(a) for a in alphas])
    np.testing.assert_allclose(jax.vmap(kmat)(alphas), loop, rtol=1e-12)
    np.testing.assert_allclose(jax.jit(kmat)(alphas[1]), loop[1], rtol=1e-12)


def test_extreme_alpha_and_equal_particles_finite_with_gradients():
    for alpha in (1e-10, 1e-6, 1e-1, 0.0):
        gas = _gas(alpha)
        K = scenes.nebula_ch4().kernel(gas, rho_s=RHO_S).matrix(M)
        assert np.all(np.isfinite(K)) and np.all(np.asarray(K) > 0)
    # turbulence-only scene: identical tiny particles have dv = 0 exactly, and finite gradients
    kern = scenes.turbulence_only().kernel(_gas(), rho_s=RHO_S)
    assert float(kern(M[0], M[0])) == 0.0
    g = jax.grad(lambda lm: kern(jnp.exp(lm), M[0]))(jnp.log(M[0]))
    assert np.isfinite(float(g))


def test_focusing_raises_kernel_for_big_bodies():
    gas = _gas()
    big = jnp.asarray(4 / 3 * np.pi * RHO_S * (1e7) ** 3)  # 100 km bodies
    k0 = scenes.nebula_ch4().kernel(gas, rho_s=RHO_S)(big, big)
    sc = Scene(velocities=(E.Brownian(), E.TurbulenceOC07(), E.RadialDrift()), focusing=True)
    k1 = sc.kernel(gas, rho_s=RHO_S)(big, big)
    assert float(k1) > 10 * float(k0)


def test_bad_scenes_and_parameters_raise_clear_errors():
    with pytest.raises(ValueError, match="non-empty tuple"):
        Scene(velocities=())
    with pytest.raises(TypeError, match="velocity modules"):
        Scene(velocities=("brownian",))
    with pytest.raises(ValueError, match="more than once"):
        Scene(velocities=(E.Brownian(), E.Brownian()))
    with pytest.raises(ValueError, match="drag_regime"):
        Scene(velocities=(E.Brownian(),), drag_regime="newton")
    with pytest.raises(ValueError, match="method"):
        E.TurbulenceOC07(method="fast")
    with pytest.raises(JaxcoagInputError, match="rho_s"):
        scenes.brownian_only().kernel(_gas(), rho_s=-1.0)
    with pytest.raises(ValueError, match="material density"):
        scenes.brownian_only().kernel(_gas())
    with pytest.raises(ValueError, match="available"):
        scenes.get("nebula_ch5")


def test_presets_name_their_effects():
    assert scenes.brownian_only().effect_names == ("brownian",)
    assert scenes.nebula_ch4().effect_names == ("brownian", "turbulence", "radial_drift")
    assert scenes.dustpy_like().effect_names == ("brownian", "turbulence", "radial_drift", "azimuthal_drift", "settling")
    assert scenes.get("molecular_cloud").effect_names == ("brownian", "turbulence")


def test_drift_uses_omega_tau_f_whatever_the_eddy_time_convention():
    # with t_L = 2 pi / Omega (ch. 2 legacy) St = tau_f/t_L changes, but drift depends on Omega tau_f
    g1 = G.ch4_disk(3 * C.AU)
    g2 = G.ch4_disk(3 * C.AU, tL_factor=2 * np.pi)
    sc = Scene(velocities=(E.RadialDrift(),))
    d1 = sc.kernel(g1, rho_s=RHO_S).relative_velocity2(M[:, None], M[None, :])
    d2 = sc.kernel(g2, rho_s=RHO_S).relative_velocity2(M[:, None], M[None, :])
    np.testing.assert_allclose(d1, d2, rtol=1e-13)
