"""Per-cell coagulation and fragmentation of the disk model (jaxcoag.disk.coagulation/velocities).

Parity: the collision tensors, every relative-velocity component, the kernel, p_frag, S_coag and the
Picard matrix J~ against DustPy 1.0.9's own Fortran routines at the CI set-up (Nr = 30, m_max = 1e2 g) at
t = 0 (MRN) and after 1e3 yr of DustPy's evolution (numbers in tests/data/dustpy_coag_ref.npz; regenerate
with ``python benchmarks/peers/dustpy_ref_coag.py``). Independent physics: per-collision mass
conservation of the tensors (Brauer et al. 2008 A.1-A.2; Stammler & Birnstiel 2022 §2.3.2), S = J~ Sigma,
mass conservation for random states, the constant-kernel Smoluchowski number decay N(t) = N0/(1 + K N0
t/2), closed-form velocity limits (Brownian, azimuthal drift, Ormel & Cuzzi 2007 heavy-particle limit),
jit/vmap consistency and gradients against central finite differences.
"""

from __future__ import annotations

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

from jaxcoag._validate import JaxcoagInputError  # noqa: E402
from jaxcoag.disk import coagulation as cg  # noqa: E402
from jaxcoag.disk import velocities as vl  # noqa: E402

REF = pathlib.Path(__file__).parent / "data" / "dustpy_coag_ref.npz"
K_B = 1.380649e-16  # DustPy 1.0.9 constants.f90 [erg K^-1]


@pytest.fixture(scope="module")
def ref():
    return dict(np.load(REF))


@pytest.fixture(scope="module")
def tens(ref):
    return cg.coagulation_tensors(ref["grid_m"], *ref["coag_args"])


def _maxrel(a, b):
    """max |a - b| / max |b| (0 if both vanish)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = np.max(np.abs(b))
    d = np.max(np.abs(a - b))
    return d / scale if scale > 0 else d


_KEYS = ("dust_v_driftmax", "dust_St", "gas_cs", "gas_T", "dust_v_rad", "delta_turb", "gas_mu", "OmegaK",
         "gas_Sigma", "dust_H", "dust_a", "dust_Sigma", "dust_SigmaFloor", "v_frag")


def _fields(ref, tag):
    """Our velocities, kernel and p_frag (nr, nm, nm) from DustPy's recorded inputs of state ``tag``."""
    return _fields_jit(ref["grid_m"], {k: ref[f"{tag}_{k}"] for k in _KEYS})


@jax.jit
def _fields_jit(m, d):
    g = d.__getitem__
    comps = dict(azi=vl.dv_azimuthal_drift(g("dust_v_driftmax"), g("dust_St")),
                 brown=vl.dv_brownian(g("gas_cs"), m, g("gas_T")),
                 rad=vl.dv_radial_drift(g("dust_v_rad")),
                 turb=vl.dv_turbulent_oc07_dustpy(g("delta_turb"), g("gas_cs"), g("gas_mu"), g("OmegaK"),
                                                  g("gas_Sigma"), g("dust_St")),
                 vert=vl.dv_settling(g("dust_H"), g("OmegaK"), g("dust_St")))
    comps["tot"] = vl.dv_total(*comps.values())
    K = cg.vertical_kernel(g("dust_a"), g("dust_H"), comps["tot"], g("dust_Sigma"), g("dust_SigmaFloor"))
    pf = cg.p_frag(comps["tot"], g("v_frag"))
    return comps, K, pf


_S_CELLS = jax.jit(jax.vmap(cg.coagulation_source, in_axes=(None, None, 0, 0, 0, 0)))
_J_CELLS = jax.jit(jax.vmap(cg.coagulation_jacobian, in_axes=(None, None, 0, 0, 0, 0)))


def _rates(ref, tag):
    _, K, pf = _fields(ref, tag)
    return K * (1.0 - pf), K * pf


