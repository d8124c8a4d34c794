//! Progress bars on stderr, off when stderr is not a terminal or with `--quiet`.

use std::io::IsTerminal;

use indicatif::ProgressBar;

/// Factory for progress spinners that respects `--quiet` and non-terminal stderr.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    enabled: bool,
}

impl Progress {
    /// Progress bars are shown when not `quiet` and stderr is a terminal.
    pub fn new(quiet: bool) -> Self {
        Self {
            enabled: !quiet && std::io::stderr().is_terminal(),
        }
    }

    /// A spinner labelled `message` for work of unknown length (hidden when disabled).
    pub fn spinner(self, message: &str) -> ProgressBar {
        if !self.enabled {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new_spinner().with_message(message.to_owned());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar
    }

    /// A bar of `len` steps labelled `message` (hidden when disabled).
    pub fn bar(self, len: u64, message: &str) -> ProgressBar {
        if !self.enabled {
            return ProgressBar::hidden();
        }
        let style = indicatif::ProgressStyle::with_template("{msg} {wide_bar} {pos}/{len} {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
        ProgressBar::new(len)
            .with_style(style)
            .with_message(message.to_owned())
    }
}
