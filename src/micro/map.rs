//! Displacement maps: f32 heights on a texel grid.
//!
//! A map covers the UV square of the skin surface: texel `(i, j)` has its
//! centre at `u = (i + ½)/width`, `v = (j + ½)/height` (row 0 at v = 0, like
//! the strain raster). Heights are stored in `height_unit_um` micrometres per
//! unit; `texel_um` is the side of a texel on the skin at rest. Reads
//! outside the grid wrap around (a tileable map) or clamp to the edge.

use rayon::prelude::*;

/// What reads outside the grid return (`wrap` or `clamp` in files).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Edge {
    /// Periodic: the map tiles.
    Wrap,
    /// The nearest edge texel.
    Clamp,
}

/// A height field on a `width × height` texel grid.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplacementMap {
    /// Texels along u.
    pub width: usize,
    /// Texels along v.
    pub height: usize,
    /// Texel side on the skin (µm).
    pub texel_um: f64,
    /// Micrometres per height unit.
    pub height_unit_um: f64,
    /// Edge handling of reads outside the grid.
    pub edge: Edge,
    /// Heights, row-major (`j * width + i`).
    pub data: Vec<f32>,
}

impl DisplacementMap {
    /// A flat map of zeros.
    pub fn zeros(width: usize, height: usize, texel_um: f64, edge: Edge) -> DisplacementMap {
        DisplacementMap {
            width,
            height,
            texel_um,
            height_unit_um: 1.0,
            edge,
            data: vec![0.0; width * height],
        }
    }