# ------------------------------------------------------------------------------------------ parity with DustPy
def test_tensors_equal_dustpy(ref, tens):
    for k in ("stick_ind", "lf_ind", "rm_ind"):
        assert np.array_equal(np.asarray(getattr(tens, k)), ref[f"coag_{k}"]), k
    for k in ("stick", "A", "eps"):
        assert np.array_equal(np.asarray(getattr(tens, k)), ref[f"coag_{k}"]), k
    # phi: normalisation sum in a different order (pairwise vs sequential): 1 ulp
    np.testing.assert_allclose(np.asarray(tens.phi), ref["coag_phi"], rtol=1e-15, atol=0.0)
    assert (tens.p, tens.q) == (7, 3)  # floor(log10 10 / (1/7)) and ceil(log10 2 / (1/7)) at 7 bins/decade


@pytest.mark.parametrize("tag", ["t0", "t1"])
def test_velocities_kernel_pfrag_equal_dustpy(ref, tag):
    comps, K, pf = _fields(ref, tag)
    nm = ref["grid_m"].size
    iu = np.triu_indices(nm)
    for c in ref[f"{tag}_cells"]:
        for k, v in comps.items():
            assert _maxrel(np.asarray(v[c])[iu], ref[f"{tag}_c{c}_vrel_{k}"]) < 1e-14, (tag, c, k)
            # symmetric, as DustPy fills both triangles
            np.testing.assert_allclose(np.asarray(v[c]), np.asarray(v[c]).T, rtol=1e-12, atol=0.0)
        r = np.asarray(K[c])[iu]
        np.testing.assert_allclose(r, ref[f"{tag}_c{c}_kernel"], rtol=1e-14, atol=0.0)
        # p_f ~ exp(-1.5 x) amplifies the round-off of x = (v_f/dv)^2 by 1.5 x (x up to ~1e3 here; XLA also
        # flushes subnormals to zero), hence rtol 1e-12 and an absolute floor far below any physical rate
        np.testing.assert_allclose(np.asarray(pf[c])[iu], ref[f"{tag}_c{c}_pfrag"], rtol=1e-12, atol=1e-250)
        assert np.all(np.tril(np.asarray(K[c]), -1) == 0.0)


@pytest.mark.parametrize("tag", ["t0", "t1"])
def test_source_equals_dustpy_s_coag(ref, tens, tag):
    Rs, Rf = _rates(ref, tag)
    S = np.asarray(_S_CELLS(tens, ref["grid_m"], Rs, Rf, ref[f"{tag}_dust_Sigma"], ref[f"{tag}_dust_SigmaFloor"]))
    Sref = ref[f"{tag}_S_coag"]
    assert np.any(Sref[1:-1] != 0.0)
    for ir in range(1, Sref.shape[0] - 1):  # DustPy has no coagulation in the first and last cell
        # S is a small difference of large gains and losses near the fragmentation equilibrium
        assert np.max(np.abs(S[ir] - Sref[ir])) <= 1e-10 * max(np.max(np.abs(Sref[ir])), 1e-300), ir


@pytest.mark.parametrize("tag", ["t0", "t1"])
def test_jacobian_equals_dustpy_sparse(ref, tens, tag):
    Rs, Rf = _rates(ref, tag)
    cells = ref[f"{tag}_cells"]
    Js = np.asarray(_J_CELLS(tens, ref["grid_m"], Rs[cells], Rf[cells], ref[f"{tag}_dust_Sigma"][cells],
                             ref[f"{tag}_dust_SigmaFloor"][cells]))
    for J, c in zip(Js, cells):
        Jr = ref[f"{tag}_c{c}_jac"]
        assert _maxrel(J, Jr) < 1e-14, (tag, c)
        # structure: nothing below the q-th sub-diagonal, column sums as DustPy's
        assert np.all(np.tril(J, -tens.q - 1) == 0.0)
        np.testing.assert_allclose(J.sum(axis=0), Jr.sum(axis=0), rtol=0.0, atol=1e-14 * np.max(np.abs(Jr)))


def test_after_evolution_not_mrn_and_floor_active(ref):
    """The t1 state exercises what t0 cannot: bins beyond the MRN cut-off and bins below the floor."""
    for c in ref["t1_cells"]:
        above = ref["t1_dust_Sigma"][c] > ref["t1_dust_SigmaFloor"][c]
        above0 = ref["t0_dust_Sigma"][c] > ref["t0_dust_SigmaFloor"][c]
        assert np.nonzero(above)[0].max() > np.nonzero(above0)[0].max() + 50
        assert not np.all(above)


