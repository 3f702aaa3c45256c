//! `navsync init`: a commented sensor sheet to fill in (the template is
//! `navsync::sensor::template`).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};

#[derive(clap::Args)]
pub struct Args {
    /// The sheet to write.
    #[arg(long, default_value = "sensor.yaml")]
    pub output: PathBuf,
    /// IMU whose figures fill the template: adis16465, icm20602 (consumer
    /// MEMS, the cautious choice for an unknown IMU), tactical or nav.
    #[arg(long, default_value = "icm20602")]
    pub preset: String,
    /// Overwrite an existing file.
    #[arg(long)]
    pub force: bool,
}

pub fn run(a: Args) -> Result<()> {
    let text = navsync::sensor::template(&a.preset)?;
    if a.output.exists() && !a.force {
        bail!(
            "{} exists: not overwritten (--force overwrites it)",
            a.output.display()
        );
    }
    navsync::io::output::write_file(&a.output, text)
        .with_context(|| format!("writing {}", a.output.display()))?;
    println!(
        "navsync init: wrote {} ({} figures). Edit the antenna lever arm and the IMU figures, then:\n  navsync process RAW... --sensor {} --output DIR",
        a.output.display(),
        a.preset,
        a.output.display()
    );
    Ok(())
}
