"""Structured Jacobian of the two-bin scheme (TwoBinScheme.jacobian, rhs_structured).

References are independent of the structured formula: ``jax.jacfwd`` of the plain right-hand side
(N + 1 JVPs through the segment sums), central finite differences of the rhs, and the plain
rhs's own JVP/VJP in the kernel parameters. Cases: pure coagulation with and without gel sweep
(gel entry > 0), FragData (Shattering with erosion, ShatterAbove), OutcomeData full (O07 recipe)
and mixed (VfragShatter mixture weight), and a velocity-free smooth Outcome using every product
channel. The jaxpr check (frag_shatter_above case) shows that ``jax.jacfwd`` of
``rhs_structured`` forms J once (no scatter batched over the N + 1 tangents).
"""

import numpy as np
import pytest
import jax
import jax.numpy as jnp

from jaxcoag import MassGrid, scenes
from jaxcoag.binned.twobin import TwoBinScheme
from jaxcoag.kernels import Constant, Product
from jaxcoag.outcomes import O07Recipe, RecipeOutcome, ShatterAbove, Shattering, VfragShatter
from jaxcoag.physics import gas as G
from jaxcoag.physics.contact import Material
from jaxcoag.physics.dominik_tielens import DTEnergy
from jaxcoag.physics.outcome import Outcome

GRID = MassGrid.log(1e-11, 1e1, 2)  # 24 bins


def _kern(alpha=1e-2):
    gas = G.midplane_state(2.4e-11, 162.0, alpha, 3.83e-8)  # thesis ch. 4 gas at 3 AU
    return scenes.nebula_ch4().kernel(gas, rho_s=3.0)


def _smooth_recipe(m1, psi1, m2, psi2, dv, mat, width=0.0):
    """A velocity-free Outcome using every product channel: efficiency, two remnants, and a
    power law of fragments whose share grows smoothly with the collision mass."""
    M = m1 + m2
    f = 0.35 * (1.0 + jnp.tanh(jnp.log(M / 1e-6)))
    return Outcome.build(eff=0.8, p_two=0.3, split=0.4, f_pwl=f, q=-1.8, m_lo=3e-11,
                         m_hi=0.1 * jnp.maximum(m1, m2) + 3e-11, psi_one=jnp.ones_like(m1))


def _state(grid, seed=0, gel=True):
    rng = np.random.default_rng(seed)
    rho = rng.uniform(0.1, 1.0, grid.nbins) * 1e-13
    return jnp.asarray(np.r_[rho, 0.3e-13 if gel else 0.0])


def _rel(a, b):
    return float(jnp.linalg.norm(a - b) / jnp.linalg.norm(b))


CASES = {
    "coag_sweep": (TwoBinScheme(gel_sweep=True), lambda: Product(1e-3), None),
    "coag_nosweep": (TwoBinScheme(gel_sweep=False), lambda: Constant(1e-10), None),
    "frag_shattering": (TwoBinScheme(), _kern, lambda: Shattering(30.0, probability="maxwellian")),
    "frag_shatter_above": (TwoBinScheme(), lambda: Constant(1e-10), lambda: ShatterAbove(1e-4, 1e-11)),
    "outcome_full": (TwoBinScheme(), _kern,
                     lambda: RecipeOutcome(O07Recipe(frag_model=DTEnergy()), Material.ch4_silicate(), width=0.3)),
    "outcome_smooth": (TwoBinScheme(), lambda: Constant(1e-10),
                       lambda: RecipeOutcome(_smooth_recipe, Material.ch4_silicate(), use_velocity=False)),
    "outcome_mixed": (TwoBinScheme(), _kern,
                      lambda: RecipeOutcome(VfragShatter(30.0), Material.ch4_silicate())),
}


def _scatter_shapes(fn, y):
    """Output shapes of every scatter in the jaxpr of fn(y) (nested jaxprs included)."""
    out = []

    def walk(jp):
        for e in jp.eqns:
            if e.primitive.name.startswith("scatter"):
                out.append(tuple(e.outvars[0].aval.shape))
            for p in e.params.values():
                for q in (p if isinstance(p, (list, tuple)) else [p]):
                    if isinstance(q, jax.extend.core.ClosedJaxpr):
                        walk(q.jaxpr)
                    elif isinstance(q, jax.extend.core.Jaxpr):
                        walk(q)

    walk(jax.make_jaxpr(fn)(y).jaxpr)
    return out


