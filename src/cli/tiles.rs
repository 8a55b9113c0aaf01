//! `skinpatch tiles`: a displacement map split into a tiled map (a folder
//! of f32 EXR tiles with `index.toml`), or a tiled map joined back into one
//! file. Split and joined back, a map keeps its bits.

use std::path::{Path, PathBuf};

use anyhow::bail;
use clap::{Args, Subcommand};
use skinpatch::micro::io::{read_map, write_exr, write_png16, MapDefaults, TexelSize};
use skinpatch::micro::tiled::TiledMap;

/// What `tiles` does.
#[derive(Subcommand)]
pub enum TilesCommand {
    /// Split a map file (.png, 16-bit, or .exr) into a tiled map's folder.
    Split(SplitArgs),
    /// Join a tiled map's folder into one map file (.exr, or .png for
    /// 16-bit).
    Join(JoinArgs),
}

/// `tiles split`.
#[derive(Args)]
pub struct SplitArgs {
    /// The map (.png, 16-bit, or .exr).
    input: PathBuf,
    /// The folder to write.
    #[arg(short, long)]
    output: PathBuf,
    /// Tile side (texels).
    #[arg(long, default_value_t = 4096)]
    tile: usize,
    /// Texel size (µm) of a map file without skinpatch metadata.
    #[arg(long, value_name = "UM")]
    texel_um: Option<f64>,
}

/// `tiles join`.
#[derive(Args)]
pub struct JoinArgs {
    /// The tiled map's folder.
    input: PathBuf,
    /// The map file to write (.exr, or .png for 16-bit).
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `tiles split` or `tiles join`.
pub fn run(command: TilesCommand) -> anyhow::Result<()> {
    match command {
        TilesCommand::Split(a) => split(&a.input, &a.output, a.tile, a.texel_um),
        TilesCommand::Join(a) => join(&a.input, &a.output),
    }
}

fn split(input: &Path, output: &Path, tile: usize, texel_um: Option<f64>) -> anyhow::Result<()> {
    if tile == 0 {
        bail!("--tile must be ≥ 1 texel");
    }
    if let Some(t) = texel_um.filter(|t| !(t.is_finite() && *t > 0.0)) {
        bail!("--texel-um must be finite and > 0, got {t}");
    }
    // Without --texel-um a sentinel texel size shows whether the
    // file brought its own.
    let unset = f64::MIN_POSITIVE;
    let defaults = MapDefaults {
        texel: TexelSize::Um(texel_um.unwrap_or(unset)),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    // The tiles and index.toml go into `output`: an input there could be
    // one of them.
    let parent = input
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if let (Ok(dir), Ok(parent)) = (std::fs::canonicalize(output), std::fs::canonicalize(parent)) {
        if dir == parent {
            bail!(
                "--output {} is the folder of the input map {}; the tiles written there could \
                 overwrite it: choose another folder",
                output.display(),
                input.display()
            );
        }
    }
    let map = read_map(input, &defaults)?;
    if texel_um.is_none() && map.texel_um == unset {
        bail!(
            "{} carries no texel size (no skinpatch metadata): give --texel-um",
            input.display()
        );
    }
    let tiled = TiledMap::write(output, &map, tile)?;
    let (cols, rows) = tiled.grid();
    println!(
        "wrote {} ({} × {} texels of {} µm in {cols} × {rows} tiles of {tile})",
        output.display(),
        map.width,
        map.height,
        map.texel_um
    );
    Ok(())
}

fn join(input: &Path, output: &Path) -> anyhow::Result<()> {
    let tiled = TiledMap::open(input)?;
    if tiled.owns(output) {
        bail!(
            "--output {} is a file of the tiled map being joined ({}); writing it would \
             overwrite an input: choose another file",
            output.display(),
            tiled.dir.display()
        );
    }
    let map = tiled.read_all()?;
    match output.extension().and_then(|e| e.to_str()) {
        Some("exr") => write_exr(output, &map)?,
        Some("png") => write_png16(output, &map)?,
        _ => bail!(
            "--output must end in .exr or .png, got {}",
            output.display()
        ),
    }
    println!(
        "wrote {} ({} × {} texels)",
        output.display(),
        map.width,
        map.height
    );
    Ok(())
}
