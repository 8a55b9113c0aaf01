//! What a run will write, estimated before it writes anything: the run is
//! refused when the estimate exceeds [`MAX_PLANNED_BYTES`] (unless forced)
//! or the free space of the output file system.
//!
//! The estimate is an upper bound for images (uncompressed pixels) and for
//! frame VTUs: the measured size of an uncompressed Float64 frame (10.1 MB
//! for patch_25k's 26,146 tets and 4,914 points: ≈ 380 bytes a tet and 100
//! a point), halved with `vtu_precision = "f32"`; compression (the default)
//! makes them smaller still (8.1 MB and 4.1 MB). `frames.vtkhdf` is
//! bounded by the same figure a frame.

use crate::error::{Error, Result};
use crate::scenario::Setup;

/// The most a run may plan to write without `--force` (bytes): 50 GB.
pub const MAX_PLANNED_BYTES: u64 = 50_000_000_000;

/// Bytes of one frame VTU per tet and per point (measured, see above).
const VTU_BYTES_PER_TET: u64 = 380;
const VTU_BYTES_PER_POINT: u64 = 100;

/// Bytes of one uncompressed Float64 frame VTU of an animated surface per
/// point (surface vertex) and per triangle (measured: 615,930 bytes for the
/// forehead example's 2,009 points and 3,840 triangles).
const SURFACE_VTU_BYTES_PER_POINT: u64 = 175;
const SURFACE_VTU_BYTES_PER_TRIANGLE: u64 = 70;

/// What a run writes, stage by stage, for the estimate.
struct Outputs<'a> {
    /// Frames in the run.
    frames: u64,
    /// One frame VTU (bytes), written `vtu_copies` times a frame (VTU and
    /// VTKHDF) plus `rest_vtu` once.
    vtu: u64,
    vtu_copies: u64,
    rest_vtu: bool,
    strain_images: Option<crate::scenario::StrainImageSettings>,
    micro: Option<&'a crate::scenario::MicroSetup>,
    /// Maps per frame (UDIM tiles; 1 otherwise).
    maps: u64,
    render: Option<&'a crate::render::RenderSetup>,
}

impl Outputs<'_> {
    fn bytes(&self) -> u64 {
        let frames = self.frames;
        let mut total = 0u64;
        let mut add =
            |count: u64, bytes: u64| total = total.saturating_add(count.saturating_mul(bytes));
        add(u64::from(self.rest_vtu), self.vtu);
        add(frames * self.vtu_copies, self.vtu);
        if let Some(images) = self.strain_images {
            if images.previews {
                // Three RGB maps a frame and map.
                add(frames * self.maps, 3 * 3 * (images.px as u64).pow(2));
            }
            if let Some([w, h]) = images.data {
                // Five f32 channels.
                add(frames * self.maps, 5 * 4 * (w as u64) * (h as u64));
            }
        }
        let every = |stride: usize| frames.div_ceil(stride.max(1) as u64);
        if let Some(m) = self.micro {
            let (width, height) = m.neutral.size();
            let texels = (width * height) as u64;
            let per_map = u64::from(m.png16) * 2 + u64::from(m.exr) * 4;
            let per_normals = u64::from(m.normal_maps) * (6 + u64::from(m.exr) * 12);
            // The neutral map and every stride-th frame of every map.
            add(
                every(m.frame_stride) * self.maps + 1,
                texels * (per_map + per_normals),
            );
        }
        if let Some(r) = self.render {
            let bytes_per_pixel = match r.format {
                crate::render::FrameFormat::Png8 => 3,
                crate::render::FrameFormat::Png16 => 6,
                crate::render::FrameFormat::Exr => 12,
            };
            let pixels = (r.width * r.height) as u64;
            add(
                every(r.frame_stride) * r.modes.len() as u64,
                pixels * bytes_per_pixel,
            );
            if r.difference {
                add(every(r.frame_stride), pixels * 3);
            }
            if r.comparison {
                add(every(r.frame_stride), 3 * pixels * 3);
            }
        }
        total
    }
}

