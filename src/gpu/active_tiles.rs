//! Which tiles of the map each stage of a microstructure frame runs on
//! (the tile lists of `convolve.wgsl`'s `convolve_strain` and
//! `normals.wgsl`'s `normals_tiles`).
//!
//! The map is cut into [`TILE`] × [`TILE`]-texel tiles, one workgroup each.
//! Two facts let a frame skip most of them without changing a bit of its
//! output:
//!
//! - **Off the surface nothing moves.** A texel more than the raster's
//!   dilation away from every surface texel takes the identity pass (α = 0
//!   returns the centre texel exactly), so D′ equals the neutral map there in
//!   every frame. The UV layout is fixed, so the tiles that can hold a
//!   surface texel or one of its dilated neighbours are known from the
//!   triangles' UV bounding boxes once ([`TilePlanner::surface`]); the
//!   intermediate and output maps start as copies of the neutral map and
//!   the other tiles are never dispatched.
//! - **Incremental frames** (opt-in, [`TilePlanner::new`]'s `tolerance`): a
//!   vertex whose raster values (`T − I`, and `Q Rᵀ` relative to its
//!   largest entry) moved by at most the tolerance since they were last
//!   convolved does not make its triangles' tiles dirty. The s pass reads
//!   the static neutral map, so it reruns on exactly the dirty tiles; the t
//!   pass reads the s pass's output up to a reach of `⌈3σ⌉ + 1` texels, so it
//!   reruns on the dirty tiles grown by that reach (σ bounded from the
//!   kernel model's largest σ and the largest texels-per-millimetre of any
//!   vertex frame); the normals read one texel around, so they rerun on the
//!   t tiles grown by one tile. With tolerance 0 an incremental frame equals
//!   a full frame bit for bit (only tiles whose inputs are unchanged keep
//!   their old values); with tolerance ε a tile keeps values computed from
//!   raster inputs within ε of the current ones.

use super::raster::RasterVertex;

/// Tile side in texels: the workgroup size of the tiled entry points.
pub const TILE: usize = 16;

/// A set of tiles over a `cols × rows` grid.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileMask {
    /// Tiles along u.
    pub cols: usize,
    /// Tiles along v.
    pub rows: usize,
    set: Vec<bool>,
}

impl TileMask {
    /// No tiles of the grid covering `width × height` texels.
    pub fn empty(width: usize, height: usize) -> TileMask {
        let (cols, rows) = (width.div_ceil(TILE), height.div_ceil(TILE));
        TileMask {
            cols,
            rows,
            set: vec![false; cols * rows],
        }
    }

    /// Every tile of the grid covering `width × height` texels.
    pub fn full(width: usize, height: usize) -> TileMask {
        let mut m = TileMask::empty(width, height);
        m.set.fill(true);
        m
    }

    /// Adds the tiles of the inclusive tile range `[x0, x1] × [y0, y1]`.
    pub fn add_range(&mut self, (x0, y0, x1, y1): TileRange) {
        for y in y0..=y1 {
            self.set[y * self.cols + x0..=y * self.cols + x1].fill(true);
        }
    }

    /// Adds every tile of `other` (same grid).
    pub fn add(&mut self, other: &TileMask) {
        debug_assert_eq!((self.cols, self.rows), (other.cols, other.rows));
        for (a, &b) in self.set.iter_mut().zip(&other.set) {
            *a |= b;
        }
    }

    /// Keeps only the tiles also in `other` (same grid).
    pub fn intersect(&mut self, other: &TileMask) {
        for (a, &b) in self.set.iter_mut().zip(&other.set) {
            *a &= b;
        }
    }

    /// The tiles within `by` tiles (Chebyshev distance) of one of these.
    pub fn grown(&self, by: usize) -> TileMask {
        if by == 0 {
            return self.clone();
        }
        let mut out = TileMask {
            set: vec![false; self.set.len()],
            ..*self
        };
        for y in 0..self.rows {
            for x in 0..self.cols {
                if self.set[y * self.cols + x] {
                    out.add_range((
                        x.saturating_sub(by),
                        y.saturating_sub(by),
                        (x + by).min(self.cols - 1),
                        (y + by).min(self.rows - 1),
                    ));
                }
            }
        }
        out
    }

    /// Whether tile `(x, y)` is in the set.
    pub fn contains(&self, x: usize, y: usize) -> bool {
        self.set[y * self.cols + x]
    }

    /// Tiles in the set.
    pub fn count(&self) -> usize {
        self.set.iter().filter(|&&b| b).count()
    }

