"""Type stubs of the extension module (re-exported by `skinpatch`)."""

from __future__ import annotations

import os
from types import TracebackType
from typing import Any, Iterator, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, "os.PathLike[str]"]
_Vec3 = Sequence[float]

__version__: str

class SkinpatchError(Exception):
    """Base class of the errors skinpatch raises."""

class ScenarioError(SkinpatchError):
    """A scenario that does not parse or validate."""

    file: str
    """The scenario file."""
    line: Optional[int]
    """1-based line of the key at fault; None when it is not in the file (an override)."""
    key: Optional[str]
    """The dotted key at fault, e.g. ``material.dermis.poisson_ratio``; None for a syntax error."""

class MeshError(SkinpatchError):
    """A mesh file that does not parse, or a mesh the simulation cannot use."""

class SolverError(SkinpatchError):
    """A frame whose equilibrium was not reached; an in-memory run stays at its last good frame."""

class GpuError(SkinpatchError):
    """A GPU stage that failed (or no adapter with SKINPATCH_REQUIRE_GPU=1)."""

class Mesh:
    """A tetrahedral mesh in millimetres."""

    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """Rest vertex positions, shape (n_vertices, 3), mm."""
    @property
    def tets(self) -> npt.NDArray[np.int64]:
        """Tets as vertex indices, shape (n_tets, 4)."""
    @property
    def tet_region(self) -> npt.NDArray[np.int32]:
        """Region id of every tet, shape (n_tets,)."""
    @property
    def regions(self) -> dict[int, str]:
        """Region names by id."""
    @property
    def top_vertices(self) -> npt.NDArray[np.int64]:
        """Mesh vertices on the top surface, shape (n_top,)."""
    @property
    def top_triangles(self) -> npt.NDArray[np.int64]:
        """Top-surface triangles as mesh vertex indices, shape (n_triangles, 3)."""
    @property
    def top_uvs(self) -> npt.NDArray[np.float64]:
        """UVs of `top_vertices`, shape (n_top, 2)."""
    @property
    def num_vertices(self) -> int: ...
    @property
    def num_tets(self) -> int: ...
    def write_vtu(
        self,
        path: _Path,
        point_data: Optional[Mapping[str, npt.ArrayLike]] = None,
        cell_data: Optional[Mapping[str, npt.ArrayLike]] = None,
    ) -> None:
        """Writes the mesh as VTU with optional extra arrays (see `write_vtu`)."""

class Scenario:
    """A validated scenario with its mesh."""

    @staticmethod
    def load(path: _Path, overrides: Optional[dict[str, Any]] = None) -> Scenario:
        """Reads and validates a scenario; `overrides` maps dotted keys to values
        (``{"material.dermis.youngs_modulus_kpa": 200}``). Raises ScenarioError,
        MeshError or FileNotFoundError."""
    @property
    def name(self) -> str: ...
    @property
    def path(self) -> str: ...
    @property
    def frames(self) -> int:
        """Frames the scenario runs, the rest frame included."""
    @property
    def frame_dt(self) -> float:
        """Time between frames, s."""
    @property
    def output_dir(self) -> str: ...
    @property
    def has_probe(self) -> bool: ...
    @property
    def has_microstructure(self) -> bool: ...
    @property
    def mesh(self) -> Mesh: ...