/// The estimated bytes a run of `setup` writes.
pub fn planned_bytes(setup: &Setup) -> u64 {
    let mesh = &setup.mesh;
    Outputs {
        frames: setup.simulation.frames as u64 + 1,
        vtu: (VTU_BYTES_PER_TET * mesh.num_tets() as u64
            + VTU_BYTES_PER_POINT * mesh.num_vertices() as u64)
            / if setup.outputs.vtu_format.f32 { 2 } else { 1 },
        // The VTKHDF steps hold the same arrays uncompressed, less the
        // connectivity of every frame after the first: a bound like the VTU's.
        vtu_copies: u64::from(setup.outputs.write_frames) + u64::from(setup.write_vtkhdf),
        rest_vtu: setup.write_mesh_vtu,
        strain_images: setup.outputs.strain_images,
        micro: setup.outputs.micro.as_ref(),
        maps: 1,
        render: setup.outputs.render.as_ref(),
    }
    .bytes()
}

/// The estimated bytes a run of an animated surface writes.
pub fn planned_surface_bytes(setup: &crate::scenario::SurfaceSetup) -> u64 {
    let top = &setup.surface.top;
    Outputs {
        frames: setup.surface.num_frames() as u64,
        vtu: (SURFACE_VTU_BYTES_PER_POINT * top.vertices.len() as u64
            + SURFACE_VTU_BYTES_PER_TRIANGLE * top.triangles.len() as u64)
            / if setup.outputs.vtu_format.f32 { 2 } else { 1 },
        vtu_copies: u64::from(setup.outputs.write_frames),
        rest_vtu: setup.write_surface_vtu,
        strain_images: setup.outputs.strain_images,
        micro: setup.outputs.micro.as_ref(),
        maps: setup.pieces.len() as u64,
        render: setup.outputs.render.as_ref(),
    }
    .bytes()
}

/// The space of a file system: bytes free to this user, bytes in all.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Space {
    free: u64,
    total: u64,
}

/// [`Space`] of the file system that holds `dir` (or its nearest existing
/// ancestor); `None` where that cannot be asked.
fn space(dir: &std::path::Path) -> Option<Space> {
    let mut at = dir;
    loop {
        if at.as_os_str().is_empty() {
            at = std::path::Path::new(".");
        }
        if at.exists() {
            return space_at(at);
        }
        at = at.parent()?;
    }
}

#[cfg(unix)]
fn space_at(path: &std::path::Path) -> Option<Space> {
    let stat = rustix::fs::statvfs(path).ok()?;
    Some(Space {
        free: stat.f_bavail.saturating_mul(stat.f_frsize),
        total: stat.f_blocks.saturating_mul(stat.f_frsize),
    })
}

#[cfg(not(unix))]
fn space_at(_: &std::path::Path) -> Option<Space> {
    None
}

/// A byte count as a reader takes it in: `512 bytes`, `3.4 MB`, `1.25 GB`.
fn bytes_text(b: u64) -> String {
    let b = b as f64;
    if b < 1e3 {
        format!("{b} bytes")
    } else if b < 1e6 {
        format!("{:.1} kB", b / 1e3)
    } else if b < 1e9 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.2} GB", b / 1e9)
    }
}

/// Refuses a run whose planned output exceeds [`MAX_PLANNED_BYTES`]
/// (unless `force`) or the free space where it goes.
pub fn check(setup: &Setup, force: bool) -> Result<()> {
    let frames = setup.simulation.frames + 1;
    refuse(
        planned_bytes(setup),
        frames,
        &setup.outputs.dir,
        force,
        "time.frame_rate_hz",
    )
}

/// [`check`] for an animated surface's run.
pub fn check_surface(setup: &crate::scenario::SurfaceSetup, force: bool) -> Result<()> {
    refuse(
        planned_surface_bytes(setup),
        setup.surface.num_frames(),
        &setup.outputs.dir,
        force,
        "surface.frame_rate_hz",
    )
}

fn refuse(
    planned: u64,
    frames: usize,
    output_dir: &std::path::Path,
    force: bool,
    rate_key: &str,
) -> Result<()> {
    refuse_within(
        planned,
        frames,
        output_dir,
        force,
        rate_key,
        space(output_dir),
    )
}

