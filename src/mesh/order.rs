//! Numbering for memory locality: reverse Cuthill–McKee on the vertex graph
//! and tets sorted by their new vertices.
//!
//! TetGen numbers vertices in insertion order and tets as its cavities
//! left them: the four vertices of a tet of `patch_25k` lie ~2,500 indices
//! apart on average, and the tets at one vertex are spread over the whole
//! tet array. Every FEM pass then reads scattered memory: the per-node
//! gather of the stiffness reads each incident tet's blocks from anywhere in
//! 19 MB. Renumbered, a tet's vertices lie ~390 apart and a vertex's tets
//! sit together (docs/PERFORMANCE.md has the figures). The geometry, the
//! regions and the boundary markers are unchanged; only the numbering is.

use std::collections::VecDeque;

use super::RawMesh;

impl super::TetMesh {
    /// This mesh renumbered by [`RawMesh::reordered_for_locality`]: the
    /// same tets, regions and boundary markers.
    pub fn renumbered(&self) -> crate::error::Result<super::TetMesh> {
        let raw = RawMesh {
            positions: self.positions.clone(),
            tets: self.tets.clone(),
            tet_region: self.tet_region.clone(),
            region_names: self
                .regions
                .iter()
                .map(|r| (r.id, r.name.clone()))
                .collect(),
            face_markers: self
                .boundary
                .iter()
                .filter(|f| f.marker != super::markers::NONE)
                .map(|f| (super::face_key(f.nodes), f.marker))
                .collect(),
        };
        super::TetMesh::from_raw("renumbered mesh", raw.reordered_for_locality())
    }

    /// The mean spread of each tet's vertex indices (largest minus
    /// smallest): a measure of how far apart the FEM's passes read.
    pub fn mean_tet_index_span(&self) -> f64 {
        let total: usize = self
            .tets
            .iter()
            .map(|t| t.iter().max().unwrap_or(&0) - t.iter().min().unwrap_or(&0))
            .sum();
        total as f64 / self.tets.len().max(1) as f64
    }
}

impl RawMesh {
    /// The same mesh with vertices in reverse Cuthill–McKee order and tets
    /// sorted by their lowest new vertex (then by the others); tet regions
    /// and face markers follow. Deterministic: ties break by old index.
    pub fn reordered_for_locality(self) -> RawMesh {
        let n = self.positions.len();
        let order = reverse_cuthill_mckee(n, &self.tets);
        let mut new_index = vec![0usize; n];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        let renumbered: Vec<[usize; 4]> =
            self.tets.iter().map(|t| t.map(|v| new_index[v])).collect();
        let mut tet_order: Vec<usize> = (0..renumbered.len()).collect();
        tet_order.sort_by_key(|&t| {
            let mut key = renumbered[t];
            key.sort_unstable();
            (key, t)
        });
        RawMesh {
            positions: order.iter().map(|&v| self.positions[v]).collect(),
            tets: tet_order.iter().map(|&t| renumbered[t]).collect(),
            tet_region: tet_order.iter().map(|&t| self.tet_region[t]).collect(),
            region_names: self.region_names,
            face_markers: self
                .face_markers
                .into_iter()
                .map(|(face, marker)| (super::face_key(face.map(|v| new_index[v])), marker))
                .collect(),
        }
    }
}

