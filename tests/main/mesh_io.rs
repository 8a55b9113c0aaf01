//! Mesh files: TetGen round trips, the Gmsh fixture, VTU read-back, and the
//! shipped meshes.

use crate::common;

use common::{cube_tetgen, root, small_patch, write_tetgen_text};
use skinpatch::mesh::generate::generate;
use skinpatch::mesh::io::{self, Values};
use skinpatch::mesh::quality::max_edge_within;
use skinpatch::mesh::{markers, TetMesh, Vec3};
use skinpatch::scenario::Scenario;

fn same_mesh(a: &TetMesh, b: &TetMesh) {
    assert_eq!(a.positions.len(), b.positions.len());
    for (p, q) in a.positions.iter().zip(&b.positions) {
        for k in 0..3 {
            assert_eq!(p[k].to_bits(), q[k].to_bits());
        }
    }
    assert_eq!(a.tets, b.tets);
    assert_eq!(a.tet_region, b.tet_region);
    assert_eq!(a.regions, b.regions);
    assert_eq!(a.boundary, b.boundary);
    assert_eq!(a.top.vertices, b.top.vertices);
    assert_eq!(a.top.uvs, b.top.uvs);
}

#[test]
fn tetgen_round_trip_is_exact() {
    let mesh = generate(&small_patch(Some(common::deep_zone()))).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().join("patch");
    io::write_tetgen(&mesh, &base).unwrap();
    let back = io::read_tetgen(&base).unwrap();
    same_mesh(&mesh, &back);
    // Reading by any of the file names gives the same mesh.
    let by_ele = io::read_mesh(&dir.path().join("patch.ele")).unwrap();
    same_mesh(&mesh, &by_ele);
}

#[test]
fn tetgen_reader_handles_comments_one_based_and_markers() {
    let dir = tempfile::tempdir().unwrap();
    let (node, ele) = cube_tetgen();
    let node = node.replace("3 0 0\n", "3 0 0   # header comment\n\n");
    let base = write_tetgen_text(dir.path(), "cube", &node, &ele);
    std::fs::write(
        dir.path().join("cube.face"),
        "# top of the cube, split in two\n2 1\n1 5 6 7 2\n2 5 7 8 2\n",
    )
    .unwrap();
    let mesh = io::read_tetgen(&base).unwrap();
    assert_eq!((mesh.num_vertices(), mesh.num_tets()), (8, 6));
    assert!((mesh.total_volume() - 1.0).abs() < 1e-15);
    assert_eq!(mesh.regions.len(), 1);
    assert_eq!(mesh.regions[0].name, "region_5");
    // Two marked top faces, ten unmarked sides; top surface from markers.
    let top: Vec<_> = mesh
        .boundary
        .iter()
        .filter(|f| f.marker == markers::TOP)
        .collect();
    assert_eq!((top.len(), mesh.boundary.len()), (2, 12));
    assert_eq!(mesh.top.triangles.len(), 2);
    assert!((mesh.top.area(&mesh.positions) - 1.0).abs() < 1e-15);
}

#[test]
fn tetgen_negative_orientation_is_flipped_and_attributes_optional() {
    let dir = tempfile::tempdir().unwrap();
    // Zero-based numbering, no attributes, tets listed with negative orientation.
    let node0 = "8 3 0 0\n0 0 0 0\n1 1 0 0\n2 1 1 0\n3 0 1 0\n4 0 0 1\n5 1 0 1\n6 1 1 1\n7 0 1 1\n";
    let ele = "6 4 0\n0 0 1 6 2\n1 0 2 6 3\n2 0 3 6 7\n3 0 7 6 4\n4 0 4 6 5\n5 0 5 6 1\n";
    let base = write_tetgen_text(dir.path(), "cube0", node0, ele);
    let mesh = io::read_tetgen(&base).unwrap();
    assert!((mesh.total_volume() - 1.0).abs() < 1e-15);
    // No markers: the top surface is found geometrically at z = 1.
    assert_eq!(mesh.top.triangles.len(), 2);
    assert_eq!(mesh.regions[0].id, 1);
}

