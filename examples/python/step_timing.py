"""Times a scenario's frames stepped in memory from Python: the Python side
of the per-frame overhead measurement (docs/PERFORMANCE.md, "Python
layer"); `cargo run --release --example step_timing` is the Rust side.

    python examples/python/step_timing.py examples/press.toml

Prints the same line as the Rust side: the mean frame and its FEM solve.
"""

import sys
import time

import skinpatch


def main(argv):
    path = argv[0] if argv else "examples/press.toml"
    run = skinpatch.Run(skinpatch.Scenario.load(path))
    frames = run.scenario_frames
    start, solve = time.perf_counter(), 0.0
    for _ in range(frames):
        frame = run.step()
        force = frame.probe_force[2]
        solve += frame.metrics["step_wall_s"]
    total = time.perf_counter() - start
    print(
        f"python: {frames} frames in {total:.3f} s, {1e3 * total / frames:.2f} ms a frame, "
        f"{1e3 * solve / frames:.2f} ms of it the FEM solve (last force {force:.6f} N)"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
