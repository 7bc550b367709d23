//! Progress bars of the training commands that also reach log files.
//!
//! indicatif hides a bar when stderr is no terminal, so a run started with its output
//! sent to a file (`nohup`, a batch job) would log nothing until it ends, hours later
//! for a Doggo. Where the bar is hidden, a [`LoggedBar`] writes a plain line each time
//! its position passes another tenth of its length.

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar, or its lines in a log.
pub struct LoggedBar {
    bar: ProgressBar,
    label: String,
    /// Tenths of the length already written as lines.
    logged_tenths: u64,
}

impl LoggedBar {
    /// A bar of `len` steps counted in `unit` (updates, steps), labelled `label`.
    pub fn new(len: u64, label: &str, unit: &str) -> Self {
        let bar = ProgressBar::new(len);
        let template = format!("{label:>10} {{bar:40}} {{pos}}/{{len}} {unit} {{elapsed_precise}} {{msg}}");
        bar.set_style(ProgressStyle::with_template(&template).expect("a valid template"));
        Self { bar, label: label.to_string(), logged_tenths: 0 }
    }

    /// Sets the length (a resumed run's budget may have changed).
    pub fn set_length(&self, len: u64) {
        self.bar.set_length(len);
    }

    /// Moves to `pos` with `message`; in a log, a line when `pos` passes another tenth.
    /// A position behind the last (the next planner candidate) starts the count again.
    pub fn set(&mut self, pos: u64, message: String) {
        let len = self.bar.length().unwrap_or(0).max(1);
        let tenths = (pos.min(len) * 10) / len;
        if pos < self.bar.position() {
            self.logged_tenths = tenths.saturating_sub(1);
        }
        self.bar.set_position(pos);
        if self.bar.is_hidden() && tenths > self.logged_tenths {
            self.logged_tenths = tenths;
            eprintln!("{} {pos}/{len} ({:.0} s): {message}", self.label, self.bar.elapsed().as_secs_f64());
        }
        self.bar.set_message(message);
    }

    /// Starts at `pos` (a resumed run) without writing a line for it.
    pub fn start_at(&mut self, pos: u64) {
        self.bar.set_position(pos);
        let len = self.bar.length().unwrap_or(0).max(1);
        self.logged_tenths = (pos.min(len) * 10) / len;
    }

    /// Runs `f` with the bar out of the way (for a line of one's own).
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
    }

    /// Removes the bar.
    pub fn clear(&self) {
        self.bar.finish_and_clear();
    }
}
