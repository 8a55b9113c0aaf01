//! `skinpatch bench gpu`: every GPU figure from one command, for the few
//! minutes a machine with a GPU is at hand. In one process it records the
//! adapter (as `gpu-info` lists it), the microstructure chain at fixed
//! texels over a range of map sizes for each strain-raster step (per stage:
//! time, bytes, GB/s against the adapter's published peak; parity with the
//! CPU reference where that runs), the renderer with and without the
//! moment filter and MSAA, the whole frame (FEM, chain, geometry, render) of
//! the scenario, and the GPU fit counter against the CPU one. The report is
//! JSON ([`GpuReport::json`]) and a Markdown summary
//! ([`GpuReport::markdown`]); `quick` sizes every part for a software
//! adapter, so that CI runs the whole command.

use std::time::Instant;

use serde_json::{json, Value};

use super::micro::{bench_micro, MapLayout, MicroBench};
use super::render::{bench_render, RenderBench};
use crate::error::{Error, Result};
use crate::gpu::micro::MicroStage;
use crate::micro::fit::{
    candidate_histogram, count_histograms, search, Axis, HistogramSettings, Objective,
};
use crate::micro::KernelParams;
use crate::render::{FrameStage, MicroFilter};
use crate::scenario::Setup;

/// How large each part of the report runs.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuBenchSizes {
    /// Map sides of the microstructure chain (texels of `texel_um`).
    pub map_sizes: Vec<usize>,
    /// Texel size of those maps (µm); `None`: the patch's width over the
    /// smallest size (a map always at least as large as the patch).
    pub texel_um: Option<f64>,
    /// Largest side the CPU reference runs at (for parity and its time).
    pub cpu_up_to: usize,
    /// Tile side for maps beyond one GPU binding.
    pub tile: usize,
    /// Strain-raster steps (map texels per raster texel).
    pub raster_steps: Vec<usize>,
    /// Timed GPU frames per map size.
    pub repetitions: usize,
    /// Image size of the render cases (px).
    pub image: (usize, usize),
    /// Side of the texture-space and shadow-map targets (px); `None`: the
    /// scenario's.
    pub texture_px: Option<usize>,
    /// Simulated frames of the render and whole-frame cases.
    pub frames: usize,
    /// Side of the fit's neutral map (texels).
    pub fit_map: usize,
    /// How long the viewer's loop runs offscreen (s).
    pub viewer_s: f64,
}

impl GpuBenchSizes {
    /// The sizes the targets are stated at, for a real GPU
    /// (within minutes on an H100-class adapter).
    pub fn full() -> GpuBenchSizes {
        GpuBenchSizes {
            map_sizes: vec![1024, 2048, 4096, 8192, 16384],
            texel_um: Some(10.0),
            cpu_up_to: 2048,
            tile: 4096,
            raster_steps: vec![1, 2, 4],
            repetitions: 10,
            image: (1920, 1080),
            texture_px: None,
            frames: 8,
            fit_map: 512,
            viewer_s: 10.0,
        }
    }

    /// Everything small enough for a software adapter in CI.
    pub fn quick() -> GpuBenchSizes {
        GpuBenchSizes {
            map_sizes: vec![128, 256],
            texel_um: None,
            cpu_up_to: 256,
            tile: 128,
            raster_steps: vec![1, 2, 4],
            repetitions: 2,
            image: (160, 90),
            texture_px: Some(256),
            frames: 2,
            fit_map: 64,
            viewer_s: 2.0,
        }
    }
}

/// The whole report, as measured.
pub struct GpuReport {
    /// The adapter the stages ran on.
    pub adapter: String,
    /// Every Vulkan adapter with its limits and optional features.
    pub adapters: Vec<Value>,
    /// The sizes used.
    pub sizes: GpuBenchSizes,
    /// The texel size the chain ran at (µm).
    pub texel_um: f64,
    /// The microstructure chain, one bench per strain-raster step.
    pub micro: Vec<(usize, MicroBench)>,
    /// The render cases: (moment filter, MSAA samples, figures).
    pub render: Vec<(MicroFilter, u32, RenderBench)>,
    /// The fit: GPU seconds, CPU seconds, whether both found the same
    /// optimum, candidates scored.
    pub fit: FitFigures,
    /// The viewer's loop without a window; `None` in a build without the
    /// `viewer` feature (the caller, above this layer, runs it).
    pub viewer: Option<ViewerLoopFigures>,
}

