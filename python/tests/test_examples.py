"""examples/python/: the force–depth curve, the modulus sweep and the
Blender loader's bpy-free part, on the small fixtures."""

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def example(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples/python" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def has_matplotlib():
    return importlib.util.find_spec("matplotlib") is not None


def test_force_depth_curve_of_the_press(tmp_path, capsys):
    out = tmp_path / "curve.png"
    curve = example("force_depth").main(
        [str(ROOT / "tests/fixtures/press_small.toml"), "--out", str(out)]
    )
    # press_small presses 0.5 mm in frames 0–3, then drags.
    depths = [d for d, _ in curve]
    assert len(curve) == 4 and depths[0] == 0.0 and depths[-1] == pytest.approx(0.5)
    forces = [f for _, f in curve]
    assert forces[0] == 0.0 and all(b > a for a, b in zip(forces, forces[1:])), forces
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == "depth_mm,force_n" and len(printed) == 5
    assert out.exists() == has_matplotlib()


def test_the_modulus_sweep_stiffens_the_press(tmp_path):
    rows = example("sweep").main(
        [
            str(ROOT / "tests/fixtures/press_small.toml"),
            "--kpa", "75", "300",
            "--frames", "4",
            "--out", str(tmp_path / "sweep.png"),
        ]
    )
    (soft, soft_peak, *_), (stiff, stiff_peak, *_) = rows
    assert (soft, stiff) == (75.0, 300.0)
    assert stiff_peak > 1.5 * soft_peak > 0.0
    assert all(r[2] >= 1.0 >= r[3] and 0.0 < r[4] <= 1.0 for r in rows)


def test_the_blender_loader_finds_a_runs_surface_and_maps(tmp_path, run_binary):
    out = run_binary(
        ROOT / "tests/fixtures/render_small.toml",
        tmp_path / "run",
        'microstructure.formats=["png16"]',
        "output.surface_glb=true",
        'render.modes=["dynamic"]',
    )
    loader = example("blender_load")
    plan = loader.main([str(out)])
    assert plan["surface_glb"] == out / "surface.glb"
    assert (plan["frames"], plan["frame_rate_hz"]) == (3, 2.0)
    assert [f for f, _ in plan["maps"]] == [0, 1, 2]
    span_mm, midlevel = plan["displacement"]
    meta = loader.png_text(plan["neutral_map"])
    scale = float(meta["skinpatch:height_scale"])
    unit = float(meta.get("skinpatch:height_unit_um", "1"))
    assert span_mm == pytest.approx(scale * 65535 * unit / 1000)
    # Height 0 lies inside the stored range.
    assert 0.0 < midlevel < 1.0
    with pytest.raises(FileNotFoundError, match="summary.json"):
        loader.collect(tmp_path)
