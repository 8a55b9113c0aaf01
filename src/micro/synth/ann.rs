//! Approximate nearest-neighbour search over neighbourhood vectors: a k-d
//! tree with a run-time dimension and best-bin-first queries that stop
//! after a given number of leaves (the priority search of Arya and Mount's
//! ANN, which the synthesis of Graham et al. 2013 §4 uses).
//!
//! The dimension is a run-time value because the synthesis compares
//! PCA-reduced neighbourhoods (5 … 13 dimensions) with whole ones (up to
//! 2 · 13² = 338); the k-d tree crates of the ecosystem fix it at compile
//! time. Splits are on the widest coordinate at the median, so the tree
//! and every query are deterministic.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Points per leaf.
const LEAF: usize = 16;

/// A k-d tree over `n` points of dimension `dim`.
pub struct KdTree {
    dim: usize,
    /// The points, row-major, in tree order.
    points: Vec<f32>,
    /// The caller's index of each point, in tree order.
    ids: Vec<u32>,
    nodes: Vec<Node>,
}

#[derive(Clone, Copy)]
enum Node {
    /// Points `start .. end` of the tree order.
    Leaf { start: u32, end: u32 },
    /// Coordinate `dim` below `split` on the left.
    Split {
        dim: u32,
        split: f32,
        left: u32,
        right: u32,
    },
}

/// A node waiting in the priority queue, nearest bound first.
struct Pending {
    bound: f32,
    node: u32,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    // Reversed: `BinaryHeap` pops the largest, we want the smallest bound
    // (ties by node index, so the order never depends on the heap's layout).
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .bound
            .total_cmp(&self.bound)
            .then(other.node.cmp(&self.node))
    }
}

impl KdTree {
    /// A tree over `points` (row-major, `dim` values each); `ids[k]` is
    /// what a query returns for point `k`.
    pub fn new(dim: usize, points: &[f32], ids: &[u32]) -> KdTree {
        assert!(dim > 0 && points.len() == dim * ids.len());
        let mut order: Vec<u32> = (0..ids.len() as u32).collect();
        let mut nodes = Vec::new();
        build(dim, points, &mut order, 0, &mut nodes);
        let mut sorted = Vec::with_capacity(points.len());
        for &k in &order {
            sorted.extend_from_slice(&points[k as usize * dim..(k as usize + 1) * dim]);
        }
        KdTree {
            dim,
            points: sorted,
            ids: order.iter().map(|&k| ids[k as usize]).collect(),
            nodes,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the tree holds no point.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The id and squared distance of the nearest point found after
    /// visiting at most `max_leaves` leaves (nearest bounds first; 0 =
    /// exhaustive, the exact nearest point). Ties go to the point met
    /// first. `None` for an empty tree.
    pub fn nearest(&self, query: &[f32], max_leaves: usize) -> Option<(u32, f32)> {
        debug_assert_eq!(query.len(), self.dim);
        if self.ids.is_empty() {
            return None;
        }
        let mut best = (u32::MAX, f32::INFINITY);
        let mut heap = BinaryHeap::new();
        heap.push(Pending {
            bound: 0.0,
            node: 0,
        });
        let mut leaves = 0;
        while let Some(Pending { bound, node }) = heap.pop() {
            if bound >= best.1 {
                break;
            }
            // Down to a leaf, queueing the far sides.
            let mut at = node;
            loop {
                match self.nodes[at as usize] {
                    Node::Split {
                        dim,
                        split,
                        left,
                        right,
                    } => {
                        let d = query[dim as usize] - split;
                        let (near, far) = if d < 0.0 {
                            (left, right)
                        } else {
                            (right, left)
                        };
                        let far_bound = bound.max(d * d);
                        if far_bound < best.1 {
                            heap.push(Pending {
                                bound: far_bound,
                                node: far,
                            });
                        }
                        at = near;
                    }
                    Node::Leaf { start, end } => {
                        for k in start as usize..end as usize {
                            let p = &self.points[k * self.dim..(k + 1) * self.dim];
                            let d = squared_distance(query, p, best.1);
                            if d < best.1 {
                                best = (k as u32, d);
                            }
                        }
                        break;
                    }
                }
            }
            leaves += 1;
            if max_leaves > 0 && leaves >= max_leaves {
                break;
            }
        }
        Some((self.ids[best.0 as usize], best.1))
    }
}

/// `|a − b|²`, stopping early (with a value ≥ `limit`) once it exceeds `limit`.
#[inline]
pub fn squared_distance(a: &[f32], b: &[f32], limit: f32) -> f32 {
    let mut sum = 0.0f32;
    for (ca, cb) in a.chunks(4).zip(b.chunks(4)) {
        for (x, y) in ca.iter().zip(cb) {
            let d = x - y;
            sum += d * d;
        }
        if sum >= limit {
            return sum;
        }
    }
    sum
}

/// Builds the subtree over `order` (indices into `points`) and returns its
/// node index.
fn build(
    dim: usize,
    points: &[f32],
    order: &mut [u32],
    offset: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    let me = nodes.len() as u32;
    if order.len() <= LEAF {
        nodes.push(Node::Leaf {
            start: offset as u32,
            end: (offset + order.len()) as u32,
        });
        return me;
    }
    // The coordinate with the widest spread.
    let mut lo = vec![f32::INFINITY; dim];
    let mut hi = vec![f32::NEG_INFINITY; dim];
    for &k in order.iter() {
        let p = &points[k as usize * dim..(k as usize + 1) * dim];
        for c in 0..dim {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let axis = (0..dim)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])).then(b.cmp(&a)))
        .unwrap_or(0);
    if hi[axis] - lo[axis] <= 0.0 {
        // Every point equal: one leaf, however large.
        nodes.push(Node::Leaf {
            start: offset as u32,
            end: (offset + order.len()) as u32,
        });
        return me;
    }
    let mid = order.len() / 2;
    let key = |k: &u32| points[*k as usize * dim + axis];
    order.select_nth_unstable_by(mid, |a, b| key(a).total_cmp(&key(b)).then(a.cmp(b)));
    let split = key(&order[mid]);
    nodes.push(Node::Leaf { start: 0, end: 0 });
    let (left_part, right_part) = order.split_at_mut(mid);
    let left = build(dim, points, left_part, offset, nodes);
    let right = build(dim, points, right_part, offset + mid, nodes);
    nodes[me as usize] = Node::Split {
        dim: axis as u32,
        split,
        left,
        right,
    };
    me
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(n: usize, dim: usize) -> Vec<f32> {
        // A deterministic scatter.
        (0..n * dim)
            .map(|k| {
                ((k as f64 * 0.618_033_988_75).fract() * 2.0 - 1.0) as f32 * ((k % dim) + 1) as f32
            })
            .collect()
    }

