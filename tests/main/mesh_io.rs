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
