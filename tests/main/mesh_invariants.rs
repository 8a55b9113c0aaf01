//! Properties that hold for any similarity transform and vertex relabelling
//! of a valid mesh.

use crate::common;

use nalgebra::{Rotation3, Vector3};
use proptest::prelude::*;
use skinpatch::mesh::generate::generate;
use skinpatch::mesh::quality::dihedral_angles;
use skinpatch::mesh::{face_key, RawMesh, TetMesh};

/// The even permutations of four elements (they keep a tet's orientation).
const EVEN: [[usize; 4]; 12] = [
    [0, 1, 2, 3],
    [0, 2, 3, 1],
    [0, 3, 1, 2],
    [1, 0, 3, 2],
    [1, 2, 0, 3],
    [1, 3, 2, 0],
    [2, 0, 1, 3],
    [2, 1, 3, 0],
    [2, 3, 0, 1],
    [3, 0, 2, 1],
    [3, 1, 0, 2],
    [3, 2, 1, 0],
];

fn base_mesh() -> &'static TetMesh {
    static MESH: std::sync::OnceLock<TetMesh> = std::sync::OnceLock::new();
    MESH.get_or_init(|| generate(&common::small_patch(None)).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn similarity_and_relabelling_preserve_the_mesh(
        axis in (-1.0f64..1.0, -1.0f64..1.0, 0.1f64..1.0),
        angle in -3.0f64..3.0,
        scale in 0.01f64..100.0,
        shift in (-50.0f64..50.0, -50.0f64..50.0, -50.0f64..50.0),
        perm_seed in any::<u64>(),
        flip_all in any::<bool>(),
    ) {
        let mesh = base_mesh();
        let rot = Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(axis.0, axis.1, axis.2)),
            angle,
        );
        let t = Vector3::new(shift.0, shift.1, shift.2);
        let positions = mesh.positions.iter().map(|p| rot * p * scale + t).collect();
        let mut seed = perm_seed;
        let tets = mesh
            .tets
            .iter()
            .map(|tet| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let p = EVEN[(seed >> 33) as usize % 12];
                let mut out = p.map(|i| tet[i]);
                if flip_all {
                    out.swap(0, 1);
                }
                out
            })
            .collect();
        let raw = RawMesh {
            positions,
            tets,
            tet_region: mesh.tet_region.clone(),
            region_names: mesh.regions.iter().map(|r| (r.id, r.name.clone())).collect(),
            // Rotated, the top is no longer the +z side: carry the markers over.
            face_markers: mesh.boundary.iter().map(|f| (face_key(f.nodes), f.marker)).collect(),
        };
        let moved = TetMesh::from_raw("transformed", raw).unwrap();
        let s3 = scale.powi(3);
        prop_assert!((moved.total_volume() - s3 * mesh.total_volume()).abs() <= 1e-9 * s3 * mesh.total_volume());
        for t in 0..moved.num_tets() {
            prop_assert!(moved.tet_volume(t) > 0.0);
            let mut a = dihedral_angles(&moved.tet_points(t));
            let mut b = dihedral_angles(&mesh.tet_points(t));
            a.sort_by(f64::total_cmp);
            b.sort_by(f64::total_cmp);
            for (x, y) in a.iter().zip(&b) {
                prop_assert!((x - y).abs() < 1e-7, "tet {t}: {x} vs {y}");
            }
        }
        prop_assert!(moved.check_closed_manifold().is_ok());
        prop_assert_eq!(moved.boundary.len(), mesh.boundary.len());
        prop_assert_eq!(moved.boundary_euler_characteristic(), 2);
    }
}

#[test]
fn unused_vertices_are_dropped_and_markers_follow() {
    let dir = tempfile::tempdir().unwrap();
    let (_, ele) = common::cube_tetgen();
    // A ninth point first in the file, used by no tet: every index shifts by one.
    let node = "9 3 0 0\n1 5 5 5\n2 0 0 0\n3 1 0 0\n4 1 1 0\n5 0 1 0\n\
                6 0 0 1\n7 1 0 1\n8 1 1 1\n9 0 1 1\n";
    let ele: String = ele
        .lines()
        .enumerate()
        .map(|(k, l)| {
            if k == 0 {
                format!("{l}\n")
            } else {
                let f: Vec<usize> = l.split_whitespace().map(|s| s.parse().unwrap()).collect();
                format!(
                    "{} {} {} {} {} {}\n",
                    f[0],
                    f[1] + 1,
                    f[2] + 1,
                    f[3] + 1,
                    f[4] + 1,
                    f[5]
                )
            }
        })
        .collect();
    let base = common::write_tetgen_text(dir.path(), "cube", node, &ele);
    std::fs::write(dir.path().join("cube.face"), "1 1\n1 6 7 8 2\n").unwrap();
    let mesh = skinpatch::mesh::io::read_tetgen(&base).unwrap();
    assert_eq!(mesh.num_vertices(), 8);
    assert!((mesh.total_volume() - 1.0).abs() < 1e-15);
    let marked: Vec<_> = mesh.boundary.iter().filter(|f| f.marker == 2).collect();
    assert_eq!(marked.len(), 1);
    for &v in &marked[0].nodes {
        assert_eq!(mesh.positions[v].z, 1.0);
    }
}