/// The viewer's render loop run offscreen: the scenario's probe path
/// played in a loop while the FEM thread solves the newest target, each
/// displayed frame turning the camera a little (so each one renders) and
/// drawn through the window's present pass into an offscreen texture.
/// Unlike a window it waits for no display refresh.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewerLoopFigures {
    /// Size of the view (px).
    pub size: (usize, usize),
    /// The shading mode shown.
    pub mode: String,
    /// Wall time of the loop (s).
    pub seconds: f64,
    /// Frames drawn and presented.
    pub frames: usize,
    /// Frames the FEM thread solved meanwhile.
    pub fem_frames: usize,
    /// Microstructure chain runs (one per new solved state in a mode that
    /// shows the deformed map).
    pub chain_runs: usize,
    /// Mean wall time of a chain run (ms); `None` without any.
    pub chain_ms: Option<f64>,
    /// Mean wall time of a render of the view (ms).
    pub render_ms: f64,
    /// Mean wall time of the present pass, waited for (ms).
    pub present_ms: f64,
    /// Largest difference (8-bit levels) between the last presented image
    /// and the renderer's own pixels sRGB-encoded on the CPU.
    pub present_max_difference: u8,
}

impl ViewerLoopFigures {
    /// Frames presented per second.
    pub fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.seconds.max(1e-9)
    }

    /// FEM frames solved per second.
    pub fn fem_frames_per_s(&self) -> f64 {
        self.fem_frames as f64 / self.seconds.max(1e-9)
    }

    fn json(&self) -> Value {
        json!({
            "width": self.size.0,
            "height": self.size.1,
            "mode": self.mode,
            "seconds": self.seconds,
            "frames": self.frames,
            "frames_per_s": self.frames_per_s(),
            "fem_frames": self.fem_frames,
            "fem_frames_per_s": self.fem_frames_per_s(),
            "chain_runs": self.chain_runs,
            "chain_ms": self.chain_ms,
            "render_ms": self.render_ms,
            "present_ms": self.present_ms,
            "present_max_difference": self.present_max_difference,
        })
    }
}

/// The GPU fit counter against the CPU one on one problem.
pub struct FitFigures {
    /// Side of the neutral map (texels).
    pub map: usize,
    /// The CPU search (s).
    pub cpu_s: f64,
    /// The same search counting on the GPU (s).
    pub gpu_s: f64,
    /// Candidates scored (the same for both).
    pub evaluations: usize,
    /// Whether both chose the same (α, σ) at the same objective.
    pub same_optimum: bool,
}