    /// Texels of a `width × height` map inside the set's tiles (tiles on
    /// the map's far edges hold fewer than [`TILE`]² of them).
    pub fn texels(&self, width: usize, height: usize) -> usize {
        let side = |k: usize, n: usize| n.min((k + 1) * TILE) - k * TILE;
        (0..self.rows)
            .flat_map(|y| (0..self.cols).map(move |x| (x, y)))
            .filter(|&(x, y)| self.contains(x, y))
            .map(|(x, y)| side(x, width) * side(y, height))
            .sum()
    }

    /// Tiles in the grid.
    pub fn total(&self) -> usize {
        self.set.len()
    }

    /// The list the tiled entry points read: the count, then each tile as
    /// `x | y << 16`, row-major.
    pub fn list(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(1 + self.count());
        out.push(0);
        for (k, _) in self.set.iter().enumerate().filter(|(_, &b)| b) {
            out.push(((k % self.cols) | (k / self.cols) << 16) as u32);
        }
        out[0] = (out.len() - 1) as u32;
        out
    }
}

/// An inclusive tile range `(x0, y0, x1, y1)`.
pub type TileRange = (usize, usize, usize, usize);

/// The tiles each stage of one frame runs on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePlan {
    /// Tiles of the pass along s.
    pub pass_s: TileMask,
    /// Tiles of the pass along t.
    pub pass_t: TileMask,
    /// Tiles whose normals change.
    pub normals: TileMask,
}

/// Decides each frame's tiles from the surface's raster vertices.
#[derive(Clone, Debug)]
pub struct TilePlanner {
    width: usize,
    height: usize,
    /// Per triangle, the tiles its raster texels and their dilated
    /// neighbours can fall in.
    triangle_tiles: Vec<Option<TileRange>>,
    triangles: Vec<[usize; 3]>,
    surface: TileMask,
    sigma_max_um: f64,
    tolerance: Option<f32>,
    /// Per vertex, the raster values last convolved (none before the first
    /// frame).
    convolved: Option<Vec<RasterVertex>>,
}

impl TilePlanner {
    /// A planner for a `width × height` map, triangles `triangles` of UVs
    /// `uvs`, raster dilation `dilate` texels and kernel σ at most
    /// `sigma_max_um`. `tolerance`: `None` runs every surface tile each
    /// frame; `Some(ε)` makes frames incremental (see the module docs).
    pub fn new(
        (width, height): (usize, usize),
        triangles: &[[usize; 3]],
        uvs: &[[f64; 2]],
        dilate: usize,
        sigma_max_um: f64,
        tolerance: Option<f32>,
    ) -> TilePlanner {
        let margin = dilate as f64 + 1.0;
        let triangle_tiles: Vec<Option<TileRange>> = triangles
            .iter()
            .map(|tri| {
                let p = tri.map(|k| uvs[k]);
                triangle_tiles(p, [0.0, 0.0], (width, height), margin, TILE)
            })
            .collect();
        let mut surface = TileMask::empty(width, height);
        for range in triangle_tiles.iter().flatten() {
            surface.add_range(*range);
        }
        TilePlanner {
            width,
            height,
            triangle_tiles,
            triangles: triangles.to_vec(),
            surface,
            sigma_max_um,
            tolerance,
            convolved: None,
        }
    }

    /// The tiles a surface texel or one of its dilated neighbours can fall
    /// in; every other tile keeps the neutral map.
    pub fn surface(&self) -> &TileMask {
        &self.surface
    }

    /// The tiles of the next frame, whose raster vertices are `vertices`.
    pub fn plan(&mut self, vertices: &[RasterVertex]) -> FramePlan {
        let tolerance = match (self.tolerance, &self.convolved) {
            (Some(t), Some(last)) if last.len() == vertices.len() => t,
            _ => return self.full(vertices),
        };
        let last = self.convolved.as_mut().expect("checked above");
        let scale = vertices
            .iter()
            .flat_map(|v| v.frame)
            .fold(0.0f32, |m, x| m.max(x.abs()));
        let moved: Vec<bool> = vertices
            .iter()
            .zip(last.iter())
            .map(|(v, l)| {
                let dt = v.t.iter().zip(&l.t).map(|(a, b)| (a - b).abs());
                let df = v
                    .frame
                    .iter()
                    .zip(&l.frame)
                    .map(|(a, b)| (a - b).abs() / scale);
                dt.chain(df).any(|d| d > tolerance || d.is_nan())
            })
            .collect();
        let mut pass_s = TileMask::empty(self.width, self.height);
        for (tri, range) in self.triangles.iter().zip(&self.triangle_tiles) {
            if let Some(range) = range {
                if tri.iter().any(|&k| moved[k]) {
                    pass_s.add_range(*range);
                }
            }
        }
        for (l, (v, &m)) in last.iter_mut().zip(vertices.iter().zip(&moved)) {
            if m {
                *l = *v;
            }
        }
        let mut pass_t = pass_s.grown(self.reach_tiles(vertices));
        // Off the surface the t pass is the identity of an unchanged map.
        pass_t.intersect(&self.surface);
        let normals = pass_t.grown(1);
        FramePlan {
            pass_s,
            pass_t,
            normals,
        }
    }