/// The reverse Cuthill–McKee order of the `n` vertices of `tets`: each
/// connected part is walked breadth first from a pseudo-peripheral vertex,
/// neighbours in ascending degree, and the whole order reversed. Returns
/// the old index of each new vertex. Vertices in no tet come last.
fn reverse_cuthill_mckee(n: usize, tets: &[[usize; 4]]) -> Vec<usize> {
    let adjacency = vertex_graph(n, tets);
    let degree = |v: usize| adjacency[v].len();
    let mut visited = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut isolated = Vec::new();
    for seed in 0..n {
        if visited[seed] {
            continue;
        }
        if adjacency[seed].is_empty() {
            visited[seed] = true;
            isolated.push(seed);
            continue;
        }
        let start = pseudo_peripheral(seed, &adjacency);
        let first = order.len();
        visited[start] = true;
        order.push(start);
        let mut head = first;
        while head < order.len() {
            let v = order[head];
            head += 1;
            let mut next: Vec<usize> = adjacency[v]
                .iter()
                .copied()
                .filter(|&w| !visited[w])
                .collect();
            next.sort_by_key(|&w| (degree(w), w));
            for w in next {
                visited[w] = true;
                order.push(w);
            }
        }
    }
    order.reverse();
    order.extend(isolated);
    order
}

/// Each vertex's neighbours (vertices sharing a tet), ascending.
fn vertex_graph(n: usize, tets: &[[usize; 4]]) -> Vec<Vec<usize>> {
    let mut adjacency = vec![Vec::new(); n];
    for tet in tets {
        for &a in tet {
            for &b in tet {
                if a != b {
                    adjacency[a].push(b);
                }
            }
        }
    }
    for list in &mut adjacency {
        list.sort_unstable();
        list.dedup();
    }
    adjacency
}

/// A vertex far from the rest of its connected part (George & Liu's
/// heuristic): from `seed`, repeatedly move to the lowest-degree vertex of
/// the last breadth-first level while the number of levels grows.
fn pseudo_peripheral(seed: usize, adjacency: &[Vec<usize>]) -> usize {
    let mut start = seed;
    let mut depth = 0;
    loop {
        let (levels, last) = breadth_first_levels(start, adjacency);
        let candidate = last
            .into_iter()
            .min_by_key(|&v| (adjacency[v].len(), v))
            .unwrap_or(start);
        if levels <= depth || candidate == start {
            return start;
        }
        depth = levels;
        start = candidate;
    }
}

