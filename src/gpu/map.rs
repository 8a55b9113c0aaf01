//! Displacement maps resident on the GPU (`shaders/map.wgsl`, shared by the
//! stages that read a map; CPU reference [`crate::micro::DisplacementMap`]).

use bytemuck::{Pod, Zeroable};

use super::{buffers, Context};
use crate::error::Result;
use crate::micro::{DisplacementMap, Edge};

/// Map access functions, prepended to the shaders that read a map.
pub const SHADER: &str = include_str!("../../shaders/map.wgsl");

/// `shaders/map.wgsl` followed by `stage`: the source of a map-reading stage.
pub fn with_map_access(stage: &str) -> String {
    format!("{SHADER}\n{stage}")
}

/// Size, edge handling and slope scaling of a map; mirrors WGSL `MapInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct MapInfo {
    /// Texels along u.
    pub width: u32,
    /// Texels along v.
    pub height: u32,
    /// 1 when reads wrap around, 0 when they clamp.
    pub wrap: u32,
    _pad0: u32,
    /// `height_unit_um / (2·texel_um)`.
    pub slope_scale: f32,
    /// Texel-spacing stretch along x for slopes.
    pub stretch_x: f32,
    /// Texel-spacing stretch along y for slopes.
    pub stretch_y: f32,
    _pad1: f32,
}

impl MapInfo {
    /// The info of `map` seen stretched by `stretch` along (x, y).
    pub fn of(map: &DisplacementMap, stretch: [f64; 2]) -> MapInfo {
        MapInfo {
            width: map.width as u32,
            height: map.height as u32,
            wrap: u32::from(map.edge == Edge::Wrap),
            slope_scale: (map.height_unit_um / (2.0 * map.texel_um)) as f32,
            stretch_x: stretch[0] as f32,
            stretch_y: stretch[1] as f32,
            ..MapInfo::default()
        }
    }
}

fn metadata(map: &DisplacementMap) -> DisplacementMap {
    DisplacementMap {
        data: Vec::new(),
        ..*map
    }
}

/// A map's heights in a storage buffer, with its metadata.
pub struct GpuMap {
    /// Heights, row-major f32.
    pub heights: wgpu::Buffer,
    /// Its `MapInfo` (unstretched) as a uniform.
    pub info: wgpu::Buffer,
    /// Metadata of the map (its `data` is empty).
    pub meta: DisplacementMap,
}

impl GpuMap {
    /// Uploads `map`.
    pub fn upload(ctx: &Context, map: &DisplacementMap) -> GpuMap {
        GpuMap {
            heights: buffers::storage(ctx, "map heights", &map.data),
            info: buffers::uniform(ctx, "map info", &MapInfo::of(map, [1.0, 1.0])),
            meta: metadata(map),
        }
    }

    /// An uninitialised map with `like`'s size and metadata.
    pub fn scratch(ctx: &Context, like: &DisplacementMap) -> GpuMap {
        let n = (like.width * like.height) as u64;
        GpuMap {
            heights: buffers::storage_zeroed(ctx, "map scratch", 4 * n),
            info: buffers::uniform(ctx, "map info", &MapInfo::of(like, [1.0, 1.0])),
            meta: metadata(like),
        }
    }

    /// Texels in the map.
    pub fn len(&self) -> usize {
        self.meta.width * self.meta.height
    }

    /// Whether the map has no texels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads the heights back.
    pub fn download(&self, ctx: &Context) -> Result<DisplacementMap> {
        let data = buffers::read::<f32>(ctx, &self.heights, self.len())?;
        Ok(DisplacementMap {
            data,
            ..self.meta.clone()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_info_matches_wgsl_layout() {
        // Four u32 then four f32: 32 bytes, a multiple of 16 as uniforms need.
        assert_eq!(std::mem::size_of::<MapInfo>(), 32);
    }
}