#[test]
fn gmsh_fixture_reads_with_counts_and_regions() {
    let path = root().join("tests/fixtures/two_layer_box.msh");
    let mesh = io::read_mesh(&path).unwrap();
    // Counts recorded when the fixture was made (see tests/fixtures/README.md).
    let expected = fixture_counts();
    assert_eq!(mesh.num_vertices(), expected.0);
    assert_eq!(mesh.num_tets(), expected.1);
    let names: Vec<(&str, i32)> = mesh
        .regions
        .iter()
        .map(|r| (r.name.as_str(), r.id))
        .collect();
    assert_eq!(names, vec![("dermis", 1), ("hypodermis", 2)]);
    // 2 × 2 × 1 mm box, top layer 0.3 mm: volumes by region and depth.
    assert!((mesh.total_volume() - 4.0).abs() < 1e-9);
    for t in 0..mesh.num_tets() {
        let z = mesh.tet_centroid(t).z;
        assert_eq!(mesh.tet_region[t], if z > -0.3 { 1 } else { 2 }, "tet {t}");
    }
    mesh.check_closed_manifold().unwrap();
    assert!((mesh.top.area(&mesh.positions) - 4.0).abs() < 1e-9);
}

/// (vertices, tets) of the Gmsh fixture, from its README (counted by meshio).
fn fixture_counts() -> (usize, usize) {
    let text = std::fs::read_to_string(root().join("tests/fixtures/README.md")).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("two_layer_box.msh:"))
        .unwrap();
    let nums: Vec<usize> = line
        .split(|c: char| !c.is_ascii_digit())
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    (nums[0], nums[1])
}

