//! Layered skin-patch meshes generated with TetGen (through `tritet`).
//!
//! The patch is the box `[−w/2, w/2] × [−d/2, d/2] × [−h, 0]`, split by
//! horizontal interfaces into layers (top layer first). It is handed to TetGen
//! as a piecewise linear complex (PLC) whose facets are:
//!
//! * the top plane (marker [`markers::TOP`]), every interface plane (internal,
//!   marker 0) and the bottom plane ([`markers::BOTTOM`]);
//! * one rectangle per layer on each side ([`markers::X_MIN`] … [`markers::Y_MAX`]);
//! * with a refinement zone, the zone's box `[x0, x1] × [y0, y1] × [−zd, 0]`:
//!   its sides and bottom as internal facets, and every plane it crosses split
//!   into the zone's rectangle plus four trapezoids joining the zone's corners
//!   to the patch's corners (so no facet needs a vertex inside an edge).
//!
//! Each layer, and each part of a layer inside the zone, is a TetGen region
//! with its own maximum tet volume; the region attribute is the layer's id,
//! so tets carry their material region exactly (the interfaces are facets).
//! TetGen's quality refinement (`-q`, radius–edge bound) grades the mesh from
//! the fine zone outward. A sphere zone (radius r about a point of the top
//! surface) is meshed as its circumscribing box `2r × 2r × r`.
//!
//! `tritet`'s interface passes the radius–edge bound only, not TetGen's
//! minimum-dihedral switch; the requested minimum dihedral angle is therefore
//! checked on the result and reported as an error when it is missed.
//!
//! TetGen keeps global state and is not thread-safe: every call holds
//! [`TETGEN_LOCK`].

use std::sync::Mutex;

use super::{markers, TetMesh, Vec3};
use crate::error::{Error, Result};

/// Serialises all calls into TetGen.
pub static TETGEN_LOCK: Mutex<()> = Mutex::new(());

/// One tissue layer of the patch.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerSpec {
    /// Region name (used by `[material.<name>]`).
    pub name: String,
    /// Region id stored per tet.
    pub id: i32,
    /// Thickness (mm).
    pub thickness_mm: f64,
    /// Maximum tet volume in this layer (mm³).
    pub max_volume_mm3: f64,
}

/// Shape of the refinement zone, on the top surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ZoneShape {
    /// A hemisphere of `radius_mm` below the top-surface point `center_mm`.
    Sphere {
        /// Centre (x, y) on the top surface (mm).
        center_mm: [f64; 2],
        /// Radius (mm).
        radius_mm: f64,
    },
    /// A box hanging from the top surface.
    Box {
        /// Centre (x, y) on the top surface (mm).
        center_mm: [f64; 2],
        /// Extent in x and y, and depth below the top surface (mm).
        size_mm: [f64; 3],
    },
}

impl ZoneShape {
    /// The box that is meshed: `([x0, y0], [x1, y1], depth)`.
    pub fn meshed_box(&self) -> ZoneBox {
        let (c, half, depth) = match *self {
            ZoneShape::Sphere {
                center_mm,
                radius_mm,
            } => (center_mm, [radius_mm; 2], radius_mm),
            ZoneShape::Box { center_mm, size_mm } => {
                (center_mm, [size_mm[0] / 2.0, size_mm[1] / 2.0], size_mm[2])
            }
        };
        (
            [c[0] - half[0], c[1] - half[1]],
            [c[0] + half[0], c[1] + half[1]],
            depth,
        )
    }
}

/// A zone's meshed box: `([x0, y0], [x1, y1], depth below the top)` (mm).
pub type ZoneBox = ([f64; 2], [f64; 2], f64);

/// A region of smaller tets near the top surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineZone {
    /// Where the zone is.
    pub shape: ZoneShape,
    /// Maximum tet volume inside the zone (mm³).
    pub max_volume_mm3: f64,
}

/// Smallest radius–edge ratio bound TetGen is given: below it, its
/// refinement may not terminate.
pub const MIN_RADIUS_EDGE: f64 = 1.1;
/// The dihedral-angle check's bound (degrees) lies below this.
pub const MAX_DIHEDRAL_DEG: f64 = 60.0;

