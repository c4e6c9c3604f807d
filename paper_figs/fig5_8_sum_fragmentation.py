"""Thesis Fig. 5.8: sum kernel K = m_i + m_j (no 1/2, K00 = 2) with catastrophic fragmentation at m_frag.

Constant-Ns, equal-mass zoom (m* = m_p, mass duplication controller), one long run with ~100 snapshots;
every product heavier than m_frag is shattered into monomers (``jaxcoag.outcomes.ShatterAbove(m_frag, 1)``,
the same outcome object the binned engine takes; thesis §5.3.4); ``leftover="stochastic"`` (MC hazard 3 in docs/design_notes.md) avoids the demagnify cascade that otherwise
fills the species capacity right after the first fragmentation.
KNOWN ENGINE LIMITATION (measured 2026-11-21, m_frag = 1e6, Ns* = 100, f_eps = 1e-2): after the first
fragmentation (t ~ 8) the event rate per unit time explodes (~700 events per 0.4 time units at t ~ 9,
~7700 at t ~ 15: freeze-down) and Ns reaches the capacity 8 Ns* even with the stochastic leftover rule
(status capacity_exceeded: emergency merges, results smoothed but consistent). Since the scheduled merge above
2 Ns* (``EqualMass(merge_above=2.0)``, thesis ch. 6) the species count stays <= 2 Ns* and the run ends
successful, at more events (measured 2026-11-26: 138 486 events, 54 621 merges, to t = 16.6; 74 308 events
without the merge rule), so the quick event cap is 2.5e5. Quick mode runs to
t = 2.4 t_first (t_first = ln(m_frag)/2) and averages over the second half of that window; the status check
accepts successful and capacity_exceeded (printed) and rejects every other status. The time-averaged m^2 f(m) over the steady state is a "bathtub": mass piles up at both ends
(two-state model: n_0 m_0 ~ n_f m_f), and the simulated volume stabilises (thesis: V ~ 2e12 >> m_frag for
m_frag = 1e10, Ns* = 1e4).
Check points (thesis Fig. 5.8, factor-2 bins, time average over the second half of the run):
  mass in the lowest 2 bins (m < 4) / max mass in any single mid-range bin (centre in
  [m_frag^0.3, m_frag^0.7]) > 1; the same for the 2 bins just below m_frag; the ratio of the two end masses
  within a factor 3 (|ln ratio| < ln 3); volume stationary: |ln(<V> last quarter / <V> third quarter)| < ln 2.

Run:   python paper_figs/fig5_8_sum_fragmentation.py --quick  (m_frag = 1e6, Ns* = 100, f_eps = 1e-2; ~1-2 min on 2 busy cores)
Full:  python paper_figs/fig5_8_sum_fragmentation.py          (thesis: m_frag = 1e10 with Ns* = 1e4 and
       m_frag = 1e20 with Ns* = 2e4, f_eps = 1e-3: ~1e6-1e7 events with O(8e4)-slot updates -- hours on this
       machine, not run here). Intermediate: --mfrag 1e10 --ns 1000 (~15-30 min).
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from fig5_3_sum_fixedNp import in_range  # noqa: E402


def _extra(p):
    p.add_argument("--mfrag", type=float, default=None, help="fragmentation mass (default 1e10; quick 1e6)")
    p.add_argument("--ns", type=int, default=None, help="Ns* (default 1e4; quick 300)")
    p.add_argument("--feps", type=float, default=None, help="f_eps (default 1e-3; quick 1e-2)")
    p.add_argument("--max-events", type=int, default=None, help="event cap (default 1e7; quick 2.5e5)")
    p.add_argument("--seed", type=int, default=5008)


def run_fragmentation(kernel, m_frag, ns, f_eps, t_out, seed, max_events):
    """One const-Ns equal-mass run with catastrophic fragmentation, capped at ``max_events``.

    Returns (MCResult, edges, rho (T, nb), real (T,) bool): ``real`` marks snapshots recorded before the
    event cap (later ones only repeat the capped state and are excluded from every average).
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    import jaxcoag
    from jaxcoag import mc

    engine = jaxcoag.MonteCarlo(grouping=mc.EqualMass(), volume=mc.ConstantSpecies(), n_particles=float(ns),
                                ns_target=ns, f_eps=f_eps, max_events=max_events, leftover="stochastic")
    res = jaxcoag.evolve(kernel, engine, jaxcoag.Monodisperse(1.0, 1.0), jnp.asarray(t_out),
                         outcome=jaxcoag.outcomes.ShatterAbove(m_frag, 1.0), key=jax.random.key(seed), throw=False)
    edges = 2.0 ** np.arange(0, int(math.ceil(math.log2(m_frag))) + 2)
    rho = np.asarray(res.mass_per_bin(jnp.asarray(edges)))
    real = np.asarray(res.n_events_snap) < max_events
    return res, edges, rho, real


