//! `petzval-fit`: fit a lens to photographs of point light sources (see `docs/lens-fit.md`).

use clap::Parser;
use petzval_fit::{Manifest, Model};
use std::path::PathBuf;
use std::process::ExitCode;

/// Fit a Petzval lens to photographs of point light sources.
#[derive(Parser, Debug)]
#[command(name = "petzval-fit", version)]
struct Args {
    /// The capture manifest (TOML).
    manifest: PathBuf,
    /// Only validate the manifest against its lens and print what would be fitted.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> petzval_fit::Result<()> {
    let manifest = Manifest::load(&args.manifest)?;
    let lens = petzval_optics::load_lens(&manifest.start_lens)?;
    let model = Model { prescription: lens.prescription().clone(), camera: Default::default() };
    let file = manifest.file.display().to_string();
    println!("start lens: {} ({} surfaces)", lens.name(), lens.surfaces().len());
    for (i, f) in manifest.free.iter().enumerate() {
        let v = model
            .get(&f.param)
            .map_err(|m| petzval_fit::Error::manifest(&file, format!("free[{}].param", i + 1), m))?;
        println!("free {:<28} start {:>12.6} in [{}, {}]", f.name, f.start.unwrap_or(v), f.min, f.max);
    }
    println!("{} captures", manifest.captures.len());
    if !args.check {
        return Err(petzval_fit::Error::manifest(
            &file,
            "(command)",
            "fitting is not implemented yet: only --check (manifest validation) works in this version",
        ));
    }
    Ok(())
}