/// Everything needed to generate a patch mesh. Build it from a validated
/// scenario; [`PatchSpec::check`] repeats the geometric checks for direct use.
#[derive(Clone, Debug, PartialEq)]
pub struct PatchSpec {
    /// Extent in x (mm).
    pub width_mm: f64,
    /// Extent in y (mm).
    pub depth_mm: f64,
    /// Layers from the top down.
    pub layers: Vec<LayerSpec>,
    /// Optional refinement zone.
    pub refine: Option<RefineZone>,
    /// TetGen radius–edge bound (`-q`), ≥ 1.1.
    pub radius_edge_max: f64,
    /// Minimum dihedral angle the result must reach (degrees); 0 disables the check.
    pub min_dihedral_deg: f64,
    /// If set, all volume limits are scaled together until the tet count is
    /// within `target_tolerance` (relative) of this number.
    pub target_tets: Option<usize>,
    /// Relative tolerance on `target_tets`.
    pub target_tolerance: f64,
}

impl PatchSpec {
    /// Total thickness (mm).
    pub fn thickness_mm(&self) -> f64 {
        self.layers.iter().map(|l| l.thickness_mm).sum()
    }

    /// Checks geometric consistency; parameter ranges are checked by the scenario.
    pub fn check(&self) -> Result<()> {
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::parameter(key, format!("must be > 0, got {v}")))
            }
        };
        positive("mesh.width_mm", self.width_mm)?;
        positive("mesh.depth_mm", self.depth_mm)?;
        if self.layers.is_empty() {
            return Err(Error::parameter("mesh", "needs at least one layer"));
        }
        for l in &self.layers {
            positive(&format!("layer '{}' thickness_mm", l.name), l.thickness_mm)?;
            positive(
                &format!("layer '{}' max_volume_mm3", l.name),
                l.max_volume_mm3,
            )?;
        }
        if !(self.radius_edge_max >= MIN_RADIUS_EDGE && self.radius_edge_max.is_finite()) {
            return Err(Error::parameter(
                "mesh.radius_edge_max",
                format!(
                    "must be ≥ {MIN_RADIUS_EDGE} (TetGen may not terminate below), got {}",
                    self.radius_edge_max
                ),
            ));
        }
        if !(0.0..MAX_DIHEDRAL_DEG).contains(&self.min_dihedral_deg) {
            return Err(Error::parameter(
                "mesh.min_dihedral_deg",
                format!(
                    "must be in [0, {MAX_DIHEDRAL_DEG}), got {}",
                    self.min_dihedral_deg
                ),
            ));
        }
        if let Some(zone) = &self.refine {
            self.check_zone(zone)?;
        }
        Ok(())
    }

    fn check_zone(&self, zone: &RefineZone) -> Result<()> {
        let key = "mesh.refine";
        if !(zone.max_volume_mm3.is_finite() && zone.max_volume_mm3 > 0.0) {
            return Err(Error::parameter(
                format!("{key}.max_volume_mm3"),
                format!("must be > 0, got {}", zone.max_volume_mm3),
            ));
        }
        let (lo, hi, zd) = zone.shape.meshed_box();
        let (w2, d2) = (self.width_mm / 2.0, self.depth_mm / 2.0);
        let inside = lo[0] > -w2 && hi[0] < w2 && lo[1] > -d2 && hi[1] < d2;
        if !(inside && lo[0] < hi[0] && lo[1] < hi[1]) {
            return Err(Error::parameter(
                key,
                format!(
                    "zone x ∈ [{}, {}], y ∈ [{}, {}] must lie strictly inside the patch \
                     x ∈ [{}, {w2}], y ∈ [{}, {d2}]",
                    lo[0], hi[0], lo[1], hi[1], -w2, -d2
                ),
            ));
        }
        let h = self.thickness_mm();
        if !(zd > 0.0 && zd < h) {
            return Err(Error::parameter(
                key,
                format!("zone depth must be in (0, {h}) mm (the patch thickness), got {zd}"),
            ));
        }
        let tol = 1e-6 * h;
        let what = match zone.shape {
            ZoneShape::Sphere { .. } => "the zone's depth (a hemisphere's radius)",
            ZoneShape::Box { .. } => "the zone's depth",
        };
        for z in self.interface_depths() {
            if (zd - z).abs() < tol {
                return Err(Error::parameter(
                    key,
                    format!(
                        "{what} {zd} mm coincides with the layer interface at {z} mm; \
                         make it larger or smaller"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Depths (positive, mm) of the interfaces between layers.
    fn interface_depths(&self) -> Vec<f64> {
        let mut z = 0.0;
        let mut out = Vec::new();
        for l in &self.layers[..self.layers.len() - 1] {
            z += l.thickness_mm;
            out.push(z);
        }
        out
    }
}

/// Generates the patch mesh. With `target_tets`, TetGen is run repeatedly with
/// all volume limits scaled by a common factor until the count is close enough.
pub fn generate(spec: &PatchSpec) -> Result<TetMesh> {
    generate_scaled(spec).map(|(mesh, _)| mesh)
}

/// Like [`generate`], also returning the factor applied to the volume limits
/// (1 without `target_tets`), as needed by [`poly_text`].
pub fn generate_scaled(spec: &PatchSpec) -> Result<(TetMesh, f64)> {
    spec.check()?;
    let Some(target) = spec.target_tets else {
        return Ok((run_tetgen(spec, 1.0)?, 1.0));
    };
    let miss = |m: &TetMesh| (m.num_tets() as f64 - target as f64).abs() / target as f64;
    let mut scale = 1.0;
    let mut best: Option<(TetMesh, f64)> = None;
    for attempt in 0..8 {
        let mesh = run_tetgen(spec, scale)?;
        let n = mesh.num_tets() as f64;
        log::info!(
            "attempt {attempt}: volume scale {scale:.4} gave {} tets (target {target})",
            mesh.num_tets()
        );
        let done = miss(&mesh) <= spec.target_tolerance;
        if best.as_ref().is_none_or(|(b, _)| miss(&mesh) < miss(b)) {
            best = Some((mesh, scale));
        }
        if done {
            break;
        }
        // The count scales roughly inversely with the volume limit; damp the step.
        scale *= (n / target as f64).powf(0.9);
    }
    let (mesh, scale) = best.expect("at least one attempt ran");
    if miss(&mesh) > spec.target_tolerance {
        return Err(Error::MeshGeneration(format!(
            "could not reach {target} ± {:.0}% tets (mesh.target_tets, mesh.target_tolerance); \
             closest was {}{}",
            100.0 * spec.target_tolerance,
            mesh.num_tets(),
            if (mesh.num_tets() as f64) > target as f64 {
                ": the patch's layers and TetGen's quality bound (mesh.radius_edge_max) need \
                 about that many at least"
            } else {
                ""
            }
        )));
    }
    Ok((mesh, scale))
}

/// The PLC handed to TetGen.
#[derive(Default)]
struct Plc {
    points: Vec<Vec3>,
    facets: Vec<(i32, Vec<usize>)>,
    /// (layer id, point inside, max volume)
    regions: Vec<(i32, Vec3, f64)>,
}

impl Plc {
    fn point(&mut self, x: f64, y: f64, z: f64) -> usize {
        self.points.push(Vec3::new(x, y, z));
        self.points.len() - 1
    }

    /// Four corners of the rectangle `[lo, hi]` at height z, counter-clockwise.
    fn rect(&mut self, lo: [f64; 2], hi: [f64; 2], z: f64) -> [usize; 4] {
        [
            self.point(lo[0], lo[1], z),
            self.point(hi[0], lo[1], z),
            self.point(hi[0], hi[1], z),
            self.point(lo[0], hi[1], z),
        ]
    }

    /// A horizontal plane: the outer rectangle, or the inner one plus four
    /// trapezoids joining it to the outer corners.
    fn plane(&mut self, outer: &[usize; 4], inner: Option<&[usize; 4]>, marker: i32) {
        match inner {
            None => self.facets.push((marker, outer.to_vec())),
            Some(inner) => {
                self.facets.push((marker, inner.to_vec()));
                for i in 0..4 {
                    let j = (i + 1) % 4;
                    self.facets
                        .push((marker, vec![outer[i], outer[j], inner[j], inner[i]]));
                }
            }
        }
    }

    /// Vertical side rectangles between two stacked, counter-clockwise rings.
    fn sides(&mut self, upper: &[usize; 4], lower: &[usize; 4], side_markers: [i32; 4]) {
        for i in 0..4 {
            let j = (i + 1) % 4;
            self.facets.push((
                side_markers[i],
                vec![upper[i], upper[j], lower[j], lower[i]],
            ));
        }
    }
}

/// Builds the PLC with all volume limits multiplied by `scale`.
fn build_plc(spec: &PatchSpec, scale: f64) -> Plc {
    let mut plc = Plc::default();
    let outer_lo = [-spec.width_mm / 2.0, -spec.depth_mm / 2.0];
    let outer_hi = [spec.width_mm / 2.0, spec.depth_mm / 2.0];
    let zone = spec.refine.map(|z| (z, z.shape.meshed_box()));
    // Outer levels (z ≤ 0) and the zone's levels: top, crossed interfaces, bottom.
    let mut levels = vec![0.0];
    levels.extend(spec.interface_depths().iter().map(|d| -d));
    levels.push(-spec.thickness_mm());
    let zone_levels: Vec<f64> = match zone {
        None => Vec::new(),
        Some((_, (_, _, zd))) => {
            let mut zl: Vec<f64> = levels.iter().copied().filter(|&z| z > -zd).collect();
            zl.push(-zd);
            zl
        }
    };
    let outer: Vec<[usize; 4]> = levels
        .iter()
        .map(|&z| plc.rect(outer_lo, outer_hi, z))
        .collect();
    let inner: Vec<[usize; 4]> = match zone {
        None => Vec::new(),
        Some((_, (lo, hi, _))) => zone_levels.iter().map(|&z| plc.rect(lo, hi, z)).collect(),
    };
    let last = levels.len() - 1;
    for (k, ring) in outer.iter().enumerate() {
        let marker = match k {
            0 => markers::TOP,
            k if k == last => markers::BOTTOM,
            _ => markers::NONE,
        };
        // The zone splits every outer plane it reaches (all but its own bottom).
        let split = (k + 1 < inner.len()).then(|| &inner[k]);
        plc.plane(ring, split, marker);
    }
    let side_markers = [
        markers::Y_MIN,
        markers::X_MAX,
        markers::Y_MAX,
        markers::X_MIN,
    ];
    for k in 0..last {
        plc.sides(&outer[k], &outer[k + 1], side_markers);
    }
    if let Some(bottom) = inner.last() {
        plc.facets.push((markers::NONE, bottom.to_vec()));
        for k in 0..inner.len() - 1 {
            plc.sides(&inner[k], &inner[k + 1], [markers::NONE; 4]);
        }
    }
    add_regions(&mut plc, spec, &levels, zone, scale);
    plc
}

fn add_regions(
    plc: &mut Plc,
    spec: &PatchSpec,
    levels: &[f64],
    zone: Option<(RefineZone, ZoneBox)>,
    scale: f64,
) {
    let corner = [-spec.width_mm / 2.0, -spec.depth_mm / 2.0];
    for (k, layer) in spec.layers.iter().enumerate() {
        let (top, bottom) = (levels[k], levels[k + 1]);
        // A point just inside the patch corner is outside the zone, which
        // lies strictly inside the patch.
        let margin = match zone {
            Some((_, (lo, _, _))) => 0.5 * (lo[0] - corner[0]).min(lo[1] - corner[1]),
            None => 0.5 * spec.width_mm.min(spec.depth_mm),
        };
        let p = Vec3::new(corner[0] + margin, corner[1] + margin, 0.5 * (top + bottom));
        plc.regions
            .push((layer.id, p, layer.max_volume_mm3 * scale));
        if let Some((z, (lo, hi, zd))) = zone {
            let (a, b) = (top.min(0.0), bottom.max(-zd));
            if a > b {
                let c = Vec3::new(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (a + b));
                let v = z.max_volume_mm3.min(layer.max_volume_mm3) * scale;
                plc.regions.push((layer.id, c, v));
            }
        }
    }
}

#[cfg(feature = "tetgen")]
fn run_tetgen(spec: &PatchSpec, scale: f64) -> Result<TetMesh> {
    use super::RawMesh;
    use std::collections::{BTreeMap, HashMap};
    let plc = build_plc(spec, scale);
    let fail = |e: &str| Error::MeshGeneration(format!("TetGen: {e}"));
    let facet_sizes = plc.facets.iter().map(|f| f.1.len()).collect();
    let raw = {
        // A poisoned lock only means another generation panicked; TetGen's
        // state is reset by each new instance, so carry on.
        let _guard = TETGEN_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let mut tg = tritet::Tetgen::new(
            plc.points.len(),
            Some(facet_sizes),
            Some(plc.regions.len()),
            None,
        )
        .map_err(fail)?;
        for (i, p) in plc.points.iter().enumerate() {
            tg.set_point(i, 0, p.x, p.y, p.z).map_err(fail)?;
        }
        for (i, (marker, pts)) in plc.facets.iter().enumerate() {
            for (m, &p) in pts.iter().enumerate() {
                tg.set_facet_point(i, m, p).map_err(fail)?;
            }
            tg.set_facet_marker(i, *marker).map_err(fail)?;
        }
        for (i, (id, p, vol)) in plc.regions.iter().enumerate() {
            tg.set_region(i, *id, p.x, p.y, p.z, Some(*vol))
                .map_err(fail)?;
        }
        tg.generate_mesh(false, false, None, Some(spec.radius_edge_max))
            .map_err(fail)?;
        let positions = (0..tg.out_npoint())
            .map(|i| Vec3::new(tg.out_point(i, 0), tg.out_point(i, 1), tg.out_point(i, 2)))
            .collect();
        let tets = (0..tg.out_ncell())
            .map(|c| std::array::from_fn(|m| tg.out_cell_point(c, m)))
            .collect();
        let tet_region = (0..tg.out_ncell()).map(|c| tg.out_cell_marker(c)).collect();
        let mut face_markers = HashMap::new();
        let mut pts = [0i32; 6];
        for f in 0..tg.out_n_marked_face() {
            let (marker, _) = tg.out_marked_face(f, &mut pts);
            if marker != markers::NONE {
                let key = super::face_key([pts[0], pts[1], pts[2]].map(|v| v as usize));
                face_markers.insert(key, marker);
            }
        }
        RawMesh {
            positions,
            tets,
            tet_region,
            region_names: spec
                .layers
                .iter()
                .map(|l| (l.id, l.name.clone()))
                .collect::<BTreeMap<_, _>>(),
            face_markers,
        }
    };
    // TetGen's numbering scatters each tet's vertices over the whole mesh;
    // the FEM's passes run faster on a banded one (see `super::order`).
    let mesh = TetMesh::from_raw("generated mesh", raw.reordered_for_locality())?;
    check_min_dihedral(&mesh, spec.min_dihedral_deg)?;
    Ok(mesh)
}

#[cfg(not(feature = "tetgen"))]
fn run_tetgen(spec: &PatchSpec, scale: f64) -> Result<TetMesh> {
    let _ = build_plc(spec, scale);
    Err(Error::FeatureDisabled(
        "mesh generation needs the `tetgen` cargo feature (enabled by default); \
         rebuild with it or load a mesh file instead"
            .into(),
    ))
}

#[cfg(feature = "tetgen")]
fn check_min_dihedral(mesh: &TetMesh, bound_deg: f64) -> Result<()> {
    if bound_deg <= 0.0 {
        return Ok(());
    }
    for t in 0..mesh.num_tets() {
        let worst = super::quality::dihedral_angles(&mesh.tet_points(t))
            .into_iter()
            .fold(f64::INFINITY, f64::min)
            .to_degrees();
        if worst < bound_deg {
            return Err(Error::MeshGeneration(format!(
                "tet {t} has a dihedral angle of {worst:.2}°, below mesh.min_dihedral_deg = \
                 {bound_deg}°; lower the bound or tighten mesh.radius_edge_max"
            )));
        }
    }
    Ok(())
}

/// The PLC of `spec` in TetGen's `.poly` format, so the same mesh can be
/// regenerated with the TetGen program: `tetgen -pq<radius_edge_max>aA file.poly`
/// (region volume limits are in the file; `target_tets` scaling is not, so
/// the limits written are the ones of `scale`).
pub fn poly_text(spec: &PatchSpec, scale: f64) -> String {
    use std::fmt::Write as _;
    let plc = build_plc(spec, scale);
    let mut s = String::new();
    let _ = writeln!(s, "# skinpatch layered patch PLC (mm); regenerate with:");
    let _ = writeln!(s, "#   tetgen -pq{}aA <this file>", spec.radius_edge_max);
    let _ = writeln!(s, "{} 3 0 0", plc.points.len());
    for (i, p) in plc.points.iter().enumerate() {
        let _ = writeln!(s, "{i} {:?} {:?} {:?}", p.x, p.y, p.z);
    }
    let _ = writeln!(s, "{} 1", plc.facets.len());
    for (marker, pts) in &plc.facets {
        let _ = writeln!(s, "1 0 {marker}");
        let list: Vec<String> = pts.iter().map(usize::to_string).collect();
        let _ = writeln!(s, "{} {}", pts.len(), list.join(" "));
    }
    let _ = writeln!(s, "0");
    let _ = writeln!(s, "{}", plc.regions.len());
    for (i, (id, p, vol)) in plc.regions.iter().enumerate() {
        let _ = writeln!(s, "{i} {:?} {:?} {:?} {id} {vol:?}", p.x, p.y, p.z);
    }
    s
}
