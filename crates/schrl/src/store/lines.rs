//! Files of JSON lines (one object per line) written whole or not at all: records go
//! to a hidden temporary sibling, which [`JsonLines::finish`] renames over the
//! target. An existing file is refused unless replacing it was asked for, and the
//! checks happen when the file is created, before any work is done for it.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::{StoreError, io};

/// A JSON-lines file being written.
pub struct JsonLines {
    path: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
}

impl JsonLines {
    /// Starts `path`; refuses an existing file unless `overwrite`, and a directory
    /// that does not exist.
    pub fn create(path: &Path, overwrite: bool) -> Result<Self, StoreError> {
        if path.exists() && !overwrite {
            return Err(StoreError::FileExists(path.to_path_buf()));
        }
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
        let file = File::create(&tmp).map_err(|e| io(path, e))?;
        Ok(Self { path: path.to_path_buf(), tmp, out: Some(BufWriter::new(file)) })
    }

    /// Appends one record as a line.
    pub fn append<T: serde::Serialize>(&mut self, record: &T) -> Result<(), StoreError> {
        let out = self.out.as_mut().expect("open until finished");
        serde_json::to_writer(&mut *out, record)
            .map_err(|e| io(&self.path, std::io::Error::other(e)))
            .and_then(|()| out.write_all(b"\n").map_err(|e| io(&self.path, e)))
    }

    /// Flushes, syncs and renames the file into place.
    pub fn finish(mut self) -> Result<(), StoreError> {
        let out = self.out.take().expect("open until finished");
        let file = out.into_inner().map_err(|e| io(&self.path, e.into_error()))?;
        file.sync_all().map_err(|e| io(&self.path, e))?;
        fs::rename(&self.tmp, &self.path).map_err(|e| io(&self.path, e))
    }
}

impl Drop for JsonLines {
    fn drop(&mut self) {
        if self.out.is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}
