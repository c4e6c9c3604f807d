"""Unit tests of the grouped MC through the public ``jaxcoag.evolve``: the first-event law (Gillespie 1975),
the App. 5.A exactness of Ormel & Spaans (2008) (mean and variance of the consumed fraction, eqs.
5.28-5.30) and snapshot semantics (pre-event state, MC hazard 11 in docs/design_notes.md).

Statistical tolerances follow from the sample size (z-scores < 4, chi-square / KS p-values > 1e-4);
seeds are fixed only for reproducibility.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxcoag as jc
from jaxcoag import kernels as K
from jaxcoag import mc

LN2 = math.log(2.0)


# ----------------------------------------------------------------------------- U5 first-event law

# a fixed grouped state exercising every rate branch: z = 0 same-species (½ w (w-1) C), in-group
# collapse (w (w 2^z - 1) C), out-of-group with N_eps > 0 and the N_eps cap z_j - z_i
U5_M = np.array([1.0, 3.0, 50.0, 7.0])
U5_W = np.array([5.0, 3.0, 2.0, 1.5])
U5_Z = np.array([0, 2, 0, 3])
U5_FEPS = 0.05
U5_B = 0.5  # K = 0.5 (m_a + m_b), V = 1


def _expected_pair_rates():
    """λ^G of every unordered pair from Ormel & Spaans (2008) eqs. (5.7), (5.10), (5.12) with ceil, (5.31)."""
    n = len(U5_M)
    Kf = lambda a, b: U5_B * (U5_M[a] + U5_M[b])
    out = {}
    for a in range(n):
        for b in range(a, n):
            if a == b:
                g = U5_W[a] * 2.0 ** U5_Z[a]
                lam = U5_W[a] * (g - 1) * Kf(a, a) if U5_Z[a] >= 1 else 0.5 * U5_W[a] * (U5_W[a] - 1) * Kf(a, a)
            else:
                za, zb = U5_Z[a], U5_Z[b]
                a_is_i = za < zb or (za == zb and U5_M[a] >= U5_M[b])
                i, j = (a, b) if a_is_i else (b, a)
                dz = U5_Z[j] - U5_Z[i]
                x = dz + math.log2(U5_M[j]) - math.log2(U5_M[i]) - math.log2(U5_FEPS)
                ne = int(min(max(math.ceil(x - 1e-9), 0), dz))
                lam = U5_W[a] * U5_W[b] * 2.0 ** (min(za, zb) + ne) * Kf(a, b)
            out[(a, b)] = lam
    return out


def _first_events(n_draws, seed):
    init = mc.initial_species(U5_M, w=U5_W, z=U5_Z, V=1.0)

    def one(k):
        r = jc.evolve(K.Sum(U5_B), mc.MonteCarlo(f_eps=U5_FEPS, capacity=8, max_events=1), init, jnp.array([1e6]), key=k,
                      throw=False)
        return r.final_state
    keys = jax.random.split(jax.random.key(seed), n_draws)
    return jax.jit(jax.vmap(one))(keys)


def _pair_of(st):
    """Donor slots of the single event: mass changed, multiplicity decreased or slot freed."""
    m = np.asarray(st.m)[:, :4]
    g = np.asarray(st.w)[:, :4] * 2.0 ** np.asarray(st.z)[:, :4]
    v = np.asarray(st.valid)[:, :4]
    g0 = U5_W * 2.0 ** U5_Z
    donor = (m != U5_M) | ~v | (g < g0 * (1 - 1e-15))
    return donor


@pytest.mark.parametrize("n_draws", [20_000, pytest.param(1_000_000, marks=pytest.mark.slow)])
def test_u5_first_event_law(n_draws):
    lam = _expected_pair_rates()
    lam_tot = sum(lam.values())
    st = _first_events(n_draws, seed=5)
    assert np.all(np.asarray(st.n_events) == 1)
    donor = _pair_of(st)
    counts = {}
    for pair in lam:
        want = np.zeros(4, bool)
        want[list(set(pair))] = True
        counts[pair] = int(np.sum(np.all(donor == want, axis=1)))
    assert sum(counts.values()) == n_draws  # every event identified as exactly one pair
    obs = np.array([counts[p] for p in lam], float)
    exp = np.array([lam[p] / lam_tot for p in lam]) * n_draws
    assert exp.min() > 20  # chi-square validity
    chi2 = float(np.sum((obs - exp) ** 2 / exp))
    assert stats.chi2.sf(chi2, df=len(obs) - 1) > 1e-4, (obs, exp)
    # waiting time: Δt λ_tot ~ Exp(1) (KS), and its mean
    e = np.asarray(st.t) * lam_tot
    assert stats.kstest(e, "expon").pvalue > 1e-4
    assert abs(e.mean() - 1.0) < 4.0 / math.sqrt(n_draws)


# ----------------------------------------------------------------------------- U6 App. 5.A

class TaggedKernel(K.AbstractKernel):
    """K = a0 V iff exactly one partner is tagged (psi > 0.5), else 0 (thesis App. 5.A test)."""

    a0V: jax.Array
    n_struct = 1

    def __call__(self, m1, m2, x1=None, x2=None):
        one = (x1[..., 0] > 0.5) != (x2[..., 0] > 0.5)
        return jnp.where(one, self.a0V, 0.0) * jnp.ones(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)))

    def log_kernel_from_log_mass(self, logm1, logm2, x1=None, x2=None):
        one = (x1[..., 0] > 0.5) != (x2[..., 0] > 0.5)
        return jnp.where(one, jnp.log(self.a0V), -jnp.inf) + jnp.zeros(jnp.broadcast_shapes(logm1.shape, logm2.shape))


U6_T = jnp.array([0.25, 0.5, 1.0, 2.0])  # a0 t (a0 = 1)
M_TARGET, Z_P = 1e30, 20


def _u6_one(k, w_p, f_eps):
    init = mc.initial_species(jnp.array([M_TARGET, 1.0]), w=jnp.stack([jnp.ones_like(w_p), w_p]),
                              z=jnp.array([0, Z_P]), psi=jnp.array([[1.0], [0.0]]), V=1.0)
    r = jc.evolve(TaggedKernel(a0V=jnp.array(1.0)), mc.MonteCarlo(f_eps=f_eps, capacity=8), init, U6_T, key=k,
                  throw=False)
    untagged = r.valid & (r.psi[..., 0] < 0.5)
    g = jnp.sum(jnp.where(untagged, r.w * jnp.exp2(r.z.astype(jnp.float64) - Z_P), 0.0), axis=-1)
    return 1.0 - g / w_p, jc.RESULTS.where(r.status == jc.RESULTS.zero_rate, jc.RESULTS.successful, r.status)


_u6_batch = jax.jit(jax.vmap(_u6_one, in_axes=(0, None, None)))  # one compilation for every case


def _consumed(w_p, n_eps, runs, seed):
    """Fraction of projectiles consumed at U6_T, one row per run."""
    # f_eps chosen so that N_eps(i = target, j = projectiles) = n_eps: x = 20 - log2(1e30) - log2 f_eps
    log2_f = Z_P - math.log2(M_TARGET) - (n_eps - 0.5 if n_eps > 0 else -1.0)
    f_eps = 2.0 ** log2_f
    ne = int(mc.n_eps(jnp.int32(0), jnp.int32(Z_P), jnp.log(M_TARGET), jnp.log(1.0), jnp.log2(f_eps)))
    assert ne == n_eps
    keys = jax.random.split(jax.random.key(seed), runs)
    frac, status = _u6_batch(keys, jnp.float64(w_p), jnp.float64(f_eps))
    assert np.all(np.asarray(status == jc.RESULTS.successful))  # successful or zero_rate (all consumed)
    return np.asarray(frac)


def _check_moments(frac, W, var_times):
    R = frac.shape[0]
    for k, t in enumerate(np.asarray(U6_T)):
        p = 1.0 - math.exp(-t)
        q = 1.0 - p
        mean_th = p                     # eq. (5.28), independent of the chunking
        var_th = p * q / W              # eq. (5.30)
        x = frac[:, k]
        z_mean = (x.mean() - mean_th) / math.sqrt(var_th / R)
        assert abs(z_mean) < 4.0, (t, x.mean(), mean_th)
        if t in var_times:
            # sampling error of the variance: mu4 of Binomial(W, p)/W
            mu4 = W * p * q * (1 + 3 * (W - 2) * p * q) / W ** 4
            se_var = math.sqrt((mu4 - var_th ** 2 * (R - 3) / (R - 1)) / R)
            z_var = (x.var(ddof=1) - var_th) / se_var
            assert abs(z_var) < 4.0, (t, x.var(ddof=1), var_th)
        # the count is integral in chunks of 2^(z_P - N_eps) projectiles
        np.testing.assert_allclose(x * W, np.round(x * W), atol=1e-9)


@pytest.mark.parametrize("runs", [4000, pytest.param(20_000, marks=pytest.mark.slow)])
def test_u6_app5a_mean_and_variance(runs):
    """App. 5.A: with chunked (grouped) events the consumed fraction has mean 1 - e^{-a0 t} for any
    chunking and variance e^{-a0 t}(1 - e^{-a0 t})/W, W = w_P 2^{N_eps} (eqs. 5.28-5.30).
    (a) N_eps = 0, w_P = 32: whole groups, never demagnifies: variance at all times.
    (b) N_eps = 3, w_P = 4: eighth groups, demagnifies once < 1 group is left. A cautious test checks
        the variance at a0 t <= 0.5 only; it holds at all times here because a demagnification
        (z -> z - 1) lowers N_eps by one as well, so the chunk of 2^(z - N_eps) = 2^17
        projectiles and W are unchanged (measured: var 0.00699 vs 0.00727 at a0 t = 1,
        0.00365 vs 0.00366 at 2, R = 4000)."""
    all_t = set(np.asarray(U6_T).tolist())
    _check_moments(_consumed(32.0, 0, runs, seed=61), 32, var_times=all_t)
    _check_moments(_consumed(4.0, 3, runs, seed=62), 32, var_times=all_t)
    # contrast: W = 4 chunks (w_P = 4, N_eps = 0) has an 8x larger variance at the same mean
    f4 = _consumed(4.0, 0, runs, seed=63)
    _check_moments(f4, 4, var_times={0.5, 1.0})


# ----------------------------------------------------------------------------- U10 snapshots

def test_u10_snapshot_is_state_after_last_event_not_later_than_t_out():
    """The state recorded at t_out[k] equals the state after the last event with time <= t_out[k]:
    the trajectory is logged event by event with max_events = 1, 2, ... (the event budget only
    truncates the same trajectory), each run's final_state being the state after that event."""
    N = 24
    kern = K.Constant(1.0)
    key = jax.random.key(10)
    t_out = jnp.array([0.013, 0.05, 0.11, 0.2, 0.37, 0.6, 0.9, 1.3])
    mono = jc.Monodisperse(1.0)
    full = jc.evolve(kern, mc.MonteCarlo(n_particles=N, capacity=N + 8), mono, t_out, key=key)
    n_ev = int(full.n_events_snap[-1])
    assert n_ev >= 8
    # same output-time shape (no recompilation), later last time so that event n_ev + 1 is logged
    t_log = t_out.at[-1].set(50.0)
    log = [jc.evolve(kern, mc.MonteCarlo(n_particles=N, capacity=N + 8, max_events=k), mono, t_log, key=key,
                     throw=False).final_state for k in range(1, n_ev + 2)]
    times = np.array([float(s.t) for s in log])
    assert np.all(np.diff(times) > 0)
    for k, tk in enumerate(np.asarray(t_out)):
        n_before = int(np.sum(times <= tk))
        assert int(full.n_events_snap[k]) == n_before
        if n_before == 0:
            np.testing.assert_array_equal(np.asarray(full.w[k])[:1], [N])
            continue
        ref = log[n_before - 1]
        for f in ("m", "w", "z", "valid"):
            np.testing.assert_array_equal(np.asarray(getattr(full, f)[k]), np.asarray(getattr(ref, f)), err_msg=f)
        # and it is not the state after the next event
        assert times[n_before] > tk