/// Runs every part on `setup`'s mesh, kernel model and scenario (its first
/// frames); `progress` hears which part starts. An error when no adapter
/// is there: the report is of GPU figures.
pub fn bench_gpu(
    setup: &Setup,
    sizes: &GpuBenchSizes,
    mut progress: impl FnMut(&str),
) -> Result<GpuReport> {
    let adapters = adapter_list();
    let ctx = crate::gpu::acquire()?.ok_or_else(crate::pipeline::render::no_gpu)?;
    let adapter = ctx.describe();
    let model = setup
        .outputs
        .micro
        .as_ref()
        .map_or_else(crate::micro::KernelModel::forehead, |m| m.model.clone());
    let (lo, hi) = setup.mesh.bounds();
    let smallest = sizes.map_sizes.iter().copied().min().unwrap_or(1).max(1);
    let texel_um = sizes
        .texel_um
        .unwrap_or((hi.x - lo.x) * 1e3 / smallest as f64);
    let mut micro = Vec::new();
    for &step in &sizes.raster_steps {
        progress(&format!("microstructure chain, strain-raster step {step}"));
        let layout = MapLayout::FixedTexel {
            texel_um,
            cpu_up_to: sizes.cpu_up_to,
            tile: Some(sizes.tile),
        };
        let bench = bench_micro(
            &setup.mesh,
            &model,
            &sizes.map_sizes,
            sizes.repetitions,
            (layout, step),
            |_| {},
        )?;
        micro.push((step, bench));
    }
    let mut render = Vec::new();
    for filter in [MicroFilter::Moments, MicroFilter::None] {
        for msaa in [4, 1] {
            progress(&format!(
                "render {} × {}, filter {filter:?}, MSAA {msaa}",
                sizes.image.0, sizes.image.1
            ));
            let mut case = setup.clone();
            let mut r = match &case.outputs.render {
                Some(r) => r.clone(),
                None => {
                    crate::scenario::RenderSection::default_setup(case.outputs.micro.is_some())?
                }
            };
            r.microstructure_filter = filter;
            r.msaa = msaa;
            r.supersample = 1;
            if let Some(px) = sizes.texture_px {
                (r.texture_px, r.shadow_map_px) = (px, px);
            }
            case.outputs.render = Some(r);
            let figures = bench_render(&case, sizes.frames, sizes.image, 3)?;
            render.push((filter, msaa, figures));
        }
    }
    progress("fit counter, GPU against CPU");
    let fit = fit_figures(&ctx, sizes.fit_map)?;
    Ok(GpuReport {
        adapter,
        adapters,
        sizes: sizes.clone(),
        texel_um,
        micro,
        render,
        fit,
        viewer: None,
    })
}

/// `gpu-info`'s table as JSON: every Vulkan adapter.
fn adapter_list() -> Vec<Value> {
    crate::gpu::adapters()
        .iter()
        .map(|a| {
            let (i, l) = (&a.info, &a.limits);
            json!({
                "name": i.name,
                "backend": format!("{:?}", i.backend),
                "device_type": format!("{:?}", i.device_type),
                "vendor": i.vendor,
                "device": i.device,
                "driver": i.driver,
                "driver_info": i.driver_info,
                "max_texture_dimension_2d": l.max_texture_dimension_2d,
                "max_storage_buffer_binding_size": l.max_storage_buffer_binding_size,
                "max_buffer_size": l.max_buffer_size,
                "float32_filterable": a.features.contains(wgpu::Features::FLOAT32_FILTERABLE),
                "timestamp_query": a.features.contains(wgpu::Features::TIMESTAMP_QUERY),
            })
        })
        .collect()
}

/// One fit problem (a procedural map stretched by 1.1 along u, the target
/// a known kernel's histogram) searched with both counters.
fn fit_figures(ctx: &crate::gpu::Context, side: usize) -> Result<FitFigures> {
    let neutral = crate::micro::procedural::generate(&crate::micro::SkinParams {
        size_px: side,
        extent_mm: side as f64 * 0.005,
        seed: 5,
        ..Default::default()
    })?;
    let (axis, r) = (Axis::U, 1.1);
    let range = crate::micro::fit::auto_range(&[&crate::micro::fit::resample(&neutral, axis, r)]);
    let hist = HistogramSettings { bins: 64, range };
    let params = KernelParams {
        alpha: 0.4,
        sigma_um: 12.0,
    };
    let target = candidate_histogram(&neutral, axis, r, params, hist);
    let objective = Objective::new(&neutral, &target, axis, r, hist);
    let start = Instant::now();
    let cpu = search(
        &objective,
        |b, d, alphas| Ok(count_histograms(b, d, alphas, hist.bins, hist.range)),
        |_| {},
    )?;
    let cpu_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let gpu = crate::gpu::fit::GpuFit::new(ctx, &objective.base, hist.bins)?
        .fit_params(&objective, |_| {})?;
    let gpu_s = start.elapsed().as_secs_f64();
    Ok(FitFigures {
        map: side,
        cpu_s,
        gpu_s,
        evaluations: cpu.evaluations,
        same_optimum: (cpu.alpha, cpu.sigma_um, cpu.distance)
            == (gpu.alpha, gpu.sigma_um, gpu.distance),
    })
}

