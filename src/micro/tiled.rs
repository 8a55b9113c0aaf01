//! Maps held as tiles: face-scale maps (a 25 cm face at 10 µm is 25,000²
//! texels, 2.5 GB of f32) that exceed one GPU storage binding or texture
//! side, read and written a tile at a time.
//!
//! A tiled map is a folder holding `index.toml` and one single-channel f32
//! EXR per tile, `tile_CCCC_RRRR.exr` for column C and row R (zero-based,
//! four digits or more), each carrying the map's metadata like any map file
//! ([`super::io::write_exr`]). Tiles are `tile × tile` texels, those of the
//! last column and row cut to the map's size. Normal maps of a tiled height
//! map sit beside its tiles as `normal_CCCC_RRRR.exr`. EXR keeps f32
//! heights exactly, so a map split into tiles and read back is the same map
//! bit for bit (16-bit PNG tiles would each be quantised to their own
//! range and disagree at the seams).
//!
//! `index.toml`:
//!
//! ```toml
//! format = "skinpatch tiled map"
//! version = 1
//! width = 32768       # texels of the whole map
//! height = 32768
//! tile = 4096         # tile side (texels)
//! texel_um = 10.0
//! height_unit_um = 1.0
//! edge = "clamp"      # or "wrap": the whole map's edge rule
//! ```

use std::collections::hash_map::{Entry, HashMap};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::map::{DisplacementMap, Edge};
use crate::error::{Error, Result};

/// The index file of a tiled map folder.
pub const INDEX_FILE: &str = "index.toml";
const FORMAT: &str = "skinpatch tiled map";

/// `index.toml` as stored.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TiledIndex {
    format: String,
    version: u32,
    width: usize,
    height: usize,
    tile: usize,
    texel_um: f64,
    height_unit_um: f64,
    edge: Edge,
}

/// A tiled map on disk (its index; tiles are read on demand).
#[derive(Clone, Debug, PartialEq)]
pub struct TiledMap {
    /// The folder.
    pub dir: PathBuf,
    /// Texels of the whole map along u.
    pub width: usize,
    /// Texels of the whole map along v.
    pub height: usize,
    /// Tile side (texels).
    pub tile: usize,
    /// Texel side on the skin (µm).
    pub texel_um: f64,
    /// Micrometres per height unit.
    pub height_unit_um: f64,
    /// The whole map's edge rule.
    pub edge: Edge,
}

/// Largest side of a tiled map (texels): 2²⁰, 10 m at 10 µm.
pub const MAX_SIDE: usize = 1 << 20;

/// Largest tile side (texels).
pub const MAX_TILE: usize = 1 << 16;

/// Whether `path` names a tiled map: a folder, or its `index.toml`.
pub fn is_tiled(path: &Path) -> bool {
    path.is_dir() || path.file_name().is_some_and(|n| n == INDEX_FILE)
}