SLOW_CASES = ("coag_nosweep", "frag_shattering", "outcome_full", "outcome_mixed")  # physical kernel: ~2-5 s each


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c
                                  for c in sorted(CASES)])
def test_structured_jacobian_equals_jacfwd(case):
    """J equals jacfwd of the plain rhs to <= 1e-12 (Frobenius, relative) and central finite
    differences (two columns: a middle bin and the gel entry); jacfwd of rhs_structured returns
    the same J and rhs_structured the same values as rhs. Default: coag_sweep, frag_shatter_above
    (FragData, mixed with sticking), outcome_smooth (OutcomeData, every channel); the cases on the
    physical kernel (velocity-dependent outcomes) are slow."""
    sch, kern, frag = CASES[case]
    y = _state(GRID, seed=len(case))
    cols = (GRID.nbins // 2, GRID.nbins)
    h = 1e-6 * float(jnp.max(y))

    @jax.jit
    def run(y):
        data = sch.precompute(kern(), GRID, None if frag is None else frag())
        f = lambda y: sch.rhs(0.0, y, data)
        fd = jnp.stack([(f(y.at[j].add(h)) - f(y.at[j].add(-h))) / (2 * h) for j in cols], axis=1)
        extra = data.frag.m_pwl if case.startswith("outcome") else (
            data.frag.ejecta if data.frag is not None else jnp.zeros(1))
        return (sch.jacobian(0.0, y, data), jax.jacfwd(f)(y), jax.jacfwd(lambda y: sch.rhs_structured(0.0, y, data))(y),
                fd, f(y), sch.rhs_structured(0.0, y, data), extra)

    J, Jref, J2, fd, f0, f1, extra = run(y)
    if case.startswith("outcome"):  # full: the Outcome describes every collision; mixed: weight p
        shapes = jax.eval_shape(lambda: sch.precompute(kern(), GRID, frag()))
        assert shapes.frag.full == (case in ("outcome_full", "outcome_smooth"))
    if frag is not None:
        assert float(jnp.max(extra)) > 0  # the setting fragments (fragment mass / ejecta > 0)
    assert float(jnp.linalg.norm(Jref)) > 0
    assert _rel(J, Jref) <= 1e-12
    assert _rel(J2, Jref) <= 1e-12
    np.testing.assert_array_equal(f1, f0)
    # the rhs is quadratic in y: central differences are exact up to the round-off of f / h
    tol = 1e-6 * float(jnp.max(jnp.abs(J))) + 1e-9 * float(jnp.max(jnp.abs(f0))) / h
    assert float(jnp.max(jnp.abs(fd - J[:, jnp.asarray(cols)]))) <= tol
    if case == "coag_sweep":
        assert float(jnp.max(jnp.abs(J[:, -1]))) > 0  # the gel column (sweep) is exercised
    if case == "frag_shatter_above":
        # jaxpr: jacfwd of rhs_structured forms J once: no scatter is batched over the N + 1 tangents
        # (the dense pair operators are built by one-off scatters in precompute; the tangents meet J
        # in one matmul)
        data = sch.precompute(kern(), GRID, frag())
        assert data.op is not None and data.ejop is not None
        s_struct = _scatter_shapes(jax.jacfwd(lambda y: sch.rhs_structured(0.0, y, data)), y)
        s_once = (_scatter_shapes(lambda y: sch.rhs(0.0, y, data), y)
                  + _scatter_shapes(lambda y: sch.jacobian(0.0, y, data), y))
        assert sorted(s_struct) == sorted(s_once)


class _ConstantDv(Constant):
    """Constant kernel with a constant relative velocity (10 m/s), for the outcome data's index pattern."""

    def relative_velocity2(self, m1, m2, x1=None, x2=None):
        return jnp.full(jnp.broadcast_shapes(jnp.shape(m1), jnp.shape(m2)), 1e6)


def _dense_and_scatter(sch, kern, frag, grid, y):
    data = sch.precompute(kern(), grid, None if frag is None else frag())
    N = grid.nbins
    return (data, sch.rhs(0.0, y, data), sch._rhs_scatter(y[:N], data), sch.jacobian(0.0, y, data),
            sch._jacobian_scatter(y[:N], data))


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c
                                  for c in sorted(CASES)])
