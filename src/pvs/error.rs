//! The errors of reading and writing PVS files: [`PvsError`] (opening a binary `.pvs` file),
//! [`EncodeError`] (a document the binary format cannot hold), and with the `bake` feature
//! [`PvsWriteError`] (either writer) and [`PvsJsonError`] (reading a JSON document).
//!
//! Each error's `Display` is the whole message, file first, ready to show to a user; the
//! `kind` fields say what went wrong for callers that handle cases differently. No error
//! returns the same text again as its `source()`.

use super::format::SHARD_FORMAT_VERSION;
#[cfg(feature = "bake")]
use super::{FORMAT, VERSION};
#[cfg(feature = "bake")]
use std::path::Path;
use std::path::PathBuf;

/// An error opening a `.pvs` file: the file (when known) and what is wrong.
///
/// # When this occurs
/// [`PvsDatabase::open`](super::PvsDatabase::open),
/// [`PvsDatabase::from_bytes`](super::PvsDatabase::from_bytes) and
/// [`binary::read`](super::binary::read) return it for a file that cannot be read, is not a
/// `.pvs` file, has another format version, or is damaged; [`PvsErrorKind`] says which.
///
/// # How to handle
/// The file cannot be used as it is: show the message (it names the file) and rebake with
/// `umbrasweep bake … -o FILE.pvs`. [`PvsErrorKind::UnsupportedVersion`] means a newer
/// umbrasweep wrote it; [`PvsErrorKind::BadMagic`] with `looks_like_json` means the JSON
/// document was given where the binary file was expected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{}{kind}", file_prefix(.path))]
pub struct PvsError {
    /// The file, for [`PvsDatabase::open`](super::PvsDatabase::open); `None` for
    /// [`PvsDatabase::from_bytes`](super::PvsDatabase::from_bytes).
    pub path: Option<PathBuf>,
    /// What is wrong.
    pub kind: PvsErrorKind,
}

/// `"PATH: "`, or nothing without a path.
fn file_prefix(path: &Option<PathBuf>) -> String {
    path.as_ref()
        .map(|p| format!("{}: ", p.display()))
        .unwrap_or_default()
}

/// What is wrong with a `.pvs` file (the message of a [`PvsError`] without the file).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PvsErrorKind {
    /// The file could not be read.
    #[error("cannot read: {0}")]
    Io(String),
    /// The file does not start with [`MAGIC`](super::format::MAGIC); `looks_like_json` when
    /// it starts with `{`.
    #[error(
        "not a umbrasweep .pvs file (no \"UMBRAPVS\" magic number){}",
        json_hint(.looks_like_json)
    )]
    BadMagic {
        /// True when the file starts with `{` (probably a JSON PVS document).
        looks_like_json: bool,
    },
    /// The file has another format version.
    #[error(
        ".pvs format version {found} is not supported (this build reads versions 1 to \
         {SHARD_FORMAT_VERSION})"
    )]
    UnsupportedVersion {
        /// The version in the header.
        found: u32,
    },
    /// The file is shorter than its header says (`expected` bytes).
    #[error("truncated: the file has {actual} bytes, its header says {expected}")]
    Truncated {
        /// The size the header states, in bytes.
        expected: u64,
        /// The file's actual size, in bytes.
        actual: u64,
    },
    /// The file is longer than its header says.
    #[error(
        "{} unexpected bytes after the end of the PVS ({actual} bytes, header says \
         {expected})",
        .actual - .expected
    )]
    TrailingBytes {
        /// The size the header states, in bytes.
        expected: u64,
        /// The file's actual size, in bytes.
        actual: u64,
    },
    /// The payload's CRC-32 is not the one in the header.
    #[error("checksum mismatch (header {stored:08x}, content {computed:08x}): the file is corrupt")]
    Checksum {
        /// The CRC-32 stored in the header.
        stored: u32,
        /// The CRC-32 of the payload as read.
        computed: u32,
    },
    /// The checksum matches but the content is inconsistent (a writer's bug).
    #[error("corrupt .pvs file: {0}")]
    Corrupt(String),
}

fn json_hint(looks_like_json: &bool) -> &'static str {
    if *looks_like_json {
        "; it looks like JSON, the other PVS format"
    } else {
        ""
    }
}

