"""Thesis Fig. 3.1 (Ormel & Cuzzi 2007 Fig. 1): F(y*) = (2/3) y*(y*-1)^2 - 1/(1+y*), the LHS of eq. 3.18d.

Horizontal lines: RHS = 0 (St -> 0, root y_a = 1.6) and RHS = -1/2 (St = 1, root y* = 1), plus the RHS
of eq. 3.21 for a few (St, beta/alpha) showing that a larger beta/alpha raises y* (§3.3.3).
Check points (eq. 3.18d; independent float64 values): y_a, F(0), F(1), min F', y*(St), eq. 3.22.
Run: python paper_figs/fig3_1_ystar.py [--quick] [--out DIR]
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402


def main(argv=None):
    args = _common.parse_args(argv, __doc__)
    _common.enable_x64()
    import jax.numpy as jnp
    import numpy as np

    from jaxcoag.physics import turbulence as T

    plt = _common.pyplot()
    n = 201 if args.quick else 2001
    y = np.linspace(0.0, 2.5, n)
    F = np.asarray(T.F_ystar(jnp.asarray(y)))

    ck = _common.Checks("Fig 3.1 (F(y*), eq. 3.18d)")
    ya = float(T.ystar_exact(0.0))
    ck.add("root y_a (RHS=0)", ya, 1.6003688037229952, 1e-12)
    ck.add("root y_a vs thesis 1.6", ya, 1.6, 1e-3)
    ck.add("F(0)", float(T.F_ystar(0.0)), -1.0, 1e-12)
    ck.add("F(1) (root at St=1)", float(T.F_ystar(1.0)), -0.5, 1e-12)
    yy = jnp.linspace(1e-6, 20.0, 20001 if args.quick else 200001)
    ck.add("min F' on (0,20]", float(jnp.min(T.dF_ystar(yy))), 0.118026, 1e-6, absolute=True)
    for st, ref in [(0.01, 1.594399), (0.1, 1.542336), (0.5, 1.329160), (0.9, 1.086965)]:
        ck.add(f"y*(St={st})", float(T.ystar_exact(st)), ref, 1e-6, absolute=True)
    ck.add("eq3.22 St(St*=1), b/a=1", float(T.st_where_star_is_one_eq322(1.0)), 0.670440, 1e-6, absolute=True)

    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    ax.plot(y, F, "k-", lw=1.8, label=r"$F(y^*)$ (LHS eq. 3.18d)")
    ax.axhline(0.0, color="C0", ls="--", lw=1, label=r"RHS $=0$ (St$\to0$): $y_a=1.60$")
    ax.axhline(-0.5, color="C3", ls="--", lw=1, label=r"RHS $=-1/2$ (St$=1$): $y^*=1$")
    ax.plot([ya], [0.0], "o", color="C0")
    ax.plot([1.0], [-0.5], "o", color="C3")
    for i, (st, boa) in enumerate([(0.5, 0.0), (0.5, 1.0), (0.5, 10.0)]):
        rhs = float(T.rhs_eq321(st, boa))
        ys = float(T.ystar_exact(st, beta_over_alpha=boa))
        ax.axhline(rhs, color=f"C{i + 4}", ls=":", lw=1,
                   label=rf"eq. 3.21, St$={st}$, $\beta/\alpha={boa:g}$: $y^*={ys:.3f}$")
        ax.plot([ys], [rhs], "s", color=f"C{i + 4}", ms=4)
    ax.set_xlim(0, 2.5)
    ax.set_ylim(-1.2, 2.5)
    ax.set_xlabel(r"$y^* = t^*/\tau_f$")
    ax.set_ylabel(r"$F(y^*)$")
    ax.set_title("Ormel 2008 Fig. 3.1 (OC07 Fig. 1)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    png = _common.savefig(fig, args, "fig3_1_ystar")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
