use super::*;
use crate::fem::boundary::Keyframes;
use crate::fem::probe::{ContactMode, ProbeShape};
use crate::fem::{Material, Volumetric};
use glam::Mat4;
use nalgebra::Vector3;

/// The camera's view-projection for a view of `viewport` pixels.
fn view_projection(camera: &OrbitCamera, viewport: [f32; 2]) -> Mat4 {
    let cam = camera.camera();
    let aspect = viewport[0] / viewport[1].max(1.0);
    cam.view_projection(aspect, cam.target, camera.distance * 4.0)
}

fn probe() -> Probe {
    Probe {
        shape: ProbeShape::Sphere { radius_mm: 1.5 },
        path: Keyframes {
            points: vec![
                (0.0, Vector3::new(-1.0, 0.0, 1.5)),
                (0.4, Vector3::new(-1.0, 0.0, 0.5)),
                (1.0, Vector3::new(1.0, 0.0, 0.5)),
            ],
        },
        axis: Keyframes {
            points: vec![(0.0, Vector3::x())],
        },
        mode: ContactMode::Coulomb(0.8),
    }
}

fn state() -> ViewerState {
    let camera = Camera {
        eye: Vec3::new(0.0, -13.0, 8.0),
        target: Vec3::new(0.0, 0.5, -1.0),
        up: Vec3::Z,
        projection: Projection::Perspective { fov_deg: 40.0 },
    };
    let light = Light {
        kind: LightKind::Directional(Vec3::new(-0.25, -0.75, -0.6).normalize()),
        color: Vec3::ONE,
        intensity: 2.0,
    };
    let control = ProbeControl::new(probe(), [-5.0, -5.0, -5.0], [5.0, 5.0, 0.0]);
    ViewerState::new(
        &camera,
        &[light],
        Some(control),
        vec![
            RegionMaterial::new(
                "dermis",
                &Material::from_scenario_units("d", 150.0, 0.45, 1100.0).unwrap(),
            ),
            RegionMaterial::new(
                "fat",
                &Material::with_volumetric("f", 15.0, 0.45, 1000.0, Volumetric::LockingFree)
                    .unwrap(),
            ),
        ],
        Some(0.8),
        [640.0, 360.0],
    )
}

#[test]
fn orbit_camera_reproduces_the_scenario_camera_and_resets_to_it() {
    let mut s = state();
    let start = s.camera.camera();
    assert!(
        (start.eye - Vec3::new(0.0, -13.0, 8.0)).length() < 1e-4,
        "{start:?}"
    );
    s.apply(Command::Orbit(30.0, -10.0));
    s.apply(Command::Pan(0.1, 0.2));
    s.apply(Command::Zoom(0.5));
    let moved = s.camera.camera();
    assert!((moved.eye - start.eye).length() > 1.0);
    // Zoom halves the distance to the (panned) target.
    let d0 = (start.eye - start.target).length();
    assert!(((moved.eye - moved.target).length() - 0.5 * d0).abs() < 1e-3);
    s.apply(Command::ResetCamera);
    assert_eq!(s.camera.camera(), start);
    // Elevation stays short of the pole, so the view never degenerates.
    s.apply(Command::Orbit(0.0, 500.0));
    assert!(s.camera.elevation_deg <= MAX_ELEVATION);
}

#[test]
fn picking_inverts_the_projection_on_the_top_plane() {
    let s = state();
    let m = view_projection(&s.camera, s.viewport);
    for p in [[0.0f32, 0.0], [1.5, -2.0], [-3.0, 2.5]] {
        let ndc = m.project_point3(Vec3::new(p[0], p[1], 0.0));
        let px = [
            (ndc.x + 1.0) * 0.5 * s.viewport[0],
            (1.0 - ndc.y) * 0.5 * s.viewport[1],
        ];
        let back = s.pick(px).expect("the patch is in view");
        assert!(
            (back[0] - p[0] as f64).abs() < 1e-3 && (back[1] - p[1] as f64).abs() < 1e-3,
            "{p:?} -> {px:?} -> {back:?}"
        );
    }
    // Above the horizon: no point of the plane.
    assert!(s.pick([320.0, -5000.0]).is_none());
}

