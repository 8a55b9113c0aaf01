//! What the viewer writes: the frames shown (PNG sequence, then an MP4
//! through ffmpeg when it is installed) and the probe path driven so far as
//! a scenario file that `skinpatch run` replays to the same states.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::export::frames;
use crate::render::{FrameFormat, Image};
use crate::scenario::Scenario;

/// The scenario that replays a viewer session: `original` (loaded from a
/// file in `base`) with its probe path replaced by the solved frames'
/// keyframes (`path`, `axis`: rows `[t, x, y, z]` at the frame times), the
/// duration covering them, the materials and friction as last set, and
/// its input paths rewritten for a file in the folder `dest`: relative to
/// `dest` where the two share a folder below the file-system root (so that
/// a project moved or shared as a whole keeps working), absolute otherwise.
/// The output folder is left to the default (`out/<file stem>`).
pub fn recorded_scenario(
    original: &Scenario,
    base: &Path,
    dest: &Path,
    path: &[[f64; 4]],
    axis: &[[f64; 4]],
    materials: &[super::state::RegionMaterial],
    friction: Option<f64>,
) -> Result<Scenario> {
    let mut s = original.clone();
    let probe = s
        .probe
        .as_mut()
        .ok_or_else(|| Error::parameter("probe", "the scenario has no [probe]: no path to save"))?;
    if path.len() < 2 {
        return Err(Error::parameter(
            "probe.path_mm",
            "only the first frame is solved: move the probe before saving its path",
        ));
    }
    probe.path_mm = path.to_vec();
    if probe.shape == crate::scenario::ProbeShapeKind::Capsule {
        probe.axis = Some(axis.to_vec());
    }
    if let Some(mu) = friction {
        probe.friction = Some(mu);
    }
    // Frame k of the replay is at k / rate, where the viewer solved it.
    s.time.duration_s = (path.len() - 1) as f64 / s.time.frame_rate_hz;
    for edited in materials {
        let m = s.material.entry(edited.region.clone()).or_default();
        m.youngs_modulus_kpa = Some(edited.youngs_kpa);
        m.poisson_ratio = Some(edited.poisson);
    }
    let dest = dest.canonicalize().ok();
    let absolute = |p: &Path| -> PathBuf {
        let joined = base.join(p);
        let target = joined.canonicalize().unwrap_or(joined);
        match &dest {
            Some(dest) => relative_path(&target, dest).unwrap_or(target),
            None => target,
        }
    };
    if let Some(file) = &s.mesh.file {
        s.mesh.file = Some(absolute(file));
    }
    if let Some(micro) = s.microstructure.as_mut() {
        micro.map = micro.map.as_deref().map(absolute);
        micro.kernel_file = micro.kernel_file.as_deref().map(absolute);
    }
    if let Some(render) = s.render.as_mut() {
        if render.albedo != "procedural" {
            render.albedo = absolute(Path::new(&render.albedo)).display().to_string();
        }
    }
    s.output.dir = None;
    Ok(s)
}

/// `target` as a path relative to the folder `from` (both absolute), or
/// `None` where they share nothing below the file-system root.
fn relative_path(target: &Path, from: &Path) -> Option<PathBuf> {
    use std::path::Component;
    if !(target.is_absolute() && from.is_absolute()) {
        return None;
    }
    let (t, f): (Vec<Component>, Vec<Component>) =
        (target.components().collect(), from.components().collect());
    let common = t.iter().zip(&f).take_while(|(a, b)| a == b).count();
    let below_root = t[..common]
        .iter()
        .filter(|c| matches!(c, Component::Normal(_)))
        .count();
    if below_root == 0 {
        return None;
    }
    let mut out = PathBuf::new();
    for _ in common..f.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c);
    }
    Some(out)
}

/// Writes `scenario` to `file` (atomically) under a comment header.
pub fn save_scenario(file: &Path, scenario: &Scenario, header: &str) -> Result<()> {
    let text = toml::to_string(scenario).map_err(|e| Error::Scenario {
        path: file.to_path_buf(),
        message: format!("cannot be written as TOML: {e}"),
        key: None,
        line: None,
    })?;
    let mut out = String::new();
    for line in header.lines() {
        out.push_str("# ");
        out.push_str(line);
        out.push('\n');
    }
    out.push('\n');
    out.push_str(&text);
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    crate::mesh::io::write_atomically(file, out.as_bytes())
}

/// Writes the frames shown while recording: `frame_NNNN.png` in a folder,
/// numbered from 0 per recording, then `frames.mp4` beside them.
pub struct FrameRecorder {
    folder: PathBuf,
    written: Vec<usize>,
}

impl FrameRecorder {
    /// Starts a recording into `folder` (created; frames of an earlier
    /// recording there are replaced).
    pub fn start(folder: &Path) -> Result<FrameRecorder> {
        std::fs::create_dir_all(folder).map_err(|e| Error::io(folder, e))?;
        Ok(FrameRecorder {
            folder: folder.to_path_buf(),
            written: Vec::new(),
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.written.len()
    }

    /// Writes the next frame.
    pub fn push(&mut self, image: &Image) -> Result<PathBuf> {
        let k = self.written.len();
        let path = self.folder.join(frames::frame_name(k, FrameFormat::Png8));
        frames::write_image(&path, image, FrameFormat::Png8)?;
        self.written.push(k);
        Ok(path)
    }

    /// Ends the recording: encodes `frames.mp4` at `fps` when ffmpeg is
    /// on the PATH and there are frames; returns the files written.
    pub fn finish(self, fps: f64) -> Result<Vec<PathBuf>> {
        let mut written: Vec<PathBuf> = self
            .written
            .iter()
            .map(|&k| self.folder.join(frames::frame_name(k, FrameFormat::Png8)))
            .collect();
        if self.written.is_empty() {
            return Ok(written);
        }
        if frames::ffmpeg_available() {
            let out = self.folder.join("frames.mp4");
            written.push(frames::encode_mp4(&self.folder, &self.written, fps, &out)?);
        } else {
            log::warn!(
                "ffmpeg is not on the PATH: the recording stays a PNG sequence in {} \
                 (install ffmpeg for an MP4)",
                self.folder.display()
            );
        }
        Ok(written)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_relative_below_a_shared_folder() {
        let rel = |t: &str, f: &str| relative_path(Path::new(t), Path::new(f));
        assert_eq!(
            rel(
                "/home/ana/skin/meshes/patch.node",
                "/home/ana/skin/out/view"
            ),
            Some(PathBuf::from("../../meshes/patch.node"))
        );
        assert_eq!(
            rel("/home/ana/skin/patch.node", "/home/ana/skin"),
            Some(PathBuf::from("patch.node"))
        );
        assert_eq!(
            rel("/home/ana/skin/out/v/map.png", "/home/ana/skin/out"),
            Some(PathBuf::from("v/map.png"))
        );
        // Nothing shared but the root: stays absolute.
        assert_eq!(rel("/data/patch.node", "/tmp/view"), None);
        assert_eq!(rel("meshes/patch.node", "/tmp"), None);
    }
}