impl GpuReport {
    /// The report as JSON: every figure, per part.
    pub fn json(&self) -> Value {
        json!({
            "skinpatch": env!("CARGO_PKG_VERSION"),
            "adapter": self.adapter,
            "adapters": self.adapters,
            "cpu_threads": rayon::current_num_threads(),
            "sizes": {
                "map_sizes": self.sizes.map_sizes,
                "texel_um": self.texel_um,
                "cpu_up_to": self.sizes.cpu_up_to,
                "tile": self.sizes.tile,
                "repetitions": self.sizes.repetitions,
                "image": [self.sizes.image.0, self.sizes.image.1],
                "frames": self.sizes.frames,
                "viewer_s": self.sizes.viewer_s,
            },
            "micro": self.micro_json(),
            "render": self.render_json(),
            "fit": {
                "map": self.fit.map,
                "cpu_s": self.fit.cpu_s,
                "gpu_s": self.fit.gpu_s,
                "evaluations": self.fit.evaluations,
                "same_optimum": self.fit.same_optimum,
            },
            "viewer": self.viewer.as_ref().map(ViewerLoopFigures::json),
        })
    }

    /// The chain's figures: per strain-raster step, per map size.
    fn micro_json(&self) -> Vec<Value> {
        self.micro
            .iter()
            .map(|(step, bench)| {
                let rows: Vec<Value> = bench
                    .rows
                    .iter()
                    .map(|r| {
                        let stages = r.stages.as_ref().map(|s| {
                            MicroStage::ALL
                                .iter()
                                .enumerate()
                                .map(|(k, stage)| {
                                    json!({
                                        "stage": stage.name(),
                                        "wall_ms": s.wall_ms[k],
                                        "gpu_ms": s.gpu_ms[k],
                                        "bytes": s.bytes[k],
                                        "gb_per_s": s.gb_per_s(k),
                                    })
                                })
                                .collect::<Vec<Value>>()
                        });
                        let resident_ms = r.stages.as_ref().map(|s| {
                            MicroStage::ALL
                                .iter()
                                .enumerate()
                                .filter(|(_, st)| st.runs_shaders())
                                .map(|(k, _)| s.ms(k))
                                .sum::<f64>()
                        });
                        json!({
                            "size": r.size,
                            "texel_um": r.texel_um,
                            "cpu_ms": r.cpu_ms,
                            "gpu_ms": r.gpu_ms,
                            "gpu_readback_ms": r.gpu_readback_ms,
                            "max_difference": r.max_difference,
                            "pass_tile_share": r.pass_tile_share,
                            "resident_frame_ms": resident_ms,
                            "stages": stages,
                            "tiled": r.tiled.as_ref().map(|t| json!({
                                "tile": t.tile,
                                "active": t.active,
                                "total": t.total,
                                "gpu_ms": t.gpu_ms,
                                "max_difference": t.max_difference,
                            })),
                            "untiled_skipped": r.untiled_skipped,
                        })
                    })
                    .collect();
                json!({
                    "raster_step": step,
                    "peak_bandwidth_gbs": bench.peak_bandwidth_gbs,
                    "rows": rows,
                })
            })
            .collect()
    }

    /// The render cases' figures with their whole frames.
    fn render_json(&self) -> Vec<Value> {
        self.render
            .iter()
            .map(|(filter, msaa, b)| {
                let passes: Vec<Value> = FrameStage::ALL
                    .iter()
                    .zip(b.stages_ms)
                    .map(|(s, ms)| json!({ "pass": s.name(), "ms": ms }))
                    .collect();
                json!({
                    "microstructure_filter": filter,
                    "msaa": msaa,
                    "width": b.size.0,
                    "height": b.size.1,
                    "frames": b.frames,
                    "render_ms": b.render_ms,
                    "render_readback_ms": b.render_readback_ms,
                    "passes": passes,
                    "whole_frame": {
                        "fem_ms": b.fem_ms,
                        "micro_ms": b.micro_ms,
                        "geometry_ms": b.geometry_ms,
                        "render_ms": b.render_ms,
                        "frames_per_s": 1e3 / whole_frame_ms(b),
                        "gpu_share": (b.micro_ms + b.render_ms) / whole_frame_ms(b),
                    },
                })
            })
            .collect()
    }

