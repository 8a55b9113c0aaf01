//! Generated meshes: exact volume and area, orientation, closed manifold
//! boundary, UV layout, regions by depth, determinism.

use crate::common;

use common::{deep_zone, small_patch};
use skinpatch::mesh::generate::{generate, PatchSpec, RefineZone, ZoneShape};
use skinpatch::mesh::{markers, TetMesh};

fn check_patch(spec: &PatchSpec, mesh: &TetMesh) {
    let (w, d, h) = (spec.width_mm, spec.depth_mm, spec.thickness_mm());
    let rel = |a: f64, b: f64| (a - b).abs() / b;

    // Volume of the box to 1e-9, every tet positive.
    assert!(
        rel(mesh.total_volume(), w * d * h) < 1e-9,
        "volume {}",
        mesh.total_volume()
    );
    for t in 0..mesh.num_tets() {
        assert!(
            mesh.tet_volume(t) > 0.0,
            "tet {t} volume {}",
            mesh.tet_volume(t)
        );
    }

    // Closed, oriented 2-manifold boundary of genus 0.
    mesh.check_closed_manifold().unwrap();
    assert_eq!(mesh.boundary_euler_characteristic(), 2);
    // Outward orientation: Σ (x·n) dA over the boundary = 3V (divergence theorem).
    let flux: f64 = mesh
        .boundary
        .iter()
        .map(|f| {
            let [a, b, c] = f.nodes.map(|v| mesh.positions[v]);
            a.dot(&(b - a).cross(&(c - a))) / 2.0
        })
        .sum();
    assert!(rel(flux, 3.0 * w * d * h) < 1e-9, "flux {flux}");

    // Every boundary face is marked with its side.
    for f in &mesh.boundary {
        let [a, b, c] = f.nodes.map(|v| mesh.positions[v]);
        let n = (b - a).cross(&(c - a)).normalize();
        let expected = if n.z > 0.999 {
            markers::TOP
        } else if n.z < -0.999 {
            markers::BOTTOM
        } else if n.x < -0.999 {
            markers::X_MIN
        } else if n.x > 0.999 {
            markers::X_MAX
        } else if n.y < -0.999 {
            markers::Y_MIN
        } else {
            markers::Y_MAX
        };
        assert_eq!(f.marker, expected, "face {:?} normal {n:?}", f.nodes);
    }

    // Top surface: area w·d at z = 0, normals up, UVs from x, y at rest.
    let top = &mesh.top;
    assert!(rel(top.area(&mesh.positions), w * d) < 1e-9);
    for (s, &v) in top.vertices.iter().enumerate() {
        let p = mesh.positions[v];
        assert_eq!(p.z, 0.0);
        let [u, vv] = top.uvs[s];
        assert!((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&vv));
        assert!((u - (p.x + w / 2.0) / w).abs() < 1e-12);
        assert!((vv - (p.y + d / 2.0) / d).abs() < 1e-12);
    }
    let uv_area: f64 = top
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|s| top.uvs[s]);
            0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        })
        .sum();
    assert!(
        (uv_area - 1.0).abs() < 1e-9,
        "UV area {uv_area} (counter-clockwise tiles cover [0,1]²)"
    );

    // Region of each tet matches the layer of its centroid.
    let interface = -spec.layers[0].thickness_mm;
    for t in 0..mesh.num_tets() {
        let z = mesh.tet_centroid(t).z;
        let expected = if spec.layers.len() == 1 || z > interface {
            1
        } else {
            2
        };
        assert_eq!(mesh.tet_region[t], expected, "tet {t} at z = {z}");
    }
    let names: Vec<&str> = mesh.regions.iter().map(|r| r.name.as_str()).collect();
    let expected: Vec<&str> = spec.layers.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(names, expected);
}

#[test]
fn two_layer_patch_is_exact() {
    let spec = small_patch(None);
    let mesh = generate(&spec).unwrap();
    check_patch(&spec, &mesh);
}