# ------------------------------------------------------------------------------------------ independent checks
def test_tensors_conserve_mass_per_collision(ref, tens):
    m = ref["grid_m"]
    nm = m.size
    J, I = np.meshgrid(np.arange(nm), np.arange(nm), indexing="ij")
    up = J <= I
    st, si = np.asarray(tens.stick), np.asarray(tens.stick_ind)
    gain = np.sum(st * np.where(si >= 0, m[np.clip(si, 0, None)], 0.0), axis=0)
    # a sticking collision conserves m_i + m_j (or, for products beyond the grid, does not happen)
    has = np.any(si >= 0, axis=0) & up
    assert np.max(np.abs(gain[has]) / (m[J] + m[I])[has]) < 1e-13
    assert float(ref["coag_masserr_stick"]) < 1e-13  # DustPy's own diagnostic
    # fragments carry A: m_i + m_j (full fragmentation) or (1 + f_exc) m_j (erosion); phi rows sum to 1
    A, eps, krm, lf = (np.asarray(x) for x in (tens.A, tens.eps, tens.rm_ind, tens.lf_ind))
    np.testing.assert_allclose(np.asarray(tens.phi).sum(axis=1), 1.0, rtol=1e-14)
    full = (J >= I - tens.p) & up
    ero = J <= I - tens.p - 1
    np.testing.assert_allclose(A[full], (m[J] + m[I])[full], rtol=1e-15)
    np.testing.assert_array_equal(lf[full], I[full])
    np.testing.assert_array_equal(lf[ero], J[ero])
    # erosion: remnant (split into krm, krm+1) + fragments = m_i + m_j, to round-off of the larger mass
    k = np.clip(krm, 0, nm - 2)
    rem = np.where(krm == I - 1, eps * m[np.clip(I - 1, 0, None)] - eps * m[I] + m[I],
                   eps * m[k] + (1 - eps) * m[k + 1])
    err = rem + A - m[I] - m[J]
    assert np.max(np.abs(err[ero]) / m[I][ero]) < 4 * np.finfo(float).eps


def test_source_conserves_mass_and_equals_jacobian_times_sigma(ref, tens):
    m = ref["grid_m"]
    nm = m.size
    rng = np.random.default_rng(7)
    floor = np.full((3, nm), 1e-14)
    sigs = 10 ** rng.uniform(-16, 0, (3, nm))  # some bins below the floor
    Rss = np.triu(10 ** rng.uniform(-4, 2, (3, nm, nm)))
    Rfs = np.triu(10 ** rng.uniform(-4, 2, (3, nm, nm)))
    Ss = np.asarray(_S_CELLS(tens, m, Rss, Rfs, sigs, floor))
    Js = np.asarray(_J_CELLS(tens, m, Rss, Rfs, sigs, floor))
    for S, J, sig in zip(Ss, Js, sigs):
        assert abs(S.sum()) < 1e-13 * np.abs(S).sum()
        np.testing.assert_allclose(J @ sig, S, rtol=0.0, atol=1e-12 * np.max(np.abs(S)))
        # bins above the largest bin above the floor take no part (DustPy's imax)
        imax = np.nonzero(sig > 1e-14)[0].max()
        assert np.all(J[:, imax + 1:] == 0.0)


