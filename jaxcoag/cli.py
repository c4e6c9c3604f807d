"""Command-line interface: ``jaxcoag demo`` (velocity/kernel demo, the default main job)."""

from __future__ import annotations

import argparse
import sys

import jax


def _enable_x64():
    jax.config.update("jax_enable_x64", True)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jaxcoag", description="Differentiable dust coagulation in JAX.")
    sub = p.add_subparsers(dest="command")
    d = sub.add_parser("demo", help="relative velocities and kernel of the ch. 4 nebula scene (table + figure)")
    d.add_argument("--disk", choices=["ch4", "mmsn"], default="ch4", help="disk preset (default ch4 = thesis Table 4.1)")
    d.add_argument("--R", type=float, default=3.0, help="radius in AU (default 3)")
    d.add_argument("--alpha", type=float, default=1e-4, help="turbulence alpha (default 1e-4)")
    d.add_argument("--rho-s", type=float, default=3.0, help="material density g/cm^3 (default 3)")
    d.add_argument("--n", type=int, default=200, help="grid points of the N x N map (default 200)")
    d.add_argument("--out", default="jaxcoag_out", help="output directory (default ./jaxcoag_out)")
    d.add_argument("--quick", action="store_true", help="small grid (seconds)")
    return p


def main(argv=None) -> int:
    _enable_x64()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        args = parser.parse_args(["demo"] + (argv or []))
    if args.command == "demo":
        from .demo import run_demo

        try:
            run_demo(disk=args.disk, R_au=args.R, alpha=args.alpha, rho_s=args.rho_s, n=args.n,
                     out=args.out, quick=args.quick)
        except (ValueError, TypeError) as e:
            print(f"jaxcoag demo: error: {e}", file=sys.stderr)
            return 2
        return 0
    parser.print_help()
    return 1


if __name__ == "__main__":
    sys.exit(main())
