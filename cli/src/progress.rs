//! A progress bar on stderr for long stages, drawn only when stderr is a terminal.

use std::io::IsTerminal;
use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};

/// Implements [`prt_bake::Progress`] with indicatif.
pub struct Bar {
    enabled: bool,
    bar: Mutex<Option<ProgressBar>>,
}

impl Bar {
    pub fn new() -> Bar {
        Bar {
            enabled: std::io::stderr().is_terminal(),
            bar: Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&mut Option<ProgressBar>)) {
        if let Ok(mut guard) = self.bar.lock() {
            f(&mut guard);
        }
    }
}

impl prt_bake::Progress for Bar {
    fn start(&self, stage: &str, total: u64) {
        if !self.enabled {
            return;
        }
        let bar = if total == 0 {
            let spinner = ProgressBar::new_spinner().with_message(stage.to_owned());
            if let Ok(style) = ProgressStyle::with_template("{msg:>8} {spinner} {elapsed}") {
                spinner.set_style(style);
            }
            spinner.enable_steady_tick(std::time::Duration::from_millis(100));
            spinner
        } else {
            let bar = ProgressBar::new(total).with_message(stage.to_owned());
            if let Ok(style) =
                ProgressStyle::with_template("{msg:>8} [{bar:40}] {pos}/{len} probes, eta {eta}")
            {
                bar.set_style(style.progress_chars("=> "));
            }
            bar
        };
        self.with(|b| *b = Some(bar));
    }

    fn advance(&self, n: u64) {
        self.with(|b| {
            if let Some(bar) = b {
                bar.inc(n);
            }
        });
    }

    fn finish(&self) {
        self.with(|b| {
            if let Some(bar) = b.take() {
                bar.finish_and_clear();
            }
        });
    }
}
