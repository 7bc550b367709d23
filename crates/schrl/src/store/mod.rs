//! Run directories: the one on-disk format of every training command.
//!
//! ```text
//! DIR/
//!   manifest.json   what the directory is: kind, format, the run's settings, and the
//!                   current checkpoint (its generation and each file's SHA-256)
//!   gen-<n>/        checkpoint n: every file one save wrote
//!   metrics.jsonl   one line per update or iteration (see [`MetricsLog`])
//!   *.png, *.svg    pictures the command draws
//!   .lock           locked by the process writing the run
//! ```
//!
//! Guarantees, and how they are kept:
//!
//! * *A save of several files is atomic as a whole.* A save writes a fresh
//!   `.gen-<n>.partial/`, syncs it, renames it to `gen-<n>/`, then replaces
//!   `manifest.json` by rename. The manifest is the commit point: a kill at any moment
//!   leaves the manifest naming either the previous complete checkpoint or the new one.
//!   Older generations are removed only after the new manifest is in place.
//! * *One writer.* [`RunWriter`] holds an exclusive advisory lock on `.lock` for its
//!   lifetime (released by the kernel when the process dies, so a killed run can be
//!   resumed); a second writer is refused at start with [`StoreError::Busy`].
//! * *One kind per directory.* The manifest names the kind of run ([`RunKind`]); every
//!   reader and writer asks for a kind and refuses another, naming both. A directory
//!   with files but no manifest is not a run and is never written into.
//! * *No foreign files.* Every file of a checkpoint is read through its checksum
//!   ([`Checkpoint::file`]); a mismatch names the file and both digests.
//!
//! Readers ([`Checkpoint::open`]) take no lock: they read the manifest once and the
//! files it names. The previous generation is kept until the next save, so a reader
//! racing one save still finds its files.

pub mod controller;
pub mod crm;
pub mod joint;
mod lines;
mod metrics;
pub mod plan_file;
pub mod planner;
pub mod pretrain;
pub mod sdf;
pub mod tltl;

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

pub use lines::JsonLines;
pub use metrics::MetricsLog;

/// The manifest's file name.
pub const MANIFEST: &str = "manifest.json";
/// The lock file's name.
const LOCK: &str = ".lock";
/// The run-directory format this build writes and reads.
pub const FORMAT: u32 = 1;

/// What kind of run a directory holds; each command reads and writes one kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunKind {
    /// `schrl control train`: a goal-conditioned controller.
    Controller,
    /// `schrl plan train`: a planner trained on a spec alone.
    Planner,
    /// `schrl train`: planner and controller trained together on a task.
    Joint,
    /// `schrl baseline train --algo tltl`: a flat policy trained on a task's robustness.
    Tltl,
    /// `schrl baseline train --algo crm` or `--algo dhrm`: a flat policy (DHRM: options
    /// under a meta-controller) trained on a reward machine.
    Crm,
    /// `schrl train`'s planner pre-training between candidates, in its run's
    /// `pretrain/` ([`pretrain::PRETRAIN`]).
    Pretrain,
}

impl RunKind {
    /// The kind's name, as the manifest writes it.
    pub fn name(self) -> &'static str {
        match self {
            RunKind::Controller => "controller",
            RunKind::Planner => "planner",
            RunKind::Joint => "joint",
            RunKind::Tltl => "tltl",
            RunKind::Crm => "crm",
            RunKind::Pretrain => "pretrain",
        }
    }

    /// The command that writes this kind.
    pub fn command(self) -> &'static str {
        match self {
            RunKind::Controller => "schrl control train",
            RunKind::Planner => "schrl plan train",
            RunKind::Joint => "schrl train",
            RunKind::Tltl => "schrl baseline train --algo tltl",
            RunKind::Crm => "schrl baseline train --algo crm|dhrm",
            RunKind::Pretrain => "schrl train",
        }
    }
}

