"""Thesis Fig. 3.2 (OC07 Fig. 2): the three t* prescriptions, St* = t*/t_L against St (log-log).

Dashed: exact root of eq. 3.18d; solid: t* = 1.6 tau_f; dotted: Cuzzi & Hogan 2003 k*/k_L = 1 + St^-3/2/2
(St* = (k*/k_L)^-2/3). t* <= t_L is enforced (Re = 1e30, so the lower clip is invisible).
Check points (thesis §3.3.2, App. 3.A; independent float64 values): St = 0.3 values 0.4302 / 0.48 / 0.3940, CH03 St*(1) = 0.763143,
CH03 St*/St -> 1.587401, exact St*(1) = 1, ya reaches 1 at St = 0.625.
Run: python paper_figs/fig3_2_tstar.py [--quick] [--out DIR]
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
    RE = 1e30
    st = np.logspace(-2, 1, 61 if args.quick else 601)
    curves = {m: np.asarray(T.st_star(jnp.asarray(st), RE, method=m)) for m in T.METHODS}

    ck = _common.Checks("Fig 3.2 (t*/t_L vs St)")
    s03 = {m: float(T.st_star(0.3, RE, method=m)) for m in T.METHODS}
    ck.add("St*(0.3) exact", s03["exact"], 0.4302, 1e-4, absolute=True)
    ck.add("St*(0.3) ya=1.6", s03["ya"], 0.48, 1e-12)
    ck.add("St*(0.3) ch03", s03["ch03"], 0.3940, 1e-4, absolute=True)
    ck.add("St*(1) exact", float(T.st_star(1.0, RE)), 1.0, 1e-12)
    ck.add("St*(1) ch03", float(T.st_star(1.0, RE, method="ch03")), 0.763143, 1e-6, absolute=True)
    ck.add("ch03 St*/St as St->0", float(T.st_star(1e-12, RE, method="ch03")) / 1e-12, 1.587401, 1e-6)
    ck.add("ya St*(0.625)", float(T.st_star(0.625, RE, method="ya")), 1.0, 1e-12)

    fig, ax = plt.subplots(figsize=(5.0, 4.2))
    ax.loglog(st, curves["exact"], "k--", label=r"exact $y^*$ (eq. 3.18d)")
    ax.loglog(st, curves["ya"], "k-", label=r"$t^* = 1.6\,\tau_f$")
    ax.loglog(st, curves["ch03"], "k:", label=r"CH03: $k^*/k_L = 1 + \frac{1}{2}{\rm St}^{-3/2}$")
    for m, mk in zip(T.METHODS, "os^"):
        ax.plot([0.3], [s03[m]], mk, color="C3", ms=4)
    ax.set_xlim(1e-2, 10)
    ax.set_ylim(1e-2, 1.5)
    ax.set_xlabel(r"St $= \tau_f/t_L$")
    ax.set_ylabel(r"$t^*/t_L$")
    ax.set_title("Ormel 2008 Fig. 3.2 (OC07 Fig. 2)", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    png = _common.savefig(fig, args, "fig3_2_tstar")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png)


if __name__ == "__main__":
    main()
