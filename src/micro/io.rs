//! Displacement map files: 16-bit greyscale PNG and single-channel f32 EXR.
//!
//! PNG stores `round((h − offset)/scale)` in 0 … 65535 with `offset` the
//! smallest height and `scale = (max − min)/65535`, so reading back is exact
//! to half a quantisation step (`scale/2`). The metadata rides in tEXt
//! chunks: `skinpatch:texel_um`, `skinpatch:height_offset`,
//! `skinpatch:height_scale`, `skinpatch:height_unit_um` and `skinpatch:edge`.
//! A PNG from elsewhere (no such chunks) is read as heights 0 … 1 in units
//! given by the caller, with the caller's texel size.
//!
//! EXR stores the heights as one f32 channel `Y` (exact round trip) with the
//! metadata as layer attributes of the same names (`skinpatch:edge` as 0 =
//! wrap, 1 = clamp).
//!
//! Normal maps (16-bit RGB PNG, f32 RGB EXR) carry the texel size, height
//! unit and edge rule of the height map they come from in the same places,
//! and a `skinpatch:content` entry saying what they hold.
//!
//! Rows are written top to bottom with v decreasing, so the image shows v up
//! like the strain maps. Writes are atomic (temporary file, then rename).
//!
//! Target normal histograms for `fit` are CSV files of weights
//! ([`read_histogram`]).

use std::path::Path;

use super::map::{DisplacementMap, Edge};
use crate::error::{Error, Result};
use crate::mesh::io::write_atomically;

/// Texel size of a file without metadata.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TexelSize {
    /// This many micrometres.
    Um(f64),
    /// The map spans this many millimetres along u.
    Extent(f64),
    /// None: a file without a texel size in its metadata is an error (an
    /// 8-bit PNG from an image editor says nothing of its scale); the text
    /// names where to give one.
    Required(&'static str),
}

impl TexelSize {
    fn of(self, path: &Path, width: usize) -> Result<f64> {
        match self {
            TexelSize::Um(t) => Ok(t),
            TexelSize::Extent(mm) => Ok(mm * 1000.0 / width.max(1) as f64),
            TexelSize::Required(hint) => Err(Error::malformed(
                path,
                format!("carries no texel size ({TEXEL} metadata); give it with {hint}"),
            )),
        }
    }
}

/// What to assume for a file that does not carry skinpatch metadata.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapDefaults {
    /// Texel side.
    pub texel: TexelSize,
    /// Micrometres per stored unit (PNG: per full 0 … 65535 range).
    pub height_unit_um: f64,
    /// Edge handling.
    pub edge: Edge,
}

const TEXEL: &str = "skinpatch:texel_um";
const OFFSET: &str = "skinpatch:height_offset";
const SCALE: &str = "skinpatch:height_scale";
const UNIT: &str = "skinpatch:height_unit_um";
const EDGE: &str = "skinpatch:edge";
/// The EXR form: one attribute holding `key=value` entries for TEXEL,
/// UNIT and EDGE. One attribute, because the EXR writer stores its custom
/// attributes in hash order, so three would make identical maps differ in
/// bytes. (Files with the three as separate f64 attributes still read.)
const EXR_METADATA: &str = "skinpatch:map";

/// What a normal map file holds, in its `skinpatch:content` entry.
const CONTENT: &str = "skinpatch:content";
const NORMAL_CONTENT: &str =
    "unit normal (x along u, y along v, z out of the skin) of the height map with this texel size";

/// The metadata every map file carries beyond its pixels: texel size,
/// height unit and edge rule (heights also carry their PNG quantisation).
fn map_entries(map: &DisplacementMap) -> [(&'static str, String); 3] {
    [
        (TEXEL, format!("{:e}", map.texel_um)),
        (UNIT, format!("{:e}", map.height_unit_um)),
        (EDGE, edge_name(map.edge).to_string()),
    ]
}

/// The EXR attribute holding `entries` as `key=value` texts.
fn exr_metadata<'a>(
    entries: impl IntoIterator<Item = (&'a str, String)>,
) -> (exr::prelude::Text, exr::prelude::AttributeValue) {
    use exr::prelude::{AttributeValue, Text};
    (
        Text::from(EXR_METADATA),
        AttributeValue::TextVector(
            entries
                .into_iter()
                .map(|(k, v)| Text::from(format!("{k}={v}").as_str()))
                .collect(),
        ),
    )
}

fn edge_name(edge: Edge) -> &'static str {
    match edge {
        Edge::Wrap => "wrap",
        Edge::Clamp => "clamp",
    }
}

