//! `skinpatch synth`: a neutral microstructure map synthesized from an
//! exemplar (the library's `pipeline::synth`), with per-level progress on
//! stderr and the result's statistics on stdout.

use std::path::PathBuf;

use clap::Args;

/// `skinpatch synth`'s arguments.
#[derive(Args)]
pub struct SynthArgs {
    /// Synthesis file (TOML).
    pub file: PathBuf,
    /// Output folder, overriding the file's [output] dir.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Override a key: `--set synthesis.alpha=1` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
}

/// Runs `skinpatch synth`.
pub fn run(args: SynthArgs) -> anyhow::Result<()> {
    let (file, output, set) = (&args.file, args.output.as_deref(), &args.set);
    skinpatch::scenario::check_output_flag(output, set)?;
    let started = std::time::Instant::now();
    let run = skinpatch::pipeline::synth::run(file, set, output, &mut |l| {
        eprintln!(
            "level {}: {} × {} texels from {} × {} exemplar texels, window {}, {} dims, \
             {:.0}% coherent, {:.1} s",
            l.level,
            l.size.0,
            l.size.1,
            l.exemplar.0,
            l.exemplar.1,
            l.window,
            l.dims,
            100.0 * l.coherent_share,
            l.seconds
        );
    })?;
    let m = &run.synthesis.map;
    let st = &run.statistics;
    println!(
        "synthesized {} × {} texels at {} µm in {:.1} s (σ_m {} µm, σ_L {} µm)",
        m.width,
        m.height,
        m.texel_um,
        run.synthesis.seconds,
        run.synthesis.sigmas_um.0,
        run.synthesis.sigmas_um.1
    );
    if let Some(e) = st.low_frequency_rms {
        println!(
            "mesostructure kept: RMS of the difference at its resolution {:.2}% of its range",
            100.0 * e
        );
    }
    println!(
        "normal histogram total variation to the exemplar: {:.3}",
        st.histogram_tv
    );
    if let Some(w) = st.spectrum_worst {
        println!(
            "power spectrum, microstructure band: worst octave {:+.1}% from the exemplar",
            100.0 * w
        );
    }
    if !run.rendered_on_gpu && run.written.iter().any(|p| p.ends_with("preview.png")) {
        println!("preview: no GPU adapter, the render panel is CPU shading");
    }
    for p in &run.written {
        println!("wrote {}", p.display());
    }
    log::info!("synth took {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}