def test_constant_kernel_number_decay_smoluchowski(ref, tens):
    """Sticking only with a constant kernel K0 from monomers: N(t) = N0 / (1 + K0 N0 t / 2) exactly
    (Smoluchowski 1916); the two-bin split keeps one particle per collision, so the discrete N follows it."""
    m = jnp.asarray(ref["grid_m"])
    nm = m.shape[0]
    K0, N0 = 1.0, 1.0
    Rs = K0 * (jnp.triu(jnp.ones((nm, nm))) - 0.5 * jnp.eye(nm))  # DustPy's (1 - delta_ij/2) on the diagonal
    Rf = jnp.zeros((nm, nm))
    sig0 = jnp.zeros(nm).at[0].set(N0 * m[0])
    floor = jnp.zeros(nm)
    rhs = lambda s: cg.coagulation_source(tens, m, Rs, Rf, s, floor)  # noqa: E731
    dt, nstep = 0.01, 300

    def rk4(_, s):
        k1 = rhs(s)
        k2 = rhs(s + 0.5 * dt * k1)
        k3 = rhs(s + 0.5 * dt * k2)
        k4 = rhs(s + dt * k3)
        return s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    sig = jax.jit(lambda s: jax.lax.fori_loop(0, nstep, rk4, s))(sig0)
    t = dt * nstep
    N = float(jnp.sum(sig / m))
    assert abs(N / (N0 / (1 + 0.5 * K0 * N0 * t)) - 1.0) < 1e-8
    assert abs(float(jnp.sum(sig)) / float(sig0[0]) - 1.0) < 1e-13
    assert float(jnp.min(sig)) >= -1e-12 * float(sig0[0])


def test_velocity_limits():
    m = jnp.array([1e-30, 1e-12, 1e-9])
    T, cs = jnp.array(100.0), jnp.array(6.0e4)
    dv = np.asarray(jax.jit(vl.dv_brownian)(cs, m, T))
    exact = np.sqrt(8 * K_B * 100.0 / np.pi * (1e-12 + 1e-9) / (1e-12 * 1e-9))
    np.testing.assert_allclose(dv[1, 2], exact, rtol=1e-14)
    np.testing.assert_allclose(dv[1, 1], np.sqrt(16 * K_B * 100.0 / (np.pi * 1e-12)), rtol=1e-14)
    # tiny masses: capped at the sound speed
    assert dv[0, 0] == 6.0e4 and dv[0, 2] == 6.0e4
    # azimuthal drift: |v_dm| |1/(1+St_j^2) - 1/(1+St_i^2)|
    st = jnp.array([0.1, 1.0, 3.0])
    az = np.asarray(vl.dv_azimuthal_drift(jnp.array(-3.0e3), st))
    np.testing.assert_allclose(az[0, 2], 3.0e3 * abs(1 / 1.01 - 1 / 10.0), rtol=1e-14)
    # OC07 heavy-particle limit (their eq. 30): St_L = St_S = St >= 1 -> dv^2 = v_g^2 2/(1+St), v_g^2 = 1.5 alpha cs^2
    alpha, om, sg, mu = jnp.array(1e-3), jnp.array(2e-7), jnp.array(100.0), jnp.array(2.3 * 1.67262192369e-24)
    st = jnp.array([1.0 - 1e-12, 1.0, 4.0])
    tu = np.asarray(jax.jit(vl.dv_turbulent_oc07_dustpy)(alpha, cs, mu, om, sg, st))
    vg2 = 1.5 * 1e-3 * 6.0e4 ** 2
    np.testing.assert_allclose(tu[2, 2] ** 2, vg2 * 2 / 5.0, rtol=1e-14)
    np.testing.assert_allclose(tu[1, 1] ** 2, vg2, rtol=1e-14)
    # continuity at tau_L = 1/Omega (regimes 5 and 6): within the accuracy of the y* fit (OC07 §3.4)
    assert abs(tu[0, 0] ** 2 / vg2 - 1.0) < 3e-3
    # settling: |Omega H min(St, 1/2)| differences
    H = jnp.array([1e12, 5e11])
    vs = np.asarray(vl.dv_settling(H, om, jnp.array([0.01, 2.0])))
    np.testing.assert_allclose(vs[0, 1], abs(2e-7 * 1e12 * 0.01 - 2e-7 * 5e11 * 0.5), rtol=1e-14)


