//! `skinpatch mesh`: a layered patch generated with TetGen from a
//! scenario's `[mesh]` section and/or flags, or a mesh file inspected; the
//! quality report, and with `--out` the mesh files.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use skinpatch::mesh::generate::{generate_scaled, poly_text};
use skinpatch::mesh::quality::max_edge_within;
use skinpatch::mesh::{io, QualityReport, TetMesh, Vec3};
use skinpatch::scenario::{MeshSection, RefineSection, Scenario, ZoneKind};

use super::print_stdout;

/// `skinpatch mesh`'s arguments.
#[derive(Args)]
pub struct MeshArgs {
    /// Read the [mesh] section of this scenario.
    #[arg(long, conflicts_with = "input")]
    scenario: Option<PathBuf>,
    /// Load this mesh (.msh, .vtu, .vtk, .node/.ele or a TetGen base name) instead of generating.
    #[arg(long)]
    input: Option<PathBuf>,
    /// Write BASE.node/.ele/.face, BASE.vtu (and BASE.poly when generating).
    #[arg(long, value_name = "BASE")]
    out: Option<PathBuf>,
    /// Renumber the --input mesh for memory locality (reverse Cuthill–McKee
    /// vertices, tets by their lowest vertex), as generated meshes are: the
    /// FEM runs faster on it. The geometry, regions and markers stay.
    #[arg(long, requires = "input")]
    renumber: bool,
    /// Patch extent in x (mm) [default 10].
    #[arg(long)]
    width_mm: Option<f64>,
    /// Patch extent in y (mm) [default 10].
    #[arg(long)]
    depth_mm: Option<f64>,
    /// Top layer (epidermis + dermis) thickness (mm) [default 1.5].
    #[arg(long)]
    top_layer_mm: Option<f64>,
    /// Bottom layer (hypodermis) thickness (mm); 0 for one layer [default 3.5].
    #[arg(long)]
    bottom_layer_mm: Option<f64>,
    /// Largest tet volume in the top layer (mm³) [default 0.004].
    #[arg(long)]
    top_max_volume_mm3: Option<f64>,
    /// Largest tet volume in the bottom layer (mm³) [default 0.02].
    #[arg(long)]
    bottom_max_volume_mm3: Option<f64>,
    /// Scale all volume limits until the mesh has about this many tets.
    #[arg(long)]
    target_tets: Option<usize>,
    /// TetGen radius-edge ratio bound (≥ 1.1) [default 1.5].
    #[arg(long)]
    radius_edge_max: Option<f64>,
    /// Fail unless every dihedral angle is at least this (degrees) [default 0: off].
    #[arg(long)]
    min_dihedral_deg: Option<f64>,
    /// Refine a hemisphere under the top surface: X,Y,RADIUS (mm).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "X,Y,R",
        conflicts_with = "refine_box",
        allow_hyphen_values = true
    )]
    refine_sphere: Option<Vec<f64>>,
    /// Refine a box hanging from the top surface: X,Y,SIZE_X,SIZE_Y,DEPTH (mm).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "X,Y,SX,SY,D",
        allow_hyphen_values = true
    )]
    refine_box: Option<Vec<f64>>,
    /// Largest tet volume inside the refinement zone (mm³).
    #[arg(long)]
    refine_max_volume_mm3: Option<f64>,
    /// Also report the longest edge of the tets within R of the point (X, Y, Z) (mm).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "X,Y,Z,R",
        allow_hyphen_values = true
    )]
    edges_within: Option<Vec<f64>>,
}

