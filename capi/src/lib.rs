//! The C API of the umbrasweep run-time library (`include/umbrasweep.h`): open a `.pvs` file
//! (or its bytes), find the cell holding a point, list or test the objects a cell sees.
//!
//! Built as a `cdylib` and a `staticlib` (`cargo build -p umbrasweep-capi`); it depends on
//! `umbrasweep` with only the `runtime` feature, so no baking dependencies come along.
//!
//! Every function accepts a null handle and out-of-range indices, answering with an error
//! value rather than crashing. A handle may be shared between threads for the `const`
//! queries; `us_pvs_visible` moves the handle's cursor, so one thread at a time uses it.

use std::ffi::{CStr, CString, c_char, c_int};
use umbrasweep::pvs::{CellId, PvsCursor, PvsDatabase};

/// An opened `.pvs` file with a cursor for `us_pvs_visible` and C copies of object names.
pub struct UsPvs {
    db: PvsDatabase,
    cursor: PvsCursor,
    names: Vec<CString>,
}

/// Copies `msg` into the caller's buffer, truncated and NUL-terminated.
///
/// # Safety
/// `err` is null or points to `err_len` writable bytes.
unsafe fn set_error(err: *mut c_char, err_len: usize, msg: &str) {
    if err.is_null() || err_len == 0 {
        return;
    }
    let n = msg.len().min(err_len - 1);
    // SAFETY: the caller guarantees `err_len` writable bytes; `n + 1 <= err_len`.
    unsafe {
        std::ptr::copy_nonoverlapping(msg.as_ptr().cast::<c_char>(), err, n);
        *err.add(n) = 0;
    }
}

fn wrap(db: PvsDatabase) -> *mut UsPvs {
    let names = (0..db.object_count() as u32)
        .map(|i| {
            let name = db.object(i).map(|o| o.name).unwrap_or("");
            CString::new(name.replace('\0', "?")).unwrap_or_default()
        })
        .collect();
    let cursor = db.cursor();
    Box::into_raw(Box::new(UsPvs { db, cursor, names }))
}

/// Opens and checks a `.pvs` file. Returns null on error, with a message in `err`.
///
/// # Safety
/// `path` is null or a NUL-terminated string; `err` is null or points to `err_len` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_open(
    path: *const c_char,
    err: *mut c_char,
    err_len: usize,
) -> *mut UsPvs {
    if path.is_null() {
        // SAFETY: forwarded from the caller.
        unsafe { set_error(err, err_len, "us_pvs_open: path is NULL") };
        return std::ptr::null_mut();
    }
    // SAFETY: the caller passes a NUL-terminated string.
    let path = unsafe { CStr::from_ptr(path) };
    #[cfg(unix)]
    let path = {
        use std::os::unix::ffi::OsStrExt;
        std::path::PathBuf::from(std::ffi::OsStr::from_bytes(path.to_bytes()))
    };
    #[cfg(not(unix))]
    let path = std::path::PathBuf::from(path.to_string_lossy().into_owned());
    match PvsDatabase::open(path) {
        Ok(db) => wrap(db),
        Err(e) => {
            // SAFETY: forwarded from the caller.
            unsafe { set_error(err, err_len, &e.to_string()) };
            std::ptr::null_mut()
        }
    }
}

/// Reads and checks the bytes of a `.pvs` file (copied; the caller keeps its buffer).
/// Returns null on error, with a message in `err`.
///
/// # Safety
/// `data` points to `len` readable bytes (or is null with `len` 0); `err` is null or points
/// to `err_len` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_open_bytes(
    data: *const u8,
    len: usize,
    err: *mut c_char,
    err_len: usize,
) -> *mut UsPvs {
    let bytes: &[u8] = if data.is_null() || len == 0 {
        &[]
    } else {
        // SAFETY: the caller guarantees `len` readable bytes.
        unsafe { std::slice::from_raw_parts(data, len) }
    };
    match PvsDatabase::from_bytes(bytes) {
        Ok(db) => wrap(db),
        Err(e) => {
            // SAFETY: forwarded from the caller.
            unsafe { set_error(err, err_len, &e.to_string()) };
            std::ptr::null_mut()
        }
    }
}

/// Closes a handle (null is ignored).
///
/// # Safety
/// `pvs` is null or a handle from `us_pvs_open*` not closed yet.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_close(pvs: *mut UsPvs) {
    if !pvs.is_null() {
        // SAFETY: the handle came from `Box::into_raw` and is closed once.
        drop(unsafe { Box::from_raw(pvs) });
    }
}

/// # Safety
/// `pvs` is null or a live handle.
unsafe fn get<'a>(pvs: *const UsPvs) -> Option<&'a UsPvs> {
    // SAFETY: the caller passes null or a live handle.
    unsafe { pvs.as_ref() }
}

/// The number of cells (0 for a null handle).
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_cell_count(pvs: *const UsPvs) -> u32 {
    // SAFETY: forwarded from the caller.
    unsafe { get(pvs) }.map_or(0, |p| p.db.cell_count() as u32)
}