#[test]
fn vtu_reads_back_with_same_counts_and_data() {
    let mesh = generate(&small_patch(None)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.vtu");
    let grid = io::Grid::from_mesh(&mesh);
    io::write_vtu(&path, &grid).unwrap();
    let back = io::read_vtu(&path).unwrap();
    assert_eq!(back.points.len(), mesh.num_vertices());
    assert_eq!(back.tets, mesh.tets);
    assert_eq!(back.points, mesh.positions);
    let region = back.cell_data.iter().find(|f| f.name == "region").unwrap();
    assert_eq!(region.values, Values::I32(mesh.tet_region.clone()));
    // Component names are written for ParaView, not read back.
    let unnamed = |fields: &[io::Field]| -> Vec<io::Field> {
        fields
            .iter()
            .cloned()
            .map(|mut f| {
                f.component_names.clear();
                f
            })
            .collect()
    };
    assert_eq!(back.point_data, unnamed(&grid.point_data));
    assert_eq!(back.cell_data, unnamed(&grid.cell_data));
    let xml = std::fs::read_to_string(&path).unwrap();
    assert!(
        xml.contains(r#"Name="uv" NumberOfComponents="2" ComponentName0="u" ComponentName1="v""#)
    );
}

/// Every storage format reads back: compressed or not, Float64 exactly,
/// Float32 to the nearest f32; compression is lossless and smaller.
#[test]
fn vtu_formats_read_back() {
    let mesh = generate(&small_patch(None)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let grid = io::Grid::from_mesh(&mesh);
    let mut sizes = Vec::new();
    for compress in [true, false] {
        for f32 in [false, true] {
            let path = dir.path().join(format!("m_{compress}_{f32}.vtu"));
            io::write_vtu_as(&path, &grid, io::VtuFormat { compress, f32 }).unwrap();
            sizes.push(std::fs::metadata(&path).unwrap().len());
            let back = io::read_vtu(&path).unwrap();
            assert_eq!(back.tets, mesh.tets);
            let round = |v: f64| if f32 { v as f32 as f64 } else { v };
            for (b, p) in back.points.iter().zip(&mesh.positions) {
                assert_eq!(*b, p.map(round), "compress {compress}, f32 {f32}");
            }
            let volume = back
                .cell_data
                .iter()
                .find(|f| f.name == "volume_mm3")
                .unwrap();
            let Values::F64(v) = &volume.values else {
                panic!("float volumes")
            };
            assert!(v
                .iter()
                .zip(0..)
                .all(|(&x, t)| x == round(mesh.tet_volume(t))));
            let region = back.cell_data.iter().find(|f| f.name == "region").unwrap();
            assert_eq!(region.values, Values::I32(mesh.tet_region.clone()));
        }
    }
    // [zlib f64, zlib f32, none f64, none f32]
    assert!(
        sizes[0] < sizes[2] && sizes[1] < sizes[3] && sizes[3] < sizes[2],
        "{sizes:?}"
    );
}

#[test]
fn vtu_rejects_mismatched_arrays() {
    let mesh = generate(&small_patch(None)).unwrap();
    let mut grid = io::Grid::from_mesh(&mesh);
    grid.cell_data
        .push(io::Field::f64("short", 1, vec![1.0; 3]));
    let dir = tempfile::tempdir().unwrap();
    let err = io::write_vtu(&dir.path().join("x.vtu"), &grid)
        .unwrap_err()
        .to_string();
    assert!(err.contains("cell array 'short' has 3 values"), "{err}");
    assert!(!dir.path().join("x.vtu").exists());
}

/// The shipped meshes are what their inputs generate, bit for bit.
fn regenerates(name: &str) -> TetMesh {
    let shipped = io::read_tetgen(&root().join("meshes").join(name)).unwrap();
    let scenario = Scenario::load(&root().join(format!("meshes/{name}.toml"))).unwrap();
    let regenerated = generate(&scenario.mesh.patch_spec().unwrap()).unwrap();
    same_mesh(&shipped, &regenerated);
    shipped
}

#[test]
fn shipped_patch_3k() {
    let mesh = regenerates("patch_3k");
    let n = mesh.num_tets();
    assert!((2700..=3300).contains(&n), "{n} tets");
    assert!((mesh.total_volume() - 500.0).abs() < 500.0 * 1e-9);
}

#[test]
fn shipped_patch_25k() {
    let mesh = regenerates("patch_25k");
    let n = mesh.num_tets();
    assert!(
        (22_500..=27_500).contains(&n),
        "{n} tets, want 25,000 ± 10%"
    );
    let (lo, hi) = mesh.bounds();
    assert_eq!(
        (lo.x, lo.y, lo.z, hi.x, hi.y, hi.z),
        (-5.0, -5.0, -5.0, 5.0, 5.0, 0.0)
    );
    // Refined under the centre: tets near the top centre are smaller than at the rim.
    let (centre_edge, _) = max_edge_within(&mesh, &Vec3::zeros(), 1.0);
    let (rim_edge, _) = max_edge_within(&mesh, &Vec3::new(4.5, 4.5, 0.0), 1.0);
    assert!(
        centre_edge < 0.6 * rim_edge,
        "centre {centre_edge} rim {rim_edge}"
    );
}

#[test]
fn shipped_hertz_block() {
    let mesh = io::read_tetgen(&root().join("meshes/hertz_block")).unwrap();
    let (lo, hi) = mesh.bounds();
    assert!(hi.x - lo.x >= 40.0 && hi.y - lo.y >= 40.0 && hi.z - lo.z >= 20.0);
    assert_eq!(hi.z, 0.0);
    // Edges ≤ 0.115 mm within 0.7 mm of the top centre …
    let (near, count) = max_edge_within(&mesh, &Vec3::zeros(), 0.7);
    assert!(near <= 0.115, "longest edge near the centre {near}");
    assert!(count > 1000);
    // … graded coarser outward.
    let (mid, _) = max_edge_within(&mesh, &Vec3::new(5.0, 0.0, 0.0), 2.0);
    let (far, _) = max_edge_within(&mesh, &Vec3::new(15.0, 15.0, -10.0), 4.0);
    assert!(near < mid && mid < far, "{near} < {mid} < {far}");
    assert!((mesh.total_volume() - 32_000.0).abs() < 32_000.0 * 1e-9);
}

/// A mesh as a sorted list of (region, the tet's corner coordinates as
/// bits, sorted): equal for two files that hold the same tets whatever the
/// order of their nodes, tets and corners.
fn canonical(mesh: &TetMesh) -> Vec<(i32, [[u64; 3]; 4])> {
    let mut out: Vec<(i32, [[u64; 3]; 4])> = (0..mesh.num_tets())
        .map(|t| {
            let mut corners: [[u64; 3]; 4] = std::array::from_fn(|i| {
                let p = mesh.positions[mesh.tets[t][i]];
                [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
            });
            corners.sort_unstable();
            (mesh.tet_region[t], corners)
        })
        .collect();
    out.sort_unstable();
    out
}

/// The Gmsh fixture written as MSH 4.1 or 2.2, text or binary, in either
/// byte order, by a writer kept here as the reference for the layouts of
/// the Gmsh file-format documentation: one volume entity per region.
pub(crate) fn encode_msh(mesh: &TetMesh, v41: bool, binary: bool, big_endian: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let int = |out: &mut Vec<u8>, v: i32| {
        if binary {
            out.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        } else {
            out.extend(format!("{v} ").bytes());
        }
    };
    let size = |out: &mut Vec<u8>, v: usize| {
        let v = v as u64;
        if binary {
            out.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        } else {
            out.extend(format!("{v} ").bytes());
        }
    };
    let real = |out: &mut Vec<u8>, v: f64| {
        if binary {
            out.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        } else {
            out.extend(format!("{v:e} ").bytes());
        }
    };
    let newline = |out: &mut Vec<u8>| {
        if !binary {
            out.push(b'\n')
        }
    };
    let version = if v41 { "4.1" } else { "2.2" };
    out.extend(format!("$MeshFormat\n{version} {} 8\n", u8::from(binary)).bytes());
    if binary {
        int(&mut out, 1);
        out.push(b'\n');
    }
    out.extend(b"$EndMeshFormat\n$PhysicalNames\n");
    out.extend(format!("{}\n", mesh.regions.len()).bytes());
    for r in &mesh.regions {
        out.extend(format!("3 {} \"{}\"\n", r.id, r.name).bytes());
    }
    out.extend(b"$EndPhysicalNames\n");
    // Node tags 10, 20, …: sparse, as Gmsh allows.
    let tag = |v: usize| 10 * (v + 1);
    if v41 {
        out.extend(b"$Entities\n");
        for n in [0, 0, 0, mesh.regions.len()] {
            size(&mut out, n);
        }
        newline(&mut out);
        for (k, r) in mesh.regions.iter().enumerate() {
            int(&mut out, k as i32 + 1);
            (0..6).for_each(|_| real(&mut out, 0.0));
            size(&mut out, 1);
            int(&mut out, r.id);
            size(&mut out, 0);
            newline(&mut out);
        }
        out.extend(b"$EndEntities\n$Nodes\n");
        let n = mesh.num_vertices();
        for v in [1, n, tag(0), tag(n - 1)] {
            size(&mut out, v);
        }
        newline(&mut out);
        for v in [3, 1, 0] {
            int(&mut out, v);
        }
        size(&mut out, n);
        newline(&mut out);
        for v in 0..n {
            size(&mut out, tag(v));
            newline(&mut out);
        }
        for p in &mesh.positions {
            (0..3).for_each(|k| real(&mut out, p[k]));
            newline(&mut out);
        }
        out.extend(b"$EndNodes\n$Elements\n");
        let t = mesh.num_tets();
        for v in [mesh.regions.len(), t, 1, t] {
            size(&mut out, v);
        }
        newline(&mut out);
        for (k, r) in mesh.regions.iter().enumerate() {
            let tets: Vec<usize> = (0..t).filter(|&i| mesh.tet_region[i] == r.id).collect();
            for v in [3, k as i32 + 1, 4] {
                int(&mut out, v);
            }
            size(&mut out, tets.len());
            newline(&mut out);
            for i in tets {
                size(&mut out, i + 1);
                mesh.tets[i].iter().for_each(|&v| size(&mut out, tag(v)));
                newline(&mut out);
            }
        }
    } else {
        out.extend(format!("$Nodes\n{}\n", mesh.num_vertices()).bytes());
        for (v, p) in mesh.positions.iter().enumerate() {
            int(&mut out, tag(v) as i32);
            (0..3).for_each(|k| real(&mut out, p[k]));
            newline(&mut out);
        }
        // A point element first (skipped), then the tets, in binary as
        // one block of like elements.
        let t = mesh.num_tets();
        out.extend(format!("$EndNodes\n$Elements\n{}\n", t + 1).bytes());
        for v in if binary {
            vec![15, 1, 2]
        } else {
            vec![1, 15, 2]
        } {
            int(&mut out, v);
        }
        if binary {
            int(&mut out, 1);
        }
        for v in [0, 0, tag(0) as i32] {
            int(&mut out, v);
        }
        newline(&mut out);
        if binary {
            for v in [4, t as i32, 2] {
                int(&mut out, v);
            }
        }
        for i in 0..t {
            if !binary {
                for v in [i as i32 + 2, 4, 2] {
                    int(&mut out, v);
                }
            } else {
                int(&mut out, i as i32 + 2);
            }
            int(&mut out, mesh.tet_region[i]);
            int(&mut out, 100 + mesh.tet_region[i]);
            mesh.tets[i]
                .iter()
                .for_each(|&v| int(&mut out, tag(v) as i32));
            newline(&mut out);
        }
    }
    out.extend(b"\n$EndElements\n");
    out
}

/// Every Gmsh layout reads to the same tets, regions and names as the text
/// 4.1 fixture: 4.1 and 2.2, text and binary, little- and big-endian.
#[test]
fn gmsh_layouts_read_the_same_mesh() {
    let fixture = io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let expected = canonical(&fixture);
    let dir = tempfile::tempdir().unwrap();
    for (v41, binary, big_endian) in [
        (true, false, false),
        (true, true, false),
        (true, true, true),
        (false, false, false),
        (false, true, false),
        (false, true, true),
    ] {
        let path = dir.path().join("box.msh");
        std::fs::write(&path, encode_msh(&fixture, v41, binary, big_endian)).unwrap();
        let what = format!("v4.1 {v41}, binary {binary}, big-endian {big_endian}");
        let mesh = io::read_mesh(&path).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert!(canonical(&mesh) == expected, "{what}: other tets");
        assert_eq!(mesh.regions, fixture.regions, "{what}");
    }
}

/// Binary Gmsh errors name the byte where the data stops making sense.
#[test]
fn binary_gmsh_errors_name_the_byte() {
    let fixture = io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("box.msh");
    let bytes = encode_msh(&fixture, true, true, false);
    let cut = bytes.len() / 2;
    std::fs::write(&path, &bytes[..cut]).unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(
        err.contains(&format!(
            "box.msh: byte {cut}: file ends early: expected an element"
        )),
        "{err}"
    );
    // A non-finite coordinate, at its own byte.
    let mut bad = bytes.clone();
    // After "$Nodes\n": the 4-size header, the block's 3 ints and size, its tags.
    let nodes = bytes.windows(7).position(|w| w == b"$Nodes\n").unwrap();
    let first_x = nodes + 7 + 4 * 8 + 3 * 4 + 8 + 8 * fixture.num_vertices();
    bad[first_x..first_x + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    std::fs::write(&path, &bad).unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(
        err.contains(&format!("box.msh: byte {first_x}: x is not finite")),
        "{err}"
    );
    // A second-order tet block.
    let text = std::fs::read_to_string(root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let elements = text.find("$Elements").unwrap();
    let block = text[elements..].find("\n3 ").unwrap() + elements;
    let line_end = text[block + 1..].find('\n').unwrap() + block + 1;
    let header: Vec<&str> = text[block + 1..line_end].split_whitespace().collect();
    let edited = format!(
        "{}\n3 {} 11 {}{}",
        &text[..block],
        header[1],
        header[3],
        &text[line_end..]
    );
    std::fs::write(&path, edited).unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(err.contains("second-order tetrahedra"), "{err}");
}

/// A mesh written as VTU by this project reads back as the same mesh, its
/// region ids from the `region` array and its names `region_<id>`.
#[test]
fn vtu_mesh_input_round_trips() {
    let fixture = io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("box.vtu");
    io::write_vtu(&path, &io::Grid::from_mesh(&fixture)).unwrap();
    let mesh = io::read_mesh(&path).unwrap();
    assert!(canonical(&mesh) == canonical(&fixture));
    let names: Vec<(&str, i32)> = mesh
        .regions
        .iter()
        .map(|r| (r.name.as_str(), r.id))
        .collect();
    assert_eq!(names, vec![("region_1", 1), ("region_2", 2)]);
    assert!((mesh.top.area(&mesh.positions) - 4.0).abs() < 1e-9);
    // Without a region array the grid is one region.
    let mut grid = io::Grid::from_mesh(&fixture);
    grid.cell_data.clear();
    io::write_vtu(&path, &grid).unwrap();
    let mesh = io::read_mesh(&path).unwrap();
    assert_eq!(mesh.tet_region, vec![1; fixture.num_tets()]);
    // A non-integer region id is refused by name.
    let mut grid = io::Grid::from_mesh(&fixture);
    grid.cell_data = vec![io::Field::f64(
        "region",
        1,
        (0..fixture.num_tets()).map(|t| t as f64 + 0.5).collect(),
    )];
    io::write_vtu(&path, &grid).unwrap();
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(
        err.contains("box.vtu") && err.contains("holds 0.5 at cell 0; region ids are integers"),
        "{err}"
    );
}

/// The files meshio writes from the fixture, in every layout users get from
/// it (Gmsh 4.1 binary, its default; 2.2 text and binary; VTU; legacy VTK
/// 5.1 and 4.2, text and binary, with triangles beside the tets), read to
/// the fixture's tets and region ids.
#[test]
fn meshio_outputs_read_as_the_fixture() {
    let fixture = io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap();
    let expected = canonical(&fixture);
    let dir = tempfile::tempdir().unwrap();
    let script = r#"
import sys, meshio, numpy as np
src, out = sys.argv[1], sys.argv[2]
m = meshio.read(src)
tets = np.vstack([c.data for c in m.cells if c.type == "tetra"])
phys = np.concatenate([d for c, d in zip(m.cells, m.cell_data["gmsh:physical"]) if c.type == "tetra"])
# Boundary triangles of the first tets, as meshers keep them.
tri = tets[:10, :3]
mesh = meshio.Mesh(m.points, [("tetra", tets), ("triangle", tri)],
                   cell_data={"gmsh:physical": [phys, np.zeros(len(tri), dtype=int)],
                              "gmsh:geometrical": [phys, np.zeros(len(tri), dtype=int)]},
                   field_data=m.field_data)
meshio.write(out + "/b41.msh", m, file_format="gmsh", binary=True)
meshio.write(out + "/a22.msh", m, file_format="gmsh22", binary=False)
meshio.write(out + "/b22.msh", m, file_format="gmsh22", binary=True)
meshio.write(out + "/m.vtu", mesh)
meshio.write(out + "/m.vtk", mesh, binary=True)
meshio.write(out + "/a.vtk", mesh, binary=False)
meshio.write(out + "/m42.vtk", mesh, file_format="vtk42", binary=True)
print("written")
"#;
    let src = root().join("tests/fixtures/two_layer_box.msh");
    let Some(out) = common::python_check(
        "meshio",
        "SKINPATCH_REQUIRE_MESHIO",
        script,
        &[src.to_str().unwrap(), dir.path().to_str().unwrap()],
    ) else {
        return;
    };
    assert!(out.contains("written"), "{out}");
    for name in [
        "b41.msh", "a22.msh", "b22.msh", "m.vtu", "m.vtk", "a.vtk", "m42.vtk",
    ] {
        let mesh = io::read_mesh(&dir.path().join(name)).unwrap_or_else(|e| panic!("{e}"));
        assert!(canonical(&mesh) == expected, "{name}: other tets");
        if name.ends_with(".msh") {
            assert_eq!(mesh.regions, fixture.regions, "{name}");
        }
    }
}

/// A compressed VTU whose header lies about its binary data — the byte
/// order, the header width, a compressor on plain data, a block table of
/// 1e9 blocks, a block of 2³¹ bytes — once made the reader panic (its
/// slices trusted those sizes). Each is an error naming the file and the
/// array.
#[test]
fn vtu_headers_that_lie_are_errors_not_panics() {
    use base64::Engine;
    let b64 = &base64::engine::general_purpose::STANDARD;
    let mesh = generate(&small_patch(None)).unwrap();
    let grid = io::Grid::from_mesh(&mesh);
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, compress: bool| {
        let path = dir.path().join(name);
        io::write_vtu_as(
            &path,
            &grid,
            io::VtuFormat {
                compress,
                f32: false,
            },
        )
        .unwrap();
        std::fs::read_to_string(&path).unwrap()
    };
    let zlib = write("zlib.vtu", true);
    let plain = write("plain.vtu", false);
    // The first compressed array's header: [blocks, block size, last
    // block size, compressed sizes…] as UInt64, base64 on its own.
    let start = zlib.find("format=\"binary\"").unwrap();
    let start = start + zlib[start..].find('>').unwrap() + 1;
    let start = start + zlib[start..].len() - zlib[start..].trim_start().len();
    let lead = b64.decode(&zlib[start..start + 32]).unwrap();
    let blocks = u64::from_le_bytes(lead[..8].try_into().unwrap()) as usize;
    let header_chars = (8 * (3 + blocks)).div_ceil(3) * 4;
    let header = b64.decode(&zlib[start..start + header_chars]).unwrap();
    let with_header = |word: usize, value: u64| {
        let mut h = header.clone();
        h[8 * word..8 * word + 8].copy_from_slice(&value.to_le_bytes());
        format!(
            "{}{}{}",
            &zlib[..start],
            b64.encode(&h),
            &zlib[start + header_chars..]
        )
    };
    let cases = [
        (
            "big_endian.vtu",
            zlib.replacen("LittleEndian", "BigEndian", 1),
        ),
        (
            "uint32_header.vtu",
            zlib.replacen("header_type=\"UInt64\"", "header_type=\"UInt32\"", 1),
        ),
        (
            "compressor_on_plain.vtu",
            plain.replacen(
                "header_type=\"UInt64\"",
                "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"",
                1,
            ),
        ),
        ("a_billion_blocks.vtu", with_header(0, 1_000_000_000)),
        ("a_huge_block.vtu", with_header(3, 1 << 31)),
    ];
    for (name, text) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let err = io::read_mesh(&path).expect_err(name).to_string();
        assert!(
            err.contains(name) && err.contains("DataArray '"),
            "{name}: {err}"
        );
    }
}

/// meshio's ASCII VTU edited the way a careless hand or script does: a
/// region array with a value beyond Int32 or a value short was once taken
/// for "no region array" and the run went on with one material; a
/// tetrahedron typed as a triangle was dropped, leaving a hole.
/// Each is now an error naming the file and the array or cell.
#[test]
fn vtu_cells_and_region_arrays_that_contradict_themselves_are_refused() {
    let fixture =
        std::fs::read_to_string(root().join("tests/fixtures/meshio_two_tets.vtu")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let read = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        io::read_mesh(&path).map_err(|e| e.to_string())
    };
    let mesh = read("as_written.vtu", &fixture).unwrap();
    assert_eq!((mesh.num_tets(), mesh.tet_region.clone()), (2, vec![1, 2]));
    let region = fixture.find("Name=\"gmsh:physical\"").unwrap();
    let types = fixture.find("Name=\"types\"").unwrap();
    let edit = |at: usize, from: &str, to: &str| {
        let end = at + fixture[at..].find("</DataArray>").unwrap();
        format!(
            "{}{}{}",
            &fixture[..at],
            fixture[at..end].replacen(from, to, 1),
            &fixture[end..]
        )
    };
    for (name, text, says) in [
        (
            "big_id.vtu",
            edit(region, "\n2\n", "\n3000000000\n"),
            "cell array 'gmsh:physical'",
        ),
        (
            "short.vtu",
            edit(region, "\n2\n", "\n"),
            "DataArray 'gmsh:physical': 1 entries of 1 values; expected 2",
        ),
        (
            "typed_triangle.vtu",
            edit(types, "\n10\n", "\n5\n"),
            "cell 0 is typed triangle (VTK type 5), which has 3 points, but lists 4",
        ),
    ] {
        let err = read(name, &text).expect_err(name);
        assert!(err.contains(name) && err.contains(says), "{name}: {err}");
    }
}
