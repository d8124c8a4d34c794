//! Progress bars on stderr, off when stderr is not a terminal or with `--quiet`.

use std::io::IsTerminal;

use indicatif::ProgressBar;
use trisplat_pipeline::Event;

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

/// Running time per frame of each extraction method, for the progress bar's message: what
/// each method costs and how long it still needs for the frames left.
#[derive(Clone, Debug, Default)]
pub struct MethodPace {
    /// Per method in first-seen order: name, total milliseconds, frames.
    methods: Vec<(&'static str, f64, usize)>,
}

impl MethodPace {
    /// Adds one frame's time of `method`.
    pub fn add(&mut self, method: &'static str, ms: f64) {
        match self.methods.iter_mut().find(|(m, _, _)| *m == method) {
            Some((_, total, n)) => {
                *total += ms;
                *n += 1;
            }
            None => self.methods.push((method, ms, 1)),
        }
    }

    /// `tsdf 3.3 s/frame, 52 min left · delaunay 250 ms/frame, 4 min left` for `left` frames
    /// to go (empty before the first frame).
    #[must_use]
    pub fn message(&self, left: usize) -> String {
        self.methods
            .iter()
            .map(|(name, total, n)| {
                let mean = total / *n as f64;
                format!(
                    "{name} {}/frame, {} left",
                    duration(mean),
                    duration(mean * left as f64)
                )
            })
            .collect::<Vec<_>>()
            .join(" · ")
    }
}

/// The progress of a main-job run on stderr, drawn from its events: a spinner while the
/// inputs are read, then a bar over the frames whose message is each method's pace
/// ([`MethodPace`]), notices printed above it.
#[derive(Debug)]
pub struct RunProgress {
    /// The command's name, before each message.
    command: &'static str,
    factory: Progress,
    spinner: ProgressBar,
    bar: Option<ProgressBar>,
    pace: MethodPace,
}

impl RunProgress {
    /// A spinner `<command>: reading inputs` until the run starts.
    #[must_use]
    pub fn new(factory: Progress, command: &'static str) -> Self {
        Self {
            command,
            factory,
            spinner: factory.spinner(&format!("{command}: reading inputs")),
            bar: None,
            pace: MethodPace::default(),
        }
    }

    /// Shows what `event` tells.
    pub fn show(&mut self, event: &Event) {
        match event {
            Event::Started { frames, .. } => {
                self.spinner.finish_and_clear();
                let message = format!("{}: meshing frames", self.command);
                self.bar = Some(self.factory.bar(*frames as u64, &message));
            }
            Event::MethodDone { method, record } => self.pace.add(method.name(), record.ms),
            Event::FrameDone { done, total, .. } | Event::FrameFailed { done, total, .. } => {
                if let Some(b) = &self.bar {
                    b.set_position(*done as u64);
                    b.set_message(format!(
                        "{}: {}",
                        self.command,
                        self.pace.message(total.saturating_sub(*done))
                    ));
                }
            }
            Event::Finishing => {
                if let Some(b) = &self.bar {
                    b.set_message(format!("{}: writing sequences and report", self.command));
                }
            }
            Event::Notice(message) => {
                let say = || eprintln!("warning: {message}");
                match &self.bar {
                    Some(b) => b.suspend(say),
                    None => self.spinner.suspend(say),
                }
            }
        }
    }

    /// Clears the spinner and the bar.
    pub fn finish(self) {
        self.spinner.finish_and_clear();
        if let Some(b) = self.bar {
            b.finish_and_clear();
        }
    }
}

/// `850 ms`, `3.3 s`, `4 min`, `2.5 h`.
fn duration(ms: f64) -> String {
    if ms < 1_000.0 {
        format!("{ms:.0} ms")
    } else if ms < 60_000.0 {
        format!("{:.1} s", ms / 1_000.0)
    } else if ms < 3_600_000.0 {
        format!("{:.0} min", ms / 60_000.0)
    } else {
        format!("{:.1} h", ms / 3_600_000.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pace_reports_each_method_mean_and_time_left() {
        let mut pace = MethodPace::default();
        assert_eq!(pace.message(10), "");
        pace.add("tsdf", 3_000.0);
        pace.add("delaunay", 200.0);
        pace.add("tsdf", 3_600.0);
        pace.add("delaunay", 300.0);
        assert_eq!(
            pace.message(1_000),
            "tsdf 3.3 s/frame, 55 min left · delaunay 250 ms/frame, 4 min left"
        );
        assert_eq!(
            pace.message(0),
            "tsdf 3.3 s/frame, 0 ms left · delaunay 250 ms/frame, 0 ms left"
        );
        let mut long = MethodPace::default();
        long.add("tsdf", 10_000.0);
        assert_eq!(long.message(973), "tsdf 10.0 s/frame, 2.7 h left");
    }
}