    /// A map of the same size and metadata filled by `f(i, j)` (parallel over
    /// rows; each texel depends only on its coordinates).
    pub fn from_fn(
        width: usize,
        height: usize,
        texel_um: f64,
        edge: Edge,
        f: impl Fn(usize, usize) -> f32 + Sync,
    ) -> DisplacementMap {
        let mut map = DisplacementMap::zeros(width, height, texel_um, edge);
        map.data
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(j, row)| {
                for (i, h) in row.iter_mut().enumerate() {
                    *h = f(i, j);
                }
            });
        map
    }

    /// A map with this one's size and metadata and the heights `data`.
    pub fn with_data(&self, data: Vec<f32>) -> DisplacementMap {
        debug_assert_eq!(data.len(), self.data.len());
        DisplacementMap {
            data,
            ..self.clone_metadata()
        }
    }

    fn clone_metadata(&self) -> DisplacementMap {
        DisplacementMap {
            width: self.width,
            height: self.height,
            texel_um: self.texel_um,
            height_unit_um: self.height_unit_um,
            edge: self.edge,
            data: Vec::new(),
        }
    }

    /// Index of texel `(i, j)`.
    #[inline]
    pub fn index(&self, i: usize, j: usize) -> usize {
        j * self.width + i
    }

    /// Height at integer texel `(i, j)`, which may lie outside the grid.
    #[inline]
    pub fn texel(&self, i: isize, j: isize) -> f32 {
        let (i, j) = match self.edge {
            Edge::Wrap => (
                i.rem_euclid(self.width as isize) as usize,
                j.rem_euclid(self.height as isize) as usize,
            ),
            Edge::Clamp => (
                i.clamp(0, self.width as isize - 1) as usize,
                j.clamp(0, self.height as isize - 1) as usize,
            ),
        };
        self.data[j * self.width + i]
    }

    /// Bilinear sample at continuous texel coordinates `(x, y)`, where texel
    /// `(i, j)`'s centre is at `(i, j)` (so integer coordinates return texel
    /// values exactly).
    #[inline]
    pub fn bilinear(&self, x: f32, y: f32) -> f32 {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (i, j) = (x0 as isize, y0 as isize);
        let a = self.texel(i, j);
        let b = self.texel(i + 1, j);
        let c = self.texel(i, j + 1);
        let d = self.texel(i + 1, j + 1);
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        top + (bottom - top) * fy
    }

    /// [`DisplacementMap::bilinear`] at the two points `(at[0], at[1])` and
    /// `(at[2], at[3])`, each of whose four texels lies in the grid
    /// (`0 ≤ x < width − 1`, `0 ≤ y < height − 1`): the same values without
    /// edge handling. Outside that range a read is wrong (truncation is not
    /// the floor below 0) or panics on the bounds check; it never reads past
    /// the map.
    #[inline]
    pub fn bilinear_interior_pair(&self, at: [f32; 4]) -> [f32; 2] {
        // The four coordinates truncated in one packed conversion
        // (non-negative here, so truncation is the floor). A scalar `as i32`
        // wraps each conversion in saturation and NaN handling, which cost
        // about a tenth of the convolution's time.
        let at = wide::f32x4::from(at);
        let whole = at.fast_trunc_int();
        let frac = (at - wide::f32x4::from_i32x4(whole)).to_array();
        let whole = whole.to_array();
        let w = self.width;
        let read = |p: usize| {
            let (fx, fy) = (frac[2 * p], frac[2 * p + 1]);
            let k = whole[2 * p + 1] as usize * w + whole[2 * p] as usize;
            // One bounds check for the four texels: the slice from (x0, y0)
            // to (x0 + 1, y0 + 1).
            let span = &self.data[k..k + w + 2];
            let (a, b, c, d) = (span[0], span[1], span[w], span[w + 1]);
            let top = a + (b - a) * fx;
            let bottom = c + (d - c) * fx;
            top + (bottom - top) * fy
        };
        [read(0), read(1)]
    }

    /// Largest |self − other| over the texels, relative to this map's
    /// height range (how GPU and CPU results are compared).
    pub fn max_difference(&self, other: &DisplacementMap) -> f64 {
        let (lo, hi) = self.range();
        let worst = self
            .data
            .iter()
            .zip(&other.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        worst as f64 / (hi - lo).max(f32::MIN_POSITIVE) as f64
    }

    /// Smallest and largest height (units).
    pub fn range(&self) -> (f32, f32) {
        self.data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }

    /// The map resampled bilinearly onto a `width × height` grid over the
    /// same area (texel centres mapped onto each other, reads past the edge
    /// by the edge rule); the texel size scales with it.
    pub fn resampled(&self, width: usize, height: usize) -> DisplacementMap {
        let (sx, sy) = (
            self.width as f64 / width.max(1) as f64,
            self.height as f64 / height.max(1) as f64,
        );
        let mut out =
            DisplacementMap::from_fn(width, height, self.texel_um * sx, self.edge, |i, j| {
                let x = (i as f64 + 0.5) * sx - 0.5;
                let y = (j as f64 + 0.5) * sy - 0.5;
                self.bilinear(x as f32, y as f32)
            });
        out.height_unit_um = self.height_unit_um;
        out
    }

    /// The map turned by 90° counter-clockwise: texel `(i, j)` of the result
    /// is texel `(j, height − 1 − i)` of this one, so a feature along +u ends
    /// up along +v.
    pub fn rotated_90(&self) -> DisplacementMap {
        let mut out = self.clone_metadata();
        out.width = self.height;
        out.height = self.width;
        out.data = (0..out.height)
            .flat_map(|j| (0..out.width).map(move |i| (i, j)))
            .map(|(i, j)| self.data[self.index(j, self.height - 1 - i)])
            .collect();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(edge: Edge) -> DisplacementMap {
        DisplacementMap::from_fn(4, 3, 5.0, edge, |i, j| (10 * j + i) as f32)
    }

    #[test]
    fn edges_wrap_or_clamp() {
        let w = ramp(Edge::Wrap);
        assert_eq!(w.texel(-1, 0), 3.0);
        assert_eq!(w.texel(4, 3), 0.0);
        let c = ramp(Edge::Clamp);
        assert_eq!(c.texel(-1, 0), 0.0);
        assert_eq!(c.texel(5, 7), 23.0);
    }

    #[test]
    fn bilinear_is_exact_on_texels_and_linear_between() {
        let m = ramp(Edge::Clamp);
        assert_eq!(m.bilinear(2.0, 1.0), 12.0);
        assert!((m.bilinear(1.5, 0.25) - 4.0).abs() < 1e-6);
    }

    #[test]
    fn rotation_moves_u_features_to_v() {
        let m = ramp(Edge::Wrap);
        let r = m.rotated_90();
        assert_eq!((r.width, r.height), (3, 4));
        // Texel (i, j) of r is texel (j, height − 1 − i) of m.
        assert_eq!(r.data[r.index(0, 0)], m.data[m.index(0, 2)]);
        assert_eq!(r.data[r.index(2, 1)], m.data[m.index(1, 0)]);
        let back = r.rotated_90().rotated_90().rotated_90();
        assert_eq!(back, m);
    }

    #[test]
    fn resampling_keeps_linear_ramps_and_scales_the_texel() {
        // A ramp in x with clamped edges: doubling the resolution keeps the
        // ramp inside, halving it averages neighbours.
        let m = DisplacementMap::from_fn(8, 4, 10.0, Edge::Clamp, |i, _| i as f32);
        let up = m.resampled(16, 8);
        assert_eq!(up.texel_um, 5.0);
        // Texel i of the finer grid has its centre at (i + ½)/2 − ½ coarse texels.
        for i in 1..15 {
            let x = (i as f32 + 0.5) / 2.0 - 0.5;
            assert!((up.data[up.index(i, 3)] - x).abs() < 1e-6, "{i}");
        }
        let down = m.resampled(4, 2);
        assert_eq!(down.texel_um, 20.0);
        assert_eq!(down.data[down.index(1, 0)], 2.5);
        assert_eq!(m.resampled(8, 4), m);
    }
}