impl TiledMap {
    /// Opens the tiled map in `path` (the folder or its `index.toml`),
    /// checking the index.
    pub fn open(path: &Path) -> Result<TiledMap> {
        let (dir, index_path) = if path.is_dir() {
            (path.to_path_buf(), path.join(INDEX_FILE))
        } else {
            let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
            (dir, path.to_path_buf())
        };
        crate::mesh::io::regular_file(&index_path)?;
        let text = std::fs::read_to_string(&index_path).map_err(|e| Error::io(&index_path, e))?;
        let bad = |m: String| Error::malformed(&index_path, m);
        let index: TiledIndex =
            toml::from_str(&text).map_err(|e| bad(format!("not a tiled map index: {e}")))?;
        if index.format != FORMAT || index.version != 1 {
            return Err(bad(format!(
                "format \"{}\" version {} is not \"{FORMAT}\" version 1",
                index.format, index.version
            )));
        }
        if index.width == 0 || index.height == 0 || index.tile == 0 {
            return Err(bad(format!(
                "width, height and tile must be ≥ 1, got {} × {} in tiles of {}",
                index.width, index.height, index.tile
            )));
        }
        if index.width.max(index.height) > MAX_SIDE || index.tile > MAX_TILE {
            return Err(bad(format!(
                "{} × {} texels in tiles of {}: a side may have at most {MAX_SIDE} texels \
                 (10 m at 10 µm), a tile at most {MAX_TILE}",
                index.width, index.height, index.tile
            )));
        }
        for (key, v) in [
            ("texel_um", index.texel_um),
            ("height_unit_um", index.height_unit_um),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!("{key} must be finite and > 0, got {v}")));
            }
        }
        let edge = index.edge;
        Ok(TiledMap {
            dir,
            width: index.width,
            height: index.height,
            tile: index.tile,
            texel_um: index.texel_um,
            height_unit_um: index.height_unit_um,
            edge,
        })
    }

    /// Makes the folder `dir` for a map with `like`'s size and metadata in
    /// tiles of `tile` texels and writes its index (tiles follow with
    /// [`TiledMap::write_tile`]).
    pub fn create(dir: &Path, like: &DisplacementMap, tile: usize) -> Result<TiledMap> {
        if tile == 0 {
            return Err(Error::parameter("tile", "must be ≥ 1 texel, got 0"));
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let index = TiledIndex {
            format: FORMAT.into(),
            version: 1,
            width: like.width,
            height: like.height,
            tile,
            texel_um: like.texel_um,
            height_unit_um: like.height_unit_um,
            edge: like.edge,
        };
        let text = toml::to_string(&index).expect("the index serialises");
        crate::mesh::io::write_atomically(&dir.join(INDEX_FILE), text.as_bytes())?;
        TiledMap::open(dir)
    }

    /// Tiles along u and v.
    pub fn grid(&self) -> (usize, usize) {
        (
            self.width.div_ceil(self.tile),
            self.height.div_ceil(self.tile),
        )
    }

    /// Texel rectangle `[x0, y0, width, height]` of tile `(col, row)`.
    pub fn tile_rect(&self, col: usize, row: usize) -> [usize; 4] {
        let (x0, y0) = (col * self.tile, row * self.tile);
        [
            x0,
            y0,
            self.tile.min(self.width - x0),
            self.tile.min(self.height - y0),
        ]
    }

    /// File of the heights of tile `(col, row)`.
    pub fn tile_path(&self, col: usize, row: usize) -> PathBuf {
        self.dir.join(format!("tile_{col:04}_{row:04}.exr"))
    }

    /// File of the normals of tile `(col, row)`.
    pub fn normal_path(&self, col: usize, row: usize) -> PathBuf {
        self.dir.join(format!("normal_{col:04}_{row:04}.exr"))
    }

    /// Whether `path` is one of this map's own files (its index, or a
    /// tile's heights or normals), which a command writing there would
    /// overwrite.
    pub fn owns(&self, path: &Path) -> bool {
        let (Some(parent), Some(name)) = (path.parent(), path.file_name().and_then(|n| n.to_str()))
        else {
            return false;
        };
        let parent = if parent.as_os_str().is_empty() {
            Path::new(".")
        } else {
            parent
        };
        // Folders cannot be hard links: their canonical paths decide.
        match (
            std::fs::canonicalize(parent),
            std::fs::canonicalize(&self.dir),
        ) {
            (Ok(a), Ok(b)) if a == b => {}
            _ => return false,
        }
        if name == INDEX_FILE {
            return true;
        }
        let (cols, rows) = self.grid();
        let tile = |prefix: &str| -> Option<(usize, usize)> {
            let (col, row) = name
                .strip_prefix(prefix)?
                .strip_suffix(".exr")?
                .split_once('_')?;
            Some((col.parse().ok()?, row.parse().ok()?))
        };
        ["tile_", "normal_"]
            .into_iter()
            .filter_map(tile)
            .any(|(col, row)| col < cols && row < rows)
    }

    /// An empty map with the whole map's metadata and `width × height`.
    pub fn metadata(&self, width: usize, height: usize) -> DisplacementMap {
        DisplacementMap {
            width,
            height,
            texel_um: self.texel_um,
            height_unit_um: self.height_unit_um,
            edge: self.edge,
            data: Vec::new(),
        }
    }

    /// Reads tile `(col, row)`, checking its size.
    pub fn read_tile(&self, col: usize, row: usize) -> Result<DisplacementMap> {
        let path = self.tile_path(col, row);
        let defaults = super::io::MapDefaults {
            texel: super::io::TexelSize::Um(self.texel_um),
            height_unit_um: self.height_unit_um,
            edge: self.edge,
        };
        let tile = super::io::read_exr(&path, &defaults)?;
        let [_, _, w, h] = self.tile_rect(col, row);
        if (tile.width, tile.height) != (w, h) {
            return Err(Error::malformed(
                &path,
                format!(
                    "tile ({col}, {row}) is {} × {} texels; the index makes it {w} × {h}",
                    tile.width, tile.height
                ),
            ));
        }
        Ok(tile)
    }

    /// Writes tile `(col, row)` (and its normals when given), checking its
    /// size.
    pub fn write_tile(
        &self,
        col: usize,
        row: usize,
        tile: &DisplacementMap,
        normals: Option<&[[f32; 3]]>,
    ) -> Result<()> {
        let [_, _, w, h] = self.tile_rect(col, row);
        assert_eq!((tile.width, tile.height), (w, h), "tile ({col}, {row})");
        super::io::write_exr(&self.tile_path(col, row), tile)?;
        if let Some(n) = normals {
            super::io::write_normal_exr(&self.normal_path(col, row), n, tile)?;
        }
        Ok(())
    }

    /// Texels `origin .. origin + size` of the whole map, those beyond its
    /// edges by its edge rule, reading each tile they touch once. The result
    /// has the map's metadata with clamped edges (a window does not wrap
    /// onto itself).
    pub fn read_window(&self, origin: [isize; 2], size: [usize; 2]) -> Result<DisplacementMap> {
        let bytes = (size[0] as u64)
            .saturating_mul(size[1] as u64)
            .saturating_mul(4);
        if let Some((needed, have)) = crate::memory::shortfall_gb(bytes) {
            return Err(Error::malformed(
                &self.dir.join(INDEX_FILE),
                format!(
                    "{} × {} texels need {needed:.1} GB in memory, {have:.1} GB are available: \
                     read the map by tiles",
                    size[0], size[1]
                ),
            ));
        }
        let source = |x: isize, n: usize| -> usize {
            match self.edge {
                Edge::Wrap => x.rem_euclid(n as isize) as usize,
                Edge::Clamp => x.clamp(0, n as isize - 1) as usize,
            }
        };
        let xs: Vec<usize> = (0..size[0])
            .map(|i| source(origin[0] + i as isize, self.width))
            .collect();
        let ys: Vec<usize> = (0..size[1])
            .map(|j| source(origin[1] + j as isize, self.height))
            .collect();
        let mut tiles: HashMap<(usize, usize), DisplacementMap> = HashMap::new();
        let mut data = Vec::with_capacity(size[0] * size[1]);
        for &y in &ys {
            for &x in &xs {
                let key = (x / self.tile, y / self.tile);
                let t = match tiles.entry(key) {
                    Entry::Occupied(e) => e.into_mut(),
                    Entry::Vacant(e) => e.insert(self.read_tile(key.0, key.1)?),
                };
                data.push(t.data[(y % self.tile) * t.width + x % self.tile]);
            }
        }
        let mut map = self.metadata(size[0], size[1]);
        map.edge = Edge::Clamp;
        map.data = data;
        Ok(map)
    }

    /// The whole map in memory.
    pub fn read_all(&self) -> Result<DisplacementMap> {
        let mut map = self.read_window([0, 0], [self.width, self.height])?;
        map.edge = self.edge;
        Ok(map)
    }

    /// Writes `map` as a tiled map in `dir` with tiles of `tile` texels.
    pub fn write(dir: &Path, map: &DisplacementMap, tile: usize) -> Result<TiledMap> {
        let tiled = TiledMap::create(dir, map, tile)?;
        let (cols, rows) = tiled.grid();
        for row in 0..rows {
            for col in 0..cols {
                tiled.write_tile(col, row, &crop(map, tiled.tile_rect(col, row)), None)?;
            }
        }
        Ok(tiled)
    }
}

