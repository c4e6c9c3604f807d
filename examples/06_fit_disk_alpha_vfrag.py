"""Fit the turbulence parameter alpha and the fragmentation velocity v_frag of a radial disk to an observed dust profile.

Shows: the differentiable radial disk (jaxcoag.disk: DustPy's model - viscous gas, dust drift and diffusion,
coagulation and fragmentation in every cell - in split mode, 7x faster than parity mode per
step on this small grid) as a forward model; a synthetic observation at known
values (DustPy's defaults alpha = 1e-3, v_frag = 1 m/s) with 1 % noise (fixed PRNG key): the dust surface density
Sigma_d(r) and the mass-weighted mean grain size a_mean(r) (``DiskResult.a_mean``, differentiable; the peak size
jumps between the modes of a bimodal distribution, docs/design_notes.md) in the cells from 3 to 30 au at two
epochs; recovery of (alpha, v_frag) from a start a factor 3 away (alpha x 3, v_frag / 3) by optimistix
Levenberg-Marquardt with forward-mode Jacobians through the whole time loop, and - in the full run - by optax Adam.

alpha and v_frag are separately identifiable: the fragmentation-limited size a_frag ~ v_frag^2 / alpha fixes their
ratio, while the growth rate before the barrier (turbulent relative velocities ~ alpha^(1/2)), the radial mixing
and the viscous gas evolution (both ~ alpha) depend on alpha alone.

    python examples/06_fit_disk_alpha_vfrag.py [--quick]

Reference: Stammler & Birnstiel (2022) ApJ 935, 35 (DustPy); Birnstiel, Klahr & Ercolano (2012) A&A 539, A148.
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from jaxcoag import disk

C = disk.gas.DUSTPY_CONSTANTS
TRUTH = {"alpha": 1e-3, "v_frag": 100.0}  # DustPy's defaults [-], [cm s^-1]


def forward_model(quick):
    """(observe, t_obs [yr]): observe(log_params) -> (ln Sigma_d, ln a_mean), each (epochs, cells)."""
    grid = dict(nr=10, r_min=3.0 * C["au"], r_max=30.0 * C["au"], m_max=10.0, bins_per_decade=4 if quick else 6)
    t_obs = np.array([1000.0, 3000.0])
    t_out = np.concatenate([[0.0], t_obs]) * C["year"]

    def observe(log_params):
        alpha, v_frag = jnp.exp(log_params[0]), jnp.exp(log_params[1])
        model = disk.dustpy_default(**grid, alpha=alpha, v_frag=v_frag)
        res = disk.solve(model, t_out, mode=disk.Split(), throw=False)
        inner = slice(1, -1)  # the boundary cells are set by DustPy's boundary conditions, not observed
        sd = res.sigma_dust_total[1:, inner]
        ap = res.a_mean()[1:, inner]
        return jnp.log(sd), jnp.log(ap)

    return observe, t_obs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="coarser mass grid, earlier epochs, Levenberg-Marquardt only")
    args = ap.parse_args(argv)
    observe, t_obs = forward_model(args.quick)
    x_true = jnp.log(jnp.array([TRUTH["alpha"], TRUTH["v_frag"]]))
    x0 = x_true + jnp.log(jnp.array([3.0, 1.0 / 3.0]))
    noise = 0.01
    obs = jax.jit(observe)(x_true)
    k1, k2 = jax.random.split(jax.random.key(2026))
    target = (obs[0] + noise * jax.random.normal(k1, obs[0].shape), obs[1] + noise * jax.random.normal(k2, obs[1].shape))
    print(f"forward model: DustPy's disk, 3-30 au in 10 cells, observed at t = {t_obs.tolist()} yr "
          f"(Sigma_d and a_mean in {obs[0].shape[1]} cells, 1 % noise)")
    print(f"truth: alpha = {TRUTH['alpha']:.3e}, v_frag = {TRUTH['v_frag']:.3e} cm/s; start: alpha x 3, v_frag / 3")

    def residuals(x, args):
        sd, ap = observe(x)
        return jnp.concatenate([(sd - target[0]).ravel(), (ap - target[1]).ravel()]) / noise

    out = {"truth": dict(TRUTH), "noise": noise, "n_data": int(2 * obs[0].size)}
    # Levenberg-Marquardt: optimistix differentiates the residuals in forward mode (jax.linearize), which runs
    # through the disk's lax.while_loop
    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-6)

    @jax.jit
    def lm(x):
        sol = optx.least_squares(residuals, solver, x, max_steps=40, throw=False)
        r0, r1 = residuals(x, None), residuals(sol.value, None)
        return sol.value, sol.result, sol.stats["num_steps"], 0.5 * jnp.sum(r0 ** 2), 0.5 * jnp.sum(r1 ** 2)

    t0 = time.perf_counter()
    x, result, nsteps, l0, l1 = lm(x0)
    dt = time.perf_counter() - t0
    p = np.exp(np.asarray(x))
    err = {"alpha": p[0] / TRUTH["alpha"] - 1.0, "v_frag": p[1] / TRUTH["v_frag"] - 1.0}
    ok = bool(result == optx.RESULTS.successful)
    print(f"levenberg_marquardt  alpha = {p[0]:.5e} (rel err {err['alpha']:+.2e}), v_frag = {p[1]:.5e} cm/s "
          f"(rel err {err['v_frag']:+.2e}), {int(nsteps)} steps, chi^2/2 {float(l0):.3e} -> {float(l1):.3e}, "
          f"{dt:.1f} s incl. compile [{'successful' if ok else optx.RESULTS[result]}]")
    out["levenberg_marquardt"] = dict(alpha=float(p[0]), v_frag=float(p[1]), rel_err_alpha=float(err["alpha"]),
                                      rel_err_v_frag=float(err["v_frag"]), steps=int(nsteps), loss0=float(l0),
                                      loss=float(l1), successful=ok, seconds=dt)
    # the Jacobian at the truth: the two columns are independent (their correlation < 1), i.e. the data constrain
    # alpha and v_frag separately and not only v_frag^2 / alpha
    J = np.asarray(jax.jit(jax.jacfwd(lambda z: residuals(z, None)))(x_true))
    corr = float(abs(J[:, 0] @ J[:, 1]) / (np.linalg.norm(J[:, 0]) * np.linalg.norm(J[:, 1])))
    cov = np.linalg.inv(J.T @ J)  # residuals are in units of the noise: Fisher covariance of ln(alpha, v_frag)
    out["jacobian_column_correlation"] = corr
    out["sigma_ln_params"] = np.sqrt(np.diag(cov)).tolist()
    print(f"Fisher 1-sigma of ln alpha, ln v_frag: {out['sigma_ln_params'][0]:.2e}, {out['sigma_ln_params'][1]:.2e}; "
          f"Jacobian column correlation {corr:.4f}")

    if not args.quick:
        # optax Adam on chi^2 / 2 in ln-parameters; gradients by forward mode (two parameters: jacfwd is cheaper than
        # reverse mode through the checkpointed scan)
        sched = optax.cosine_decay_schedule(0.1, 60, alpha=1e-2)
        opt = optax.adam(sched)
        loss = lambda z: 0.5 * jnp.sum(residuals(z, None) ** 2)

        @jax.jit
        def adam(x):
            def step(carry, _):
                z, s = carry
                # the loss as jacfwd's aux: one forward solve per step gives both value and gradient
                g, v = jax.jacfwd(lambda q: (lambda v: (v, v))(loss(q)), has_aux=True)(z)
                upd, s = opt.update(g, s, z)
                return (optax.apply_updates(z, upd), s), v

            (z, _), hist = jax.lax.scan(step, (x, opt.init(x)), None, length=60)
            return z, hist, loss(z)

        t0 = time.perf_counter()
        z, hist, lz = adam(x0)
        dt = time.perf_counter() - t0
        q = np.exp(np.asarray(z))
        print(f"adam (60 steps)      alpha = {q[0]:.5e} (rel err {q[0] / TRUTH['alpha'] - 1:+.2e}), v_frag = {q[1]:.5e} "
              f"cm/s (rel err {q[1] / TRUTH['v_frag'] - 1:+.2e}), chi^2/2 {float(hist[0]):.3e} -> {float(lz):.3e}, "
              f"{dt:.1f} s incl. compile")
        out["adam"] = dict(alpha=float(q[0]), v_frag=float(q[1]), loss=float(lz), history=np.asarray(hist).tolist(),
                           seconds=dt)
    best = out["levenberg_marquardt"]
    print(f"recovered alpha={best['alpha']:.6e} v_frag={best['v_frag']:.6e} true=({TRUTH['alpha']:.1e}, "
          f"{TRUTH['v_frag']:.1f}) rel_err=({abs(best['rel_err_alpha']):.2e}, {abs(best['rel_err_v_frag']):.2e})")
    return out


if __name__ == "__main__":
    main()