class Frame:
    """One solved frame; arrays are new copies on every access."""

    @property
    def index(self) -> int:
        """Frame number (0: the rest frame)."""
    @property
    def time(self) -> float:
        """Simulated time, s."""
    @property
    def metrics(self) -> dict[str, Union[int, float]]:
        """The frame's metrics.csv row by column name."""
    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """Deformed positions, shape (n_vertices, 3), mm."""
    @property
    def displacements(self) -> npt.NDArray[np.float64]:
        """Displacements from rest, shape (n_vertices, 3), mm."""
    @property
    def principal_stretches(self) -> npt.NDArray[np.float64]:
        """Principal stretches per tet, λ1 ≥ λ2 ≥ λ3, shape (n_tets, 3)."""
    @property
    def principal_strains(self) -> npt.NDArray[np.float64]:
        """Principal Biot strains λ − 1 per tet, shape (n_tets, 3)."""
    @property
    def volume_ratio(self) -> npt.NDArray[np.float64]:
        """J = det F per tet, shape (n_tets,)."""
    @property
    def surface_stretch(self) -> npt.NDArray[np.float64]:
        """(r_s, r_t) per vertex, shape (n_vertices, 2); NaN off the top surface."""
    @property
    def probe_centre(self) -> Optional[npt.NDArray[np.float64]]:
        """The probe's centre where the frame was solved, shape (3,), mm; None without a probe."""
    @property
    def probe_force(self) -> npt.NDArray[np.float64]:
        """Force of the skin on the probe, shape (3,), N."""
    @property
    def contact_nodes(self) -> npt.NDArray[np.int64]:
        """Vertices in contact, ascending, shape (n_contact,)."""
    @property
    def contact_forces(self) -> npt.NDArray[np.float64]:
        """Probe force on each contact node, shape (n_contact, 3), N."""
    @property
    def contact_pressure(self) -> npt.NDArray[np.float64]:
        """Contact pressure at each contact node, shape (n_contact,), N/mm²."""
    @property
    def stresses(self) -> npt.NDArray[np.float64]:
        """Cauchy stress per tet, shape (n_tets, 3, 3), N/mm²."""
    @property
    def von_mises(self) -> npt.NDArray[np.float64]:
        """Von Mises stress per tet, shape (n_tets,), N/mm²."""
    @property
    def region_volumes(self) -> dict[str, dict[str, Union[int, float]]]:
        """Per region: rest_mm3, deformed_mm3, change, min_volume_ratio, tets_below."""
    def deformed_map(self) -> npt.NDArray[np.float32]:
        """The microstructure deformed by this frame, shape (height, width), µm."""
    def write_vtu(self, path: _Path) -> None:
        """Writes the frame as `skinpatch run` writes frames/frame_NNNN.vtu."""

class Run:
    """A FEM run stepped frame by frame; iterate it to run the scenario's frames."""

    def __init__(
        self,
        scenario: Scenario,
        outputs: bool = False,
        output_dir: Optional[_Path] = None,
    ) -> None: ...
    def step(
        self,
        probe_target: Optional[_Vec3] = None,
        probe_axis: Optional[_Vec3] = None,
    ) -> Frame:
        """Solves the next frame, the probe's centre at `probe_target` (mm) when given."""
    def __iter__(self) -> Iterator[Frame]: ...
    def __next__(self) -> Frame: ...
    @property
    def next_frame(self) -> int: ...
    @property
    def scenario_frames(self) -> int: ...
    @property
    def frame_dt(self) -> float: ...
    def finish(self) -> list[str]:
        """Ends the run, closing its files; returns the files written."""
    def __enter__(self) -> Run: ...
    def __exit__(
        self,
        exc_type: Optional[type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> bool: ...

def neutral_map(scenario: Scenario) -> npt.NDArray[np.float32]:
    """The scenario's neutral microstructure map, shape (height, width), µm."""

def fit(samples_path: _Path) -> dict[str, Any]:
    """Fits kernel parameters and a kernel model to a samples file, as `skinpatch fit` does.

    Returns `rows` (per sample and point: source, r, alpha, sigma_um; fitted
    samples also axis, range, distance, alpha_valley, sigma_valley_um,
    seconds), `model` (alpha, sigma_compression_um, sigma_stretch_um as
    lists of (r, value) knots), `written` (the kernel file or None) and
    `device` (where candidates were counted, or None).
    """

def read_mesh(path: _Path) -> Mesh:
    """Reads a TetGen .node, Gmsh .msh, .vtu or legacy .vtk tet mesh."""

def write_vtu(
    path: _Path,
    mesh: Mesh,
    point_data: Optional[Mapping[str, npt.ArrayLike]] = None,
    cell_data: Optional[Mapping[str, npt.ArrayLike]] = None,
) -> None:
    """Writes `mesh` as VTU with extra point/cell arrays (1-D or 2-D, one row per point/tet).

    The file is replaced atomically; a `path` that is a symbolic link, FIFO,
    device or folder raises OSError and is left as it was.
    """