/// Texels `[x0, y0, width, height]` of `map` (inside it), with its metadata.
pub fn crop(map: &DisplacementMap, rect: [usize; 4]) -> DisplacementMap {
    DisplacementMap {
        width: rect[2],
        height: rect[3],
        texel_um: map.texel_um,
        height_unit_um: map.height_unit_um,
        edge: map.edge,
        data: crop_values(&map.data, map.width, rect),
    }
}

/// Entries `[x0, y0, width, height]` of a row-major grid `grid_width` wide.
pub fn crop_values<T: Copy>(values: &[T], grid_width: usize, [x0, y0, w, h]: [usize; 4]) -> Vec<T> {
    let mut out = Vec::with_capacity(w * h);
    for j in y0..y0 + h {
        out.extend_from_slice(&values[j * grid_width + x0..j * grid_width + x0 + w]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(width: usize, height: usize, edge: Edge) -> DisplacementMap {
        let mut m = DisplacementMap::from_fn(width, height, 7.5, edge, |i, j| {
            (i as f32 * 0.37).sin() * 3.0 + (j as f32 * 0.21).cos() + (i * j % 11) as f32 * 0.01
        });
        m.height_unit_um = 0.25;
        m
    }

    #[test]
    fn a_map_split_into_tiles_reads_back_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let map = sample(70, 45, Edge::Wrap);
        let tiled = TiledMap::write(&dir.path().join("m.tiles"), &map, 32).unwrap();
        assert_eq!(tiled.grid(), (3, 2));
        assert_eq!(tiled.tile_rect(2, 1), [64, 32, 6, 13]);
        let again = TiledMap::open(&dir.path().join("m.tiles/index.toml")).unwrap();
        assert_eq!(again, tiled);
        assert_eq!(again.read_all().unwrap(), map);
    }

    #[test]
    fn windows_follow_the_edge_rule_across_tiles() {
        let dir = tempfile::tempdir().unwrap();
        for edge in [Edge::Wrap, Edge::Clamp] {
            let map = sample(50, 40, edge);
            let tiled = TiledMap::write(&dir.path().join(format!("{edge:?}")), &map, 16).unwrap();
            let w = tiled.read_window([-5, 30], [60, 20]).unwrap();
            for j in 0..20 {
                for i in 0..60 {
                    let want = map.texel(i as isize - 5, j as isize + 30);
                    assert_eq!(w.data[j * 60 + i], want, "{edge:?} ({i}, {j})");
                }
            }
        }
    }

    #[test]
    fn bad_indexes_and_tiles_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let map = sample(40, 40, Edge::Clamp);
        let path = dir.path().join("m.tiles");
        let tiled = TiledMap::write(&path, &map, 16).unwrap();
        let index = path.join(INDEX_FILE);
        let text = std::fs::read_to_string(&index).unwrap();
        for (from, to, expected) in [
            ("tile = 16", "tile = 0", "tile must be ≥ 1"),
            (
                "edge = \"clamp\"",
                "edge = \"mirror\"",
                "unknown variant `mirror`, expected `wrap` or `clamp`",
            ),
            ("version = 1", "version = 2", "version 1"),
            ("texel_um = 7.5", "texel_um = -1.0", "texel_um must be"),
            ("tile = 16", "tile = 16\ncolour = 1", "unknown field"),
        ] {
            std::fs::write(&index, text.replace(from, to)).unwrap();
            let err = TiledMap::open(&path).unwrap_err().to_string();
            assert!(
                err.contains(expected) && err.contains("index.toml"),
                "{err}"
            );
        }
        std::fs::write(&index, &text).unwrap();
        // A tile of the wrong size, and a missing one.
        crate::micro::io::write_exr(&tiled.tile_path(1, 1), &crop(&map, [0, 0, 10, 16])).unwrap();
        let err = tiled.read_tile(1, 1).unwrap_err().to_string();
        assert!(
            err.contains("tile_0001_0001.exr") && err.contains("16 × 16"),
            "{err}"
        );
        std::fs::remove_file(tiled.tile_path(2, 0)).unwrap();
        let err = tiled.read_all().unwrap_err().to_string();
        assert!(err.contains("tile_0002_0000.exr"), "{err}");
    }
}