/// The number of breadth-first levels from `start` and the vertices of
/// the last one.
fn breadth_first_levels(start: usize, adjacency: &[Vec<usize>]) -> (usize, Vec<usize>) {
    let mut level = vec![usize::MAX; adjacency.len()];
    level[start] = 0;
    let mut queue = VecDeque::from([start]);
    let mut deepest = 0;
    while let Some(v) = queue.pop_front() {
        deepest = deepest.max(level[v]);
        for &w in &adjacency[v] {
            if level[w] == usize::MAX {
                level[w] = level[v] + 1;
                queue.push_back(w);
            }
        }
    }
    let last = (0..adjacency.len())
        .filter(|&v| level[v] == deepest)
        .collect();
    (deepest + 1, last)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{TetMesh, Vec3};
    use std::collections::{BTreeMap, HashMap};

    /// A 2 × n strip of cubes, six tets each, numbered randomly.
    fn shuffled_strip(n: usize) -> RawMesh {
        let mut positions = Vec::new();
        for i in 0..=n {
            for j in 0..2 {
                for k in 0..2 {
                    positions.push(Vec3::new(i as f64, j as f64, k as f64));
                }
            }
        }
        let id = |i: usize, j: usize, k: usize| 4 * i + 2 * j + k;
        let mut tets = Vec::new();
        for i in 0..n {
            let c = |a: usize, b: usize, d: usize| id(i + a, b, d);
            let (p0, p6) = (c(0, 0, 0), c(1, 1, 1));
            for path in [
                [c(1, 0, 0), c(1, 1, 0)],
                [c(1, 1, 0), c(0, 1, 0)],
                [c(0, 1, 0), c(0, 1, 1)],
                [c(0, 1, 1), c(0, 0, 1)],
                [c(0, 0, 1), c(1, 0, 1)],
                [c(1, 0, 1), c(1, 0, 0)],
            ] {
                tets.push([p0, path[0], path[1], p6]);
            }
        }
        // A fixed pseudo-random permutation of the vertices.
        let m = positions.len();
        let mut perm: Vec<usize> = (0..m).collect();
        let mut state = 12345u64;
        for i in (1..m).rev() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            perm.swap(i, (state >> 33) as usize % (i + 1));
        }
        let mut shuffled = vec![Vec3::zeros(); m];
        for (old, &new) in perm.iter().enumerate() {
            shuffled[new] = positions[old];
        }
        let tets: Vec<[usize; 4]> = tets.iter().rev().map(|t| t.map(|v| perm[v])).collect();
        let tet_region = (0..tets.len()).map(|t| 1 + (t % 2) as i32).collect();
        let mut face_markers = HashMap::new();
        face_markers.insert(crate::mesh::face_key([perm[0], perm[1], perm[2]]), 3);
        RawMesh {
            positions: shuffled,
            tets,
            tet_region,
            region_names: BTreeMap::new(),
            face_markers,
        }
    }

    /// The marked faces by their corners' coordinates, with their markers.
    fn marked_faces(r: &RawMesh) -> Vec<([[u64; 3]; 3], i32)> {
        let mut faces: Vec<_> = r
            .face_markers
            .iter()
            .map(|(f, &marker)| {
                let mut corners = f.map(|v| {
                    let x = r.positions[v];
                    [x.x, x.y, x.z].map(f64::to_bits)
                });
                corners.sort_unstable();
                (corners, marker)
            })
            .collect();
        faces.sort_unstable();
        faces
    }

    fn bandwidth(tets: &[[usize; 4]]) -> usize {
        tets.iter()
            .map(|t| t.iter().max().unwrap() - t.iter().min().unwrap())
            .max()
            .unwrap()
    }

    #[test]
    fn renumbering_keeps_the_mesh_and_narrows_its_bandwidth() {
        let raw = shuffled_strip(40);
        let before = bandwidth(&raw.tets);
        let key = |r: &RawMesh, t: usize| {
            let mut p = r.tets[t].map(|v| {
                let x = r.positions[v];
                [x.x, x.y, x.z].map(|c| c.to_bits())
            });
            p.sort_unstable();
            (p, r.tet_region[t])
        };
        let mut old_tets: Vec<_> = (0..raw.tets.len()).map(|t| key(&raw, t)).collect();
        let old_faces = marked_faces(&raw);
        let new = raw.clone().reordered_for_locality();
        let mut new_tets: Vec<_> = (0..new.tets.len()).map(|t| key(&new, t)).collect();
        old_tets.sort();
        new_tets.sort();
        assert_eq!(old_tets, new_tets, "the same tets, regions and positions");
        assert_eq!(marked_faces(&new), old_faces, "the same marked faces");
        // A strip of cubes 2 × 2 vertices across: a tet joins two
        // neighbouring cross-sections, which the walk numbers within a few
        // levels of four vertices; the shuffled numbering spans most of
        // the 164.
        let after = bandwidth(&new.tets);
        assert!(after <= 8, "bandwidth {after} (before {before})");
        assert!(before > 100, "the shuffle spreads the tets: {before}");
        // Tets sorted by their lowest vertex.
        let lowest: Vec<usize> = new.tets.iter().map(|t| *t.iter().min().unwrap()).collect();
        assert!(lowest.windows(2).all(|w| w[0] <= w[1]));
        // Still a valid mesh, with the same volume.
        let a = TetMesh::from_raw("old", raw).unwrap();
        let b = TetMesh::from_raw("new", new).unwrap();
        assert!((a.total_volume() - b.total_volume()).abs() < 1e-12);
        assert_eq!(a.boundary.len(), b.boundary.len());
    }

    #[test]
    fn renumbering_is_deterministic() {
        let a = shuffled_strip(10).reordered_for_locality();
        let b = shuffled_strip(10).reordered_for_locality();
        assert_eq!(a.tets, b.tets);
        assert_eq!(a.positions, b.positions);
    }
}