def test_dense_pair_operator_equals_scatter_form(case):
    """The dense pair operators (jaxcoag.binned.pairop) give the scatter form's right-hand side and
    Jacobian to round-off (<= 1e-13 of the largest entry; the gel-sweep term is added by both paths
    alike, so it is left out here), conserve mass to round-off (sum of the rhs <= 1e-13 of sum |rhs|)
    and are used wherever the data allow (every case but the "full" OutcomeData)."""
    sch, kern, frag = CASES[case]
    y = _state(GRID, seed=3 + len(case))
    N = GRID.nbins
    data, f, f_sc, J, J_sc = jax.jit(lambda y: _dense_and_scatter(sch, kern, frag, GRID, y))(y)
    full = case in ("outcome_full", "outcome_smooth")
    assert (data.op is None) == full
    if full:
        return
    if data.sweep is not None:  # same sweep term on both sides: compare the pair part only
        swept = data.sweep * y[:N] * y[N]
        f = f - jnp.concatenate([-swept, jnp.sum(swept)[None]])
        J = J - jax.jacfwd(lambda z: jnp.concatenate([-data.sweep * z[:N] * z[N],
                                                       jnp.sum(data.sweep * z[:N] * z[N])[None]]))(y)
    scale = float(jnp.max(jnp.abs(f_sc)))
    assert scale > 0
    assert float(jnp.max(jnp.abs(f - f_sc))) <= 1e-13 * scale
    assert abs(float(jnp.sum(f))) <= 1e-13 * float(jnp.sum(jnp.abs(f)))
    assert float(jnp.max(jnp.abs(J - J_sc))) <= 1e-13 * float(jnp.max(jnp.abs(J_sc)))


@pytest.mark.parametrize("bpd", [1, 3, 7, 20])
def test_pair_categories_reproduce_every_target(bpd):
    """pair_categories: each entry's category formula (L: iL + o, S: iS + o, F: the fixed row) gives its
    own target, for the sticking tensors and Shattering (erosion remnants at offsets -1/0) on regular
    grids from 1 to 20 bins per decade; the offsets run from -1 to floor(bpd log10 2) + 1, so the count
    grows with resolution (7 at 7 bins per decade, 11 at 20) but not with the bin count."""
    from jaxcoag.binned.pairop import MAX_CATEGORIES, pair_categories
    from jaxcoag.binned.twobin import coagulation_tensors, pair_indices

    counts = []
    for decades in (6, 12):
        g = MassGrid.log(1e-12, 10.0 ** (decades - 12), bpd)
        N = g.nbins
        iL, iS, idx, _ = coagulation_tensors(g)
        fd = Shattering(100.0).twobin_data(_ConstantDv(1e-10), g, *pair_indices(N))
        targets = np.concatenate([idx, np.asarray(fd.idx)], axis=1)
        cats, code = pair_categories(targets, iL, iS, N + 1)
        base = np.array([c[0] for c in cats])[code]
        off = np.array([c[1] for c in cats])[code]
        rebuilt = np.where(base == "L", iL[:, None] + off, np.where(base == "S", iS[:, None] + off, off))
        np.testing.assert_array_equal(rebuilt, targets)
        assert ("F", N) in cats                     # the gel accumulator is a fixed row
        # the furthest product of a pair (2 m_i) lands floor(bpd log10 2) + 1 bins above the larger partner
        assert max(o for b, o in cats if b == "L") == int(np.floor(bpd * np.log10(2.0))) + 1
        assert min(o for b, o in cats if b == "L") == -1                       # eroded remnants
        assert len(cats) <= MAX_CATEGORIES
        counts.append(len(cats))
    assert counts[0] == counts[1]


def test_irregular_grid_falls_back_to_the_scatter_form(monkeypatch):
    """A pattern with more categories than MAX_CATEGORIES keeps the scatter form (op None) and gives the
    same right-hand side as the dense form to round-off."""
    import jaxcoag.binned.pairop as po

    sch, kern, frag = CASES["frag_shatter_above"]
    y = _state(GRID, seed=11)
    data_d = sch.precompute(kern(), GRID, frag())
    monkeypatch.setattr(po, "MAX_CATEGORIES", 2)
    data_s = sch.precompute(kern(), GRID, frag())
    assert data_d.op is not None and data_s.op is None and data_s.ejop is None
    f_d, f_s = sch.rhs(0.0, y, data_d), sch.rhs(0.0, y, data_s)
    assert float(jnp.max(jnp.abs(f_d - f_s))) <= 1e-13 * float(jnp.max(jnp.abs(f_s)))
    assert _rel(sch.jacobian(0.0, y, data_s), sch.jacobian(0.0, y, data_d)) <= 1e-13