def test_kernel_and_pfrag_closed_forms():
    a = jnp.array([1e-4, 1e-3])
    H = jnp.array([2e11, 1e11])
    v = jnp.array([[3.0, 5.0], [5.0, 7.0]])
    kern = jax.jit(cg.vertical_kernel)
    K = np.asarray(kern(a, H, v))
    np.testing.assert_allclose(K[0, 1], np.pi * 1.1e-3 ** 2 * 5.0 / np.sqrt(2 * np.pi * 5e22), rtol=1e-14)
    np.testing.assert_allclose(K[1, 1], 0.5 * np.pi * 4e-6 * 7.0 / np.sqrt(2 * np.pi * 2e22), rtol=1e-14)
    assert K[1, 0] == 0.0
    Kf = np.asarray(kern(a, H, v, jnp.array([1.0, 1e-3]), jnp.array([1e-2, 1e-2])))
    # bin 1 is below its floor: every pair with it vanishes, the (0, 0) pair stays
    assert np.all(Kf[:, 1] == 0.0) and Kf[0, 0] == K[0, 0] > 0.0
    # p_f: x = (v_f/dv)^2; dv = v_f -> 2.5 e^-1.5; dv = 0 -> 0; dv >> v_f -> 1
    pf = np.asarray(cg.p_frag(jnp.array([[100.0, 0.0], [1e8, 1.0]]), 100.0))
    np.testing.assert_allclose(pf[0, 0], 2.5 * np.exp(-1.5), rtol=1e-15)
    assert pf[0, 1] == 0.0 and abs(pf[1, 0] - 1.0) < 1e-11 and pf[1, 1] == 0.0
    assert float(cg.p_stick(jnp.array([[100.0]]), 100.0)[0, 0]) == pytest.approx(1 - 2.5 * np.exp(-1.5), rel=1e-15)


# ------------------------------------------------------------------------------------------ transformations
def test_jit_equals_eager_and_vmap_equals_loop(ref, tens):
    Rs, Rf = _rates(ref, "t1")
    m = ref["grid_m"]
    sig, fl = ref["t1_dust_Sigma"], ref["t1_dust_SigmaFloor"]
    cells = np.array([3, 12])
    Jv = np.asarray(_J_CELLS(tens, m, Rs[cells], Rf[cells], sig[cells], fl[cells]))
    Sv = np.asarray(_S_CELLS(tens, m, Rs[cells], Rf[cells], sig[cells], fl[cells]))
    # eager (op by op) == jit(vmap) for one cell; the summation order of the segment sums may differ
    c = cells[0]
    np.testing.assert_allclose(Jv[0], np.asarray(cg.coagulation_jacobian(tens, m, Rs[c], Rf[c], sig[c], fl[c])),
                               rtol=1e-14, atol=1e-14 * np.max(np.abs(Jv[0])))
    # vmap over cells == a loop of jitted single-cell calls
    fj = jax.jit(cg.coagulation_jacobian)
    fs = jax.jit(cg.coagulation_source)
    for n, c in enumerate(cells):
        np.testing.assert_allclose(Jv[n], np.asarray(fj(tens, m, Rs[c], Rf[c], sig[c], fl[c])), rtol=1e-14,
                                   atol=1e-14 * np.max(np.abs(Jv[n])))
        # S is a small difference of large gains and losses (see test_source_equals_dustpy_s_coag)
        np.testing.assert_allclose(Sv[n], np.asarray(fs(tens, m, Rs[c], Rf[c], sig[c], fl[c])), rtol=1e-12,
                                   atol=1e-11 * np.max(np.abs(Sv[n])))
    # velocities: vmapped over a batch of alpha values == one by one
    t = "t1"
    args = [ref[f"{t}_{k}"][cells] for k in ("gas_cs", "gas_mu", "OmegaK", "gas_Sigma", "dust_St")]
    alphas = jnp.array([1e-4, 1e-3])
    turb = jax.jit(vl.dv_turbulent_oc07_dustpy)
    vb = jax.jit(jax.vmap(lambda al: vl.dv_turbulent_oc07_dustpy(al, *args)))(alphas)
    for n in range(2):
        np.testing.assert_allclose(np.asarray(vb[n]), np.asarray(turb(alphas[n], *args)), rtol=1e-14, atol=0.0)