/// Writes `map` as a 16-bit greyscale PNG with its metadata, quantised
/// over the map's own height range.
pub fn write_png16(path: &Path, map: &DisplacementMap) -> Result<()> {
    write_png16_in(path, map, None).map(|_| ())
}

/// Writes `map` as a 16-bit greyscale PNG quantised over `range` (height
/// units; `None`: the map's own range), so that a sequence written over one
/// range shares one offset and scale. Returns the number of texels outside
/// `range`, stored clipped to its ends.
pub fn write_png16_in(
    path: &Path,
    map: &DisplacementMap,
    range: Option<[f64; 2]>,
) -> Result<usize> {
    let [lo, hi] = range.unwrap_or_else(|| {
        let (lo, hi) = map.range();
        if lo.is_finite() {
            [lo as f64, hi as f64]
        } else {
            [0.0, 0.0]
        }
    });
    let scale = if hi > lo { (hi - lo) / 65535.0 } else { 1.0 };
    let mut bytes = Vec::with_capacity(2 * map.data.len());
    let mut clipped = 0;
    for h in flip_rows(&map.data, map.width, map.height) {
        let q = ((h as f64 - lo) / scale).round();
        clipped += usize::from(!(0.0..=65535.0).contains(&q));
        let q = q.clamp(0.0, 65535.0) as u16;
        bytes.extend_from_slice(&q.to_be_bytes());
    }
    let mut out = Vec::new();
    let failed = |e: png::EncodingError| Error::io(path, std::io::Error::other(e));
    {
        let mut encoder = png::Encoder::new(&mut out, map.width as u32, map.height as u32);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Sixteen);
        let quantisation = [(OFFSET, format!("{lo:e}")), (SCALE, format!("{scale:e}"))];
        for (key, value) in map_entries(map).into_iter().chain(quantisation) {
            encoder.add_text_chunk(key.into(), value).map_err(failed)?;
        }
        let mut writer = encoder.write_header().map_err(failed)?;
        writer.write_image_data(&bytes).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    write_atomically(path, &out)?;
    Ok(clipped)
}

/// Reads a 16-bit (or 8-bit) greyscale PNG.
pub fn read_png16(path: &Path, defaults: &MapDefaults) -> Result<DisplacementMap> {
    let bad = |message: String| Error::malformed(path, message);
    crate::mesh::io::regular_file(path)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder
        .read_info()
        .map_err(|e| bad(format!("not a readable PNG: {e}")))?;
    let info = reader.info();
    let (width, height) = (info.width as usize, info.height as usize);
    let decoded = reader
        .output_buffer_size()
        .ok_or_else(|| bad("image too large".into()))?;
    check_decoded_size(path, width, height, decoded as u64)?;
    if info.color_type != png::ColorType::Grayscale {
        return Err(bad(format!(
            "a displacement map must be greyscale, this PNG is {:?}",
            info.color_type
        )));
    }
    let depth = info.bit_depth;
    let text: std::collections::HashMap<String, String> = info
        .uncompressed_latin1_text
        .iter()
        .map(|c| (c.keyword.clone(), c.text.clone()))
        .collect();
    let number = |key: &str| -> Result<Option<f64>> {
        text.get(key)
            .map(|v| {
                v.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(format!("metadata {key} = {v:?} is not a finite number")))
            })
            .transpose()
    };
    let full = match depth {
        png::BitDepth::Sixteen => 65535.0,
        png::BitDepth::Eight => 255.0,
        other => {
            return Err(bad(format!(
                "unsupported bit depth {other:?} (use 8 or 16)"
            )))
        }
    };
    let offset = number(OFFSET)?.unwrap_or(0.0);
    let scale = number(SCALE)?.unwrap_or(1.0 / full);
    let texel_um = match number(TEXEL)? {
        Some(t) => t,
        None => defaults.texel.of(path, width)?,
    };
    let height_unit_um = number(UNIT)?.unwrap_or(defaults.height_unit_um);
    if [texel_um, height_unit_um, scale]
        .iter()
        .any(|v| v.is_nan() || *v <= 0.0)
    {
        return Err(bad(format!(
            "texel size ({texel_um} µm), height unit ({height_unit_um} µm) and scale ({scale}) must be > 0"
        )));
    }
    let edge = match text.get(EDGE).map(String::as_str) {
        None => defaults.edge,
        Some("wrap") => Edge::Wrap,
        Some("clamp") => Edge::Clamp,
        Some(other) => {
            return Err(bad(format!(
                "metadata {EDGE} = {other:?}, expected wrap or clamp"
            )))
        }
    };
    let mut buf = vec![0u8; decoded];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| bad(format!("corrupt PNG data: {e}")))?;
    let stride = frame.line_size;
    let mut top_down = Vec::with_capacity(width * height);
    for row in 0..height {
        let line = &buf[row * stride..(row + 1) * stride];
        for i in 0..width {
            let q = match depth {
                png::BitDepth::Sixteen => u16::from_be_bytes([line[2 * i], line[2 * i + 1]]) as f64,
                _ => line[i] as f64,
            };
            top_down.push((offset + q * scale) as f32);
        }
    }
    let mut map = DisplacementMap::zeros(width, height, texel_um, edge);
    map.height_unit_um = height_unit_um;
    map.data = flip_rows(&top_down, width, height);
    Ok(map)
}

