"""skinpatch from Python: simulate a deforming patch of skin and read each
frame's fields as numpy arrays.

    import skinpatch
    scenario = skinpatch.Scenario.load("examples/press.toml")
    for frame in skinpatch.Run(scenario):
        print(frame.index, frame.probe_force[2])

Units: millimetres, seconds, newtons (stresses in N/mm² = MPa), heights
of the microstructure maps in micrometres.
"""

from ._native import (
    Frame,
    GpuError,
    Mesh,
    MeshError,
    Run,
    Scenario,
    ScenarioError,
    SkinpatchError,
    SolverError,
    __version__,
    fit,
    neutral_map,
    read_mesh,
    write_vtu,
)

__all__ = [
    "Frame",
    "GpuError",
    "Mesh",
    "MeshError",
    "Run",
    "Scenario",
    "ScenarioError",
    "SkinpatchError",
    "SolverError",
    "__version__",
    "fit",
    "neutral_map",
    "read_mesh",
    "write_vtu",
]
