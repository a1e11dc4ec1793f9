//! A progress bar for runs that take more than about a second.

use std::time::{Duration, Instant};

use echelon::sim::{Frame, Observer, ObserverError};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Shows a bar on stderr once a run has taken [`Progress::DELAY`]; never when
/// stderr is not a terminal (indicatif hides it) or with `--quiet`. The
/// environment variable `ECHELON_PROGRESS_DELAY_MS` changes the delay (the
/// tests set it to 0).
#[derive(Debug)]
pub(crate) struct Progress {
    steps: u64,
    started: Instant,
    delay: Duration,
    enabled: bool,
    bar: Option<ProgressBar>,
}

impl Progress {
    /// Runs shorter than this show no bar.
    pub(crate) const DELAY: Duration = Duration::from_secs(1);
    /// Steps between two looks at the clock: attach it with
    /// `Every::new(Progress::CHECK_EVERY, …)`.
    pub(crate) const CHECK_EVERY: u64 = 1024;

    /// A progress observer for a run of `steps` steps.
    pub(crate) fn new(steps: u64, quiet: bool) -> Progress {
        let delay = std::env::var("ECHELON_PROGRESS_DELAY_MS")
            .ok()
            .and_then(|v| v.parse().ok())
            .map_or(Self::DELAY, Duration::from_millis);
        Progress {
            steps,
            started: Instant::now(),
            delay,
            enabled: !quiet,
            bar: None,
        }
    }

    /// Clears the bar.
    fn clear(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

/// A run that fails ends without `finish`: the bar is cleared all the same
/// before the error is printed.
impl Drop for Progress {
    fn drop(&mut self) {
        self.clear();
    }
}

impl Progress {
    /// The run has taken `step` of its steps and is at time `t`, s: the bar
    /// shows it, appearing once the run has taken [`Progress::DELAY`] (for
    /// a caller that steps without frames, as `echelon bench` does).
    pub(crate) fn at(&mut self, step: u64, t: f64) {
        if !self.enabled {
            return;
        }
        match &self.bar {
            Some(bar) => bar.set_position(step),
            None if self.started.elapsed() >= self.delay => {
                let bar =
                    ProgressBar::with_draw_target(Some(self.steps), ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(
                        "{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}%  t = {msg} s",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar.set_message(format!("{t:.1}"));
                bar.set_position(step);
                self.bar = Some(bar);
            }
            None => {}
        }
        if let Some(bar) = &self.bar {
            bar.set_message(format!("{t:.1}"));
        }
    }
}

impl Observer for Progress {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.at(frame.step, frame.t);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.clear();
        Ok(())
    }
}
