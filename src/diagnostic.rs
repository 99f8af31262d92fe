//! What an error tells besides its message: the file and line it is about, and what to do. Error
//! types of every layer implement [`Diagnostic`], so that reports (`<stem>.error.json`) are built
//! from the errors themselves rather than from a table kept elsewhere.

use std::path::Path;

pub trait Diagnostic: std::fmt::Display {
    /// The file the error is about, when it names one.
    fn file(&self) -> Option<&Path> {
        None
    }

    /// The 1-based line of [`Diagnostic::file`], when the error has one.
    fn line(&self) -> Option<u64> {
        None
    }

    /// What to do about it, when the message does not say (`Hint: …` in a message wins).
    fn hint(&self) -> Option<&'static str> {
        None
    }
}
