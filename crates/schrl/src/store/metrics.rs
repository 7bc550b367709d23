//! `metrics.jsonl`: one JSON line per update or iteration of a run.
//!
//! Lines are appended as training goes, so the log can run ahead of the last
//! checkpoint. On resume the lines the checkpoint covers are kept and the rest
//! dropped (they will be written again, identically, as the run repeats that work);
//! the kept lines are written to a new file that replaces the log by rename, so a kill
//! during the rewrite loses nothing. A kill can cut the last line short: a last line
//! that does not parse is dropped; a bad line before it is an error naming its number.

use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::{RunWriter, StoreError, invalid, io, write_atomic};

/// The log's file name.
pub(super) const METRICS: &str = "metrics.jsonl";

/// The metrics log of a run being written.
pub struct MetricsLog {
    path: PathBuf,
    file: File,
}

impl MetricsLog {
    /// Opens the log of `run`. Without `resume` it starts empty; with `resume` it keeps
    /// the lines for which `covered` holds and returns them as the history.
    pub fn open<T: Serialize + DeserializeOwned>(
        run: &RunWriter,
        resume: bool,
        covered: impl Fn(&T) -> bool,
    ) -> Result<(Self, Vec<T>), StoreError> {
        let path = run.dir().join(METRICS);
        let history: Vec<T> =
            if resume { read(&path)?.into_iter().filter(|m| covered(m)).collect() } else { vec![] };
        let mut text = Vec::new();
        for m in &history {
            serde_json::to_writer(&mut text, m).map_err(|e| io(&path, e))?;
            text.push(b'\n');
        }
        write_atomic(&path, &text)?;
        let file = OpenOptions::new().append(true).open(&path).map_err(|e| io(&path, e))?;
        Ok((Self { path, file }, history))
    }

    /// Appends one line.
    pub fn append<T: Serialize>(&mut self, metrics: &T) -> Result<(), StoreError> {
        let mut line = serde_json::to_vec(metrics).map_err(|e| io(&self.path, e))?;
        line.push(b'\n');
        // One write per line: a line is never interleaved with another.
        self.file.write_all(&line).map_err(|e| io(&self.path, e))
    }
}

/// The lines of the log at `path` (none if it does not exist).
fn read<T: DeserializeOwned>(path: &Path) -> Result<Vec<T>, StoreError> {
    let text = match fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(vec![]),
        Err(e) => return Err(io(path, e)),
    };
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let mut out = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        match serde_json::from_str(line) {
            Ok(m) => out.push(m),
            Err(_) if i + 1 == lines.len() => break,
            Err(e) => return Err(invalid(path, format!("line {}: {e}", i + 1))),
        }
    }
    Ok(out)
}