    /// Every surface tile (the first frame, or frames that are not
    /// incremental); normals everywhere on the first frame.
    fn full(&mut self, vertices: &[RasterVertex]) -> FramePlan {
        let normals = if self.convolved.is_none() {
            TileMask::full(self.width, self.height)
        } else {
            self.surface.grown(1)
        };
        self.convolved = Some(vertices.to_vec());
        FramePlan {
            pass_s: self.surface.clone(),
            pass_t: self.surface.clone(),
            normals,
        }
    }

    /// How far (in tiles) the t pass reads the s pass's output
    /// ([`pass_reach`]); the whole grid when the bound is not finite.
    fn reach_tiles(&self, vertices: &[RasterVertex]) -> usize {
        match pass_reach(vertices, (self.width, self.height), self.sigma_max_um) {
            Some(reach) => reach.div_ceil(TILE),
            None => self.surface.cols.max(self.surface.rows),
        }
    }
}

/// The inclusive range of `tile`-texel tiles of a `width × height` map that
/// the texels within `margin` texels of triangle `uvs` (moved by `shift`
/// UV) can fall in; `None` when it misses the map or is not finite. Texel
/// `i` has its centre at `u = (i + ½)/width`.
pub fn triangle_tiles(
    uvs: [[f64; 2]; 3],
    shift: [f64; 2],
    (width, height): (usize, usize),
    margin: f64,
    tile: usize,
) -> Option<TileRange> {
    let size = [width as f64, height as f64];
    let mut range = [[0.0; 2]; 2];
    for c in 0..2 {
        let lo = uvs.iter().map(|q| q[c]).fold(f64::INFINITY, f64::min) + shift[c];
        let hi = uvs.iter().map(|q| q[c]).fold(f64::NEG_INFINITY, f64::max) + shift[c];
        let first = (lo * size[c] - 0.5 - margin).floor();
        let last = (hi * size[c] - 0.5 + margin).ceil();
        if !(first.is_finite() && last.is_finite()) || last < 0.0 || first >= size[c] {
            return None;
        }
        range[c] = [first, last];
    }
    let at = |t: f64, n: usize| (t.max(0.0) as usize / tile).min(n.div_ceil(tile) - 1);
    Some((
        at(range[0][0], width),
        at(range[1][0], height),
        at(range[0][1], width),
        at(range[1][1], height),
    ))
}

