"""Force–depth curve of the press: steps the scenario's run from Python
and plots the probe force against the indentation depth (matplotlib).

    python examples/python/force_depth.py                  # examples/press.toml
    python examples/python/force_depth.py SCENARIO --out curve.png --frames 20

The depth is how far the probe's centre has gone down since the first
frame (for a probe starting on the skin, as in press.toml: the indentation);
the curve covers the frames while the probe goes down (the press, not the
drag that follows). Prints the curve as CSV on stdout and writes the plot.
"""

import argparse
import pathlib
import sys

import skinpatch


def press_curve(scenario, frames=None):
    """(depth mm, force N) pairs of the press phase of `scenario`'s run:
    the frames while the probe goes down (at most `frames`)."""
    run = skinpatch.Run(scenario)
    start, curve = None, []
    for frame in run:
        if frames is not None and frame.index >= frames:
            break
        centre = frame.probe_centre
        if centre is None:
            raise SystemExit(f"{scenario.path}: the scenario has no [probe]")
        start = centre[2] if start is None else start
        depth = float(start - centre[2])
        if curve and depth <= curve[-1][0] + 1e-12:
            break  # the press is over: the probe stops, rises or drags from here
        curve.append((depth, float(frame.probe_force[2])))
    return curve


def main(argv=None):
    root = pathlib.Path(__file__).resolve().parents[2]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default=root / "examples/press.toml")
    parser.add_argument("--out", default="out/python/force_depth.png", help="plot file")
    parser.add_argument("--frames", type=int, help="stop after this many frames")
    args = parser.parse_args(argv)
    scenario = skinpatch.Scenario.load(args.scenario)
    curve = press_curve(scenario, args.frames)
    print("depth_mm,force_n")
    for depth, force in curve:
        print(f"{depth:.6f},{force:.6e}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot (pip install matplotlib)", file=sys.stderr)
        return curve
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    ax.plot([d for d, _ in curve], [f for _, f in curve], "o-", ms=3)
    ax.set_xlabel("indentation depth (mm)")
    ax.set_ylabel("probe force (N)")
    ax.set_title(f"{scenario.name}: force against depth")
    ax.grid(alpha=0.3)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out)
    print(f"wrote {out}", file=sys.stderr)
    return curve


if __name__ == "__main__":
    main()
