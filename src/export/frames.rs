//! Rendered frame files: numbered sequences as 8-bit or 16-bit sRGB PNG or
//! linear float EXR, each written atomically (a temporary file renamed into
//! place, so an interrupted run leaves only complete frames), and an
//! optional MP4 per sequence through an installed `ffmpeg` (also renamed
//! into place when complete).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{Error, Result};
pub use crate::imaging::encode::{
    write_comparison, write_difference, write_image, COMPARISON_GAP_PX, DIFFERENCE_RANGE,
};
use crate::imaging::FrameFormat;

/// File name of frame `frame` in `format`.
pub fn frame_name(frame: usize, format: FrameFormat) -> String {
    format!("frame_{frame:04}.{}", format.extension())
}

/// Whether an `ffmpeg` executable runs.
pub fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Encodes the PNG frames of `folder` (`frame_NNNN.png`, `frame_numbers`
/// in order) into `out` (H.264, yuv420p) at `fps` with ffmpeg: the files are
/// piped to it in order, one video frame each, so gaps from a frame stride
/// do not matter.
pub fn encode_mp4(folder: &Path, frame_numbers: &[usize], fps: f64, out: &Path) -> Result<PathBuf> {
    use std::io::Write as _;
    use std::process::Stdio;
    if !ffmpeg_available() {
        return Err(Error::MissingTool(format!(
            "render.mp4 needs ffmpeg on the PATH (e.g. `apt-get install ffmpeg`); \
             the frames in {} are complete without it",
            folder.display()
        )));
    }
    let failed = |e: std::io::Error| Error::io(out, e);
    // Encoded beside the target and renamed into place when complete.
    let partial = out.with_extension("partial.mp4");
    let mut child = Command::new("ffmpeg")
        .args(["-y", "-loglevel", "error", "-f", "image2pipe", "-framerate"])
        .arg(format!("{fps}"))
        // Converted to video levels with the BT.709 matrix and tagged so:
        // an untagged file leaves players to guess (often BT.601, which
        // shifts skin tones).
        .args(["-i", "-", "-vf"])
        .arg("pad=ceil(iw/2)*2:ceil(ih/2)*2,scale=out_color_matrix=bt709:out_range=tv")
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .args(["-colorspace", "bt709", "-color_primaries", "bt709"])
        .args(["-color_trc", "bt709", "-color_range", "tv"])
        .arg(&partial)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(failed)?;
    let fed = (|| -> Result<()> {
        let mut stdin = child.stdin.take().expect("stdin was piped");
        for &f in frame_numbers {
            let path = folder.join(frame_name(f, FrameFormat::Png8));
            let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            stdin.write_all(&bytes).map_err(failed)?;
        }
        Ok(())
    })();
    let output = child.wait_with_output().map_err(failed)?;
    if !output.status.success() || fed.is_err() {
        let _ = std::fs::remove_file(&partial);
        fed?;
        return Err(failed(std::io::Error::other(format!(
            "ffmpeg failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        ))));
    }
    std::fs::rename(&partial, out).map_err(failed)?;
    Ok(out.to_path_buf())
}