impl std::fmt::Display for RunKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One file of a checkpoint.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileEntry {
    /// SHA-256 of the contents, lowercase hex (as `sha256sum` prints it).
    pub sha256: String,
    /// Size in bytes.
    pub bytes: u64,
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The kind of run.
    pub kind: RunKind,
    /// Run-directory format ([`FORMAT`]).
    pub format: u32,
    /// The run's settings, whole (the command's settings struct).
    pub settings: serde_json::Value,
    /// The current checkpoint's generation (`gen-<n>/`); `None` before the first save.
    pub generation: Option<u64>,
    /// The current checkpoint's files.
    pub files: BTreeMap<String, FileEntry>,
}

/// A run-directory problem; each names the path it concerns.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// Reading or writing failed.
    #[error("{path}: {message}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the system said.
        message: String,
    },
    /// Another process is writing the run.
    #[error("{0} is in use by another process (its .lock is held)")]
    Busy(PathBuf),
    /// The directory holds another kind of run.
    #[error("{dir} holds a {found} run (written by `{}`), not a {wanted} run", found.command())]
    OtherKind {
        /// The run directory.
        dir: PathBuf,
        /// The kind the manifest names.
        found: RunKind,
        /// The kind asked for.
        wanted: RunKind,
    },
    /// The directory already holds a run of this kind, and replacing it was not asked for.
    #[error("{dir} already holds a {kind} run")]
    Exists {
        /// The run directory.
        dir: PathBuf,
        /// Its kind.
        kind: RunKind,
    },
    /// A single file (not a run) exists, and replacing it was not asked for.
    #[error("{0} already exists")]
    FileExists(PathBuf),
    /// The directory is not a run directory.
    #[error("{0} is not a schrl run directory (it has no {MANIFEST})")]
    NotARun(PathBuf),
    /// The directory has files but no manifest: it is not ours to write into.
    #[error(
        "{0} is not empty and is not a schrl run directory (no {MANIFEST}); choose an empty or new directory"
    )]
    Foreign(PathBuf),
    /// The run has not saved a checkpoint yet.
    #[error("{0} has no checkpoint yet (the run stopped before its first save)")]
    NoCheckpoint(PathBuf),
    /// A file's contents do not match the manifest.
    #[error(
        "{path}: checksum {found} does not match the manifest's {expected} (a file from another run or save?)"
    )]
    Checksum {
        /// The file.
        path: PathBuf,
        /// The manifest's digest.
        expected: String,
        /// The file's digest.
        found: String,
    },
    /// A file is malformed, or the checkpoint lacks a file the reader needs.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

fn io(path: &Path, e: impl std::fmt::Display) -> StoreError {
    StoreError::Io { path: path.to_path_buf(), message: e.to_string() }
}

fn invalid(path: &Path, message: impl Into<String>) -> StoreError {
    StoreError::Invalid { path: path.to_path_buf(), message: message.into() }
}

/// SHA-256 and size of the file at `path`.
fn digest(path: &Path) -> Result<FileEntry, StoreError> {
    let mut f = File::open(path).map_err(|e| io(path, e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut bytes = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(|e| io(path, e))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok(FileEntry { sha256: hex(&h.finalize()), bytes })
}

/// Lowercase hex, as `sha256sum` prints a digest.
fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

fn sync_dir(dir: &Path) -> Result<(), StoreError> {
    File::open(dir).and_then(|d| d.sync_all()).map_err(|e| io(dir, e))
}

/// Writes a single file (not a run) atomically ([`write_atomic`]); refuses to replace an
/// existing one unless `force`.
pub(crate) fn save_file(path: &Path, contents: &[u8], force: bool) -> Result<(), StoreError> {
    if path.exists() && !force {
        return Err(StoreError::FileExists(path.to_path_buf()));
    }
    write_atomic(path, contents)
}

/// Refuses a state file (`path`) of another layout than this build's: `found` is the
/// file's `format`, `wanted` the one this build reads, `what` what the file holds.
pub(crate) fn check_format(path: &Path, found: u32, wanted: u32, what: &str) -> Result<(), StoreError> {
    if found == wanted {
        return Ok(());
    }
    Err(invalid(path, format!("format {found} is not {wanted}, {what} this schrl reads")))
}

/// Writes `path` through a temporary sibling, synced, then renamed over it.
pub fn write_atomic(path: &Path, contents: &[u8]) -> Result<(), StoreError> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let result = File::create(&tmp)
        .and_then(|mut f| {
            f.write_all(contents)?;
            f.sync_all()
        })
        .and_then(|()| fs::rename(&tmp, path));
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(io(path, e));
    }
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        sync_dir(parent)?;
    }
    Ok(())
}