def _cell_objective(ref, tens, cell, tag="t1", through_velocities=False):
    """sum(S * m^0.5) of one cell as a function of (log Sigma, log v_frag, log St), through the kernel,
    p_frag and S_coag, and (``through_velocities``) DustPy's velocities, where St enters turbulence, drift
    and settling; otherwise the velocities are those of the recorded St."""
    g = lambda k: jnp.asarray(ref[f"{tag}_{k}"])  # noqa: E731
    m = jnp.asarray(ref["grid_m"])
    fl = g("dust_SigmaFloor")[cell]

    def vrel_of(st):
        return vl.dv_total_dustpy(m=m, T=g("gas_T")[cell], cs=g("gas_cs")[cell], mu=g("gas_mu")[cell],
                                  alpha=g("delta_turb")[cell], omega=g("OmegaK")[cell],
                                  sigma_gas=g("gas_Sigma")[cell], St=st, v_rad=g("dust_v_rad")[cell],
                                  v_drift_max=g("dust_v_driftmax")[cell], H=g("dust_H")[cell])

    vrel0 = jax.jit(vrel_of)(g("dust_St")[cell])

    @jax.jit
    def obj(log_sig, log_vf, log_st):
        sig = jnp.exp(log_sig)
        vrel = vrel_of(jnp.exp(log_st)) if through_velocities else vrel0
        K = cg.vertical_kernel(g("dust_a")[cell], g("dust_H")[cell], vrel, sig, fl)
        pf = cg.p_frag(vrel, jnp.exp(log_vf))
        S = cg.coagulation_source(tens, m, K * (1 - pf), K * pf, sig, fl)
        return jnp.sum(S * jnp.sqrt(m))

    return obj, (jnp.log(g("dust_Sigma")[cell]), jnp.log(g("v_frag")[cell]), jnp.log(g("dust_St")[cell]))


def _check_gradients(ref, tens, through_velocities):
    obj, x = _cell_objective(ref, tens, 3, through_velocities=through_velocities)
    args = (0, 1, 2) if through_velocities else (0, 1)
    grads = jax.jit(jax.grad(obj, argnums=args))(*x)
    for gr in grads:
        assert np.all(np.isfinite(np.asarray(gr)))  # including the diagonal of the velocity pairs
    rng = np.random.default_rng(3)
    h = 1e-5
    for n in args:
        d = jnp.asarray(rng.normal(size=np.shape(x[n])))
        xp, xm = list(x), list(x)
        xp[n] = x[n] + h * d
        xm[n] = x[n] - h * d
        fd = (obj(*xp) - obj(*xm)) / (2 * h)
        assert abs(float(jnp.sum(grads[n] * d)) / float(fd) - 1.0) < 1e-6, n


def test_gradients_match_finite_differences(ref, tens):
    """d sum(S m^0.5) / d(log Sigma, log v_frag) of a t1 cell vs central differences."""
    _check_gradients(ref, tens, through_velocities=False)


@pytest.mark.slow
def test_gradients_through_velocities_match_finite_differences(ref, tens):
    """The same through DustPy's velocities, also w.r.t. log St."""
    _check_gradients(ref, tens, through_velocities=True)


def test_velocity_gradient_zero_where_components_vanish():
    # equal velocities: every drift term vanishes; the safe square root keeps the gradient finite (= 0)
    z = jax.jit(jax.grad(lambda vr: jnp.sum(vl.dv_total(vl.dv_radial_drift(vr)))))(jnp.zeros(4))
    assert np.all(np.asarray(z) == 0.0)


def test_bad_input_raises():
    with pytest.raises(JaxcoagInputError, match="logarithmic"):
        cg.coagulation_tensors(np.array([1.0, 2.0, 3.0, 4.0]))
    with pytest.raises(JaxcoagInputError, match="erosion_mass_ratio"):
        cg.coagulation_tensors(np.geomspace(1e-12, 1.0, 20), erosion_mass_ratio=0.5)
    t = cg.coagulation_tensors(np.geomspace(1e-12, 1.0, 20))
    with pytest.raises(JaxcoagInputError, match="one cell"):
        cg.coagulation_source(t, np.geomspace(1e-12, 1.0, 20), np.zeros((2, 20, 20)), np.zeros((2, 20, 20)),
                              np.ones((2, 20)), np.zeros((2, 20)))