impl MeshArgs {
    /// Applies the flags on top of a [mesh] section.
    fn overlay(&self, mut m: MeshSection) -> anyhow::Result<MeshSection> {
        macro_rules! set {
            ($($field:ident),*) => { $( if self.$field.is_some() { m.$field = self.$field; } )* };
        }
        set!(
            width_mm,
            depth_mm,
            top_layer_mm,
            bottom_layer_mm,
            top_max_volume_mm3,
            bottom_max_volume_mm3,
            target_tets,
            radius_edge_max,
            min_dihedral_deg
        );
        let zone = match (&self.refine_sphere, &self.refine_box) {
            (Some(s), _) if s.len() != 3 => bail!("--refine-sphere takes X,Y,R, got {s:?}"),
            (_, Some(b)) if b.len() != 5 => bail!("--refine-box takes X,Y,SX,SY,D, got {b:?}"),
            (Some(s), _) => Some(RefineSection {
                shape: ZoneKind::Sphere,
                center_mm: [s[0], s[1]],
                radius_mm: Some(s[2]),
                size_mm: None,
                max_volume_mm3: f64::NAN,
            }),
            (_, Some(b)) => Some(RefineSection {
                shape: ZoneKind::Box,
                center_mm: [b[0], b[1]],
                radius_mm: None,
                size_mm: Some([b[2], b[3], b[4]]),
                max_volume_mm3: f64::NAN,
            }),
            _ => None,
        };
        if let Some(mut zone) = zone {
            zone.max_volume_mm3 = self
                .refine_max_volume_mm3
                .or(m.refine.as_ref().map(|r| r.max_volume_mm3))
                .context("--refine-sphere/--refine-box need --refine-max-volume-mm3")?;
            m.refine = Some(zone);
        } else if let (Some(v), Some(r)) = (self.refine_max_volume_mm3, m.refine.as_mut()) {
            r.max_volume_mm3 = v;
        } else if self.refine_max_volume_mm3.is_some() {
            bail!(
                "--refine-max-volume-mm3 needs a refinement zone (--refine-sphere or --refine-box)"
            );
        }
        Ok(m)
    }
}

impl MeshArgs {
    /// The flag the user typed for the scenario key `key`, if any: a value
    /// refused by the mesh checks is named as it was given.
    fn flag_for(&self, key: &str) -> Option<&'static str> {
        let given = |set: bool, flag: &'static str| set.then_some(flag);
        match key {
            "mesh.width_mm" => given(self.width_mm.is_some(), "--width-mm"),
            "mesh.depth_mm" => given(self.depth_mm.is_some(), "--depth-mm"),
            "mesh.top_layer_mm" => given(self.top_layer_mm.is_some(), "--top-layer-mm"),
            "mesh.bottom_layer_mm" => given(self.bottom_layer_mm.is_some(), "--bottom-layer-mm"),
            "mesh.top_max_volume_mm3" => {
                given(self.top_max_volume_mm3.is_some(), "--top-max-volume-mm3")
            }
            "mesh.bottom_max_volume_mm3" => given(
                self.bottom_max_volume_mm3.is_some(),
                "--bottom-max-volume-mm3",
            ),
            "mesh.target_tets" => given(self.target_tets.is_some(), "--target-tets"),
            "mesh.radius_edge_max" => given(self.radius_edge_max.is_some(), "--radius-edge-max"),
            "mesh.min_dihedral_deg" => given(self.min_dihedral_deg.is_some(), "--min-dihedral-deg"),
            "mesh.refine" => given(self.refine_sphere.is_some(), "--refine-sphere")
                .or(given(self.refine_box.is_some(), "--refine-box"))
                .or(given(
                    self.refine_max_volume_mm3.is_some(),
                    "--refine-max-volume-mm3",
                )),
            _ => None,
        }
    }

    /// `e` with its scenario key replaced by the flag that set it.
    fn name_flag(&self, e: skinpatch::Error) -> anyhow::Error {
        match e {
            skinpatch::Error::Parameter { key, reason } => match self.flag_for(&key) {
                Some(flag) => anyhow::anyhow!("{flag}: {reason}"),
                None => skinpatch::Error::Parameter { key, reason }.into(),
            },
            e => e.into(),
        }
    }
}