fn read_manifest(dir: &Path) -> Result<Option<Manifest>, StoreError> {
    let path = dir.join(MANIFEST);
    let text = match fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path, e)),
    };
    let m: Manifest = serde_json::from_str(&text).map_err(|e| invalid(&path, e.to_string()))?;
    if m.format != FORMAT {
        return Err(invalid(
            &path,
            format!("run-directory format {} is not {FORMAT}, which this schrl reads", m.format),
        ));
    }
    Ok(Some(m))
}

fn gen_dir(dir: &Path, generation: u64) -> PathBuf {
    dir.join(format!("gen-{generation}"))
}

/// A committed checkpoint and the settings of its run, read through the manifest.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    dir: PathBuf,
    manifest: Manifest,
}

impl Checkpoint {
    /// Opens the run in `dir`, which must be of `kind`. The run may have no checkpoint
    /// yet ([`Checkpoint::has_files`]).
    pub fn open(dir: &Path, kind: RunKind) -> Result<Self, StoreError> {
        let manifest = read_manifest(dir)?.ok_or_else(|| StoreError::NotARun(dir.to_path_buf()))?;
        if manifest.kind != kind {
            return Err(StoreError::OtherKind { dir: dir.to_path_buf(), found: manifest.kind, wanted: kind });
        }
        Ok(Self { dir: dir.to_path_buf(), manifest })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The manifest.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Whether a checkpoint has been saved.
    pub fn has_files(&self) -> bool {
        self.manifest.generation.is_some()
    }

    /// The run's settings.
    pub fn settings<T: DeserializeOwned>(&self) -> Result<T, StoreError> {
        serde_json::from_value(self.manifest.settings.clone())
            .map_err(|e| invalid(&self.dir.join(MANIFEST), format!("settings: {e}")))
    }

    /// Where the checkpoint's file `name` lies, unchecked (to name it in messages).
    pub fn path_of(&self, name: &str) -> PathBuf {
        gen_dir(&self.dir, self.manifest.generation.unwrap_or(0)).join(name)
    }

    /// The manifest's entry for `name`.
    fn entry(&self, name: &str) -> Result<&FileEntry, StoreError> {
        if self.manifest.generation.is_none() {
            return Err(StoreError::NoCheckpoint(self.dir.clone()));
        }
        self.manifest
            .files
            .get(name)
            .ok_or_else(|| invalid(&self.dir.join(MANIFEST), format!("the checkpoint has no file '{name}'")))
    }

    fn check(&self, name: &str, expected: &FileEntry, found: String) -> Result<(), StoreError> {
        if found == expected.sha256 {
            return Ok(());
        }
        Err(StoreError::Checksum { path: self.path_of(name), expected: expected.sha256.clone(), found })
    }

    /// The path of the checkpoint's file `name`, after checking its checksum.
    pub fn file(&self, name: &str) -> Result<PathBuf, StoreError> {
        let expected = self.entry(name)?;
        let path = self.path_of(name);
        self.check(name, expected, digest(&path)?.sha256)?;
        Ok(path)
    }

    /// The checkpoint's JSON file `name`, read once, checked and parsed.
    pub fn json<T: DeserializeOwned>(&self, name: &str) -> Result<T, StoreError> {
        let expected = self.entry(name)?;
        let path = self.path_of(name);
        let bytes = fs::read(&path).map_err(|e| io(&path, e))?;
        self.check(name, expected, hex(&Sha256::digest(&bytes)))?;
        serde_json::from_slice(&bytes).map_err(|e| invalid(&path, e.to_string()))
    }
}

/// The files of one save in progress ([`RunWriter::save`]).
pub struct SaveFiles {
    dir: PathBuf,
    files: BTreeMap<String, FileEntry>,
}

impl SaveFiles {
    /// Writes file `name` with `write`, which is given the path to create.
    pub fn write_with<E: std::fmt::Display>(
        &mut self,
        name: &str,
        write: impl FnOnce(&Path) -> Result<(), E>,
    ) -> Result<(), StoreError> {
        let path = self.dir.join(name);
        write(&path).map_err(|e| io(&path, e))?;
        File::open(&path).and_then(|f| f.sync_all()).map_err(|e| io(&path, e))?;
        self.files.insert(name.to_string(), digest(&path)?);
        Ok(())
    }

