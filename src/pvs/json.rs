//! Reading and writing the JSON PVS document, with errors naming the file.

use super::error::{PvsJsonError, PvsJsonErrorKind, PvsWriteError, PvsWriteErrorKind};
use super::{FORMAT, PvsDocument, VERSION};
use std::path::Path;

/// Reads a PVS JSON document and checks its format tag, version and ids.
///
/// # Errors
/// A [`PvsJsonError`] naming the file: unreadable, not JSON, another format or version, or
/// cells naming objects that do not exist.
pub fn read(path: &Path) -> Result<PvsDocument, PvsJsonError> {
    let fail = |kind| PvsJsonError {
        path: path.to_path_buf(),
        kind,
    };
    let text = std::fs::read_to_string(path).map_err(|e| fail(PvsJsonErrorKind::Io(e)))?;
    let doc: PvsDocument =
        serde_json::from_str(&text).map_err(|e| fail(PvsJsonErrorKind::Parse(e)))?;
    if doc.format != FORMAT {
        return Err(fail(PvsJsonErrorKind::Format { found: doc.format }));
    }
    if doc.version != VERSION {
        return Err(fail(PvsJsonErrorKind::Version { found: doc.version }));
    }
    let n = doc.objects.len() as u32;
    for (i, c) in doc.cells.iter().enumerate() {
        if let Some(&bad) = c.visible.iter().find(|&&id| id >= n) {
            return Err(fail(PvsJsonErrorKind::MissingObject {
                cell: i,
                object: bad,
                objects: n,
            }));
        }
    }
    Ok(doc)
}

/// Reads a PVS in either form: a binary `.pvs` file (told by its magic number, whatever its
/// name) as [`binary::read`](super::binary::read) turns it into the document, else a JSON
/// document as [`read`] does. Errors are messages naming the file.
///
/// # Errors
/// The file cannot be read, or is neither a valid `.pvs` file nor a valid JSON document.
pub fn read_any(path: &Path) -> Result<PvsDocument, String> {
    let mut head = [0u8; 8];
    let is_binary = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
        .is_ok()
        && head == super::format::MAGIC;
    if is_binary {
        super::binary::read(path).map_err(|e| e.to_string())
    } else {
        read(path).map_err(|e| e.to_string())
    }
}

/// Writes the document atomically (temporary file, then rename).
///
/// # Errors
/// A [`PvsWriteError`] naming the file: [`PvsWriteErrorKind::Io`] when it cannot be written
/// (`path` is then untouched).
pub fn write(path: &Path, doc: &PvsDocument) -> Result<(), PvsWriteError> {
    let text = serde_json::to_vec_pretty(doc).map_err(|e| PvsWriteError {
        path: path.to_path_buf(),
        kind: PvsWriteErrorKind::Serialize(e),
    })?;
    crate::util::write_atomic(path, &text).map_err(|m| PvsWriteError::io(path, m.to_string()))
}
