//! Tetrahedral meshes from VTK unstructured grids (`.vtu`, legacy `.vtk`).
//!
//! The tets are the grid's linear tetrahedra; vertices, lines and surface
//! cells are skipped with a warning that counts them (meshers and meshio
//! often keep the boundary triangles beside the volume), a cell whose
//! point count contradicts its type (a tetrahedron typed as a triangle) and
//! other volume cells refused. The region of each tet
//! comes from the first integer-valued cell array among [`REGION_ARRAYS`]
//! (the name this project writes, then those of Gmsh via meshio, VTK's
//! `CellEntityIds`, Medit and TetGen); without one the mesh is one region,
//! id 1. VTK has no place for region names, so regions are named
//! `region_<id>` (scenario materials refer to them by that name).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::vtk_data::cell;
use super::vtu::{load_unstructured, Values};
use crate::error::{Error, Result};
use crate::mesh::{RawMesh, TetMesh};

/// Cell arrays that hold region ids, in order of preference.
pub const REGION_ARRAYS: [&str; 6] = [
    "region",
    "gmsh:physical",
    "CellEntityIds",
    "medit:ref",
    "tetgen:ref",
    "RegionId",
];

/// Reads a tetrahedral mesh from a `.vtu` or legacy `.vtk` file.
pub fn read_vtk_mesh(path: &Path) -> Result<TetMesh> {
    let bad = |message: String| Error::malformed(path, message);
    let grid = load_unstructured(path)?;
    let mut tets = Vec::new();
    let mut tet_cells = Vec::new();
    let mut skipped: BTreeMap<String, usize> = BTreeMap::new();
    for (k, cell) in grid.cells.iter().enumerate() {
        let nodes = grid.nodes(cell);
        let kind = cell.kind;
        if let Some(n) = cell::fixed_points(kind).filter(|&n| n != nodes.len()) {
            return Err(bad(format!(
                "cell {k} is typed {}, which has {n} points, but lists {} points{}",
                cell::name(kind),
                nodes.len(),
                if nodes.len() == 4 && kind != cell::TETRA {
                    "; a tetrahedron is type 10"
                } else {
                    ""
                }
            )));
        }
        match kind {
            cell::TETRA => {
                tets.push([nodes[0], nodes[1], nodes[2], nodes[3]]);
                tet_cells.push(k);
            }
            _ if cell::below_volume(kind) => *skipped.entry(cell::name(kind)).or_default() += 1,
            cell::QUADRATIC_TETRA => {
                return Err(bad(format!(
                    "cell {k} is a quadratic tetrahedron; only linear tetrahedra are supported"
                )))
            }
            other => {
                return Err(bad(format!(
                    "cell {k} is a {}; only linear tetrahedra are supported as volume cells",
                    cell::name(other)
                )))
            }
        }
    }
    if tets.is_empty() {
        return Err(bad("the grid has no tetrahedra".into()));
    }
    if !skipped.is_empty() {
        let counts: Vec<String> = skipped.iter().map(|(t, n)| format!("{n} {t}")).collect();
        log::warn!(
            "{}: read {} tetrahedra; skipped {} (not volume cells)",
            path.display(),
            tets.len(),
            counts.join(", ")
        );
    }
    let tet_region = match REGION_ARRAYS
        .iter()
        .find_map(|name| grid.cell_data.iter().find(|f| f.name == *name))
    {
        Some(field) => {
            if field.components != 1 || field.values.len() != grid.cells.len() {
                return Err(bad(format!(
                    "cell array '{}' must hold one value per cell ({} cells), has {} × {}",
                    field.name,
                    grid.cells.len(),
                    field.values.len() / field.components.max(1),
                    field.components
                )));
            }
            let region_of = |k: usize| -> Result<i32> {
                match &field.values {
                    Values::I32(v) => Ok(v[k]),
                    Values::F64(v) => {
                        let x = v[k];
                        if x.fract() == 0.0 && x.abs() <= f64::from(i32::MAX) {
                            Ok(x as i32)
                        } else {
                            Err(bad(format!(
                                "cell array '{}' holds {x} at cell {k}; region ids are \
                                 integers within ±2147483647",
                                field.name
                            )))
                        }
                    }
                }
            };
            tet_cells
                .iter()
                .map(|&k| region_of(k))
                .collect::<Result<Vec<i32>>>()?
        }
        None => {
            log::warn!(
                "{}: no region array (looked for {}); the mesh is one region, id 1",
                path.display(),
                REGION_ARRAYS.join(", ")
            );
            vec![1; tets.len()]
        }
    };
    let raw = RawMesh {
        positions: grid.points,
        tets,
        tet_region,
        region_names: BTreeMap::new(),
        face_markers: HashMap::new(),
    };
    TetMesh::from_raw(&path.display().to_string(), raw)
}
