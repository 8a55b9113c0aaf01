"""Parameter sweep over the dermis's Young's modulus: runs the scenario
once per value (in memory, through overrides) and collects the peak probe
force and the surface stretch range of each run.

    python examples/python/sweep.py                         # examples/press.toml, 5 moduli
    python examples/python/sweep.py SCENARIO --kpa 75 150 300 --frames 20 --region dermis

Prints a table (CSV) and, with matplotlib, plots the peak force against
the modulus.
"""

import argparse
import pathlib
import sys

import numpy as np

import skinpatch


def sweep(path, moduli_kpa, region="dermis", frames=None):
    """One row per modulus: (kPa, peak |F_z| N, largest r_s, smallest r_t,
    smallest volume ratio)."""
    rows = []
    for kpa in moduli_kpa:
        scenario = skinpatch.Scenario.load(
            path, {f"material.{region}.youngs_modulus_kpa": float(kpa)}
        )
        peak, rs_max, rt_min, j_min = 0.0, 1.0, 1.0, 1.0
        for frame in skinpatch.Run(scenario):
            if frames is not None and frame.index >= frames:
                break
            m = frame.metrics
            peak = max(peak, abs(m["probe_force_z_n"]))
            rs_max, rt_min = max(rs_max, m["rs_max"]), min(rt_min, m["rt_min"])
            j_min = min(j_min, float(np.min(frame.volume_ratio)))
        rows.append((float(kpa), peak, rs_max, rt_min, j_min))
        print(f"  {region} at {kpa:g} kPa: peak force {peak:.4f} N", file=sys.stderr)
    return rows


def main(argv=None):
    root = pathlib.Path(__file__).resolve().parents[2]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default=root / "examples/press.toml")
    parser.add_argument("--kpa", type=float, nargs="+", default=[50, 100, 150, 250, 400])
    parser.add_argument("--region", default="dermis", help="the [material.<region>] to vary")
    parser.add_argument("--frames", type=int, help="frames per run (default: all)")
    parser.add_argument("--out", default="out/python/sweep.png", help="plot file")
    args = parser.parse_args(argv)
    rows = sweep(args.scenario, args.kpa, args.region, args.frames)
    print("youngs_modulus_kpa,peak_force_n,rs_max,rt_min,min_volume_ratio")
    for row in rows:
        print(",".join(f"{v:.6g}" for v in row))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot (pip install matplotlib)", file=sys.stderr)
        return rows
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    ax.plot([r[0] for r in rows], [r[1] for r in rows], "o-")
    ax.set_xlabel(f"{args.region} Young's modulus (kPa)")
    ax.set_ylabel("peak probe force (N)")
    ax.grid(alpha=0.3)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}", file=sys.stderr)
    return rows


if __name__ == "__main__":
    main()