    /// The report's headline figures as Markdown tables.
    pub fn markdown(&self) -> String {
        let ms = |x: Option<f64>| x.map_or("–".to_string(), |v| format!("{v:.3}"));
        let mut md = format!(
            "# skinpatch bench gpu\n\nAdapter: {}; {} CPU threads.\n\n\
             ## Microstructure chain ({} µm texels)\n\n\
             | step | size | GPU ms | resident stages ms | CPU ms | max GPU−CPU diff / range | tiled GPU ms |\n\
             |---|---|---|---|---|---|---|\n",
            self.adapter,
            rayon::current_num_threads(),
            self.texel_um
        );
        for (step, bench) in &self.micro {
            for r in &bench.rows {
                let resident = r.stages.as_ref().map(|s| {
                    (0..MicroStage::COUNT)
                        .filter(|&k| MicroStage::ALL[k].runs_shaders())
                        .map(|k| s.ms(k))
                        .sum::<f64>()
                });
                md += &format!(
                    "| {step} | {} | {} | {} | {} | {} | {} |\n",
                    r.size,
                    ms(r.gpu_ms),
                    ms(resident),
                    ms(r.cpu_ms),
                    r.max_difference
                        .map_or("–".to_string(), |d| format!("{d:.1e}")),
                    ms(r.tiled.as_ref().map(|t| t.gpu_ms)),
                );
            }
        }
        md += &format!(
            "\n## Renderer and whole frame ({} × {} px)\n\n\
             | filter | MSAA | render ms | FEM ms | chain ms | geometry ms | whole frame/s | GPU share |\n\
             |---|---|---|---|---|---|---|---|\n",
            self.sizes.image.0, self.sizes.image.1
        );
        for (filter, msaa, b) in &self.render {
            let whole = whole_frame_ms(b);
            md += &format!(
                "| {filter:?} | {msaa} | {:.3} | {:.2} | {:.3} | {:.3} | {:.2} | {:.1}% |\n",
                b.render_ms,
                b.fem_ms,
                b.micro_ms,
                b.geometry_ms,
                1e3 / whole,
                100.0 * (b.micro_ms + b.render_ms) / whole
            );
        }
        md += &format!(
            "\n## Fit counter ({}² map, {} candidates)\n\n| CPU s | GPU s | same optimum |\n\
             |---|---|---|\n| {:.3} | {:.3} | {} |\n",
            self.fit.map,
            self.fit.evaluations,
            self.fit.cpu_s,
            self.fit.gpu_s,
            if self.fit.same_optimum { "yes" } else { "no" }
        );
        md += &match &self.viewer {
            Some(v) => format!(
                "\n## Viewer loop, offscreen ({} × {} px, mode {}, {:.1} s)\n\n\
                 | frames/s | FEM frames/s | render ms | chain ms | present ms |\n\
                 |---|---|---|---|---|\n| {:.1} | {:.2} | {:.3} | {} | {:.3} |\n",
                v.size.0,
                v.size.1,
                v.mode,
                v.seconds,
                v.frames_per_s(),
                v.fem_frames_per_s(),
                v.render_ms,
                ms(v.chain_ms),
                v.present_ms
            ),
            None => "\n## Viewer loop, offscreen\n\nNot measured: built without the `viewer` \
                     feature.\n"
                .to_string(),
        };
        md
    }
}

/// One whole frame: FEM step, chain, geometry and render (ms).
fn whole_frame_ms(b: &RenderBench) -> f64 {
    b.fem_ms + b.micro_ms + b.geometry_ms + b.render_ms
}

/// Writes the JSON report to `path` and the Markdown beside it (`.md`),
/// each atomically; returns the Markdown's path.
pub fn write_report(report: &GpuReport, path: &std::path::Path) -> Result<std::path::PathBuf> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let text = serde_json::to_string_pretty(&report.json())
        .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    crate::mesh::io::write_atomically(path, text.as_bytes())?;
    let md = path.with_extension("md");
    crate::mesh::io::write_atomically(&md, report.markdown().as_bytes())?;
    Ok(md)
}
