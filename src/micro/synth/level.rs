//! One pyramid level of the synthesis ([`super::synthesize`]): the
//! exemplar's features (windows of A_h and A′_h, PCA-projected) in a k-d
//! tree, the start of S at the coarsest level or its upsampling from the
//! coarser one, and the correction passes (best approximate against best
//! coherent match, four parity sub-passes each).

use rayon::prelude::*;

use super::ann::{squared_distance, KdTree};
use super::SynthParams;
use crate::micro::map::{DisplacementMap, Edge};
use crate::micro::procedural::mix;

/// The feature projection: PCA (mean, then rows of the basis) or none.
pub(super) struct Projection {
    input: usize,
    mean: Vec<f32>,
    /// `dims × input`, row-major; empty: the identity.
    basis: Vec<f32>,
}

impl Projection {
    pub(super) fn dims(&self) -> usize {
        if self.basis.is_empty() {
            self.input
        } else {
            self.basis.len() / self.input
        }
    }

    fn apply(&self, x: &[f32], out: &mut [f32]) {
        if self.basis.is_empty() {
            out.copy_from_slice(x);
            return;
        }
        for (o, row) in out.iter_mut().zip(self.basis.chunks(self.input)) {
            let mut sum = 0.0f32;
            for ((r, xi), m) in row.iter().zip(x).zip(&self.mean) {
                sum += r * (xi - m);
            }
            *o = sum;
        }
    }

    /// The `dims` leading principal axes of `features` (rows of `input`
    /// values), from at most `MAX_SAMPLES` rows taken at a fixed stride.
    fn pca(
        input: usize,
        dims: usize,
        rows: usize,
        feature: impl Fn(usize, &mut [f32]) + Sync,
    ) -> Projection {
        const MAX_SAMPLES: usize = 8192;
        const CHUNK: usize = 256;
        let stride = rows.div_ceil(MAX_SAMPLES).max(1);
        let samples: Vec<usize> = (0..rows).step_by(stride).collect();
        // Mean and second moments per chunk of samples (f64), added in
        // chunk order: the same sums on any thread count.
        let partial: Vec<(Vec<f64>, Vec<f64>)> = samples
            .par_chunks(CHUNK)
            .map(|chunk| {
                let mut x = vec![0.0f32; input];
                let mut sum = vec![0.0f64; input];
                let mut outer = vec![0.0f64; input * input];
                for &r in chunk {
                    feature(r, &mut x);
                    for a in 0..input {
                        let xa = x[a] as f64;
                        sum[a] += xa;
                        let row = &mut outer[a * input..(a + 1) * input];
                        for (o, &xb) in row[a..].iter_mut().zip(&x[a..]) {
                            *o += xa * xb as f64;
                        }
                    }
                }
                (sum, outer)
            })
            .collect();
        let n = samples.len() as f64;
        let mut sum = vec![0.0f64; input];
        let mut outer = vec![0.0f64; input * input];
        for (s, o) in partial {
            sum.iter_mut().zip(s).for_each(|(a, b)| *a += b);
            outer.iter_mut().zip(o).for_each(|(a, b)| *a += b);
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / n).collect();
        let cov = nalgebra::DMatrix::from_fn(input, input, |a, b| {
            let (a, b) = (a.min(b), a.max(b));
            outer[a * input + b] / n - mean[a] * mean[b]
        });
        let eig = nalgebra::SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..input).collect();
        order.sort_by(|&a, &b| {
            eig.eigenvalues[b]
                .total_cmp(&eig.eigenvalues[a])
                .then(a.cmp(&b))
        });
        let mut basis = Vec::with_capacity(dims * input);
        for &c in order.iter().take(dims) {
            basis.extend(eig.eigenvectors.column(c).iter().map(|&v| v as f32));
        }
        Projection {
            input,
            mean: mean.iter().map(|&m| m as f32).collect(),
            basis,
        }
    }
}

/// One pyramid level's images, exemplar features and search tree.
pub(super) struct LevelData<'a> {
    pub(super) ex_a1: &'a DisplacementMap,
    pub(super) guide: &'a DisplacementMap,
    pub(super) window: usize,
    /// Window offsets and the square roots of their Gaussian weights.
    taps: Vec<(isize, isize, f32)>,
    /// √(1 − α), √α.
    weights: (f32, f32),
    pub(super) projection: Projection,
    /// Exemplar texels that can be matched.
    pub(super) candidates: Vec<u32>,
    /// Exemplar texel → index into `candidates` (`u32::MAX`: none).
    candidate_of: Vec<u32>,
    /// Projected features of the candidates, `dims` each.
    features: Vec<f32>,
    tree: KdTree,
    ann_leaves: usize,
    /// `(1 + 2^(l − L) κ)²`.
    coherence_factor: f32,
}

