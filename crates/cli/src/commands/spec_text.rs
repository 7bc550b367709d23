//! Reading spec text given inline or as `@file`, with errors that point into it.

use std::path::PathBuf;

use anyhow::{Context, Result, anyhow};
use stl::{Formula, SpecError};

/// Spec text and where it came from.
pub struct SpecText {
    /// The text.
    pub text: String,
    /// The file it was read from, if any.
    pub origin: Option<PathBuf>,
}

impl SpecText {
    /// `arg` is either formula text or `@path` to a file holding it.
    pub fn load(arg: &str) -> Result<Self> {
        match arg.strip_prefix('@') {
            Some(path) => {
                let path = PathBuf::from(path);
                let text = schrl::task::read_text(&path, schrl::task::MAX_TASK_FILE_BYTES)
                    .with_context(|| format!("cannot read spec file {}", path.display()))?;
                Ok(Self { text, origin: Some(path) })
            }
            None => Ok(Self { text: arg.to_string(), origin: None }),
        }
    }

    fn prefix(&self) -> String {
        match &self.origin {
            Some(p) => format!("{}: ", p.display()),
            None => "spec: ".to_string(),
        }
    }

    /// Parses the text, rendering a syntax error with its line and a caret.
    pub fn parse(&self) -> Result<Formula> {
        stl::parse(&self.text).map_err(|e| anyhow!("{}{}", self.prefix(), e.render(&self.text)))
    }

    /// Explains a binding error, locating the offending name in the text.
    pub fn explain(&self, err: SpecError) -> anyhow::Error {
        let name = match &err {
            SpecError::Unbound { name, .. } | SpecError::Ambiguous(name) => Some(name.as_str()),
            SpecError::NonFiniteThreshold { name, .. } | SpecError::Dimension { name, .. } => {
                Some(name.as_str())
            }
        };
        match name.and_then(|n| stl::locate_name(&self.text, n)) {
            Some((line, column)) => anyhow!("{}line {line}, column {column}: {err}", self.prefix()),
            None => anyhow!("{}{err}", self.prefix()),
        }
    }
}