/// Why [`binary::encode`](super::binary::encode) cannot store a document in the `.pvs`
/// format (the message names the cell or object, not the file).
///
/// # When this occurs
/// The document breaks a rule of the binary format (`docs/pvs-format.md`): objects numbered
/// other than `0, 1, 2…` in order, a cell whose visible ids are not strictly ascending or name
/// a missing object, or a size beyond the format's 32-bit counts and lengths. Documents that
/// `bake` makes never do; hand-made or edited JSON documents may.
///
/// # How to handle
/// Fix the document (renumber the objects, sort and deduplicate each cell's `visible`, drop
/// ids of missing objects) or rebake it. A document too large for the format can still be
/// written as JSON (`pvs::json::write`, with the `bake` feature).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// `objects` objects: the format counts them in a `u32` below `0xFFFFFFFF`.
    #[error("too many objects for the .pvs format")]
    TooManyObjects {
        /// The number of objects in the document.
        objects: usize,
    },
    /// `cells` cells: the format counts them in a `u32` below `0xFFFFFFFF`.
    #[error("too many cells for the .pvs format")]
    TooManyCells {
        /// The number of cells in the document.
        cells: usize,
    },
    /// The object at position `index` has id `id`: the format numbers objects by position.
    #[error("object {index} has id {id}: the .pvs format numbers objects 0, 1, 2… in order")]
    ObjectOutOfOrder {
        /// The object's position in the document.
        index: usize,
        /// Its id.
        id: u32,
    },
    /// Cell `cell` lists object `object`, but the document has only `objects` objects.
    #[error("cell {cell} lists object {object}, but there are only {objects} objects")]
    MissingObject {
        /// The cell's position in the document.
        cell: usize,
        /// The id it lists.
        object: u32,
        /// The number of objects in the document.
        objects: u32,
    },
    /// Cell `cell` lists `id` after `previous` (not strictly ascending: unsorted or repeated).
    #[error("cell {cell}: visible ids are not strictly ascending ({previous} then {id})")]
    NotAscending {
        /// The cell's position in the document.
        cell: usize,
        /// The id listed before `id`.
        previous: u32,
        /// The offending id.
        id: u32,
    },
    /// A string of `len` bytes (scene path, setting, object or culler name): the format
    /// stores lengths in a `u32` below `0xFFFFFFFF`.
    #[error("a string is longer than 4 GiB")]
    StringTooLong {
        /// The string's length in bytes.
        len: usize,
    },
    /// The record of cell `cell` needs more than `u32::MAX` bytes.
    #[error("a record exceeds 4 GiB")]
    RecordTooLarge {
        /// The cell's position in the document.
        cell: usize,
    },
    /// The records together need more than `u32::MAX` bytes.
    #[error("the PVS data exceeds 4 GiB")]
    DataTooLarge,
    /// The `split` table does not map the objects: source object `index`'s clusters are not where
    /// they should be (each source's must follow the previous one's and all cover the
    /// objects).
    #[error("split objects: source object {index}: {why}")]
    BadSplit {
        /// The source object's position in `split.sources`.
        index: usize,
        /// What is wrong.
        why: String,
    },
    /// Cell `cell` names as its `parent` a cell that does not come before it.
    #[error("cell {cell} is a half of cell {parent}, which does not come before it")]
    BadParent {
        /// The cell's position in the document.
        cell: usize,
        /// The parent it names.
        parent: u32,
    },
}

/// An error writing a PVS file with [`binary::write`](super::binary::write) or
/// [`json::write`](super::json::write): the file and what went wrong.
///
/// # When this occurs
/// The document cannot be stored in the format ([`PvsWriteErrorKind::Encode`]), or the file
/// cannot be written: a missing or read-only directory, a full disk
/// ([`PvsWriteErrorKind::Io`]). Writes are atomic (temporary file, then rename), so on any
/// error `path` keeps what it held before.
///
/// # How to handle
/// Show the message (it names the file). For `Encode`, see [`EncodeError`]; for `Io`, write
/// somewhere else or free space and try again.
#[cfg(feature = "bake")]
#[derive(Debug, thiserror::Error)]
#[error("{path}: {kind}")]
pub struct PvsWriteError {
    /// The file being written.
    pub path: PathBuf,
    /// What went wrong.
    pub kind: PvsWriteErrorKind,
}

#[cfg(feature = "bake")]
impl PvsWriteError {
    /// An error of [`crate::util::write_atomic`], whose messages start with `"PATH: "`: the
    /// rest becomes the [`PvsWriteErrorKind::Io`] text, so the message is unchanged.
    pub(crate) fn io(path: &Path, message: String) -> Self {
        let prefix = format!("{}: ", path.display());
        let message = match message.strip_prefix(&prefix) {
            Some(rest) => rest.to_string(),
            None => message,
        };
        PvsWriteError {
            path: path.to_path_buf(),
            kind: PvsWriteErrorKind::Io(message),
        }
    }
}

/// What went wrong writing a PVS file (the message of a [`PvsWriteError`] without the file).
#[cfg(feature = "bake")]
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PvsWriteErrorKind {
    /// The binary format cannot hold the document ([`binary::write`](super::binary::write)).
    #[error("{0}")]
    Encode(EncodeError),
    /// The document could not be turned into JSON ([`json::write`](super::json::write));
    /// `bake`'s documents always can.
    #[error("cannot serialise the PVS document: {0}")]
    Serialize(serde_json::Error),
    /// Creating, writing or renaming the file failed: the operation and the system's message
    /// (`"cannot write: …"`, `"write failed: …"`, `"cannot create a temporary file in DIR: …"`).
    #[error("{0}")]
    Io(String),
}

