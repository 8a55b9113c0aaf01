//! Unit tests of the scenario sections: parsing, overrides, validation.

use super::*;

fn parse(text: &str) -> Result<Scenario> {
    Scenario::parse(text, Path::new("test.toml"))
}

#[test]
fn unknown_key_names_path_line_and_suggestion() {
    let err = parse("[mesh]\nwidth_mm = 10\nwidht_mm = 12\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("unknown key mesh.widht_mm"), "{err}");
    assert!(err.contains("did you mean width_mm?"), "{err}");
    assert!(err.contains("line 3"), "{err}");
}

#[test]
fn unknown_section_is_rejected() {
    let err = parse("[meshh]\n").unwrap_err().to_string();
    assert!(err.contains("unknown key meshh"), "{err}");
    assert!(err.contains("did you mean mesh?"), "{err}");
}

#[test]
fn wrong_type_names_key() {
    let err = parse("[mesh]\nwidth_mm = \"wide\"\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("mesh.width_mm"), "{err}");
    assert!(err.contains("line 2"), "{err}");
}

#[test]
fn range_errors_name_key_and_value() {
    let s = parse("[mesh]\ntop_layer_mm = -1\n").unwrap();
    let err = bounds::check(&s).unwrap_err().to_string();
    assert_eq!(err, "mesh.top_layer_mm must be > 0, got -1");
    let s = parse("[mesh]\nwidth_mm = nan\n").unwrap();
    let err = bounds::check(&s).unwrap_err().to_string();
    assert_eq!(err, "mesh.width_mm must be > 0, got NaN");
    // Setup checks them before anything else.
    let err = Setup::from_scenario(&s, Path::new("test.toml")).unwrap_err();
    assert_eq!(err.to_string(), "mesh.width_mm must be > 0, got NaN");
}

#[test]
fn file_conflicts_with_generation_keys() {
    let s = parse("[mesh]\nfile = \"a.msh\"\nwidth_mm = 3\n").unwrap();
    let err = s.mesh.source(Path::new(".")).unwrap_err().to_string();
    assert!(err.starts_with("mesh.width_mm has no effect"), "{err}");
}

#[test]
fn defaults_are_the_design_patch() {
    let spec = parse("").unwrap().mesh.patch_spec().unwrap();
    assert_eq!((spec.width_mm, spec.depth_mm), (10.0, 10.0));
    let t: Vec<f64> = spec.layers.iter().map(|l| l.thickness_mm).collect();
    assert_eq!(t, vec![1.5, 3.5]);
    assert_eq!(spec.layers[0].name, "dermis");
}

#[test]
fn refine_zone_outside_patch_is_rejected() {
    let s = parse(
        "[mesh.refine]\nshape = \"sphere\"\ncenter_mm = [4.5, 0]\nradius_mm = 1\nmax_volume_mm3 = 0.001\n",
    )
    .unwrap();
    let err = s.mesh.patch_spec().unwrap_err().to_string();
    assert!(err.contains("strictly inside the patch"), "{err}");
}

#[test]
fn vtu_options_are_checked() {
    let format = |text: &str| parse(text).map(|s| s.output.vtu_format());
    assert_eq!(
        format("").unwrap(),
        crate::mesh::io::VtuFormat {
            compress: true,
            f32: false
        }
    );
    assert_eq!(
        format("[output]\nvtu_precision = \"f32\"\nvtu_compression = \"none\"\n").unwrap(),
        crate::mesh::io::VtuFormat {
            compress: false,
            f32: true
        }
    );
    for (text, key) in [
        (
            "[output]\nvtu_precision = \"f16\"\n",
            "output.vtu_precision",
        ),
        (
            "[output]\nvtu_compression = \"lz4\"\n",
            "output.vtu_compression",
        ),
    ] {
        let err = format(text).unwrap_err().to_string();
        assert!(err.contains(key), "{err}");
    }
}

/// An enum-like key given a value it does not know: the line, the key,
/// every accepted value and the closest one, from the file and from
/// `--set` alike.
#[test]
fn unknown_values_name_the_key_the_values_and_the_closest() {
    let err = parse("[solver]\nlinear = \"two-levl\"\n")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(
            "line 2: solver.linear must be \"cg\", \"direct\", \"factored-cg\" or \
             \"two-level\", got \"two-levl\"; did you mean two-level?"
        ),
        "{err}"
    );
    // Nothing close: no suggestion.
    let err = parse("[time]\nintegrator = \"rk4\"\n")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("time.integrator must be \"quasi-static\" or \"implicit-euler\", got \"rk4\""),
        "{err}"
    );
    assert!(!err.contains("did you mean"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.toml");
    std::fs::write(&path, "[boundary]\nbottom = \"fixed\"\n").unwrap();
    let err = Scenario::load_with(&path, &["boundary.sides=roller".into()])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("with --set: boundary.sides must be \"clamped\", \"rollers\" or \"free\", got \"roller\"; did you mean rollers?"),
        "{err}"
    );
}

#[test]
fn strain_image_options_are_checked() {
    let settings = |text: &str| {
        let scenario = parse(text).unwrap();
        bounds::check(&scenario).map(|()| scenario.output.strain_image_settings())
    };
    assert_eq!(settings("").unwrap(), None);
    let on = settings("[output]\nstrain_images = true\nstrain_image_px = 128\n").unwrap();
    assert_eq!(
        on,
        Some(StrainImageSettings {
            px: 128,
            range: 0.25,
            previews: true,
            data: None,
        })
    );
    let data = settings("[output]\nstrain_data = true\nstrain_image_px = 64\n").unwrap();
    assert_eq!(
        data,
        Some(StrainImageSettings {
            px: 64,
            range: 0.25,
            previews: false,
            data: Some([64, 64]),
        })
    );
    for (text, key) in [
        ("[output]\nstrain_image_px = 0\n", "output.strain_image_px"),
        (
            "[output]\nstrain_image_px = 9000\n",
            "output.strain_image_px",
        ),
        (
            "[output]\nstrain_image_range = -0.1\n",
            "output.strain_image_range",
        ),
        (
            "[output]\nstrain_image_range = nan\n",
            "output.strain_image_range",
        ),
    ] {
        let err = settings(text).unwrap_err().to_string();
        assert!(err.contains(key), "{text}: {err}");
    }
}

#[test]
fn key_line_finds_values_tables_and_array_entries() {
    let text = "[mesh]\nfile = \"m.node\"\n\n[material.dermis]\nyoungs_modulus_kpa = 150\n\
                poisson_ratio = 0.45\n\n[[render.lights]]\nintensity = 1\n\n[[render.lights]]\n\
                intensity = 2\n";
    assert_eq!(key_line(text, "mesh.file"), Some(2));
    assert_eq!(key_line(text, "material.dermis"), Some(4));
    assert_eq!(key_line(text, "material.dermis.poisson_ratio"), Some(6));
    assert_eq!(key_line(text, "render.lights.1.intensity"), Some(12));
    assert_eq!(key_line(text, "render.lights.2.intensity"), None);
    assert_eq!(key_line(text, "material.fat"), None);
    assert_eq!(key_line("not toml [", "mesh"), None);
}

#[test]
fn schema_errors_carry_their_key_and_line() {
    let path = Path::new("s.toml");
    let at = |text: &str| match Scenario::parse(text, path).unwrap_err() {
        Error::Scenario { key, line, .. } => (key, line),
        e => panic!("{e}"),
    };
    let unknown = "[mesh]\nfile = \"m.node\"\n[material.dermis]\nyoung_modulus_kpa = 3\n";
    assert_eq!(
        at(unknown),
        (Some("material.dermis.young_modulus_kpa".into()), Some(4))
    );
    let wrong_type = "[mesh]\nfile = \"m.node\"\n[probe]\nradius_mm = \"big\"\n";
    assert_eq!(at(wrong_type), (Some("probe.radius_mm".into()), Some(4)));
    assert_eq!(at("[mesh\n"), (None, Some(1)));
}