/// Row order reversed: file rows run top to bottom (v down), map rows v up.
fn flip_rows<T: Copy>(values: &[T], width: usize, height: usize) -> Vec<T> {
    (0..height)
        .rev()
        .flat_map(|row| values[row * width..(row + 1) * width].iter().copied())
        .collect()
}

/// Writes `map` as a single-channel f32 EXR with its metadata.
pub fn write_exr(path: &Path, map: &DisplacementMap) -> Result<()> {
    use exr::prelude::{AnyChannel, FlatSamples, LayerAttributes};
    let channel = AnyChannel::new(
        "Y",
        FlatSamples::F32(flip_rows(&map.data, map.width, map.height)),
    );
    let mut attributes = LayerAttributes::named("height");
    let (key, value) = exr_metadata(map_entries(map));
    attributes.other.insert(key, value);
    write_exr_channels(path, (map.width, map.height), attributes, vec![channel])
}

/// Writes one EXR layer of f32 channels, atomically.
pub(crate) fn write_exr_channels(
    path: &Path,
    size: (usize, usize),
    attributes: exr::prelude::LayerAttributes,
    channels: Vec<exr::prelude::AnyChannel<exr::prelude::FlatSamples>>,
) -> Result<()> {
    use exr::prelude::{AnyChannels, Encoding, Image, Layer, LineOrder, SmallVec, WritableImage};
    // Tiles in increasing order: compressed in parallel, but written in a
    // fixed order, so identical images give identical bytes.
    let encoding = Encoding {
        line_order: LineOrder::Increasing,
        ..Encoding::FAST_LOSSLESS
    };
    let layer = Layer::new(
        size,
        attributes,
        encoding,
        AnyChannels::sort(SmallVec::from_vec(channels)),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    write_atomically(path, bytes.get_ref())
}

/// Reads a single-channel EXR (channel `Y`, or the only channel).
pub fn read_exr(path: &Path, defaults: &MapDefaults) -> Result<DisplacementMap> {
    use exr::prelude::{read_first_flat_layer_from_file, AttributeValue, Text};
    let bad = |message: String| Error::malformed(path, message);
    crate::mesh::io::regular_file(path)?;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| bad(format!("not a readable EXR: {e}")))?;
    for header in &meta.headers {
        let size = header.layer_size;
        let samples = header.channels.list.len() as u64 * size.area() as u64;
        check_decoded_size(path, size.width(), size.height(), samples * 4)?;
    }
    let image = read_first_flat_layer_from_file(path)
        .map_err(|e| bad(format!("not a readable EXR: {e}")))?;
    let layer = &image.layer_data;
    let channels = &layer.channel_data.list;
    let channel = channels
        .iter()
        .find(|c| c.name.eq("Y"))
        .or(if channels.len() == 1 {
            channels.first()
        } else {
            None
        })
        .ok_or_else(|| {
            bad(format!(
                "expected one channel or a channel Y, found {}",
                channels.len()
            ))
        })?;
    let (width, height) = (layer.size.width(), layer.size.height());
    let values: Vec<f32> = channel.sample_data.values_as_f32().collect();
    // key=value entries of the one metadata attribute, if present.
    let mut entries = std::collections::BTreeMap::new();
    if let Some(AttributeValue::TextVector(list)) =
        layer.attributes.other.get(&Text::from(EXR_METADATA))
    {
        for entry in list {
            let entry = entry.to_string();
            let (key, value) = entry.split_once('=').ok_or_else(|| {
                bad(format!(
                    "metadata {EXR_METADATA} entry {entry:?} is not key=value"
                ))
            })?;
            entries.insert(key.to_string(), value.to_string());
        }
    }
    let number = |key: &str| -> Result<Option<f64>> {
        if let Some(text) = entries.get(key) {
            return text
                .parse()
                .map(Some)
                .map_err(|_| bad(format!("metadata {key} = {text:?} is not a number")));
        }
        Ok(match layer.attributes.other.get(&Text::from(key)) {
            Some(&AttributeValue::F64(v)) => Some(v),
            Some(&AttributeValue::F32(v)) => Some(v as f64),
            _ => None,
        })
    };
    let texel_um = match number(TEXEL)? {
        Some(t) => t,
        None => defaults.texel.of(path, width)?,
    };
    let height_unit_um = number(UNIT)?.unwrap_or(defaults.height_unit_um);
    if [texel_um, height_unit_um]
        .iter()
        .any(|v| v.is_nan() || *v <= 0.0)
    {
        return Err(bad(format!(
            "texel size ({texel_um} µm) and height unit ({height_unit_um} µm) must be > 0"
        )));
    }
    let edge = match entries.get(EDGE).map(String::as_str) {
        Some("wrap") => Edge::Wrap,
        Some("clamp") => Edge::Clamp,
        Some(other) => {
            return Err(bad(format!(
                "metadata {EDGE} = {other:?}, expected wrap or clamp"
            )))
        }
        None => match layer.attributes.other.get(&Text::from(EDGE)) {
            Some(&AttributeValue::F64(0.0)) => Edge::Wrap,
            Some(&AttributeValue::F64(_)) => Edge::Clamp,
            _ => defaults.edge,
        },
    };
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!(
            "height at texel ({}, {}) is not finite",
            k % width.max(1),
            height - 1 - k / width.max(1)
        )));
    }
    let mut map = DisplacementMap::zeros(width, height, texel_um, edge);
    map.height_unit_um = height_unit_um;
    map.data = flip_rows(&values, width, height);
    Ok(map)
}