    /// Writes `value` as the JSON file `name`.
    pub fn json<T: Serialize>(&mut self, name: &str, value: &T) -> Result<(), StoreError> {
        let text = serde_json::to_vec(value).map_err(|e| io(&self.dir.join(name), e))?;
        self.write_with(name, |p| fs::write(p, &text))
    }
}

/// The one process writing a run directory: holds its lock, saves checkpoints.
pub struct RunWriter {
    dir: PathBuf,
    manifest: Manifest,
    _lock: File,
}

/// What [`RunWriter::create`] does with a run of the same kind already in the directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Refuse ([`StoreError::Exists`]).
    Refuse,
    /// Delete its checkpoints and metrics and start anew.
    Replace,
}

fn lock(dir: &Path) -> Result<File, StoreError> {
    let path = dir.join(LOCK);
    let f = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| io(&path, e))?;
    match f.try_lock() {
        Ok(()) => Ok(f),
        Err(fs::TryLockError::WouldBlock) => Err(StoreError::Busy(dir.to_path_buf())),
        Err(fs::TryLockError::Error(e)) => Err(io(&path, e)),
    }
}

impl RunWriter {
    /// Starts a new run of `kind` with `settings` in `dir` (created if needed). Refuses
    /// a directory in use, one holding another kind of run or foreign files, and — with
    /// [`Existing::Refuse`] — one holding a run of this kind.
    pub fn create<S: Serialize>(
        dir: &Path,
        kind: RunKind,
        settings: &S,
        existing: Existing,
    ) -> Result<Self, StoreError> {
        fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
        let foreign = |dir: &Path| -> Result<(), StoreError> {
            let has_files = fs::read_dir(dir)
                .map_err(|e| io(dir, e))?
                .filter_map(|e| e.ok())
                .any(|e| e.file_name() != LOCK);
            if has_files { Err(StoreError::Foreign(dir.to_path_buf())) } else { Ok(()) }
        };
        // Checked before locking, so no lock file is left in a foreign directory, and
        // again under the lock, where nothing can change it.
        if read_manifest(dir)?.is_none() {
            foreign(dir)?;
        }
        let lock = lock(dir)?;
        let old = read_manifest(dir)?;
        if old.is_none() {
            foreign(dir)?;
        }
        if let Some(old) = &old {
            if old.kind != kind {
                return Err(StoreError::OtherKind { dir: dir.to_path_buf(), found: old.kind, wanted: kind });
            }
            if existing == Existing::Refuse {
                return Err(StoreError::Exists { dir: dir.to_path_buf(), kind });
            }
        }
        let settings = serde_json::to_value(settings).map_err(|e| io(&dir.join(MANIFEST), e))?;
        let w = Self {
            dir: dir.to_path_buf(),
            manifest: Manifest { kind, format: FORMAT, settings, generation: None, files: BTreeMap::new() },
            _lock: lock,
        };
        // The new manifest claims the directory before anything of the old run goes.
        w.write_manifest()?;
        let metrics = dir.join(metrics::METRICS);
        if metrics.exists() {
            fs::remove_file(&metrics).map_err(|e| io(&metrics, e))?;
        }
        w.remove_stale_generations()?;
        Ok(w)
    }