/// The number of objects (0 for a null handle).
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_object_count(pvs: *const UsPvs) -> u32 {
    // SAFETY: forwarded from the caller.
    unsafe { get(pvs) }.map_or(0, |p| p.db.object_count() as u32)
}

/// The cell holding the point (the lowest index where cells overlap; with adaptive
/// subdivision, the smallest cell of the hierarchy holding it), or -1.
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_cell_at(pvs: *const UsPvs, x: f32, y: f32, z: f32) -> i64 {
    // SAFETY: forwarded from the caller.
    unsafe { get(pvs) }
        .and_then(|p| p.db.cell_at([x, y, z]))
        .map_or(-1, |c| c.0 as i64)
}

/// The cell this cell is a half of (adaptive subdivision), or -1 for a cell given to the
/// bake, a bad cell or a null handle.
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_cell_parent(pvs: *const UsPvs, cell: u32) -> i64 {
    // SAFETY: forwarded from the caller.
    match unsafe { get(pvs) } {
        Some(p) if (cell as usize) < p.db.cell_count() => {
            p.db.cell_parent(CellId(cell)).map_or(-1, |c| c.0 as i64)
        }
        _ => -1,
    }
}

/// With `bake --split-objects`: the object of the scene file that object (cluster) `object`
/// belongs to; without a split the object itself; -1 for a bad object or a null handle.
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_source_of(pvs: *const UsPvs, object: u32) -> i64 {
    // SAFETY: forwarded from the caller.
    match unsafe { get(pvs) } {
        Some(p) if (object as usize) < p.db.object_count() => match p.db.split() {
            Some(t) => t.source_of(object) as i64,
            None => object as i64,
        },
        _ => -1,
    }
}

/// Writes a cell's bounds to `min[3]` and `max[3]`; 0 on success, -1 for a bad cell.
///
/// # Safety
/// `pvs` is null or a live handle; `min` and `max` are null or point to 3 floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_cell_bounds(
    pvs: *const UsPvs,
    cell: u32,
    min: *mut f32,
    max: *mut f32,
) -> c_int {
    // SAFETY: forwarded from the caller.
    let Some(p) = (unsafe { get(pvs) }) else {
        return -1;
    };
    if cell as usize >= p.db.cell_count() || min.is_null() || max.is_null() {
        return -1;
    }
    let (lo, hi) = p.db.cell_bounds(CellId(cell));
    // SAFETY: the caller guarantees 3 writable floats at each.
    unsafe {
        std::ptr::copy_nonoverlapping(lo.as_ptr(), min, 3);
        std::ptr::copy_nonoverlapping(hi.as_ptr(), max, 3);
    }
    0
}

/// How many objects a cell sees, or -1 for a bad cell.
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_visible_count(pvs: *const UsPvs, cell: u32) -> i64 {
    // SAFETY: forwarded from the caller.
    match unsafe { get(pvs) } {
        Some(p) if (cell as usize) < p.db.cell_count() => p.db.visible_count(CellId(cell)) as i64,
        _ => -1,
    }
}

/// Writes the ids of the objects `cell` sees, ascending, to `out` (at most `cap` of them) and
/// returns how many there are (which may exceed `cap`), or -1 for a bad cell. Decodes
/// incrementally from the previous call's cell; does not allocate.
///
/// # Safety
/// `pvs` is null or a live handle not used by another thread meanwhile; `out` is null (with
/// `cap` 0) or points to `cap` writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_visible(
    pvs: *mut UsPvs,
    cell: u32,
    out: *mut u32,
    cap: usize,
) -> i64 {
    // SAFETY: the caller passes null or a live handle used by this thread only.
    let Some(p) = (unsafe { pvs.as_mut() }) else {
        return -1;
    };
    if cell as usize >= p.db.cell_count() {
        return -1;
    }
    let mut n = 0usize;
    for id in p.cursor.visible(&p.db, CellId(cell)) {
        if n < cap && !out.is_null() {
            // SAFETY: `n < cap` and the caller guarantees `cap` writable slots.
            unsafe { *out.add(n) = id };
        }
        n += 1;
    }
    n as i64
}

/// 1 when `cell` sees `object`, 0 when not (or for an object id out of range), -1 for a bad
/// cell. Does not allocate.
///
/// # Safety
/// `pvs` is null or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_is_visible(pvs: *const UsPvs, cell: u32, object: u32) -> c_int {
    // SAFETY: forwarded from the caller.
    match unsafe { get(pvs) } {
        Some(p) if (cell as usize) < p.db.cell_count() => {
            p.db.is_visible(CellId(cell), object) as c_int
        }
        _ => -1,
    }
}

/// An object's name (NUL-terminated, owned by the handle), or null for a bad id.
///
/// # Safety
/// `pvs` is null or a live handle; the string lives as long as the handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn us_pvs_object_name(pvs: *const UsPvs, object: u32) -> *const c_char {
    // SAFETY: forwarded from the caller.
    unsafe { get(pvs) }
        .and_then(|p| p.names.get(object as usize))
        .map_or(std::ptr::null(), |s| s.as_ptr())
}
