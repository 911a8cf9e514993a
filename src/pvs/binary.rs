//! The binary PVS file (placeholder until it lands).

use super::PvsDocument;
use std::path::Path;

/// Writes `doc` as a binary `.pvs` file, atomically.
///
/// # Errors
/// I/O errors, naming the file.
pub fn write(path: &Path, _doc: &PvsDocument) -> Result<(), String> {
    Err(format!(
        "{}: the binary .pvs format is not built yet (use .json)",
        path.display()
    ))
}