/// Refuses a map whose header claims more texels than memory holds: its
/// `decoded` bytes plus two f32 copies of its `width × height` texels
/// (the decoded values and the map), against the memory available.
fn check_decoded_size(path: &Path, width: usize, height: usize, decoded: u64) -> Result<()> {
    let needed = decoded.saturating_add(8u64.saturating_mul(width as u64 * height as u64));
    match crate::memory::shortfall_gb(needed) {
        Some((needed, have)) => Err(Error::malformed(
            path,
            format!(
                "its header claims {width} × {height} texels, which need about {needed:.1} GB \
                 to read; {have:.1} GB are available"
            ),
        )),
        None => Ok(()),
    }
}

/// Reads a map by extension: `.png` or `.exr`.
pub fn read_map(path: &Path, defaults: &MapDefaults) -> Result<DisplacementMap> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => read_png16(path, defaults),
        Some("exr") => read_exr(path, defaults),
        _ => Err(Error::malformed(
            path,
            "unknown displacement map format (expected .png or .exr)",
        )),
    }
}

/// Writes the normals of `map` as a 16-bit RGB PNG, each component `n`
/// stored as `round((n + 1)/2 · 65535)` (the usual tangent-space encoding;
/// x along u, y along v, z out of the skin), rows with v up like the height
/// maps, with the map's texel size, height unit and edge rule as tEXt
/// chunks like a height map's, and `skinpatch:content` saying what it holds.
pub fn write_normal_png16(path: &Path, normals: &[[f32; 3]], map: &DisplacementMap) -> Result<()> {
    let mut bytes = Vec::with_capacity(6 * normals.len());
    for n in flip_rows(normals, map.width, map.height) {
        for c in n {
            let q = ((c.clamp(-1.0, 1.0) + 1.0) * 0.5 * 65535.0).round() as u16;
            bytes.extend_from_slice(&q.to_be_bytes());
        }
    }
    let mut out = Vec::new();
    let failed = |e: png::EncodingError| Error::io(path, std::io::Error::other(e));
    {
        let mut encoder = png::Encoder::new(&mut out, map.width as u32, map.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Sixteen);
        let content = (
            CONTENT,
            format!("{NORMAL_CONTENT}; stored as (n + 1)/2 of 65535"),
        );
        for (key, value) in map_entries(map).into_iter().chain([content]) {
            encoder.add_text_chunk(key.into(), value).map_err(failed)?;
        }
        let mut writer = encoder.write_header().map_err(failed)?;
        writer.write_image_data(&bytes).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    write_atomically(path, &out)
}

/// Writes the normals of `map` as an f32 EXR with channels `R`, `G`, `B` =
/// the normal's x (along u), y (along v) and z, rows with v up, and the
/// map's metadata in the same `skinpatch:map` attribute as a height EXR
/// (plus `skinpatch:content`).
pub fn write_normal_exr(path: &Path, normals: &[[f32; 3]], map: &DisplacementMap) -> Result<()> {
    use exr::prelude::{AnyChannel, FlatSamples, LayerAttributes};
    let (width, height) = (map.width, map.height);
    let component = |c: usize| -> Vec<f32> {
        (0..height)
            .rev()
            .flat_map(|row| {
                normals[row * width..(row + 1) * width]
                    .iter()
                    .map(move |n| n[c])
            })
            .collect()
    };
    let channels = ["R", "G", "B"]
        .iter()
        .enumerate()
        .map(|(c, name)| AnyChannel::new(*name, FlatSamples::F32(component(c))))
        .collect::<Vec<_>>();
    let mut attributes = LayerAttributes::named("normal");
    let content = (CONTENT, NORMAL_CONTENT.to_string());
    let (key, value) = exr_metadata(map_entries(map).into_iter().chain([content]));
    attributes.other.insert(key, value);
    write_exr_channels(path, (width, height), attributes, channels)
}

/// Reads a target histogram: `bins` lines of `bins` comma-separated
/// non-negative weights, normalised to sum 1.
pub fn read_histogram(
    path: &Path,
    hist: crate::micro::fit::HistogramSettings,
) -> Result<crate::micro::NormalHistogram> {
    let text = crate::mesh::io::read_input_text(path)?;
    let bad = |line: usize, message: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let rows: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if rows.len() != hist.bins {
        return Err(bad(
            0,
            format!(
                "expected {} rows of weights, found {}",
                hist.bins,
                rows.len()
            ),
        ));
    }
    let mut cells = Vec::with_capacity(hist.bins * hist.bins);
    for (k, row) in rows.iter().enumerate() {
        let values: Vec<&str> = row.split(',').collect();
        if values.len() != hist.bins {
            return Err(bad(
                k + 1,
                format!("expected {} weights, found {}", hist.bins, values.len()),
            ));
        }
        for v in values {
            let w: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|w: &f64| w.is_finite() && *w >= 0.0)
                .ok_or_else(|| {
                    bad(
                        k + 1,
                        format!("{:?} is not a non-negative number", v.trim()),
                    )
                })?;
            cells.push(w);
        }
    }
    let total: f64 = cells.iter().sum();
    if total <= 0.0 {
        return Err(bad(0, "the histogram is empty (all weights 0)".into()));
    }
    cells.iter_mut().for_each(|c| *c /= total);
    Ok(crate::micro::NormalHistogram {
        bins: hist.bins,
        range: hist.range,
        cells,
    })
}
