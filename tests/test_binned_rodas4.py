"""Rodas4 (Hairer & Wanner's RODAS, jaxcoag.binned.Rodas4), the binned engine's default with fragmentation.

Independent references: closed-form solutions (logistic growth; a stiff Prothero-Robinson-type pair with
the smooth solution e^{-2t}; the linear test equation), diffrax's Kvaerno5 on the same fragmentation box at
a tight tolerance, and central finite differences of the solve in ln v_frag.
"""

import numpy as np
import pytest
import jax
import jax.numpy as jnp
import diffrax

import jaxcoag
from jaxcoag import Binned, MassGrid, evolve
from jaxcoag.binned import Rodas4, monodisperse
from jaxcoag.binned.solve import default_implicit_solver
from jaxcoag.outcomes import Shattering

from _testkernels import SqrtAlphaKernel


def _fixed(f, y0, t1, n):
    sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, a: f(y)), Rodas4(), 0.0, t1, t1 / n, jnp.asarray(y0),
                              stepsize_controller=diffrax.ConstantStepSize(), max_steps=10 * n)
    return sol.ys[-1]


def test_order_four_on_a_nonstiff_problem():
    """Logistic growth y' = y (1 - y), y(0) = 0.1 (exact 1/(1 + 9 e^-t)) with a decoupled linear
    component: with fixed steps h = 1/5, 1/10, 1/20, 1/40 to t = 2 the error falls by ~2^4 per halving
    (measured ratios 20.3, 18.4, 17.3: approaching 16 from above); observed order of the last halving
    within 3.8-4.3."""
    f = lambda y: jnp.stack([y[0] * (1.0 - y[0]), -0.5 * y[1]])
    exact = np.array([1.0 / (1.0 + 9.0 * np.exp(-2.0)), np.exp(-1.0)])
    errs = [float(np.max(np.abs(np.asarray(_fixed(f, [0.1, 1.0], 2.0, n)) - exact))) for n in (10, 20, 40, 80)]
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 14.0) & (ratios < 22.0)), (errs, ratios)
    assert 3.8 <= np.log2(ratios[-1]) <= 4.3


def test_stiff_component_follows_its_smooth_solution():
    """y2' = -y2, y1' = -lambda (y1 - y2^2) - 2 y2^2 (exact y1 = e^{-2t}, y2 = e^{-t}) with lambda = 1e8:
    steps 1e6 times the stiff time scale stay accurate (stiffly accurate, L-stable method: error <= 1e-4 at
    h = 0.1, falling with h), where any explicit method is unstable."""
    lam = 1e8
    f = lambda y: jnp.stack([-lam * (y[0] - y[1] ** 2) - 2.0 * y[1] ** 2, -y[1]])
    exact = np.array([np.exp(-2.0), np.exp(-1.0)])
    e10 = float(np.max(np.abs(np.asarray(_fixed(f, [1.0, 1.0], 1.0, 10)) - exact)))
    e40 = float(np.max(np.abs(np.asarray(_fixed(f, [1.0, 1.0], 1.0, 40)) - exact)))
    assert e10 < 1e-4 and e40 < e10 / 8.0, (e10, e40)


def test_l_stable_one_huge_step():
    """The linear test equation y' = lambda y with h lambda = -1e10: one step damps to |R| < 1e-8
    (R(infinity) = 0 for a stiffly accurate Rosenbrock method)."""
    y1 = _fixed(lambda y: -1e10 * y, [1.0, -2.0], 1.0, 1)
    assert float(jnp.max(jnp.abs(y1))) < 2e-8


_Turb = SqrtAlphaKernel  # K = pi (a1 + a2)^2 dv, dv^2 = 1 + alpha 1e10 ((m1/1e6)^(2/3) + (m2/1e6)^(2/3))


GRID = MassGrid.log(1e-12, 1e8, 2)
N0 = monodisperse(GRID, 1.5e-12, 1e-6)
TS = np.concatenate([[0.0], np.logspace(6, 11, 6)])