/// [`refuse`] with `free` bytes free where the run goes.
fn refuse_within(
    planned: u64,
    frames: usize,
    output_dir: &std::path::Path,
    force: bool,
    rate_key: &str,
    space: Option<Space>,
) -> Result<()> {
    let gb = |b: u64| b as f64 / 1e9;
    if planned > MAX_PLANNED_BYTES && !force {
        return Err(Error::parameter(
            "output",
            format!(
                "the run would write about {:.1} GB ({frames} frames), over the {:.0} GB a run \
                 may write without --force; lower {rate_key} or the image sizes, raise \
                 the frame strides, turn off outputs, or pass --force",
                gb(planned),
                gb(MAX_PLANNED_BYTES)
            ),
        ));
    }
    if let Some(Space { total: 0, .. }) = space {
        // /proc, /sys and the like: no blocks to write to at all.
        return Err(Error::io(
            output_dir,
            std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                "it is on a file system that stores no files (a virtual one such as /proc or \
                 /sys); choose an output folder on a disk",
            ),
        ));
    }
    if let Some(Space { free, .. }) = space {
        // The previous run's files go before this run writes: their space
        // is this run's too.
        let previous = crate::export::outputs::run_files_bytes(output_dir);
        if planned > free.saturating_add(previous) {
            let freed = if previous > 0 {
                format!(
                    " (counting the {} of the previous run's files it replaces)",
                    bytes_text(previous)
                )
            } else {
                String::new()
            };
            return Err(Error::io(
                output_dir,
                std::io::Error::new(
                    std::io::ErrorKind::StorageFull,
                    format!(
                        "the run would write about {} but only {} are free there{freed}; \
                         free some space, choose another output folder, or write fewer \
                         frames or images",
                        bytes_text(planned),
                        bytes_text(free.saturating_add(previous)),
                    ),
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The estimate for the main job's outputs is within a factor of two
    /// of what it writes (measured: 589 MB of frame VTUs, 91 MB of maps,
    /// 20 MB of strain maps, 8 MB of renders), and grows with the frames.
    #[test]
    fn the_main_jobs_estimate_is_the_right_size() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/press.toml");
        let mut setup = Setup::load(&path).unwrap();
        let planned = planned_bytes(&setup) as f64;
        assert!((0.7e9..1.6e9).contains(&planned), "{planned}");
        setup.simulation.frames *= 10;
        assert!(planned_bytes(&setup) as f64 > 9.0 * planned);
        assert!(space(std::path::Path::new("no/such/folder")).is_some_and(|s| s.free > 0));
    }

    /// The free-space check counts the previous run's files, which the
    /// run removes before it writes, and only those.
    #[test]
    fn the_previous_runs_files_count_as_free() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        std::fs::create_dir(out.join("frames")).unwrap();
        std::fs::write(out.join("frames/frame_0001.vtu"), vec![0u8; 3000]).unwrap();
        std::fs::write(out.join("notes.txt"), vec![0u8; 5000]).unwrap();
        let free = Space {
            free: 1000,
            total: 1_000_000,
        };
        let check =
            |planned| refuse_within(planned, 2, out, false, "time.frame_rate_hz", Some(free));
        check(4000).unwrap();
        let e = check(4001).unwrap_err().to_string();
        assert!(
            e.contains("about 4.0 kB but only 4.0 kB are free")
                && e.contains("counting the 3.0 kB"),
            "{e}"
        );
        std::fs::remove_file(out.join("frames/frame_0001.vtu")).unwrap();
        assert!(check(1001).is_err());
        check(1000).unwrap();
    }

    /// A virtual file system (no blocks at all) is named as such, not as
    /// a disk with 0 bytes free; sizes read in the unit that fits.
    #[test]
    fn a_folder_on_a_virtual_file_system_is_named() {
        let none = Space { free: 0, total: 0 };
        let e = refuse_within(
            10,
            2,
            std::path::Path::new("/proc/x"),
            false,
            "k",
            Some(none),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("/proc/x") && e.contains("stores no files") && !e.contains("free"),
            "{e}"
        );
        if std::path::Path::new("/proc/self").exists() {
            assert_eq!(
                space(std::path::Path::new("/proc/x")).map(|s| s.total),
                Some(0)
            );
        }
        assert_eq!(bytes_text(512), "512 bytes");
        assert_eq!(bytes_text(3_400_000), "3.4 MB");
        assert_eq!(bytes_text(1_250_000_000), "1.25 GB");
    }
}