def test_dense_rhs_vmap_matches_loop():
    """vmap of the dense right-hand side and Jacobian over states equals a loop (bitwise up to the
    batched reduction order: 1e-15)."""
    sch, kern, frag = CASES["frag_shatter_above"]
    data = sch.precompute(kern(), GRID, frag())
    ys = jnp.stack([_state(GRID, seed=s) for s in range(4)])
    fv = jax.vmap(lambda y: sch.rhs(0.0, y, data))(ys)
    Jv = jax.vmap(lambda y: sch.jacobian(0.0, y, data))(ys)
    for k in range(4):
        f1 = sch.rhs(0.0, ys[k], data)
        assert float(jnp.max(jnp.abs(fv[k] - f1))) <= 1e-15 * float(jnp.max(jnp.abs(f1)))
        assert _rel(Jv[k], sch.jacobian(0.0, ys[k], data)) <= 1e-15


@pytest.mark.slow
def test_default_config_box_jacobian():
    """The default ``jaxcoag run`` box (135 bins, Shattering, DustPy's 1-AU gas): structured J equals
    jacfwd of the plain rhs on the initial state and on a random positive state (~8 s; the default
    test_structured_jacobian_equals_jacfwd[frag_shattering] covers the same code on 24 bins)."""
    from jaxcoag import config as cfgmod
    from jaxcoag.binned.engine import _fragmentation

    b = cfgmod.build(cfgmod.default())
    sch, grid = b.engine.scheme, b.engine.grid
    data = sch.precompute(b.kernel, grid, _fragmentation(b.outcome))
    assert grid.nbins > 100 and data.frag is not None
    y0 = sch.init(grid, b.initial)
    rng = np.random.default_rng(3)
    jac_ref = jax.jit(jax.jacfwd(lambda y: sch.rhs(0.0, y, data)))
    jac = jax.jit(lambda y: sch.jacobian(0.0, y, data))
    for y in (y0, y0 + jnp.asarray(rng.uniform(0.0, 1.0, y0.shape)) * jnp.max(y0)):
        assert _rel(jac(y), jac_ref(y)) <= 1e-12


@pytest.mark.slow
@pytest.mark.parametrize("case", ["coag_sweep", "frag_shattering"])
def test_custom_jvp_data_tangents_and_reverse_mode(case):
    """Forward mode in y and a kernel/outcome parameter together (Product b; or alpha and v_frag
    of Shattering on the physical kernel) and reverse mode through rhs_structured equal the plain
    rhs's JVP/VJP to 1e-12 (the parameter tangent goes through the data JVP of the custom rule).
    ~2 s and ~15 s (slow); in the default suite test_binned_gradients.py::test_steady_state_implicit_gradient
    differentiates through the same rule (Newton Jacobian in y, implicit-function VJP in v_frag)."""
    sch = TwoBinScheme()
    y = _state(GRID, 5)
    if case == "coag_sweep":
        make = lambda a, b: sch.precompute(Product(a * b), GRID)
        args, tans = (y, 1e-3, 2.0), (None, 1e-4, 0.5)
    else:
        make = lambda alpha, vf: sch.precompute(_kern(alpha), GRID, Shattering(vf, probability="maxwellian"))
        args, tans = (y, 1e-2, 30.0), (None, 1e-3, 1.0)
    tans = (jnp.asarray(np.random.default_rng(1).normal(size=y.shape)) * 1e-14,) + tans[1:]
    w = jnp.linspace(1.0, 2.0, y.shape[0])

    @jax.jit
    def run(args, tans):
        out = []
        for fn in (sch.rhs, sch.rhs_structured):
            f = lambda y, a, b: fn(0.0, y, make(a, b))
            o, t = jax.jvp(f, args, tans)
            g = jax.grad(lambda *a: jnp.sum(w * f(*a)), argnums=(0, 1, 2))(*args)
            out.append((o, t) + g)
        return out

    ref, got = run(args, tans)
    np.testing.assert_array_equal(got[0], ref[0])
    for a, b in zip(ref[1:], got[1:]):
        assert float(jnp.max(jnp.abs(a))) > 0
        assert _rel(jnp.asarray(b), jnp.asarray(a)) <= 1e-12