/// An error reading a PVS JSON document with [`json::read`](super::json::read): the file and
/// what is wrong with it.
///
/// # When this occurs
/// The file cannot be read, is not JSON of the document's shape, has another `format` tag or
/// `version`, or has a cell listing an object the document lacks; [`PvsJsonErrorKind`] says
/// which.
///
/// # How to handle
/// Show the message (it names the file). A binary `.pvs` file given by mistake fails as
/// [`PvsJsonErrorKind::Parse`]: open it with [`PvsDatabase::open`](super::PvsDatabase::open)
/// or [`binary::read`](super::binary::read) instead. Otherwise rebake the document with
/// `umbrasweep bake … -o FILE.json`.
#[cfg(feature = "bake")]
#[derive(Debug, thiserror::Error)]
#[error("{path}: {kind}")]
pub struct PvsJsonError {
    /// The file being read.
    pub path: PathBuf,
    /// What is wrong.
    pub kind: PvsJsonErrorKind,
}

/// What is wrong with a PVS JSON document (the message of a [`PvsJsonError`] without the
/// file).
#[cfg(feature = "bake")]
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PvsJsonErrorKind {
    /// The file could not be read (missing, unreadable, not UTF-8).
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    /// The text is not JSON, or not of the document's shape.
    #[error("not a PVS document: {0}")]
    Parse(serde_json::Error),
    /// The `format` tag is `found`, not [`FORMAT`](super::FORMAT).
    #[error("format is {found:?}, expected {FORMAT:?}")]
    Format {
        /// The document's `format` value.
        found: String,
    },
    /// The document's `version` is `found`, not [`VERSION`](super::VERSION).
    #[error("PVS version {found} is not supported (this build reads version {VERSION})")]
    Version {
        /// The document's `version` value.
        found: u32,
    },
    /// Cell `cell` lists object `object`, but the document has only `objects` objects.
    #[error("cell {cell} lists object {object}, but there are only {objects} objects")]
    MissingObject {
        /// The cell's position in the document.
        cell: usize,
        /// The id it lists.
        object: u32,
        /// The number of objects in the document.
        objects: u32,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages users and tests match on, word for word.
    #[test]
    fn pvs_error_messages() {
        let at = |kind| {
            PvsError {
                path: Some(PathBuf::from("city.pvs")),
                kind,
            }
            .to_string()
        };
        assert_eq!(
            at(PvsErrorKind::Io("gone".into())),
            "city.pvs: cannot read: gone"
        );
        assert_eq!(
            at(PvsErrorKind::BadMagic {
                looks_like_json: false
            }),
            "city.pvs: not a umbrasweep .pvs file (no \"UMBRAPVS\" magic number)"
        );
        assert_eq!(
            at(PvsErrorKind::BadMagic {
                looks_like_json: true
            }),
            "city.pvs: not a umbrasweep .pvs file (no \"UMBRAPVS\" magic number); it looks like \
             JSON, the other PVS format"
        );
        assert_eq!(
            at(PvsErrorKind::UnsupportedVersion { found: 9 }),
            format!(
                "city.pvs: .pvs format version 9 is not supported (this build reads versions 1 \
                 to {SHARD_FORMAT_VERSION})"
            )
        );
        assert_eq!(
            at(PvsErrorKind::Truncated {
                expected: 24,
                actual: 8
            }),
            "city.pvs: truncated: the file has 8 bytes, its header says 24"
        );
        assert_eq!(
            at(PvsErrorKind::TrailingBytes {
                expected: 30,
                actual: 33
            }),
            "city.pvs: 3 unexpected bytes after the end of the PVS (33 bytes, header says 30)"
        );
        assert_eq!(
            at(PvsErrorKind::Checksum {
                stored: 0xab,
                computed: 0x1234_5678
            }),
            "city.pvs: checksum mismatch (header 000000ab, content 12345678): the file is corrupt"
        );
        let bare = PvsError {
            path: None,
            kind: PvsErrorKind::Corrupt("cell 3 has non-finite bounds".into()),
        };
        assert_eq!(
            bare.to_string(),
            "corrupt .pvs file: cell 3 has non-finite bounds"
        );
    }

    #[cfg(feature = "bake")]
    #[test]
    fn write_io_errors_keep_the_message_and_name_the_file_once() {
        let p = Path::new("out/city.pvs");
        let e = PvsWriteError::io(p, "out/city.pvs: cannot write: denied".into());
        assert!(matches!(&e.kind, PvsWriteErrorKind::Io(m) if m == "cannot write: denied"));
        assert_eq!(e.to_string(), "out/city.pvs: cannot write: denied");
    }
}