def steady_window(t_out, real):
    """Indices of the averaging window: the second half of the snapshots actually reached."""
    import numpy as np

    n_real = int(np.sum(real))
    return np.arange(n_real // 2, n_real), n_real


def main(argv=None):
    args = _common.parse_args(argv, __doc__, _extra)
    _common.enable_x64()
    import numpy as np

    import jaxcoag
    from jaxcoag import kernels as K

    plt = _common.pyplot()
    m_frag = args.mfrag or (1e6 if args.quick else 1e10)
    ns = args.ns or (100 if args.quick else 10000)
    args.feps = args.feps or (1e-2 if args.quick else 1e-3)
    t_first = math.log(m_frag) / 2.0           # m_p ~ e^{2t} for K = m_i + m_j without fragmentation
    t_out = np.linspace(0.25 * t_first, (2.4 if args.quick else 6.0) * t_first, 100)
    print(f"Fig 5.8: K = m_i + m_j, const-Ns equal-mass, Ns* = {ns}, m_frag = {m_frag:g}, f_eps = {args.feps:g}, "
          f"t = {t_out[0]:.3g}..{t_out[-1]:.3g} (100 snapshots)")
    max_events = args.max_events or (250000 if args.quick else 10**7)
    res, edges, rho, real = run_fragmentation(K.Sum(1.0), m_frag, ns, args.feps, t_out, args.seed, max_events)
    win, n_real = steady_window(t_out, real)
    status = jaxcoag.status_names(res.status)
    V = np.asarray(res.V)
    print(f"status {status} (flags {res.flag_names()}); events {int(res.n_events)}; duplications {int(res.n_dup)}; "
          f"merges {int(res.n_merge)}")
    T = len(t_out)
    ml1 = np.asarray(res.largest_mass())
    print(f"snapshots reached before the event cap: {n_real}/{T} (t <= {t_out[max(n_real - 1, 0)]:.4g}); "
          f"events at snapshots {np.asarray(res.n_events_snap)[::10].tolist()}; M_L1 {ml1[::10].round(0).tolist()}")
    if n_real < T:
        print(f"GAP: the event cap {max_events} was reached at t = {t_out[max(n_real - 1, 0)]:.4g} (freeze-down after "
              f"the first fragmentation; status {status}); the averages use the snapshots reached.")
    win = win if win.size else np.arange(T // 2, T)
    avg = rho[win].mean(axis=0)
    mc_ = np.sqrt(edges[:-1] * edges[1:])
    top = np.searchsorted(edges, m_frag, side="right") - 1          # bin holding m_frag
    low = avg[:2].sum()
    high = avg[max(top - 2, 0):top].sum() if edges[top] == m_frag else avg[top - 1:top + 1].sum()
    mid = (mc_ >= m_frag ** 0.3) & (mc_ <= m_frag ** 0.7)
    mid_max = max(float(avg[mid].max()), 1e-300)
    low, high = max(low, 1e-300), max(high, 1e-300)
    v3 = V[win[: win.size // 2]].mean()
    v4 = V[win[win.size // 2:]].mean()
    print(f"time-averaged mass: lowest 2 bins {low:.4g}, 2 bins below m_frag {high:.4g}, max mid bin {mid_max:.4g}; "
          f"V(3rd quarter) {v3:.4g}, V(last quarter) {v4:.4g}, Ns (last) {int(res.n_species[-1])}")
    ck = _common.Checks(f"Fig 5.8 (K = m_i+m_j, catastrophic fragmentation at {m_frag:g}, Ns*={ns})")
    ck.add("status neither successful nor capacity_exceeded", float(status not in ("successful", "capacity_exceeded")),
           0.0, 0.0, absolute=True)
    ck.add("snapshots reached before the event cap", float(n_real), float(T), 0.0, absolute=True)
    in_range(ck, "low-end mass / max mid bin (>1)", low / mid_max, 1.0, 1e6)
    in_range(ck, "high-end mass / max mid bin (>1)", high / mid_max, 1.0, 1e6)
    ck.add("|ln(low/high)| (<ln 3)", abs(math.log(low / high)), 0.0, math.log(3.0), absolute=True)
    ck.add("|ln V_last/V_3rd quarter| (<ln 2)", abs(math.log(v4 / v3)), 0.0, math.log(2.0), absolute=True)

    fig, axs = plt.subplots(1, 2, figsize=(10.5, 4.2))
    dm = edges[1:] - edges[:-1]
    for k in win[::10]:
        axs[0].loglog(mc_, np.where(rho[k] > 0, rho[k] * mc_ / dm, np.nan), "-", color="0.7", lw=0.6)
    axs[0].loglog(mc_, np.where(avg > 0, avg * mc_ / dm, np.nan), "ko-", ms=3,
                  label=f"time average (snapshots {win[0]}-{win[-1]})")
    axs[0].axvline(m_frag, color="C3", ls=":", lw=0.8)
    axs[0].set_xlabel("m")
    axs[0].set_ylabel(r"$m^2 f(m)$")
    axs[0].legend(fontsize=7)
    axs[0].set_title(f"m_frag = {m_frag:g}, Ns* = {ns}; grey: snapshots", fontsize=9)
    axs[1].semilogy(t_out[:max(n_real, 1)], V[:max(n_real, 1)], "k-")
    axs[1].set_xlabel("t")
    axs[1].set_ylabel("simulated volume V")
    fig.suptitle("Ormel 2008 Fig. 5.8: sum kernel K = m_i + m_j with catastrophic fragmentation (bathtub)",
                 fontsize=10)
    png = _common.savefig(fig, args, "fig5_8_sum_fragmentation")
    ck.print()
    print(f"wrote {png}")
    return ck.result(png, volume_last=float(v4))


if __name__ == "__main__":
    main()