/// How far (texels) a pass at any texel of a `width × height` map reads
/// around it: `⌈3σ⌉` taps of unit length plus the bilinear neighbour, σ in
/// texels at most `sigma_max_um` times the largest texels per millimetre of
/// any vertex frame (interpolation and dilation cannot exceed the
/// vertices' largest). `None` when a frame is not finite.
pub fn pass_reach(
    vertices: &[RasterVertex],
    (width, height): (usize, usize),
    sigma_max_um: f64,
) -> Option<usize> {
    let (w, h) = (width as f64, height as f64);
    let per_mm = vertices
        .iter()
        .map(|v| {
            let f = v.frame.map(f64::from);
            // Frobenius norm of diag(w, h)·Q Rᵀ bounds its columns' lengths.
            ((f[0] * w).powi(2) + (f[1] * w).powi(2) + (f[2] * h).powi(2) + (f[3] * h).powi(2))
                .sqrt()
        })
        .fold(0.0f64, |m, x| {
            if m.is_nan() || x.is_nan() {
                f64::NAN
            } else {
                m.max(x)
            }
        });
    // A margin for the shader's f32 arithmetic.
    let sigma = sigma_max_um * 1e-3 * per_mm * (1.0 + 1e-4);
    sigma.is_finite().then(|| (3.0 * sigma).ceil() as usize + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(t: f32, frame: f32) -> RasterVertex {
        RasterVertex {
            uv: [0.0, 0.0],
            t: [t, 0.0, 0.0, 0.0],
            frame: [frame, 0.0, 0.0, frame],
        }
    }

    #[test]
    fn texels_of_a_mask_stop_at_the_map_edges() {
        // 40 × 20 texels: tiles of 16, 16 and 8 columns, 16 and 4 rows.
        let mut m = TileMask::empty(40, 20);
        assert_eq!(m.texels(40, 20), 0);
        m.add_range((2, 1, 2, 1));
        assert_eq!(m.texels(40, 20), 8 * 4);
        m.add_range((0, 0, 1, 0));
        assert_eq!(m.texels(40, 20), 8 * 4 + 2 * 256);
        assert_eq!(TileMask::full(40, 20).texels(40, 20), 800);
    }

    /// Two triangles: one in the top-left corner, one far from it.
    fn planner(tolerance: Option<f32>) -> TilePlanner {
        let uvs = [
            [0.01, 0.01],
            [0.05, 0.01],
            [0.01, 0.05],
            [0.9, 0.9],
            [0.95, 0.9],
            [0.9, 0.95],
        ];
        TilePlanner::new(
            (256, 256),
            &[[0, 1, 2], [3, 4, 5]],
            &uvs,
            4,
            10.0,
            tolerance,
        )
    }

    #[test]
    fn a_list_holds_its_count_then_packed_tiles() {
        let mut m = TileMask::empty(40, 20);
        assert_eq!((m.cols, m.rows), (3, 2));
        m.add_range((1, 1, 2, 1));
        assert_eq!(m.list(), vec![2, 1 | 1 << 16, 2 | 1 << 16]);
        let g = m.grown(1);
        assert_eq!(g.count(), 6);
        assert_eq!(TileMask::empty(0, 0).list(), vec![0]);
    }

    #[test]
    fn the_surface_covers_the_triangles_and_their_dilation_only() {
        let p = planner(None);
        // Triangle 1 spans texels 2.1 … 12.3 (+ 5 margin): tiles 0 … 1.
        assert!(p.surface().contains(0, 0) && p.surface().contains(1, 1));
        // Triangle 2 spans texels 229.9 … 242.7: tiles 14 … 15.
        assert!(p.surface().contains(14, 14) && p.surface().contains(15, 15));
        assert!(!p.surface().contains(7, 7) && !p.surface().contains(2, 0));
        assert_eq!(p.surface().count(), 8);
    }

    #[test]
    fn incremental_frames_follow_the_vertices_that_moved() {
        let mut p = planner(Some(1e-3));
        let rest: Vec<RasterVertex> = (0..6).map(|_| vertex(0.0, 0.01)).collect();
        let first = p.plan(&rest);
        assert_eq!(first.pass_s, *p.surface());
        assert_eq!(first.normals.count(), first.normals.total());
        // Nothing moved: nothing to do.
        let still = p.plan(&rest);
        assert_eq!(
            (
                still.pass_s.count(),
                still.pass_t.count(),
                still.normals.count()
            ),
            (0, 0, 0)
        );
        // Below the tolerance, and drift does not accumulate unseen: the
        // values are compared with those last convolved.
        let mut moved = rest.clone();
        moved[4] = vertex(0.0009, 0.01);
        assert_eq!(p.plan(&moved).pass_s.count(), 0);
        moved[4] = vertex(0.0018, 0.01);
        let plan = p.plan(&moved);
        assert!(plan.pass_s.contains(15, 15) && !plan.pass_s.contains(0, 0));
        // Frames of 0.01 UV/mm on 256 texels: ≤ 3.7 texels/mm, σ ≤ 0.04
        // texels, reach 2 texels: one tile around the s tiles, on the surface.
        assert_eq!(plan.pass_t, plan.pass_s);
        assert_eq!(plan.normals, plan.pass_t.grown(1));
        // A NaN always counts as moved.
        moved[0] = vertex(f32::NAN, 0.01);
        assert!(p.plan(&moved).pass_s.contains(0, 0));
    }

    #[test]
    fn frames_that_are_not_incremental_run_every_surface_tile() {
        let mut p = planner(None);
        let rest: Vec<RasterVertex> = (0..6).map(|_| vertex(0.0, 0.01)).collect();
        p.plan(&rest);
        let again = p.plan(&rest);
        assert_eq!(again.pass_s, *p.surface());
        assert_eq!(again.pass_t, *p.surface());
        assert_eq!(again.normals, p.surface().grown(1));
    }

    #[test]
    fn a_wide_kernel_reaches_across_tiles() {
        let mut p = planner(Some(0.0));
        let rest: Vec<RasterVertex> = (0..6).map(|_| vertex(0.0, 1.0)).collect();
        p.plan(&rest);
        let mut moved = rest.clone();
        moved[0] = vertex(0.1, 1.0);
        // Frames of 1 UV/mm on 256 texels: ≤ 363 texels/mm, σ ≤ 3.7 texels,
        // reach 12 texels → 1 tile; the other triangle's tiles stay untouched.
        let plan = p.plan(&moved);
        assert_eq!(plan.pass_t, {
            let mut m = plan.pass_s.grown(1);
            m.intersect(p.surface());
            m
        });
        assert!(!plan.pass_t.contains(15, 15));
    }
}
