//! Reading and writing the JSON PVS document, with errors naming the file.

use super::{FORMAT, PvsDocument, VERSION};
use std::path::Path;

/// Reads a PVS JSON document and checks its format tag, version and ids.
///
/// # Errors
/// A message naming the file: unreadable, not JSON, another format or version, or cells
/// naming objects that do not exist.
pub fn read(path: &Path) -> Result<PvsDocument, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let doc: PvsDocument = serde_json::from_str(&text)
        .map_err(|e| format!("{}: not a PVS document: {e}", path.display()))?;
    if doc.format != FORMAT {
        return Err(format!(
            "{}: format is {:?}, expected {FORMAT:?}",
            path.display(),
            doc.format
        ));
    }
    if doc.version != VERSION {
        return Err(format!(
            "{}: PVS version {} is not supported (this build reads version {VERSION})",
            path.display(),
            doc.version
        ));
    }
    let n = doc.objects.len() as u32;
    for (i, c) in doc.cells.iter().enumerate() {
        if let Some(bad) = c.visible.iter().find(|&&id| id >= n) {
            return Err(format!(
                "{}: cell {i} lists object {bad}, but there are only {n} objects",
                path.display()
            ));
        }
    }
    Ok(doc)
}

/// Writes the document atomically (temporary file, then rename).
///
/// # Errors
/// I/O errors, with the path.
pub fn write(path: &Path, doc: &PvsDocument) -> Result<(), String> {
    let text = serde_json::to_vec_pretty(doc).map_err(|e| e.to_string())?;
    crate::util::write_atomic(path, &text)
}