    /// Takes over the run of `kind` in `dir` to continue it; returns the writer and
    /// the run's last checkpoint (which may have no files yet).
    pub fn resume(dir: &Path, kind: RunKind) -> Result<(Self, Checkpoint), StoreError> {
        // Checked before locking, so a missing directory is not created.
        Checkpoint::open(dir, kind)?;
        let lock = lock(dir)?;
        // Read again under the lock: the previous writer may have saved meanwhile.
        let ckpt = Checkpoint::open(dir, kind)?;
        let w = Self { dir: dir.to_path_buf(), manifest: ckpt.manifest.clone(), _lock: lock };
        w.remove_stale_generations()?;
        Ok((w, ckpt))
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The run's settings, as saved.
    pub fn settings<T: DeserializeOwned>(&self) -> Result<T, StoreError> {
        serde_json::from_value(self.manifest.settings.clone())
            .map_err(|e| invalid(&self.dir.join(MANIFEST), format!("settings: {e}")))
    }

    /// Replaces the run's settings (e.g. a longer step budget on resume); takes effect
    /// with the next save.
    pub fn set_settings<S: Serialize>(&mut self, settings: &S) -> Result<(), StoreError> {
        self.manifest.settings =
            serde_json::to_value(settings).map_err(|e| io(&self.dir.join(MANIFEST), e))?;
        Ok(())
    }

    /// Saves a checkpoint: `write` writes its files, then the save commits as a whole.
    pub fn save(
        &mut self,
        write: impl FnOnce(&mut SaveFiles) -> Result<(), StoreError>,
    ) -> Result<(), StoreError> {
        let next = self.manifest.generation.map_or(0, |g| g + 1);
        let partial = self.dir.join(format!(".gen-{next}.partial"));
        if partial.exists() {
            fs::remove_dir_all(&partial).map_err(|e| io(&partial, e))?;
        }
        fs::create_dir(&partial).map_err(|e| io(&partial, e))?;
        let mut files = SaveFiles { dir: partial.clone(), files: BTreeMap::new() };
        write(&mut files)?;
        sync_dir(&partial)?;
        let target = gen_dir(&self.dir, next);
        if target.exists() {
            fs::remove_dir_all(&target).map_err(|e| io(&target, e))?;
        }
        fs::rename(&partial, &target).map_err(|e| io(&target, e))?;
        sync_dir(&self.dir)?;
        self.manifest.generation = Some(next);
        self.manifest.files = files.files;
        self.write_manifest()?;
        self.remove_stale_generations()
    }

    /// The current checkpoint, as a reader sees it.
    pub fn checkpoint(&self) -> Checkpoint {
        Checkpoint { dir: self.dir.clone(), manifest: self.manifest.clone() }
    }

    fn write_manifest(&self) -> Result<(), StoreError> {
        let path = self.dir.join(MANIFEST);
        let text = serde_json::to_vec_pretty(&self.manifest).map_err(|e| io(&path, e))?;
        write_atomic(&path, &text)
    }

    /// Removes partial saves and generations other than the current and the one
    /// before it (kept for readers racing a save).
    fn remove_stale_generations(&self) -> Result<(), StoreError> {
        let keep = |g: u64| self.manifest.generation.is_some_and(|c| g == c || g + 1 == c);
        for entry in fs::read_dir(&self.dir).map_err(|e| io(&self.dir, e))?.filter_map(|e| e.ok()) {
            let name = entry.file_name().to_string_lossy().into_owned();
            let stale = if name.starts_with(".gen-") && name.ends_with(".partial") {
                true
            } else if let Some(g) = name.strip_prefix("gen-").and_then(|g| g.parse::<u64>().ok()) {
                !keep(g)
            } else {
                false
            };
            if stale {
                fs::remove_dir_all(entry.path()).map_err(|e| io(&entry.path(), e))?;
            }
        }
        Ok(())
    }
}