#[test]
fn probe_presses_to_its_depth_slides_and_lifts() {
    let mut s = state();
    let hover = s.probe.as_ref().unwrap().target().centre.z;
    assert!(
        (hover - (1.5 + 0.75)).abs() < 1e-12,
        "hovers half a radius above: {hover}"
    );
    s.apply(Command::Depth(1.0));
    s.apply(Command::Press([0.5, -0.5]));
    let pressed = s.probe.as_ref().unwrap().target();
    assert_eq!((pressed.centre.x, pressed.centre.y), (0.5, -0.5));
    assert!((pressed.centre.z - 0.5).abs() < 1e-12, "{pressed:?}");
    s.apply(Command::MoveTo([2.0, 0.0]));
    assert_eq!(s.probe.as_ref().unwrap().target().centre.x, 2.0);
    // Off the patch: held at its edge.
    s.apply(Command::MoveTo([50.0, 0.0]));
    assert_eq!(s.probe.as_ref().unwrap().target().centre.x, 5.0);
    // Too deep: held at the limit (two radii, or 60% of the thickness).
    s.apply(Command::Depth(100.0));
    assert_eq!(s.probe.as_ref().unwrap().depth_mm, 3.0);
    s.apply(Command::Release);
    assert!((s.probe.as_ref().unwrap().target().centre.z - hover).abs() < 1e-12);
    // Bad values change nothing and say why.
    s.apply(Command::Depth(f64::NAN));
    assert!(s.rejected.as_deref().unwrap().contains("depth"));
    assert_eq!(s.probe.as_ref().unwrap().depth_mm, 3.0);
}

#[test]
fn path_playback_follows_the_keyframes_and_loops() {
    let mut s = state();
    s.apply(Command::Play(0.0));
    let p = s.probe.as_mut().unwrap();
    p.advance(0.4);
    assert!((p.target().centre - Vector3::new(-1.0, 0.0, 0.5)).norm() < 1e-12);
    p.advance(1.0);
    assert_eq!(
        p.target().centre,
        Vector3::new(1.0, 0.0, 0.5),
        "held at the end"
    );
    s.apply(Command::Loop(true));
    s.apply(Command::Scrub(0.9));
    let p = s.probe.as_mut().unwrap();
    p.advance(0.5);
    assert!(
        matches!(p.drive, ProbeDrive::Path { t_s, playing: false, .. } if (t_s - 0.9).abs() < 1e-12),
        "scrubbing pauses"
    );
    s.apply(Command::Pause(false));
    let p = s.probe.as_mut().unwrap();
    p.advance(0.3);
    assert!(
        matches!(p.drive, ProbeDrive::Path { t_s, .. } if (t_s - 0.2).abs() < 1e-9),
        "{:?}",
        p.drive
    );
}

#[test]
fn material_and_friction_edits_bump_the_version_once() {
    let mut s = state();
    s.apply(Command::Material("dermis".into(), 200.0, 0.4));
    s.apply(Command::Material("dermis".into(), 200.0, 0.4));
    assert_eq!(s.materials_version, 1);
    s.apply(Command::Friction(0.3));
    assert_eq!((s.materials_version, s.friction), (2, Some(0.3)));
    s.apply(Command::Material("dermis".into(), 200.0, 0.5));
    assert!(s.rejected.as_deref().unwrap().contains("Poisson"));
    s.apply(Command::Material("dermis".into(), 200.0, 0.499));
    assert!(s.rejected.as_deref().unwrap().contains("[0, 0.49]"));
    s.apply(Command::Material("bone".into(), 200.0, 0.3));
    assert!(s
        .rejected
        .as_deref()
        .unwrap()
        .contains("regions: dermis, fat"));
    assert_eq!(s.materials_version, 2);
    // A locking-free region takes ν up to its own limit.
    s.apply(Command::Material("fat".into(), 15.0, 0.499));
    assert_eq!((s.materials_version, s.materials[1].poisson), (3, 0.499));
}

#[test]
fn key_light_turns_and_scales() {
    let mut s = state();
    let (az, el) = s.key_light.unwrap();
    // The scenario's direction comes back unchanged.
    let LightKind::Directional(d) = s.lights()[0].kind else {
        panic!("directional")
    };
    assert!((d - Vec3::new(-0.25, -0.75, -0.6).normalize()).length() < 1e-5);
    s.apply(Command::LightDirection(az + 90.0, el));
    s.apply(Command::LightIntensity(0.5));
    let l = s.lights()[0];
    assert_eq!(l.intensity, 1.0);
    let LightKind::Directional(turned) = l.kind else {
        panic!("directional")
    };
    assert!(
        turned.dot(d).abs() < 0.7,
        "turned by 90° in azimuth: {turned} vs {d}"
    );
}
