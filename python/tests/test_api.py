"""The Python package against the binary's files and its documented API."""

import csv
import math
import os
import pathlib
import signal
import threading
import time

import numpy as np
import pytest

import skinpatch


def press_small(root, **overrides):
    return skinpatch.Scenario.load(root / "tests/fixtures/press_small.toml", overrides)


def test_metrics_equal_the_binarys_to_the_last_digit(root, run_binary, tmp_path):
    out = run_binary(root / "tests/fixtures/press_small.toml", tmp_path / "bin")
    with open(out / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    frames = list(skinpatch.Run(press_small(root)))
    assert len(frames) == len(rows) == 7
    for frame, row in zip(frames, rows):
        metrics = frame.metrics
        assert list(metrics) == list(row), "the dict has metrics.csv's columns in order"
        for key, text in row.items():
            if key == "step_wall_s":
                continue
            value = metrics[key]
            # The CSV holds the shortest digits that read back to the same bits.
            assert float(text) == value, (frame.index, key, text, value)
            assert type(value) is (int if key in INTEGER_COLUMNS else float)


INTEGER_COLUMNS = {
    "frame",
    "contact_nodes",
    "newton_iterations",
    "linear_iterations",
    "folded_vertices",
    "inverted_tets",
}


def test_frame_vtu_files_are_the_binarys_byte_for_byte(root, run_binary, tmp_path):
    scenario = root / "tests/fixtures/press_small.toml"
    out = run_binary(scenario, tmp_path / "bin", "output.frames_vtu=true")
    for frame in skinpatch.Run(skinpatch.Scenario.load(scenario, {"output.frames_vtu": True})):
        mine = tmp_path / f"frame_{frame.index:04}.vtu"
        frame.write_vtu(mine)
        theirs = out / "frames" / f"frame_{frame.index:04}.vtu"
        assert mine.read_bytes() == theirs.read_bytes(), frame.index


def test_arrays_are_the_vtu_arrays_bit_for_bit(root, run_binary, tmp_path):
    meshio = pytest.importorskip("meshio") if not _require("MESHIO") else __import__("meshio")
    scenario = root / "tests/fixtures/press_small.toml"
    out = run_binary(scenario, tmp_path / "bin", "output.frames_vtu=true")
    frames = list(skinpatch.Run(press_small(root)))
    last = frames[-1]
    grid = meshio.read(out / "frames" / f"frame_{last.index:04}.vtu")
    assert np.array_equal(grid.points, last.positions)
    assert np.array_equal(grid.point_data["displacement_mm"], last.displacements)
    assert np.array_equal(grid.point_data["surface_stretch"], last.surface_stretch, equal_nan=True)
    cells = {k: v[0] for k, v in grid.cell_data.items()}
    assert np.array_equal(cells["principal_biot_strain"], last.principal_strains)
    assert np.array_equal(cells["principal_stretch"], last.principal_stretches)
    assert np.array_equal(cells["volume_ratio"], last.volume_ratio)
    assert np.array_equal(cells["von_mises_stress_n_mm2"], last.von_mises)
    s = last.stresses
    voigt = np.stack(
        [s[:, 0, 0], s[:, 1, 1], s[:, 2, 2], s[:, 0, 1], s[:, 1, 2], s[:, 0, 2]], axis=1
    )
    assert np.array_equal(cells["cauchy_stress_n_mm2"], voigt)
    pressure = np.zeros(len(last.positions))
    pressure[last.contact_nodes] = last.contact_pressure
    assert np.array_equal(grid.point_data["contact_pressure_n_mm2"], pressure)
    force = np.zeros((len(last.positions), 3))
    force[last.contact_nodes] = last.contact_forces
    assert np.array_equal(grid.point_data["contact_force_n"], force)


def _require(what):
    import os

    return os.environ.get(f"SKINPATCH_REQUIRE_{what}") == "1"


def test_arrays_have_the_documented_shapes_and_dtypes(root):
    scenario = press_small(root)
    mesh = scenario.mesh
    n, t = mesh.num_vertices, mesh.num_tets
    run = skinpatch.Run(scenario)
    run.step()
    frame = run.step()
    expected = {
        "positions": ((n, 3), np.float64),
        "displacements": ((n, 3), np.float64),
        "principal_strains": ((t, 3), np.float64),
        "principal_stretches": ((t, 3), np.float64),
        "volume_ratio": ((t,), np.float64),
        "surface_stretch": ((n, 2), np.float64),
        "probe_force": ((3,), np.float64),
        "probe_centre": ((3,), np.float64),
        "stresses": ((t, 3, 3), np.float64),
        "von_mises": ((t,), np.float64),
    }
    for name, (shape, dtype) in expected.items():
        a = getattr(frame, name)
        assert (a.shape, a.dtype) == (shape, dtype), name
    k = len(frame.contact_nodes)
    assert k > 0 and frame.contact_nodes.dtype == np.int64
    assert frame.contact_forces.shape == (k, 3) and frame.contact_pressure.shape == (k,)
    assert (mesh.positions.shape, mesh.tets.shape) == ((n, 3), (t, 4))
    assert mesh.tets.dtype == np.int64 and mesh.tet_region.dtype == np.int32
    assert set(mesh.regions.values()) == {"dermis", "hypodermis"}
    top = mesh.top_vertices
    assert mesh.top_uvs.shape == (len(top), 2)
    assert set(np.unique(mesh.top_triangles)) <= set(top)
    # Off the top surface the stretch is NaN, on it finite.
    on_top = np.zeros(n, bool)
    on_top[top] = True
    assert np.isfinite(frame.surface_stretch[on_top]).all()
    assert np.isnan(frame.surface_stretch[~on_top]).all()
    # Consistency between fields.
    assert np.allclose(frame.displacements, frame.positions - mesh.positions, rtol=0, atol=1e-15)
    assert np.array_equal(frame.principal_strains, frame.principal_stretches - 1.0)
    assert frame.probe_force[2] == frame.metrics["probe_force_z_n"]
    assert np.allclose(frame.contact_forces.sum(axis=0), -frame.probe_force, atol=1e-12)
    vol = frame.region_volumes["dermis"]
    assert math.isclose(vol["change"], vol["deformed_mm3"] / vol["rest_mm3"] - 1.0, rel_tol=1e-12)


def test_a_probe_driven_from_python_follows_the_scenario_path(root):
    # press_small's path: (0, 0, 1.5) at t 0, (0, 0, 1.0) at 0.5 s, (0.5, 0, 1.0) at 1 s.
    scenario = press_small(root)
    keys = [(0.0, (0.0, 0.0, 1.5)), (0.5, (0.0, 0.0, 1.0)), (1.0, (0.5, 0.0, 1.0))]

    def pose(t):
        for (t0, a), (t1, b) in zip(keys, keys[1:]):
            if t <= t1:
                s = (t - t0) / (t1 - t0)
                return tuple(x + s * (y - x) for x, y in zip(a, b))
        return keys[-1][1]

    scripted = list(skinpatch.Run(scenario))
    driven = skinpatch.Run(scenario)
    for frame in scripted:
        mine = driven.step(probe_target=pose(frame.time))
        assert np.allclose(mine.probe_centre, frame.probe_centre, rtol=0, atol=1e-12)
        assert np.abs(mine.positions - frame.positions).max() < 1e-9, frame.index
        assert np.abs(mine.probe_force - frame.probe_force).max() < 1e-9
    with pytest.raises(StopIteration):
        next(driven)


def test_scenario_errors_carry_file_line_and_key(root, tmp_path):
    text = (root / "tests/fixtures/press_small.toml").read_text()
    text = text.replace('"../../meshes/', f'"{root}/meshes/')
    bad = tmp_path / "bad.toml"

    bad.write_text(text.replace("friction = 0.8", "fricton = 0.8"))
    with pytest.raises(skinpatch.ScenarioError) as e:
        skinpatch.Scenario.load(bad)
    line = text.splitlines().index("friction = 0.8") + 1
    assert (e.value.file, e.value.line, e.value.key) == (str(bad), line, "probe.fricton")
    assert "did you mean friction" in str(e.value)

    bad.write_text(text.replace("friction = 0.8", "friction = -0.8"))
    with pytest.raises(skinpatch.ScenarioError) as e:
        skinpatch.Scenario.load(bad)
    assert (e.value.line, e.value.key) == (line, "probe.friction")
    assert f"line {line}" in str(e.value) and "-0.8" in str(e.value)

    # A bad override names its key; its value is in no line of the file.
    with pytest.raises(skinpatch.ScenarioError) as e:
        press_small(root, **{"material.dermis.poisson_ratio": 0.7})
    assert (e.value.line, e.value.key) == (None, "material.dermis.poisson_ratio")
    with pytest.raises(skinpatch.ScenarioError) as e:
        press_small(root, **{"probe.radius_mm": "big"})
    assert e.value.key == "probe.radius_mm"

    with pytest.raises(FileNotFoundError):
        skinpatch.Scenario.load(tmp_path / "missing.toml")
    bad.write_text(text.replace("patch_3k.node", "no_such_mesh.node"))
    with pytest.raises((FileNotFoundError, skinpatch.SkinpatchError)):
        skinpatch.Scenario.load(bad)


def test_numpy_integers_override_integer_keys(root):
    # A numpy.int64 was passed on as the float 2.0, which an integer key
    # refuses ("invalid type: floating point").
    scenario = press_small(root, **{"time.substeps": np.int64(2), "time.duration_s": np.float64(0.5)})
    run = skinpatch.Run(scenario)
    assert run.scenario_frames == 4


def test_overrides_change_the_run(root):
    soft = list(skinpatch.Run(press_small(root)))[3]
    stiff_scenario = press_small(root, **{"material.dermis.youngs_modulus_kpa": 600.0})
    stiff = list(skinpatch.Run(stiff_scenario))[3]
    assert stiff.probe_force[2] > 1.2 * soft.probe_force[2]


def test_ctrl_c_stops_between_frames_and_the_run_goes_on(root):
    # Python's own Ctrl-C handler, even where the test runner was started
    # with SIGINT ignored (a background job of a shell).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        run = skinpatch.Run(press_small(root))
        solved = []
        ctrl_c = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
        with pytest.raises(KeyboardInterrupt):
            ctrl_c.start()
            # An in-memory run steps on past the scenario's end; 0.3 s is
            # some 20 frames.
            while len(solved) < 5000:
                solved.append(run.step().index)
        ctrl_c.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert 1 < len(solved) < 5000
    # The frame being solved when Ctrl-C came finishes (or is never begun).
    assert run.next_frame in (len(solved), len(solved) + 1)
    assert run.step().index == run.next_frame - 1


def test_a_run_moves_between_threads_and_refuses_a_second_caller(root, tmp_path):
    # A run made here and stepped and finished in another thread raised
    # pyo3's PanicException ("Run is unsendable"); it now simply runs there.
    run = skinpatch.Run(press_small(root), outputs=True, output_dir=tmp_path / "out")
    first = run.step()
    seen = {}

    def elsewhere():
        try:
            seen["index"] = run.step().index
            seen["written"] = run.finish()
        except BaseException as e:
            seen["error"] = f"{type(e).__name__}: {e}"

    worker = threading.Thread(target=elsewhere)
    worker.start()
    worker.join()
    assert "error" not in seen, seen["error"]
    assert first.index == 0 and seen["index"] == 1
    assert any(str(p).endswith("metrics.csv") for p in seen["written"])
    # Two threads at once: the second is refused with a RuntimeError, never
    # a panic (whichever thread loses the race).
    run = skinpatch.Run(press_small(root))
    errors = []

    def busy():
        try:
            for _ in range(20):
                run.step()
        except BaseException as e:  # a PanicException is a BaseException
            errors.append(f"{type(e).__name__}: {e}")

    threads = [threading.Thread(target=busy) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(e.startswith("RuntimeError") and "borrowed" in e for e in errors), errors


@pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX only")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # fork with threads
def test_a_child_forked_after_work_raises_instead_of_hanging(root):
    # step() in a child forked after the parent had stepped never returned:
    # the child has none of the worker threads the solve hands work to.
    run = skinpatch.Run(press_small(root))
    run.step()
    pid = os.fork()
    if pid == 0:
        code = 3
        try:
            run.step()
        except RuntimeError as e:
            code = 0 if "forked" in str(e) and "spawn" in str(e) else 4
        except BaseException:
            code = 5
        os._exit(code)
    for _ in range(600):
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.1)
    else:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        pytest.fail("the forked child's step() did not return within 60 s")
    assert os.waitstatus_to_exitcode(status) == 0
    # The parent goes on as before.
    assert run.step().index == 1


def test_an_empty_output_folder_is_refused(root, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "metrics.csv").write_text("mine\n")
    with pytest.raises(skinpatch.ScenarioError, match="output.dir.*is empty"):
        skinpatch.Run(press_small(root), outputs=True, output_dir="")
    assert (tmp_path / "metrics.csv").read_text() == "mine\n"


def test_files_that_are_not_regular_are_refused_not_read(tmp_path):
    # A FIFO blocked Scenario.load and fit forever (their error-message text
    # was read before the checks that refuse it).
    fifo = tmp_path / "scenario.toml"
    os.mkfifo(fifo)
    for call in (lambda: skinpatch.Scenario.load(fifo), lambda: skinpatch.fit(fifo)):
        with pytest.raises(OSError, match="not a regular file"):
            call()


def test_write_vtu_never_replaces_a_link_or_a_pipe(root, tmp_path):
    # Each was replaced by a regular file and reported success.
    mesh = skinpatch.read_mesh(root / "meshes/patch_3k.node")
    target = tmp_path / "target.vtu"
    target.write_bytes(b"kept")
    link = tmp_path / "link.vtu"
    link.symlink_to(target)
    fifo = tmp_path / "fifo.vtu"
    os.mkfifo(fifo)
    for path, what in ((link, "symbolic link"), (fifo, "not a regular file")):
        with pytest.raises(OSError, match=what):
            skinpatch.write_vtu(path, mesh)
    assert link.is_symlink() and target.read_bytes() == b"kept"
    assert fifo.is_fifo()


def test_a_failed_frame_keeps_the_run_at_its_last_good_state(root):
    run = skinpatch.Run(press_small(root))
    run.step()
    with pytest.raises(ValueError):
        run.step(probe_target=(float("nan"), 0.0, 1.0))
    assert run.step().index == 1


def test_a_run_with_outputs_writes_what_the_binary_writes(root, run_binary, tmp_path):
    scenario = press_small(root)
    with skinpatch.Run(scenario, outputs=True, output_dir=tmp_path / "py") as run:
        frames = [f.index for f in run]
    assert frames == list(range(7))
    written = run.finish()
    assert tmp_path / "py" / "metrics.csv" in map(type(tmp_path), written)
    with pytest.raises(skinpatch.SkinpatchError):
        run.step()
    out = run_binary(root / "tests/fixtures/press_small.toml", tmp_path / "bin")

    def rows(path):
        # All but the wall time (the last column).
        return [line.rsplit(",", 1)[0] for line in path.read_text().splitlines()]

    assert rows(tmp_path / "py" / "metrics.csv") == rows(out / "metrics.csv")
    assert (tmp_path / "py" / "volume.csv").read_text() == (out / "volume.csv").read_text()


def test_maps_are_in_micrometres_and_deform_under_the_probe(root):
    scenario = skinpatch.Scenario.load(root / "tests/fixtures/render_small.toml")
    neutral = skinpatch.neutral_map(scenario)
    assert neutral.dtype == np.float32 and neutral.shape == (256, 256)
    assert 1.0 < float(neutral.std()) < 500.0, "heights in µm"
    run = skinpatch.Run(scenario)
    rest = run.step().deformed_map()
    run.step()
    pressed = run.step().deformed_map()  # the probe 0.7 mm down
    assert rest.shape == pressed.shape == neutral.shape
    # At rest the kernel leaves the map as it is (to the filter's rounding).
    assert np.abs(rest - neutral).max() < 1e-3 * np.abs(neutral).max()
    assert np.abs(pressed - neutral).max() > 1e-2 * np.abs(neutral).max()
    with pytest.raises(skinpatch.SkinpatchError):
        list(skinpatch.Run(press_small(root)))[0].deformed_map()


def test_mesh_io_round_trips(root, tmp_path):
    mesh = skinpatch.read_mesh(root / "meshes/patch_3k.node")
    scenario_mesh = press_small(root).mesh
    assert np.array_equal(mesh.positions, scenario_mesh.positions)
    assert np.array_equal(mesh.tets, scenario_mesh.tets)
    j = np.linspace(0.0, 1.0, mesh.num_tets)
    skinpatch.write_vtu(
        tmp_path / "m.vtu",
        mesh,
        point_data={"height": mesh.positions[:, 2], "uvw": mesh.positions},
        cell_data={"j": j, "label": np.arange(mesh.num_tets, dtype=np.int32)},
    )
    again = skinpatch.read_mesh(tmp_path / "m.vtu")
    assert np.array_equal(again.positions, mesh.positions)
    assert np.array_equal(again.tets, mesh.tets)
    assert np.array_equal(again.tet_region, mesh.tet_region)
    with pytest.raises(ValueError, match="point array 'bad'"):
        skinpatch.write_vtu(tmp_path / "x.vtu", mesh, point_data={"bad": j})
    with pytest.raises(skinpatch.MeshError):
        bad = tmp_path / "bad.vtu"
        bad.write_text("<VTKFile>")
        skinpatch.read_mesh(bad)


def test_fit_finds_the_kernel_the_example_maps_were_made_with(root, tmp_path):
    """`skinpatch.fit` is `skinpatch fit`: the shipped samples, made with the
    forehead kernel at r = 1.15 and 0.85, give that kernel back (the values
    examples/fit/samples.toml states) and the same kernel file as the binary."""
    import shutil
    import subprocess

    from conftest import binary

    for name in ["neutral.png", "stretched_115.png", "compressed_085.png"]:
        shutil.copy(root / "examples/fit" / name, tmp_path / name)
    text = (root / "examples/fit/samples.toml").read_text()
    text = text.replace('output = "../../out/fit/kernel.toml"', 'output = "kernel.toml"')
    (tmp_path / "samples.toml").write_text(text)
    report = skinpatch.fit(tmp_path / "samples.toml")
    rows = report["rows"]
    assert [(r["r"], r["axis"]) for r in rows] == [(1.15, "u"), (0.85, "u")]
    assert abs(rows[0]["alpha"] - 0.463) <= 0.011 and abs(rows[0]["sigma_um"] - 17.43) <= 0.51
    assert abs(rows[1]["alpha"] + 0.710) <= 0.011 and abs(rows[1]["sigma_um"] - 13.03) <= 0.51
    assert report["model"]["alpha"][0] != report["model"]["alpha"][-1]
    written = pathlib.Path(report["written"])
    python_kernel = written.read_text()
    subprocess.run([str(binary()), "fit", str(tmp_path / "samples.toml")], check=True,
                   capture_output=True)
    assert written.read_text() == python_kernel, "the binary writes the same kernel file"


def test_fit_errors_name_the_key(tmp_path):
    (tmp_path / "samples.toml").write_text("[[point]]\nr = 50.0\nalpha = 0.1\nsigma_um = 3.0\n")
    with pytest.raises(skinpatch.ScenarioError) as e:
        skinpatch.fit(tmp_path / "samples.toml")
    assert e.value.key == "point[0].r", e.value
    with pytest.raises(FileNotFoundError):
        skinpatch.fit(tmp_path / "missing.toml")