def test_fragmentation_box_matches_kvaerno5_and_is_the_default():
    """Growth to a fragmentation equilibrium (40 bins, Shattering at 100 cm/s): the automatic solver is
    Rodas4; at rtol 1e-8 it agrees with Kvaerno5 (+ chord, a Jacobian per stage) to 1e-6 of the total
    mass at every output, conserves mass to 1e-12, and at the default rtol 1e-6 stays within 2e-5 of the
    tight solution."""
    out = Shattering(100.0)
    r4 = evolve(_Turb(1e-3), Binned(GRID, rtol=1e-8, atol=1e-12), N0, TS, outcome=out)
    assert r4.solver == "Rodas4"
    k5 = evolve(_Turb(1e-3), Binned(GRID, rtol=1e-8, atol=1e-12, solver=default_implicit_solver(1e-8, 1e-22)),
                N0, TS, outcome=out)
    m4, m5 = np.asarray(r4.mass_per_bin()), np.asarray(k5.mass_per_bin())
    M = m5.sum(axis=1).max()
    assert np.max(np.abs(m4 - m5)) < 1e-6 * M
    assert np.max(np.abs(np.asarray(r4.mass_drift))) < 1e-12
    # the equilibrium is reached: the last two outputs agree, and the distribution is not monomers
    assert np.max(np.abs(m4[-1] - m4[-2])) < 1e-3 * M and m4[-1].argmax() > 5
    rd = evolve(_Turb(1e-3), Binned(GRID), N0, TS, outcome=out)
    assert np.max(np.abs(np.asarray(rd.mass_per_bin()) - m4)) < 2e-5 * M


def test_gradient_through_rodas4_vs_finite_differences_and_vmap():
    """d <ln m>_M(t_end) / d ln v_frag through the Rodas4 solve: reverse mode (jax.grad) and forward mode
    (jax.jvp with diffrax.ForwardMode) agree with central differences in ln v_frag (h = 1e-3) to 1e-4 relative; vmap over two
    v_frag equals the loop to 1e-12."""
    ts = np.array([0.0, 1e9, 1e10])
    lc = jnp.asarray(GRID.log_centers)

    def mean_log_m(lvf, adjoint=None):
        r = evolve(_Turb(1e-3), Binned(GRID, rtol=1e-8, atol=1e-12, adjoint=adjoint), N0, ts,
                   outcome=Shattering(jnp.exp(lvf)))
        m = r.mass_per_bin()[-1]
        return jnp.sum(m * lc) / jnp.sum(m)

    f = jax.jit(mean_log_m)
    x = jnp.log(100.0)
    g_rev = float(jax.jit(jax.grad(mean_log_m))(x))
    g_fwd = float(jax.jit(lambda x: jax.jvp(lambda z: mean_log_m(z, diffrax.ForwardMode()), (x,), (1.0,))[1])(x))
    h = 1e-3
    g_fd = (float(f(x + h)) - float(f(x - h))) / (2 * h)
    assert abs(g_fd) > 0.1                       # v_frag sets the equilibrium size
    assert abs(g_rev - g_fd) <= 1e-4 * abs(g_fd) and abs(g_fwd - g_fd) <= 1e-4 * abs(g_fd)
    xs = jnp.log(jnp.array([60.0, 150.0]))
    v = jax.jit(jax.vmap(mean_log_m))(xs)
    loop = jnp.stack([f(xi) for xi in xs])
    assert float(jnp.max(jnp.abs(v - loop))) <= 1e-12 * float(jnp.max(jnp.abs(loop)))


def test_config_method_rodas4_and_kvaerno5():
    """[solver] method = "rodas4" builds Rodas4, "kvaerno5" the Kvaerno5 + chord solver (also with
    fragmentation), "auto" leaves the choice to the engine (Rodas4 with fragmentation)."""
    from jaxcoag import config as cfgmod
    from jaxcoag.binned.solve import Kvaerno5Stagewise

    cfg = cfgmod.default()
    assert cfg.has_fragmentation
    assert isinstance(cfgmod._binned_solver(cfg.replace(**{"solver.method": "rodas4"}), 1e-11), Rodas4)
    assert isinstance(cfgmod._binned_solver(cfg.replace(**{"solver.method": "kvaerno5"}), 1e-11), Kvaerno5Stagewise)
    assert cfgmod._binned_solver(cfg, 1e-11) is None
    assert jaxcoag.Binned(GRID).solver_name(Shattering(100.0)) == "Rodas4"
