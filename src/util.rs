//! Helpers shared by the writers: atomic file output (temporary file, then rename), so a
//! failed command never leaves a partial file behind.

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
///
/// # Errors
/// Any I/O error, with the path in the message; `path` is untouched on error.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Like [`write_atomic`], with a closure that writes the content.
///
/// # Errors
/// Any I/O error of the closure or of the rename, with the path in the message.
pub fn write_atomic_with(
    path: &Path,
    f: impl FnOnce(&mut std::io::BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
) -> Result<(), String> {
    // Special files (a pipe, /dev/stdout, /dev/null) are written in place: renaming over
    // them would replace the device with a regular file.
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
        && !meta.is_dir()
    {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| format!("{}: cannot write: {e}", path.display()))?;
        let mut w = std::io::BufWriter::new(&mut file);
        f(&mut w).map_err(|e| format!("{}: write failed: {e}", path.display()))?;
        w.flush()
            .map_err(|e| format!("{}: write failed: {e}", path.display()))?;
        return Ok(());
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| {
        format!(
            "{}: cannot create a temporary file in {}: {e}",
            path.display(),
            dir.display()
        )
    })?;
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
        f(&mut w).map_err(|e| format!("{}: write failed: {e}", path.display()))?;
        w.flush()
            .map_err(|e| format!("{}: write failed: {e}", path.display()))?;
    }
    tmp.persist(path)
        .map_err(|e| format!("{}: cannot write: {}", path.display(), e.error))?;
    Ok(())
}
