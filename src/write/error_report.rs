//! `<stem>.error.json`: why a take failed (conventions.md, "Takes and names"), written atomically
//! where the take's outputs would have gone, and removed by the next successful conversion.
//!
//! ```json
//! {"source": "sub/walk.log", "reason": "…: line 12: …", "file": "in/sub/walk.log", "line": 12,
//!  "hint": "…"}
//! ```

use crate::diagnostic::Diagnostic;
use crate::write::write_atomic;
use serde::{Deserialize, Serialize};
use std::io;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorReport {
    /// The take's source (as the batch names it: relative to its input root).
    pub source: String,
    /// What went wrong (the error's message, without its hint).
    pub reason: String,
    /// The file the error is about, when it names one.
    pub file: Option<String>,
    /// The line of `file`, when the error has one.
    pub line: Option<u64>,
    /// What to do about it.
    pub hint: Option<String>,
}

impl ErrorReport {
    /// A report of an error: its message (a `Hint: …` in it split off), and the file, line and
    /// hint it tells ([`Diagnostic`]).
    pub fn from_error(source: &str, error: &dyn Diagnostic) -> ErrorReport {
        let mut report = ErrorReport::from_message(source, &error.to_string());
        report.file = error.file().map(|f| f.to_string_lossy().into_owned());
        report.line = error.line();
        if report.hint.is_none() {
            report.hint = error.hint().map(str::to_string);
        }
        report
    }

    /// A report from a message; a `Hint: …` in it becomes the hint.
    pub fn from_message(source: &str, message: &str) -> ErrorReport {
        let (reason, hint) = match message.find("Hint:").or_else(|| message.find("hint:")) {
            Some(i) => (
                message[..i]
                    .trim_end()
                    .trim_end_matches(['.', ',', ';'])
                    .to_string(),
                Some(message[i + 5..].trim().to_string()),
            ),
            None => (message.trim().to_string(), None),
        };
        ErrorReport {
            source: source.to_string(),
            reason,
            file: None,
            line: None,
            hint,
        }
    }
}

/// `<out_dir>/<stem>.error.json`.
pub fn error_report_path(out_dir: &Path, stem: &str) -> PathBuf {
    out_dir.join(format!("{stem}.error.json"))
}

/// Writes the report atomically; returns its path.
pub fn write_error_report(out_dir: &Path, stem: &str, report: &ErrorReport) -> io::Result<PathBuf> {
    let path = error_report_path(out_dir, stem);
    let json = serde_json::to_vec_pretty(report).map_err(io::Error::other)?;
    write_atomic(&path, |w| {
        w.write_all(&json)?;
        w.write_all(b"\n")
    })?;
    Ok(path)
}

/// Removes `<stem>.error.json` if it exists.
pub fn remove_error_report(out_dir: &Path, stem: &str) -> io::Result<()> {
    match std::fs::remove_file(error_report_path(out_dir, stem)) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read::ReadError;

    #[test]
    fn line_errors_keep_file_and_line_and_hints_split_off() {
        let e = ReadError::Line {
            path: "in/a.log".into(),
            line: 7,
            message: "expected 8 fields. Hint: check the separator".into(),
        };
        let r = ErrorReport::from_error("a.log", &e);
        assert_eq!(r.file.as_deref(), Some("in/a.log"));
        assert_eq!(r.line, Some(7));
        assert_eq!(r.reason, "in/a.log: line 7: expected 8 fields");
        assert_eq!(r.hint.as_deref(), Some("check the separator"));

        let dir = tempfile::tempdir().unwrap();
        let path = write_error_report(dir.path(), "a", &r).unwrap();
        let back: ErrorReport = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(back, r);
        remove_error_report(dir.path(), "a").unwrap();
        assert!(!path.exists());
        remove_error_report(dir.path(), "a").unwrap();
    }

    #[test]
    fn binary_files_name_the_file_without_a_line() {
        let e = ReadError::Binary {
            path: "x.log".into(),
            offset: 0,
        };
        let r = ErrorReport::from_error("x.log", &e);
        assert!(r.reason.contains("binary"), "{}", r.reason);
        assert_eq!(r.line, None);
        assert!(r.hint.is_some());
        let json = serde_json::to_value(&r).unwrap();
        assert!(json["line"].is_null());
    }
}
