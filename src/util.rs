//! Helpers shared by the writers: atomic file output (temporary file, then rename), so a
//! failed command never leaves a partial file behind.

use std::io::Write;
use std::path::{Path, PathBuf};

/// A file could not be written. Its message names the file, what failed and the I/O error
/// (`PATH: cannot write: …`).
///
/// When this occurs: the folder is missing or not writable, the disk is full, or the path
/// names a folder. How to handle: fix the path or the permissions; the file is left as it was.
#[derive(Debug, thiserror::Error)]
#[error("{}: {what}: {error}", path.display())]
pub struct WriteError {
    /// The file being written.
    pub path: PathBuf,
    /// What failed (`cannot write`, `write failed`, `cannot create a temporary file in DIR`).
    pub what: String,
    /// The I/O error.
    pub error: std::io::Error,
}

fn write_error(path: &Path, what: impl Into<String>) -> impl FnOnce(std::io::Error) -> WriteError {
    let (path, what) = (path.to_path_buf(), what.into());
    move |error| WriteError { path, what, error }
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
///
/// # Errors
/// Any I/O error, with the path in the message; `path` is untouched on error.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], with a closure that writes the content.
///
/// # Errors
/// Any I/O error of the closure or of the rename, with the path in the message.
pub fn write_atomic_with(
    path: &Path,
    f: impl FnOnce(&mut std::io::BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    // Special files (a pipe, /dev/stdout, /dev/null) are written in place: renaming over
    // them would replace the device with a regular file.
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
        && !meta.is_dir()
    {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(write_error(path, "cannot write"))?;
        let mut w = std::io::BufWriter::new(&mut file);
        f(&mut w).map_err(write_error(path, "write failed"))?;
        w.flush().map_err(write_error(path, "write failed"))?;
        return Ok(());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(write_error(
        path,
        format!("cannot create a temporary file in {}", dir.display()),
    ))?;
    // Temporary files are created 0600; the result should have the usual permissions.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = tmp
            .as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644));
    }
    {
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        f(&mut w).map_err(write_error(path, "write failed"))?;
        w.flush().map_err(write_error(path, "write failed"))?;
    }
    tmp.persist(path)
        .map_err(|e| write_error(path, "cannot write")(e.error))?;
    Ok(())
}
