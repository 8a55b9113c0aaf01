//! The newer input doors (glTF/OBJ surfaces, synth, fit, tiles, viewer
//! scripts) under bad input: each case once crashed, ran without bound or
//! overwrote an input, and now fails with an error that names the file and
//! the element.

use crate::surface::{read_error, temp, tiny_gltf, write};

/// Malformed glTF documents that the `gltf` crate's readers would panic or
/// recurse on are refused up front, naming the accessor, view or node.
#[test]
fn malformed_gltf_is_refused_by_name_not_by_panic() {
    let dir = temp("gltf_doors");
    let good = tiny_gltf(1, 2, true, 0.0);
    // Accessors: 0 POSITION, 1 TEXCOORD_0, 2 morph delta, 3 key times,
    // 4 morph weights.
    let cases: Vec<(&str, String, &[&str])> = vec![
        (
            "float_indices",
            good.replacen("\"targets\":[", "\"indices\":3,\"targets\":[", 1),
            &["indices is accessor 3", "Scalar F32", "U32"],
        ),
        (
            "position_99",
            good.replacen("\"POSITION\":0", "\"POSITION\":99", 1),
            &["mesh 0 primitive 0", "POSITION is accessor 99", "has 5"],
        ),
        (
            "position_vec2",
            good.replacen("\"POSITION\":0", "\"POSITION\":1", 1),
            &["POSITION is accessor 1 of Vec2 F32", "Vec3"],
        ),
        (
            "missing_target_node",
            good.replacen("\"target\":{\"node\":0", "\"target\":{\"node\":7", 1),
            &["animation 0 channel 0", "target node 7", "has 1"],
        ),
        (
            "own_child",
            good.replacen(
                "{\"name\":\"Face\",\"mesh\":0}",
                "{\"name\":\"Face\",\"mesh\":0,\"children\":[0]}",
                1,
            ),
            &["node 0 lists itself as a child"],
        ),
        (
            "overrun",
            good.replacen("\"count\":3,", "\"count\":3000,", 1),
            &["accessor 0", "3000 elements", "overrun its buffer view 0"],
        ),
        (
            "view_outside_buffer",
            good.replacen("\"byteOffset\":0,", "\"byteOffset\":4000000,", 1),
            &["buffer view 0 spans bytes 4000000"],
        ),
    ];
    for (name, text, wanted) in cases {
        assert_ne!(text, good, "{name}: the mutation applies");
        let file = format!("{name}.gltf");
        let e = read_error(&write(&dir, &file, &text), None);
        assert!(e.contains(&file), "{name}: {e}");
        for w in wanted {
            assert!(e.contains(w), "{name}: {e} lacks {w:?}");
        }
    }
    // Two nodes that are each other's child.
    let cycle = good.replacen(
        "\"nodes\":[{\"name\":\"Face\",\"mesh\":0}]",
        "\"nodes\":[{\"name\":\"Face\",\"mesh\":0,\"children\":[1]},{\"name\":\"B\",\"children\":[0]}]",
        1,
    );
    assert_ne!(cycle, good);
    let e = read_error(&write(&dir, "cycle.gltf", &cycle), None);
    assert!(
        e.contains("cycle.gltf") && e.contains("own ancestor"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// External buffers are read for their declared length only, and only
/// from regular files: a device such as /dev/zero is refused instead of
/// read without end.
#[test]
fn gltf_buffers_are_read_for_their_declared_length() {
    let dir = temp("gltf_buffers");
    let good = tiny_gltf(1, 2, true, 0.0);
    let start = good.find("data:application").unwrap();
    let end = start + good[start..].find('"').unwrap();
    let uri = &good[start..end];
    use base64::Engine;
    let mut bin = base64::engine::general_purpose::STANDARD
        .decode(uri.split_once(";base64,").unwrap().1)
        .unwrap();
    // A file longer than declared: the tail is never read.
    bin.extend(std::iter::repeat_n(0xAB, 1 << 20));
    std::fs::write(dir.join("data.bin"), &bin).unwrap();
    let external = good.replacen(uri, "data.bin", 1);
    let path = write(&dir, "external.gltf", &external);
    let options = skinpatch::surface::ReadOptions {
        frame_rate_hz: 4.0,
        ..Default::default()
    };
    let s = skinpatch::surface::AnimatedSurface::read(&path, &options).unwrap();
    assert_eq!(s.num_frames(), 5);
    if std::path::Path::new("/dev/zero").exists() {
        let zero = good.replacen(uri, "/dev/zero", 1);
        let e = read_error(&write(&dir, "zero.gltf", &zero), None);
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
        #[cfg(unix)]
        {
            let link = dir.join("device.gltf");
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let e = read_error(&link, None);
            assert!(
                e.contains("device.gltf") && e.contains("not a regular file"),
                "{e}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A PNG whose header claims a million texels a side (a hundred bytes on
/// disk) is refused before anything is allocated, naming the size.
#[test]
fn a_map_header_claiming_terabytes_is_refused_before_allocating() {
    let dir = temp("huge_png");
    let chunk = |kind: &[u8], data: &[u8]| -> Vec<u8> {
        let mut c = (data.len() as u32).to_be_bytes().to_vec();
        let body: Vec<u8> = kind.iter().chain(data).copied().collect();
        c.extend(&body);
        c.extend(crc32(&body).to_be_bytes());
        c
    };
    let side: u32 = 1_000_000;
    let mut ihdr = side.to_be_bytes().to_vec();
    ihdr.extend(side.to_be_bytes());
    ihdr.extend([16, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(chunk(b"IHDR", &ihdr));
    png.extend(chunk(
        b"IDAT",
        &[0x78, 0x01, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    ));
    png.extend(chunk(b"IEND", &[]));
    let path = dir.join("huge.png");
    std::fs::write(&path, png).unwrap();
    let defaults = skinpatch::micro::io::MapDefaults {
        texel: skinpatch::micro::io::TexelSize::Um(10.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    let e = skinpatch::micro::io::read_map(&path, &defaults)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("huge.png") && e.contains("claims 1000000 × 1000000 texels"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// CRC-32 (the PNG chunk checksum), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

use crate::common::skinpatch;

/// `tiles join` of an index claiming a billion texels a side, and `bench
/// micro` at a side of 10⁸, are refused with a message instead of aborting
/// on an allocation (exit 134).
#[test]
fn sizes_beyond_memory_are_refused_before_allocating() {
    use skinpatch::micro::tiled::TiledMap;
    use skinpatch::micro::{DisplacementMap, Edge};
    let dir = tempfile::tempdir().unwrap();
    let map = DisplacementMap::from_fn(8, 8, 10.0, Edge::Wrap, |i, j| (i + j) as f32);
    let folder = dir.path().join("map.tiles");
    TiledMap::write(&folder, &map, 4).unwrap();
    let index = folder.join("index.toml");
    let text = std::fs::read_to_string(&index).unwrap();
    let huge = text.replacen("width = 8", "width = 1000000000", 1);
    assert_ne!(huge, text);
    std::fs::write(&index, huge).unwrap();
    let out = dir.path().join("joined.exr");
    let o = skinpatch(&[
        "tiles",
        "join",
        folder.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("index.toml") && e.contains("1000000000 × 8") && e.contains("at most"),
        "{e}"
    );
    assert!(!out.exists());
    let o = skinpatch(&[
        "bench",
        "micro",
        "--scenario",
        "tests/fixtures/render_small.toml",
        "--sizes",
        "64,99999999",
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("--sizes") && e.contains("99999999"), "{e}");
}

/// Sampling the forehead's 2 s animation at 10⁹ Hz would hold two billion
/// frames: refused up front with the count, not sampled until memory runs
/// out.
#[test]
fn a_sampling_rate_beyond_memory_is_refused_up_front() {
    let glb = crate::common::root().join("examples/surfaces/forehead.glb");
    let options = skinpatch::surface::ReadOptions {
        frame_rate_hz: 1e9,
        ..Default::default()
    };
    let start = std::time::Instant::now();
    let e = skinpatch::surface::AnimatedSurface::read(&glb, &options)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("forehead.glb") && e.contains("frames of") && e.contains("frame_rate_hz"),
        "{e}"
    );
    assert!(start.elapsed().as_secs_f64() < 5.0);
}

/// `fit` with its output on its neutral map or on the samples file itself
/// is refused, naming both, and both files stay as they were.
#[test]
fn fit_never_writes_over_its_inputs() {
    use skinpatch::micro::io::write_png16;
    use skinpatch::micro::{DisplacementMap, Edge};
    let dir = tempfile::tempdir().unwrap();
    let neutral = DisplacementMap::from_fn(32, 32, 5.0, Edge::Wrap, |i, j| {
        ((i * 7 + j * 3) % 11) as f32
    });
    let map = dir.path().join("neutral.png");
    write_png16(&map, &neutral).unwrap();
    let before = std::fs::read(&map).unwrap();
    for (output, what) in [
        ("neutral.png", "neutral map"),
        ("samples.toml", "samples file"),
    ] {
        let samples = format!(
            "neutral = \"neutral.png\"\noutput = \"./{output}\"\n\
             [[sample]]\nmap = \"neutral.png\"\nr = 1.0\naxis = \"u\"\n"
        );
        let file = dir.path().join("samples.toml");
        std::fs::write(&file, &samples).unwrap();
        let o = skinpatch(&["fit", file.to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(
            e.contains("output") && e.contains(output) && e.contains(&format!("run's {what}")),
            "{e}"
        );
        assert_eq!(std::fs::read(&map).unwrap(), before);
        assert_eq!(std::fs::read_to_string(&file).unwrap(), samples);
    }
}

/// `synth` run again on its own last result (the exemplar is the output
/// folder's `synthesized.exr`) is refused, naming both, and the result
/// stays as it was.
#[test]
fn synth_never_writes_over_its_inputs() {
    use skinpatch::micro::io::write_exr;
    use skinpatch::micro::{DisplacementMap, Edge};
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("out")).unwrap();
    let earlier = DisplacementMap::from_fn(32, 32, 5.0, Edge::Wrap, |i, j| {
        ((i * 7 + j * 3) % 11) as f32
    });
    let result = dir.path().join("out/synthesized.exr");
    write_exr(&result, &earlier).unwrap();
    let before = std::fs::read(&result).unwrap();
    let file = dir.path().join("again.toml");
    std::fs::write(
        &file,
        format!(
            "[synthesis]\nexemplar = \"out/synthesized.exr\"\nsize_px = 48\n\
             mesostructure_sigma_um = 10.0\n[output]\ndir = {:?}\nformats = [\"exr\"]\n",
            dir.path().join("out")
        ),
    )
    .unwrap();
    let o = skinpatch(&["synth", file.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("again.toml") && e.contains("synthesized.exr") && e.contains("run's exemplar"),
        "{e}"
    );
    assert_eq!(std::fs::read(&result).unwrap(), before);
}

/// `run` reading its mesh from its own output folder (the `mesh.node` an
/// earlier run wrote with `mesh_tetgen`) is refused before the folder is
/// touched, naming the key and both files; the mesh stays as it was.
#[test]
fn run_never_clears_its_own_mesh_input() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    for ext in ["node", "ele"] {
        std::fs::copy(
            crate::common::root().join(format!("meshes/patch_3k.{ext}")),
            out.join(format!("mesh.{ext}")),
        )
        .unwrap();
    }
    let before = std::fs::read(out.join("mesh.ele")).unwrap();
    let fixture = crate::common::root().join("tests/fixtures/press_small.toml");
    let text = std::fs::read_to_string(&fixture)
        .unwrap()
        .replace("../../meshes/patch_3k.node", "out/mesh.node");
    let file = dir.path().join("again.toml");
    std::fs::write(&file, text).unwrap();
    let o = skinpatch(&["run", file.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("mesh.file") && e.contains("mesh.node") && e.contains("output.dir"),
        "{e}"
    );
    assert_eq!(std::fs::read(out.join("mesh.ele")).unwrap(), before);
    assert!(!out.join("metrics.csv").exists());
    // Elsewhere, the same mesh runs.
    let o = skinpatch(&[
        "run",
        file.to_str().unwrap(),
        "-o",
        dir.path().join("other").to_str().unwrap(),
        "--set",
        "time.duration_s=0.2",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Any input inside the output folder under a name the run writes is
/// refused before the folder is touched: a neutral map that is an earlier
/// run's frame 0 (it was replaced by this run's frame 0) and the scenario
/// file itself named `metrics.csv` (it was overwritten).
#[test]
fn run_never_clears_any_input() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(out.join("micro")).unwrap();
    let map = out.join("micro/height_0000.png");
    std::fs::copy(crate::common::root().join("examples/fit/neutral.png"), &map).unwrap();
    let before = std::fs::read(&map).unwrap();
    let mesh = crate::common::root().join("meshes/patch_3k.node");
    let text = format!(
        "[mesh]\nfile = {:?}\n[time]\nduration_s = 0.1\nframe_rate_hz = 10\n",
        mesh.to_str().unwrap()
    );
    let with_map = dir.path().join("with_map.toml");
    std::fs::write(
        &with_map,
        format!("{text}[microstructure]\nmap = \"out/micro/height_0000.png\"\n"),
    )
    .unwrap();
    let own = out.join("metrics.csv");
    std::fs::write(&own, &text).unwrap();
    for (file, key, kept) in [
        (&with_map, "microstructure.map", &map),
        (&own, "scenario file", &own),
    ] {
        let kept_before = std::fs::read(kept).unwrap();
        let o = skinpatch(&["run", file.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(e.contains(key) && e.contains("output.dir"), "{e}");
        assert_eq!(std::fs::read(kept).unwrap(), kept_before);
    }
    assert_eq!(std::fs::read(&map).unwrap(), before);
    assert!(!out.join("volume.csv").exists());
}

/// An override that spans lines (whose later lines were dropped without a
/// word) and `--output` beside `--set output.dir` (one of which was
/// ignored) are refused, for `run` and `synth` alike.
#[test]
fn overrides_that_would_be_dropped_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    for command in [
        vec!["run", "tests/fixtures/press_small.toml"],
        vec!["synth", "examples/synth.toml"],
    ] {
        let mut args = command.clone();
        args.extend([
            "-o",
            out,
            "--set",
            "probe.radius_mm=1.0\nprobe.friction=5.0",
        ]);
        let o = skinpatch(&args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{command:?}: {e}");
        assert!(e.contains("spans lines"), "{command:?}: {e}");
        let mut args = command.clone();
        args.extend(["-o", out, "--set", "output.dir=\"elsewhere\""]);
        let o = skinpatch(&args);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{command:?}: {e}");
        assert!(
            e.contains("--output") && e.contains("output.dir") && e.contains("give one"),
            "{command:?}: {e}"
        );
        assert!(!std::path::Path::new(out).exists());
    }
}

/// `fit` refuses points outside the model's ranges and maps too small for
/// a histogram, naming the key.
#[test]
fn fit_refuses_points_out_of_range_and_tiny_maps() {
    use skinpatch::micro::io::write_png16;
    use skinpatch::micro::{DisplacementMap, Edge};
    let dir = tempfile::tempdir().unwrap();
    let points = "[[point]]\nr = 0.8\nalpha = -1.0\nsigma_um = 8.0\n\
                  [[point]]\nr = 1.2\nalpha = 0.5\nsigma_um = 18.0\n";
    let tiny = DisplacementMap::from_fn(1, 1, 5.0, Edge::Wrap, |_, _| 1.0);
    write_png16(&dir.path().join("tiny.png"), &tiny).unwrap();
    for (extra, wanted) in [
        (
            "[[point]]\nr = 1.1\nalpha = 0.2\nsigma_um = -3.0\n",
            "point[2].sigma_um must be > 0, got -3",
        ),
        (
            "[[point]]\nr = 1.1\nalpha = 5.0\nsigma_um = 3.0\n",
            "point[2].alpha must be in [-2, 1], got 5",
        ),
        (
            "neutral = \"tiny.png\"\n[[sample]]\nmap = \"tiny.png\"\nr = 1.0\naxis = \"u\"\n",
            "neutral tiny.png is 1 × 1 texels",
        ),
    ] {
        // Top-level keys first, then the tables.
        let text = if extra.starts_with("neutral") {
            format!("{extra}{points}")
        } else {
            format!("{points}{extra}")
        };
        let file = dir.path().join("samples.toml");
        std::fs::write(&file, text).unwrap();
        let o = skinpatch(&["fit", file.to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(e.contains(wanted), "{e}");
    }
}

/// A render run refused for lack of a GPU (the Vulkan driver hidden)
/// leaves no folder behind, not empty `render/<mode>` folders.
#[test]
fn a_render_refused_for_lack_of_a_gpu_leaves_no_folders() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = crate::common::binary()
        .current_dir(crate::common::root())
        .args(["run", "-q", "tests/fixtures/render_small.toml", "-o"])
        .arg(&out)
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("WGPU_BACKEND", "vulkan")
        .env_remove("SKINPATCH_REQUIRE_GPU")
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    if o.status.success() {
        // Some adapter was found without the Vulkan driver: nothing to check.
        return;
    }
    assert!(e.contains("[render] needs a GPU adapter"), "{e}");
    // The error itself says why, quiet run or not: the manifest the
    // variable names does not exist, or (without a loader) what to install.
    assert!(
        e.contains("these manifests do not exist: icd.json") || e.contains("apt-get install"),
        "{e}"
    );
    assert!(!out.exists(), "{e}");
}

/// `skinpatch mesh --renumber --out BASE` onto the mesh it reads, and
/// `tiles split` into the folder of the map it splits, are refused before
/// anything is written (the first replaced the mesh with its renumbered
/// copy; the second could write a tile over its input).
#[test]
fn mesh_and_tiles_never_write_over_their_input() {
    use crate::common::{root, skinpatch, text};
    let dir = tempfile::tempdir().unwrap();
    let p = |path: &std::path::Path| path.to_str().unwrap().to_string();
    let base = dir.path().join("patch");
    for ext in ["node", "ele", "face"] {
        std::fs::copy(
            root().join(format!("meshes/patch_3k.{ext}")),
            base.with_extension(ext),
        )
        .unwrap();
    }
    let before: Vec<Vec<u8>> = ["node", "ele", "face"]
        .iter()
        .map(|e| std::fs::read(base.with_extension(e)).unwrap())
        .collect();
    let node = base.with_extension("node");
    let renumber = |out: &std::path::Path| {
        skinpatch(&["mesh", "--input", &p(&node), "--renumber", "--out", &p(out)])
    };
    let o = renumber(&base);
    let e = text(&o.stderr);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains(&format!("--out {}", p(&base)))
            && e.contains("patch.node, which is the --input mesh"),
        "{e}"
    );
    for (k, ext) in ["node", "ele", "face"].iter().enumerate() {
        assert_eq!(
            std::fs::read(base.with_extension(ext)).unwrap(),
            before[k],
            "{ext}"
        );
    }
    assert!(!dir.path().join("patch.vtu").exists());
    // Another base beside it is fine.
    let o = renumber(&dir.path().join("renumbered"));
    assert!(o.status.success(), "{}", text(&o.stderr));

    let map = dir.path().join("map.png");
    std::fs::copy(root().join("examples/fit/neutral.png"), &map).unwrap();
    let before = std::fs::read(&map).unwrap();
    let o = skinpatch(&[
        "tiles",
        "split",
        &p(&map),
        "-o",
        &p(dir.path()),
        "--tile",
        "16",
        "--texel-um",
        "10",
    ]);
    let e = text(&o.stderr);
    assert!(
        !o.status.success() && e.contains("is the folder of the input map"),
        "{e}"
    );
    assert_eq!(std::fs::read(&map).unwrap(), before);
    assert!(!dir.path().join("index.toml").exists());
}