/// Runs `skinpatch mesh`.
pub fn run(args: MeshArgs) -> anyhow::Result<()> {
    if let Some(base) = &args.out {
        refuse_overwriting_inputs(&args, base)?;
    }
    let (mesh, poly) = if let Some(input) = &args.input {
        let mesh = io::read_mesh(input)?;
        let mesh = if args.renumber {
            mesh.renumbered()?
        } else {
            mesh
        };
        (mesh, None)
    } else {
        let section = match &args.scenario {
            Some(path) => Scenario::load(path)?.mesh,
            None => MeshSection::default(),
        };
        if section.file.is_some() {
            bail!("the scenario's [mesh] loads a file; use --input to inspect a mesh file");
        }
        let spec = args
            .overlay(section)?
            .patch_spec()
            .map_err(|e| args.name_flag(e))?;
        let (mesh, scale) = generate_scaled(&spec).map_err(|e| args.name_flag(e))?;
        (mesh, Some(poly_text(&spec, scale)))
    };
    let mut report = QualityReport::of(&mesh).to_string();
    report += &numbering_line(&mesh, args.input.is_some() && !args.renumber);
    if let Some(e) = &args.edges_within {
        let [x, y, z, r] = e[..] else {
            bail!("--edges-within takes X,Y,Z,R, got {e:?}");
        };
        let (longest, n) = max_edge_within(&mesh, &Vec3::new(x, y, z), r);
        report +=
            &format!("within {r} mm of ({x}, {y}, {z}): {n} tets, longest edge {longest:.4} mm\n");
    }
    // Files first: a closed stdout must not cost the user their mesh.
    if let Some(base) = &args.out {
        report += &write_mesh_files(&mesh, base, poly.as_deref())?;
    }
    print_stdout(&report)
}

/// How spread the vertex numbering is, with a hint to renumber a loaded
/// mesh whose tets span more than three times `n^(2/3)` indices on average
/// (`n` vertices): a banded numbering of a solid spans about a cross-section,
/// `n^(2/3)`; TetGen's own spans a good part of the whole.
fn numbering_line(mesh: &TetMesh, loaded: bool) -> String {
    let span = mesh.mean_tet_index_span();
    let mut line = format!(
        "numbering: a tet's vertex indices span {span:.0} on average ({} vertices)\n",
        mesh.num_vertices()
    );
    if loaded && span > 3.0 * (mesh.num_vertices() as f64).powf(2.0 / 3.0) {
        line += "  scattered: `--renumber --out BASE` writes it renumbered, which the FEM runs faster on\n";
    }
    line
}

/// Refuses an `--out BASE` that would write over a file the command reads:
/// the `--input` mesh (with a TetGen mesh's three files) or the scenario.
fn refuse_overwriting_inputs(args: &MeshArgs, base: &Path) -> anyhow::Result<()> {
    let mut inputs: Vec<(&str, PathBuf)> = Vec::new();
    if let Some(input) = &args.input {
        inputs.push(("--input mesh", input.clone()));
        for candidate in [input.with_extension(""), input.clone()] {
            inputs.extend(io::tetgen_paths(&candidate).map(|p| ("--input mesh", p)));
        }
    }
    if let Some(scenario) = &args.scenario {
        inputs.push(("--scenario file", scenario.clone()));
    }
    let mut outputs: Vec<PathBuf> = io::tetgen_paths(base).into();
    outputs.extend(["vtu", "poly"].map(|ext| PathBuf::from(format!("{}.{ext}", base.display()))));
    for output in &outputs {
        for (what, input) in &inputs {
            if skinpatch::export::outputs::same_file(output, input) {
                bail!(
                    "--out {} would write {}, which is the {what} ({}); choose another BASE \
                     (nothing was written)",
                    base.display(),
                    output.display(),
                    input.display()
                );
            }
        }
    }
    Ok(())
}

fn write_mesh_files(mesh: &TetMesh, base: &Path, poly: Option<&str>) -> anyhow::Result<String> {
    if let Some(dir) = base.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut written: Vec<PathBuf> = io::tetgen_paths(base).into();
    io::write_tetgen(mesh, base)?;
    let vtu = PathBuf::from(format!("{}.vtu", base.display()));
    io::write_vtu(&vtu, &io::Grid::from_mesh(mesh))?;
    written.push(vtu);
    if let Some(text) = poly {
        let path = PathBuf::from(format!("{}.poly", base.display()));
        io::write_atomically(&path, text.as_bytes())?;
        written.push(path);
    }
    Ok(written
        .iter()
        .map(|p| format!("wrote {}\n", p.display()))
        .collect())
}
