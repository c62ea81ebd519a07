//! Where a benchmark's report goes: stdout always, and with `--out DIR` the file
//! `DIR/<benchmark>.md`, written atomically so that a run that fails or is interrupted leaves
//! the table that was there (docs/results holds the published ones).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// The `--out` option of the benchmarks that write a table.
#[derive(clap::Args, Default)]
pub struct Out {
    /// Also write the report to DIR/NAME.md, NAME being the benchmark's (e.g. --out docs/results).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

impl Out {
    /// Prints `md` and, with `--out`, writes it to `<out>/<kind>.md`.
    pub fn report(&self, kind: &str, md: &str) -> Result<()> {
        println!("{md}");
        self.write(kind, md)
    }

    /// With `--out`, writes `md` to `<out>/<kind>.md`.
    pub fn write(&self, kind: &str, md: &str) -> Result<()> {
        match &self.out {
            Some(dir) => write(dir, &format!("{kind}.md"), md.as_bytes()),
            None => Ok(()),
        }
    }
}

/// Writes `bytes` to `dir/name` atomically (creating `dir`) and says so on stdout.
pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(name);
    prt_format::io::write_bytes_atomic(&path, bytes)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}
