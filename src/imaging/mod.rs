//! Images and colour, one room below both the renderer and the exporters:
//! the linear RGBA [`Image`] a renderer produces, the frame file formats,
//! the sRGB transfer functions and the colour maps ([`colour`]), and the
//! encoders that write an image as PNG or EXR ([`encode`]).
//!
//! Everything here is plain data and pure functions apart from `encode`'s
//! writers, which write atomically (a temporary file renamed into place).

pub mod colour;
pub mod encode;

/// A linear RGBA image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width (px).
    pub width: usize,
    /// Height (px).
    pub height: usize,
    /// Linear RGBA, row-major.
    pub pixels: Vec<[f32; 4]>,
}

/// Frame file format (`png8`, `png16`, `exr` in scenario files).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum FrameFormat {
    /// 8-bit sRGB PNG.
    Png8,
    /// 16-bit sRGB PNG.
    Png16,
    /// Linear 32-bit float OpenEXR.
    Exr,
}

impl FrameFormat {
    /// File extension.
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Png8 | FrameFormat::Png16 => "png",
            FrameFormat::Exr => "exr",
        }
    }
}
