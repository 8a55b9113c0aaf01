//! The per-frame chain over a tiled map ([`crate::micro::tiled`]): maps
//! beyond one storage binding or texture side, convolved tile by tile.
//!
//! Each map tile the surface can change gets its own resident chain
//! ([`GpuMicro`]) over the tile and a halo around it, built on the first
//! frame; the halo holds every texel the tile's outputs read, so a tile's
//! result equals the untiled chain's there up to the f32 rounding of its
//! UVs moved into the window. What a texel reads: the t pass reads the s
//! pass's output up to the kernel's reach `R` ([`super::active_tiles::pass_reach`]),
//! the s pass reads the neutral map up to `R` and takes its parameters from
//! the raster up to the dilation `d` away, and the normals read one texel
//! around: a halo of `2R + d + 2` texels. A tile farther than `R + d + 2`
//! texels from every surface texel keeps the neutral map (and its normals)
//! and has no chain. With a wrapping map the surface is also drawn across
//! each edge of a window that reaches past the map's edges.
//!
//! Every chain runs the same incremental-frame rule as an untiled one
//! ([`GpuMicro::set_incremental`]).

use super::active_tiles::{pass_reach, triangle_tiles};
use super::micro::{GpuMicro, UvWindow};
use super::raster::vertices;
use super::Context;
use crate::error::{Error, Result};
use crate::micro::tiled::{crop, crop_values, TiledMap};
use crate::micro::{DisplacementMap, Edge, KernelModel};
use crate::strain::SurfaceField;

/// One tile of a frame, as [`TiledMicro::deform`] hands it out.
pub enum TileFrame {
    /// The tile's deformed heights (and normals when asked for).
    Deformed {
        /// D′ over the tile.
        map: DisplacementMap,
        /// Its normals.
        normals: Option<Vec<[f32; 3]>>,
    },
    /// Beyond the surface's reach: the neutral tile (and its normals).
    Neutral,
}

struct TileChain {
    col: usize,
    row: usize,
    chain: GpuMicro,
}

/// The resident chains of a tiled map.
pub struct TiledMicro {
    ctx: Context,
    source: TiledMap,
    model: KernelModel,
    dilate: usize,
    tolerance: Option<f64>,
    /// Map texels per raster texel ([`GpuMicro::set_raster_step`]).
    step: usize,
    halo: usize,
    chains: Vec<TileChain>,
}

impl TiledMicro {
    /// The chains of `source` under `model` with the raster dilated by
    /// `dilate` texels; nothing is read or built before the first frame.
    pub fn new(ctx: Context, source: TiledMap, model: &KernelModel, dilate: usize) -> TiledMicro {
        TiledMicro {
            ctx,
            source,
            model: model.clone(),
            dilate,
            tolerance: None,
            step: 1,
            halo: 0,
            chains: Vec::new(),
        }
    }

    /// Incremental frames in every chain ([`GpuMicro::set_incremental`]).
    pub fn set_incremental(&mut self, tolerance: Option<f64>) {
        self.tolerance = tolerance;
        for c in &mut self.chains {
            c.chain.set_incremental(tolerance);
        }
    }

    /// A coarse strain raster in every chain ([`GpuMicro::set_raster_step`]).
    /// The tile side (and, for a wrapping map, its size) must be a multiple
    /// of `step`, so every chain's raster lies on the whole map's grid and
    /// the tiles equal the untiled chain.
    pub fn set_raster_step(&mut self, step: usize) -> Result<()> {
        let step = step.max(1);
        let src = &self.source;
        if !src.tile.is_multiple_of(step) {
            return Err(Error::parameter(
                "microstructure.strain_raster_step",
                format!(
                    "the tiled map's tile side ({}) must be a multiple of the step ({step})",
                    src.tile
                ),
            ));
        }
        if src.edge == Edge::Wrap
            && !(src.width.is_multiple_of(step) && src.height.is_multiple_of(step))
        {
            return Err(Error::parameter(
                "microstructure.strain_raster_step",
                format!(
                    "a wrapping tiled map's size ({} × {}) must be a multiple of the step ({step})",
                    src.width, src.height
                ),
            ));
        }
        self.step = step;
        self.chains.clear();
        self.halo = 0;
        Ok(())
    }

    /// The tiled map the chains convolve.
    pub fn source(&self) -> &TiledMap {
        &self.source
    }

    /// The tiles that have a chain (the others keep the neutral map).
    pub fn active_tiles(&self) -> Vec<(usize, usize)> {
        self.chains.iter().map(|c| (c.col, c.row)).collect()
    }

    /// The halo around each tile (texels; 0 before the first frame).
    pub fn halo(&self) -> usize {
        self.halo
    }

    /// Gives the device back.
    pub fn into_context(self) -> Context {
        self.ctx
    }