impl<'a> LevelData<'a> {
    pub(super) fn new(
        ex_a: &'a DisplacementMap,
        ex_a1: &'a DisplacementMap,
        guide: &'a DisplacementMap,
        exemplar_edge: Edge,
        params: &SynthParams,
        level: usize,
    ) -> LevelData<'a> {
        let n = params.window(level);
        let r = (n / 2) as isize;
        let sigma = r.max(1) as f32;
        let mut taps = Vec::with_capacity(n * n);
        for dy in -r..=r {
            for dx in -r..=r {
                let g = (-((dx * dx + dy * dy) as f32) / (2.0 * sigma * sigma)).exp();
                taps.push((dx, dy, g.sqrt()));
            }
        }
        let weights = (
            (1.0 - params.alpha).sqrt() as f32,
            params.alpha.sqrt() as f32,
        );
        let (ew, eh) = (ex_a1.width, ex_a1.height);
        let inside = |x: usize, y: usize| match exemplar_edge {
            Edge::Wrap => true,
            Edge::Clamp => {
                let r = r as usize;
                x >= r && y >= r && x + r < ew && y + r < eh
            }
        };
        let candidates: Vec<u32> = (0..ew * eh)
            .filter(|&p| inside(p % ew, p / ew))
            .map(|p| p as u32)
            .collect();
        let mut candidate_of = vec![u32::MAX; ew * eh];
        for (k, &p) in candidates.iter().enumerate() {
            candidate_of[p as usize] = k as u32;
        }
        let input = 2 * taps.len();
        let exemplar_feature = |k: usize, out: &mut [f32]| {
            let p = candidates[k] as usize;
            let (x, y) = ((p % ew) as isize, (p / ew) as isize);
            let (a_half, a1_half) = out.split_at_mut(taps.len());
            for (t, &(dx, dy, g)) in taps.iter().enumerate() {
                a_half[t] = weights.0 * g * ex_a.texel(x + dx, y + dy);
                a1_half[t] = weights.1 * g * ex_a1.texel(x + dx, y + dy);
            }
        };
        let dims = params.pca_dims.unwrap_or(n).min(input);
        let projection = if dims == 0 {
            Projection {
                input,
                mean: vec![0.0; input],
                basis: Vec::new(),
            }
        } else {
            Projection::pca(input, dims, candidates.len(), exemplar_feature)
        };
        let d = projection.dims();
        let mut features = vec![0.0f32; candidates.len() * d];
        features
            .par_chunks_mut(d * 1024)
            .enumerate()
            .for_each(|(c, chunk)| {
                let mut x = vec![0.0f32; input];
                for (o, out) in chunk.chunks_mut(d).enumerate() {
                    exemplar_feature(c * 1024 + o, &mut x);
                    projection.apply(&x, out);
                }
            });
        let ids: Vec<u32> = (0..candidates.len() as u32).collect();
        let tree = KdTree::new(d, &features, &ids);
        let finest = (params.levels - 1) as i32;
        let f = 1.0 + 2f64.powi(level as i32 - finest) * params.kappa;
        LevelData {
            ex_a1,
            guide,
            window: n,
            taps,
            weights,
            projection,
            candidates,
            candidate_of,
            features,
            tree,
            ann_leaves: params.ann_leaves,
            coherence_factor: (f * f) as f32,
        }
    }

    /// The coarsest level's start: blocks of `window × window` output
    /// texels, each a piece of the exemplar at an offset drawn from (seed,
    /// block). Coherent pieces from the start: a start of independent
    /// random texels leaves the coarse levels, where the coherence rule
    /// favours the approximate match, as a patchwork of single texels.
    pub(super) fn start(&self, seed: u64) -> Vec<u32> {
        let (w, h) = (self.guide.width, self.guide.height);
        let (ew, eh) = (self.ex_a1.width, self.ex_a1.height);
        let b = self.window;
        (0..w * h)
            .map(|q| {
                let (i, j) = (q % w, q / w);
                let block = ((j / b) * w.div_ceil(b) + i / b) as u64;
                let offset = mix(seed ^ mix(block + 0x5157_4e54));
                let (ox, oy) = (
                    (offset % ew as u64) as usize,
                    ((offset >> 32) % eh as u64) as usize,
                );
                self.nearest_candidate((ox + i % b) as isize, (oy + j % b) as isize, ew, eh)
            })
            .collect()
    }

    /// The coarser level's sources carried to this level: texel (i, j)
    /// takes child (i mod 2, j mod 2) of its parent's source.
    pub(super) fn upsample(
        &self,
        coarse: &[u32],
        coarse_width: usize,
        coarse_exemplar_width: usize,
    ) -> Vec<u32> {
        let (w, h) = (self.guide.width, self.guide.height);
        let (ew, eh) = (self.ex_a1.width, self.ex_a1.height);
        (0..w * h)
            .map(|q| {
                let (i, j) = (q % w, q / w);
                let p = coarse[(j / 2) * coarse_width + i / 2] as usize;
                let (px, py) = (p % coarse_exemplar_width, p / coarse_exemplar_width);
                let (x, y) = (2 * px + i % 2, 2 * py + j % 2);
                self.nearest_candidate(x as isize, y as isize, ew, eh)
            })
            .collect()
    }

    /// The exemplar texel (x, y), wrapped, or moved to the nearest candidate.
    fn nearest_candidate(&self, x: isize, y: isize, ew: usize, eh: usize) -> u32 {
        let (x, y) = (
            x.rem_euclid(ew as isize) as usize,
            y.rem_euclid(eh as isize) as usize,
        );
        let p = y * ew + x;
        if self.candidate_of[p] != u32::MAX {
            return p as u32;
        }
        // Clamped exemplar: into the interior.
        let r = self.window / 2;
        let cx = x.clamp(r, ew - 1 - r);
        let cy = y.clamp(r, eh - 1 - r);
        (cy * ew + cx) as u32
    }

    /// One correction pass (four parity sub-passes); returns how many
    /// texels took the coherence match.
    pub(super) fn correct(&self, s: &mut [u32]) -> usize {
        let (w, h) = (self.guide.width, self.guide.height);
        let mut coherent = 0;
        for parity in 0..4 {
            let (px, py) = (parity % 2, parity / 2);
            let rows: Vec<usize> = (py..h).step_by(2).collect();
            let current: &[u32] = s;
            let updates: Vec<(Vec<u32>, usize)> = rows
                .par_iter()
                .map_init(
                    || Scratch::new(2 * self.taps.len(), self.projection.dims()),
                    |scratch, &j| {
                        let mut row = Vec::with_capacity(w / 2 + 1);
                        let mut count = 0;
                        for i in (px..w).step_by(2) {
                            let (p, c) = self.best_match(current, i, j, scratch);
                            row.push(p);
                            count += c as usize;
                        }
                        (row, count)
                    },
                )
                .collect();
            for (&j, (row, count)) in rows.iter().zip(updates) {
                coherent += count;
                for (k, p) in row.into_iter().enumerate() {
                    s[j * w + px + 2 * k] = p;
                }
            }
        }
        coherent
    }

    /// Output texel `q + (dx, dy)` by the output's edge rule.
    #[inline]
    fn output_index(&self, i: usize, j: usize, dx: isize, dy: isize) -> usize {
        let (w, h) = (self.guide.width as isize, self.guide.height as isize);
        let (x, y) = (i as isize + dx, j as isize + dy);
        let (x, y) = match self.guide.edge {
            Edge::Wrap => (x.rem_euclid(w), y.rem_euclid(h)),
            Edge::Clamp => (x.clamp(0, w - 1), y.clamp(0, h - 1)),
        };
        (y * w + x) as usize
    }

    /// The exemplar texel for output texel (i, j) and whether it is the
    /// coherence match.
    fn best_match(&self, s: &[u32], i: usize, j: usize, scratch: &mut Scratch) -> (u32, bool) {
        let n = self.taps.len();
        {
            let (b_half, b1_half) = scratch.x.split_at_mut(n);
            for (t, &(dx, dy, g)) in self.taps.iter().enumerate() {
                let q = self.output_index(i, j, dx, dy);
                b_half[t] = self.weights.0 * g * self.guide.data[q];
                b1_half[t] = self.weights.1 * g * self.ex_a1.data[s[q] as usize];
            }
        }
        self.projection.apply(&scratch.x, &mut scratch.y);
        let y = &scratch.y;
        let d = y.len();
        let (k_app, d_app) = self
            .tree
            .nearest(y, self.ann_leaves)
            .expect("a level has candidates");
        // Coherence candidates: S(q) and S(r) + (q − r) for the 8 neighbours.
        let (ew, eh) = (self.ex_a1.width as isize, self.ex_a1.height as isize);
        let wraps = self.candidates.len() == (ew * eh) as usize;
        let mut best_coh = (u32::MAX, f32::INFINITY);
        for (dx, dy) in NEIGHBOURS {
            let r = self.output_index(i, j, dx, dy);
            let p = s[r] as isize;
            let (mut x, mut y0) = (p % ew - dx, p / ew - dy);
            if wraps {
                x = x.rem_euclid(ew);
                y0 = y0.rem_euclid(eh);
            } else if x < 0 || y0 < 0 || x >= ew || y0 >= eh {
                continue;
            }
            let c = self.candidate_of[(y0 * ew + x) as usize];
            if c == u32::MAX {
                continue;
            }
            let f = &self.features[c as usize * d..(c as usize + 1) * d];
            let dist = squared_distance(y, f, best_coh.1);
            if dist < best_coh.1 {
                best_coh = (c, dist);
            }
        }
        if best_coh.0 != u32::MAX && best_coh.1 <= d_app * self.coherence_factor {
            (self.candidates[best_coh.0 as usize], true)
        } else {
            (self.candidates[k_app as usize], false)
        }
    }
}

/// The coherence candidates' offsets: the texel itself, then its eight
/// neighbours.
const NEIGHBOURS: [(isize, isize); 9] = [
    (0, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// Per-thread buffers of a pass.
struct Scratch {
    x: Vec<f32>,
    y: Vec<f32>,
}

impl Scratch {
    fn new(input: usize, dims: usize) -> Scratch {
        Scratch {
            x: vec![0.0; input],
            y: vec![0.0; dims],
        }
    }
}