    fn brute(points: &[f32], dim: usize, q: &[f32]) -> (u32, f32) {
        let mut best = (0u32, f32::INFINITY);
        for (k, p) in points.chunks(dim).enumerate() {
            let d = squared_distance(q, p, f32::INFINITY);
            if d < best.1 {
                best = (k as u32, d);
            }
        }
        best
    }

    #[test]
    fn exhaustive_queries_find_the_nearest_point() {
        for dim in [1, 3, 7, 20] {
            let n = 700;
            let pts = points(n, dim);
            let ids: Vec<u32> = (0..n as u32).collect();
            let tree = KdTree::new(dim, &pts, &ids);
            assert_eq!(tree.len(), n);
            for q in points(40, dim).chunks(dim) {
                let q: Vec<f32> = q.iter().map(|x| x * 0.93 + 0.01).collect();
                let (id, d) = tree.nearest(&q, 0).unwrap();
                let (bid, bd) = brute(&pts, dim, &q);
                assert_eq!(d, bd, "dim {dim}");
                let _ = (id, bid);
                // The distance of the returned id is the one reported.
                let p = &pts[id as usize * dim..(id as usize + 1) * dim];
                assert_eq!(squared_distance(&q, p, f32::INFINITY), d);
            }
        }
    }

    #[test]
    fn bounded_queries_are_close_and_never_better_than_exact() {
        let (n, dim) = (5000, 9);
        let pts = points(n, dim);
        let ids: Vec<u32> = (0..n as u32).map(|k| k * 3).collect();
        let tree = KdTree::new(dim, &pts, &ids);
        let mut ratio_sum = 0.0;
        let queries = points(100, dim);
        for q in queries.chunks(dim) {
            let exact = tree.nearest(q, 0).unwrap().1;
            let (id, approx) = tree.nearest(q, 8).unwrap();
            assert_eq!(id % 3, 0, "ids are the caller's");
            assert!(approx >= exact);
            ratio_sum += (approx / exact.max(1e-12)) as f64;
        }
        // Eight leaves of 16 points find neighbours within a few per cent
        // of the nearest distance on average in 9 dimensions.
        assert!(ratio_sum / 100.0 < 1.5, "mean ratio {}", ratio_sum / 100.0);
    }

    #[test]
    fn duplicate_points_and_empty_trees() {
        let pts = vec![1.0f32; 3 * 100];
        let ids: Vec<u32> = (0..100).collect();
        let tree = KdTree::new(3, &pts, &ids);
        assert_eq!(tree.nearest(&[1.0, 1.0, 1.0], 1).unwrap().1, 0.0);
        let empty = KdTree::new(2, &[], &[]);
        assert!(empty.is_empty());
        assert!(empty.nearest(&[0.0, 0.0], 0).is_none());
    }
}