#[test]
fn zone_through_the_interface_is_exact_and_finer() {
    let spec = small_patch(Some(deep_zone()));
    let mesh = generate(&spec).unwrap();
    check_patch(&spec, &mesh);
    // Tets inside the zone respect its volume limit; outside they are larger on average.
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for t in 0..mesh.num_tets() {
        let c = mesh.tet_centroid(t);
        let v = mesh.tet_volume(t);
        if (c.x - 0.5).abs() < 0.75 && (c.y + 0.25).abs() < 0.5 && c.z > -1.6 {
            assert!(v <= 0.005 * (1.0 + 1e-9), "tet {t} in zone has volume {v}");
            inside.push(v);
        } else {
            outside.push(v);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(mean(&outside) > 3.0 * mean(&inside));
}

#[test]
fn sphere_zone_and_single_layer() {
    let mut spec = small_patch(Some(RefineZone {
        shape: ZoneShape::Sphere {
            center_mm: [-1.0, 0.5],
            radius_mm: 0.6,
        },
        max_volume_mm3: 0.002,
    }));
    spec.layers.truncate(1);
    spec.layers[0].thickness_mm = 2.0;
    let mesh = generate(&spec).unwrap();
    check_patch(&spec, &mesh);
    assert_eq!(mesh.regions.len(), 1);
}

#[test]
fn target_count_is_reached() {
    let mut spec = small_patch(None);
    spec.target_tets = Some(2000);
    let mesh = generate(&spec).unwrap();
    let n = mesh.num_tets() as f64;
    assert!((n - 2000.0).abs() <= 0.05 * 2000.0, "{n} tets");
    check_patch(&spec, &mesh);
}

#[test]
fn generation_is_deterministic() {
    let spec = small_patch(Some(deep_zone()));
    let (a, b) = (generate(&spec).unwrap(), generate(&spec).unwrap());
    assert_eq!(a.tets, b.tets);
    let bits = |m: &TetMesh| -> Vec<u64> {
        m.positions
            .iter()
            .flat_map(|p| p.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
}

#[test]
fn generation_is_safe_from_many_threads() {
    // TetGen is not thread-safe; the lock must serialise concurrent requests.
    let spec = small_patch(None);
    let reference = generate(&spec).unwrap().tets;
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..4)
            .map(|_| s.spawn(|| generate(&spec).unwrap().tets))
            .collect();
        for h in handles {
            assert_eq!(h.join().unwrap(), reference);
        }
    });
}

#[test]
fn min_dihedral_bound_is_enforced() {
    let mut spec = small_patch(None);
    spec.min_dihedral_deg = 59.0;
    let err = generate(&spec).unwrap_err().to_string();
    assert!(err.contains("below mesh.min_dihedral_deg = 59"), "{err}");
}

#[test]
fn bad_specs_are_rejected_before_tetgen() {
    type Edit = Box<dyn Fn(&mut PatchSpec)>;
    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|s| s.width_mm = -1.0),
            "mesh.width_mm must be > 0, got -1",
        ),
        (
            Box::new(|s| s.depth_mm = f64::NAN),
            "mesh.depth_mm must be > 0, got NaN",
        ),
        (
            Box::new(|s| s.radius_edge_max = 1.0),
            "mesh.radius_edge_max must be ≥ 1.1",
        ),
        (
            Box::new(|s| {
                s.refine = Some(RefineZone {
                    shape: ZoneShape::Box {
                        center_mm: [0.0, 0.0],
                        size_mm: [1.0, 1.0, 1.0],
                    },
                    max_volume_mm3: 0.01,
                })
            }),
            "coincides with the layer interface",
        ),
        (
            Box::new(|s| {
                s.refine = Some(RefineZone {
                    shape: ZoneShape::Sphere {
                        center_mm: [0.0, 0.0],
                        radius_mm: 3.0,
                    },
                    max_volume_mm3: 0.01,
                })
            }),
            "strictly inside the patch",
        ),
    ];
    for (edit, expected) in cases {
        let mut spec = small_patch(None);
        edit(&mut spec);
        let err = generate(&spec).unwrap_err().to_string();
        assert!(err.contains(expected), "{err} should contain {expected}");
    }
}
