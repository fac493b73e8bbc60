//! A mistake in a pipeline file, located by its line and column (or by the command line's
//! setting it is in), and how a key path is found in the file's text.
use std::path::PathBuf;

/// A pipeline mistake, located in its file.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    pub file: PathBuf,
    pub line: usize,
    pub column: usize,
    pub message: String,
    /// Further mistakes in the same file, each shown on its own line.
    pub also: Vec<ConfigError>,
    /// The command line's setting the mistake is in (`-S reward.ceiling=2`), in place of a
    /// line of the file.
    pub setting: Option<String>,
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Each problem on one line: a quoted value's line breaks are escaped.
        let message = crate::error::one_line(self.message.clone());
        match &self.setting {
            Some(s) => write!(f, "{}: {s}: {message}", self.file.display())?,
            None => write!(f, "{}:{}:{}: {message}", self.file.display(), self.line, self.column)?,
        }
        for e in &self.also {
            write!(f, "\n{e}")?;
        }
        Ok(())
    }
}

/// Where a key path is in the YAML text: the line and column of its last key, found by
/// tracking the chain of enclosing keys by indentation; (1, 1) when not found.
pub fn locate(text: &str, path: &[&str]) -> (usize, usize) {
    let mut stack: Vec<(usize, String)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('#') || trimmed.starts_with('-') {
            continue;
        }
        let Some((key, _)) = trimmed.split_once(':') else { continue };
        let indent = line.len() - trimmed.len();
        while stack.last().is_some_and(|(d, _)| *d >= indent) {
            stack.pop();
        }
        stack.push((indent, key.trim().to_string()));
        if stack.len() == path.len() && stack.iter().zip(path).all(|((_, k), p)| k == p) {
            return (i + 1, indent + 1);
        }
    }
    (1, 1)
}

/// The text of the pipeline file at `path`, or the error that names it.
pub fn read(path: &std::path::Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|e| ConfigError {
        file: path.into(),
        line: 0,
        column: 0,
        message: format!("cannot read the pipeline file: {e}"),
        also: vec![],
        setting: None,
    })
}
