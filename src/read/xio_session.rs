//! Not yet written.

use super::{ReadError, ReadOptions};
use crate::take::Take;
use std::path::Path;

pub fn looks_like(_head: &[u8]) -> bool {
    false
}

pub fn read(path: &Path, _options: &ReadOptions) -> Result<Take, ReadError> {
    Err(ReadError::format(path, "reader not written yet"))
}
pub fn looks_like_folder(_p: &std::path::Path) -> bool {
    false
}