    /// One frame in every chain, waited for, nothing read back (for timing).
    pub fn run(&mut self, field: &SurfaceField) -> Result<()> {
        self.prepare(field)?;
        for c in &mut self.chains {
            c.chain.submit(field, true);
        }
        self.ctx.finish()
    }

    /// Builds the chains on the first frame, and again when the kernels of
    /// `field` reach farther than the halo.
    fn prepare(&mut self, field: &SurfaceField) -> Result<()> {
        let size = (self.source.width, self.source.height);
        let reach =
            pass_reach(&vertices(field), size, self.model.max_sigma_um()).ok_or_else(|| {
                Error::parameter("microstructure", "the surface's UV frames are not finite")
            })?;
        // A multiple of the step, so each window starts on the raster grid.
        let halo = (2 * reach + self.reach_past_surface() + 2).next_multiple_of(self.step);
        if halo > self.halo {
            self.build(field, reach, halo)?;
        }
        Ok(())
    }

    /// One frame: `emit(col, row, tile)` for every tile of the map, in
    /// row-major order (normals too when `normals`).
    pub fn deform(
        &mut self,
        field: &SurfaceField,
        normals: bool,
        mut emit: impl FnMut(usize, usize, TileFrame) -> Result<()>,
    ) -> Result<()> {
        self.prepare(field)?;
        let (cols, rows) = self.source.grid();
        let mut chains = self.chains.iter_mut().peekable();
        for row in 0..rows {
            for col in 0..cols {
                match chains.peek_mut() {
                    Some(c) if (c.col, c.row) == (col, row) => {
                        let frame = c.chain.deform(field, normals)?;
                        let [_, _, w, h] = self.source.tile_rect(col, row);
                        let inner = [self.halo, self.halo, w, h];
                        let mut map = crop(&frame.map, inner);
                        map.edge = self.source.edge;
                        let normals = frame
                            .normals
                            .map(|n| crop_values(&n, frame.map.width, inner));
                        emit(col, row, TileFrame::Deformed { map, normals })?;
                        chains.next();
                    }
                    _ => emit(col, row, TileFrame::Neutral)?,
                }
            }
        }
        Ok(())
    }

    /// How far (texels) the raster's values reach past the surface.
    fn reach_past_surface(&self) -> usize {
        crate::strain::raster::stepped_reach(self.dilate, self.step)
    }

    /// Chains for the tiles within `reach + dilate + 2` texels of the
    /// surface's UV bounding boxes, each over its tile and `halo`.
    fn build(&mut self, field: &SurfaceField, reach: usize, halo: usize) -> Result<()> {
        let margin = (reach + self.reach_past_surface() + 2) as f64 + 1.0;
        let src = &self.source;
        let (tri, uvs) = field.layout();
        let shifts: &[f64] = if src.edge == Edge::Wrap {
            &[-1.0, 0.0, 1.0]
        } else {
            &[0.0]
        };
        let (cols, rows) = src.grid();
        let mut active = vec![false; cols * rows];
        for t in tri {
            let p = t.map(|k| [uvs[k].x, uvs[k].y]);
            for &su in shifts {
                for &sv in shifts {
                    let size = (src.width, src.height);
                    if let Some((x0, y0, x1, y1)) =
                        triangle_tiles(p, [su, sv], size, margin, src.tile)
                    {
                        for row in y0..=y1 {
                            active[row * cols + x0..=row * cols + x1].fill(true);
                        }
                    }
                }
            }
        }
        let window = [src.tile.min(src.width), src.tile.min(src.height)].map(|n| n + 2 * halo);
        self.ctx
            .check_map(window[0], window[1], super::micro::LARGEST_BYTES_PER_TEXEL)?;
        self.chains.clear();
        self.halo = halo;
        for (k, _) in active.iter().enumerate().filter(|(_, &a)| a) {
            let (col, row) = (k % cols, k / cols);
            let [x0, y0, w, h] = src.tile_rect(col, row);
            let origin = [x0 as isize - halo as isize, y0 as isize - halo as isize];
            let neutral = src.read_window(origin, [w + 2 * halo, h + 2 * halo])?;
            let win = UvWindow {
                origin,
                map_size: [src.width, src.height],
                wrap: src.edge == Edge::Wrap,
            };
            let mut chain =
                GpuMicro::for_window(self.ctx.clone(), &neutral, &self.model, self.dilate, win)?;
            chain.set_incremental(self.tolerance);
            chain.set_raster_step(self.step);
            self.chains.push(TileChain { col, row, chain });
        }
        log::info!(
            "tiled microstructure: {} of {} tiles within the surface's reach ({reach} texels), halo {halo}",
            self.chains.len(),
            cols * rows
        );
        Ok(())
    }
}
