//! The engine-side run-time library: [`PvsDatabase`] opens a `.pvs` file (see
//! `docs/pvs-format.md`), finds the cell holding a point through a uniform-grid index
//! ([`PvsDatabase::cell_at`]) and answers visibility queries by decoding the delta-PVS
//! records. Builds with `--no-default-features --features runtime`.
//!
//! Every record of a file is checked when it is opened (checksum, structure, and each cell's
//! decoded set against its stored count), so queries never fail. A [`PvsCursor`] keeps one
//! decoded set and moves from cell to cell by XOR-ing only the records on the path between
//! them in the delta tree: walking to a neighbouring cell usually decodes one or two small
//! records, and no query allocates.
//!
//! ```
//! use umbrasweep::pvs::{PvsCell, PvsDocument, PvsObject, binary, database::PvsDatabase};
//!
//! // A document as `bake` makes it: two objects, two cells side by side.
//! let object = |id: u32, name: &str| PvsObject {
//!     id, name: name.into(), triangles: 12, min: [0.0; 3], max: [1.0; 3],
//! };
//! let cell = |x: f32, visible: Vec<u32>| PvsCell {
//!     min: [x, 0.0, 0.0], max: [x + 1.0, 1.0, 1.0], visible, ms: 0.0, cullers: Vec::new(),
//!     parent: None,
//! };
//! let doc = PvsDocument {
//!     format: umbrasweep::pvs::FORMAT.into(), version: umbrasweep::pvs::VERSION,
//!     scene: "demo.obj".into(), settings: Default::default(),
//!     objects: vec![object(0, "house"), object(1, "tree")],
//!     cells: vec![cell(0.0, vec![0, 1]), cell(1.0, vec![1])],
//!     summary: None, split: None,
//! };
//! let bytes = binary::encode(&doc).unwrap(); // what `bake -o OUT.pvs` writes
//! let db = PvsDatabase::from_bytes(&bytes).unwrap();
//!
//! let here = db.cell_at([1.5, 0.5, 0.5]).expect("inside the second cell");
//! assert_eq!(here.index(), 1);
//! assert!(db.is_visible(here, 1) && !db.is_visible(here, 0));
//!
//! // A cursor decodes incrementally and does not allocate per query.
//! let mut cursor = db.cursor();
//! for cell in [0, 1, 0] {
//!     let cell = umbrasweep::pvs::database::CellId(cell);
//!     let ids: Vec<u32> = cursor.visible(&db, cell).collect();
//!     assert_eq!(ids, doc.cells[cell.index()].visible);
//! }
//! ```

pub use super::error::{PvsError, PvsErrorKind};
use super::format::{
    CELL_RECORD_LEN, ENC_BITSET, ENC_LIST, ENC_RUNS, HEADER_LEN, LATEST_FORMAT_VERSION, MAGIC,
    NO_PARENT, NO_STRING, OBJECT_RECORD_LEN, TAG_CULLING, TAG_HIERARCHY, TAG_SHARD, TAG_SPLIT,
    crc32, get_varint,
};
use super::{
    FORMAT, PvsCell, PvsDocument, PvsObject, PvsSettings, PvsSource, PvsSplit, PvsSummary, VERSION,
};
use crate::settings::{Placement, Spacing, SweepChoice};
use glam::Vec3;
use std::fmt;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The index of a cell in a [`PvsDatabase`] (its position in the baked cell list).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct CellId(pub u32);

impl CellId {
    /// The cell's index as a `usize`.
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl fmt::Display for CellId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

fn corrupt(m: impl Into<String>) -> PvsErrorKind {
    PvsErrorKind::Corrupt(m.into())
}

/// One object of the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectInfo<'a> {
    /// The object's name in the scene (may be empty).
    pub name: &'a str,
    /// Triangle count of the object.
    pub triangles: u32,
    /// World bounds (`+inf`/`-inf` for an object without triangles).
    pub min: [f32; 3],
    /// Upper corner of the world bounds (see `min`).
    pub max: [f32; 3],
}

/// How a cell's PVS is stored in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellRecordInfo {
    /// The cell whose set this record is a difference from; `None` for a key cell.
    pub parent: Option<CellId>,
    /// [`ENC_BITSET`], [`ENC_RUNS`] or [`ENC_LIST`].
    pub encoding: u8,
    /// The record's size in bytes.
    pub bytes: usize,
    /// Records decoded to rebuild the set from scratch (1 for a key cell).
    pub depth: u32,
}

/// Sizes and shape of a database, for `umbrasweep inspect` and reports.
#[derive(Clone, Debug, PartialEq)]
pub struct PvsStats {
    /// Number of cells.
    pub cells: usize,
    /// Number of objects.
    pub objects: usize,
    /// Cells stored in full.
    pub key_cells: usize,
    /// Records per encoding: bitset, runs, list.
    pub records_by_encoding: [usize; 3],
    /// The PVS records alone.
    pub pvs_data_bytes: usize,
    /// The cell table (bounds, parent, count, length, encoding), 40 bytes per cell.
    pub cell_table_bytes: usize,
    /// The whole file (header included).
    pub file_bytes: usize,
    /// One plain bitset per cell: `cells × ceil(objects / 8)`.
    pub plain_bitset_bytes: usize,
    /// Mean number of visible objects per cell.
    pub mean_visible: f64,
    /// The largest [`CellRecordInfo::depth`] over cells (records decoded for the worst cell).
    pub max_depth: u32,
    /// The mean [`CellRecordInfo::depth`] over cells.
    pub mean_depth: f64,
}

#[derive(Clone, Debug)]
struct Cell {
    min: [f32; 3],
    max: [f32; 3],
    parent: u32,
    depth: u32,
    count: u32,
    start: usize,
    len: usize,
    enc: u8,
}

impl Cell {
    fn contains(&self, p: Vec3) -> bool {
        let p = p.to_array();
        (0..3).all(|k| self.min[k] <= p[k] && p[k] <= self.max[k])
    }
}

/// A uniform grid over the cells' bounds; each bucket lists the cells overlapping it,
/// ascending.
#[derive(Clone, Debug)]
struct CellGrid {
    lo: [f32; 3],
    hi: [f32; 3],
    scale: [f32; 3],
    dims: [usize; 3],
    start: Vec<u32>,
    list: Vec<u32>,
}

impl CellGrid {
    /// The grid over the cells `indexed` says (all but the halves of subdivided cells).
    fn new(cells: &[Cell], indexed: impl Fn(usize) -> bool) -> Self {
        let live: Vec<usize> = (0..cells.len())
            .filter(|&i| indexed(i) && (0..3).all(|k| cells[i].min[k] <= cells[i].max[k]))
            .collect();
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        let mut mean = [0f64; 3];
        for &i in &live {
            for k in 0..3 {
                lo[k] = lo[k].min(cells[i].min[k]);
                hi[k] = hi[k].max(cells[i].max[k]);
                mean[k] += (cells[i].max[k] - cells[i].min[k]) as f64 / live.len() as f64;
            }
        }
        let mut dims = [1usize; 3];
        let mut scale = [0f32; 3];
        if live.is_empty() {
            (lo, hi) = ([0.0; 3], [-1.0; 3]);
        } else {
            for k in 0..3 {
                let ext = (hi[k] - lo[k]) as f64;
                if ext > 0.0 && mean[k] > 0.0 {
                    dims[k] = ((ext / mean[k]).ceil() as usize).clamp(1, 1024);
                }
            }
            let cap = (16 * live.len()).max(64);
            while dims.iter().product::<usize>() > cap {
                let k = (0..3).max_by_key(|&k| dims[k]).unwrap_or(0);
                dims[k] = dims[k].div_ceil(2);
            }
            for k in 0..3 {
                let ext = hi[k] - lo[k];
                if ext > 0.0 {
                    scale[k] = dims[k] as f32 / ext;
                }
            }
        }
        let mut g = CellGrid {
            lo,
            hi,
            scale,
            dims,
            start: vec![0; dims.iter().product::<usize>() + 1],
            list: Vec::new(),
        };
        // Two passes: count per bucket, then fill (cells in ascending order).
        for pass in 0..2 {
            let mut fill = g.start.clone();
            for &i in &live {
                let a = g.coords(Vec3::from(cells[i].min));
                let b = g.coords(Vec3::from(cells[i].max));
                for z in a[2]..=b[2] {
                    for y in a[1]..=b[1] {
                        for x in a[0]..=b[0] {
                            let bucket = g.bucket([x, y, z]);
                            if pass == 0 {
                                g.start[bucket + 1] += 1;
                            } else {
                                g.list[fill[bucket] as usize] = i as u32;
                                fill[bucket] += 1;
                            }
                        }
                    }
                }
            }
            if pass == 0 {
                for b in 1..g.start.len() {
                    g.start[b] += g.start[b - 1];
                }
                g.list = vec![0; *g.start.last().unwrap_or(&0) as usize];
            }
        }
        g
    }

    fn coords(&self, p: Vec3) -> [usize; 3] {
        let p = p.to_array();
        [0, 1, 2].map(|k| {
            let t = ((p[k] - self.lo[k]) * self.scale[k]).floor();
            // `as` saturates (NaN gives 0).
            (t.max(0.0) as usize).min(self.dims[k] - 1)
        })
    }

    fn bucket(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    fn candidates(&self, p: Vec3) -> &[u32] {
        let q = p.to_array();
        if !(0..3).all(|k| self.lo[k] <= q[k] && q[k] <= self.hi[k]) {
            return &[];
        }
        let b = self.bucket(self.coords(p));
        &self.list[self.start[b] as usize..self.start[b + 1] as usize]
    }
}

/// Flips bits `s..e` of `bits`.
fn xor_range(bits: &mut [u64], s: usize, e: usize) {
    if s >= e {
        return;
    }
    let (ws, we) = (s / 64, (e - 1) / 64);
    let ms = !0u64 << (s % 64);
    let me = !0u64 >> (63 - (e - 1) % 64);
    if ws == we {
        bits[ws] ^= ms & me;
    } else {
        bits[ws] ^= ms;
        for w in &mut bits[ws + 1..we] {
            *w ^= !0;
        }
        bits[we] ^= me;
    }
}

/// XORs the set held by record `rec` (encoding `enc`, `n` objects) into `bits`, checking the
/// record's structure; on an error `bits` is partly changed.
fn xor_record(rec: &[u8], enc: u8, n: u32, bits: &mut [u64]) -> Result<(), &'static str> {
    match enc {
        ENC_BITSET => {
            if rec.len() != n.div_ceil(8) as usize {
                return Err("a bitset record has the wrong length");
            }
            if !n.is_multiple_of(8) && rec.last().is_some_and(|&b| b >> (n % 8) != 0) {
                return Err("a bitset record sets bits past the last object");
            }
            for (w, chunk) in bits.iter_mut().zip(rec.chunks(8)) {
                let mut b = [0u8; 8];
                b[..chunk.len()].copy_from_slice(chunk);
                *w ^= u64::from_le_bytes(b);
            }
        }
        ENC_RUNS => {
            let (mut pos, mut at) = (0usize, 0u64);
            while pos < rec.len() {
                let clear = get_varint(rec, &mut pos).ok_or("a bad varint in a runs record")?;
                let set = get_varint(rec, &mut pos).ok_or("a runs record ends in a clear run")?;
                let s = at + clear as u64;
                at = s + set as u64;
                if at > n as u64 {
                    return Err("a runs record goes past the last object");
                }
                xor_range(bits, s as usize, at as usize);
            }
        }
        ENC_LIST => {
            let (mut pos, mut next) = (0usize, 0u64);
            while pos < rec.len() {
                let gap = get_varint(rec, &mut pos).ok_or("a bad varint in a list record")?;
                let id = next + gap as u64;
                if id >= n as u64 {
                    return Err("a list record names a missing object");
                }
                bits[(id / 64) as usize] ^= 1 << (id % 64);
                next = id + 1;
            }
        }
        _ => return Err("a record has an unknown encoding"),
    }
    Ok(())
}

/// Whether the set of a (valid) record holds `object`.
fn record_has(rec: &[u8], enc: u8, object: u32) -> bool {
    let mut pos = 0;
    match enc {
        ENC_BITSET => rec
            .get((object / 8) as usize)
            .is_some_and(|b| b >> (object % 8) & 1 != 0),
        ENC_RUNS => {
            let mut at = 0u64;
            while let (Some(clear), Some(set)) =
                (get_varint(rec, &mut pos), get_varint(rec, &mut pos))
            {
                let s = at + clear as u64;
                if (object as u64) < s {
                    return false;
                }
                at = s + set as u64;
                if (object as u64) < at {
                    return true;
                }
            }
            false
        }
        _ => {
            let mut next = 0u64;
            while let Some(gap) = get_varint(rec, &mut pos) {
                let id = next + gap as u64;
                if id >= object as u64 {
                    return id == object as u64;
                }
                next = id + 1;
            }
            false
        }
    }
}

fn next_bit(words: &[u64], w: &mut usize, cur: &mut u64) -> Option<u32> {
    while *cur == 0 {
        *w += 1;
        *cur = *words.get(*w)?;
    }
    let tz = cur.trailing_zeros();
    *cur &= *cur - 1;
    Some(*w as u32 * 64 + tz)
}

/// The ids of a cell's visible objects, ascending, borrowed from a [`PvsCursor`].
#[derive(Clone, Debug)]
pub struct Visible<'a> {
    words: &'a [u64],
    w: usize,
    cur: u64,
}

impl Iterator for Visible<'_> {
    type Item = u32;
    fn next(&mut self) -> Option<u32> {
        next_bit(self.words, &mut self.w, &mut self.cur)
    }
}

/// The ids of a cell's visible objects, ascending, owning its decoded set (from
/// [`PvsDatabase::visible`]).
#[derive(Clone, Debug)]
pub struct VisibleSet {
    words: Vec<u64>,
    w: usize,
    cur: u64,
}

impl Iterator for VisibleSet {
    type Item = u32;
    fn next(&mut self) -> Option<u32> {
        next_bit(&self.words, &mut self.w, &mut self.cur)
    }
}

/// A reader that names what ran past the end.
struct Rd<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Rd<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], PvsErrorKind> {
        match self.b.get(self.pos..self.pos.saturating_add(n)) {
            Some(s) => {
                self.pos += n;
                Ok(s)
            }
            None => Err(corrupt(format!("{what} runs past the end of the payload"))),
        }
    }
    fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N], PvsErrorKind> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }
    fn u8(&mut self, what: &str) -> Result<u8, PvsErrorKind> {
        Ok(self.arr::<1>(what)?[0])
    }
    fn bool(&mut self, what: &str) -> Result<bool, PvsErrorKind> {
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(corrupt(format!("{what} is {v}, not 0 or 1"))),
        }
    }
    fn u32(&mut self, what: &str) -> Result<u32, PvsErrorKind> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64, PvsErrorKind> {
        Ok(u64::from_le_bytes(self.arr(what)?))
    }
    fn f32(&mut self, what: &str) -> Result<f32, PvsErrorKind> {
        Ok(f32::from_le_bytes(self.arr(what)?))
    }
    fn f64(&mut self, what: &str) -> Result<f64, PvsErrorKind> {
        Ok(f64::from_le_bytes(self.arr(what)?))
    }
    fn vec3(&mut self, what: &str) -> Result<[f32; 3], PvsErrorKind> {
        Ok([self.f32(what)?, self.f32(what)?, self.f32(what)?])
    }
    fn opt_str(&mut self, what: &str) -> Result<Option<String>, PvsErrorKind> {
        let n = self.u32(what)?;
        if n == NO_STRING {
            return Ok(None);
        }
        let b = self.take(n as usize, what)?;
        String::from_utf8(b.to_vec())
            .map(Some)
            .map_err(|_| corrupt(format!("{what} is not UTF-8")))
    }
    fn str(&mut self, what: &str) -> Result<String, PvsErrorKind> {
        self.opt_str(what)?
            .ok_or_else(|| corrupt(format!("{what} is missing")))
    }
    fn usize_u64(&mut self, what: &str) -> Result<usize, PvsErrorKind> {
        usize::try_from(self.u64(what)?).map_err(|_| corrupt(format!("{what} is too large")))
    }
}

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// An opened `.pvs` file: the object table, the cells with their spatial index, and the
/// delta-PVS records. Immutable and `Sync`: share it between threads, one [`PvsCursor`] each.
#[derive(Clone, Debug)]
pub struct PvsDatabase {
    id: u64,
    objects: u32,
    words: usize,
    scene: String,
    settings: PvsSettings,
    summary: Option<PvsSummary>,
    object_table: Vec<(u32, [f32; 3], [f32; 3])>,
    names: Vec<String>,
    cells: Vec<Cell>,
    ms: Vec<f64>,
    data: Vec<u8>,
    /// Version 5 (a shard's file): the shard's description for `umbrasweep merge`.
    shard: Option<String>,
    /// Version 6 with split objects: the clusters' mapping to the objects of the file.
    split: Option<PvsSplit>,
    /// Version 6 with a cell hierarchy: per cell the cell it is a half of, or `NO_PARENT`.
    up: Vec<u32>,
    /// Per cell its halves (CSR over `halves`); empty without a hierarchy.
    halves_start: Vec<u32>,
    halves: Vec<u32>,
    grid: CellGrid,
    file_bytes: usize,
}

impl PvsDatabase {
    /// Opens and checks a `.pvs` file.
    ///
    /// # Errors
    /// A [`PvsError`] naming the file: unreadable, bad magic, another format version,
    /// truncated or with trailing bytes, checksum mismatch, or inconsistent content.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, PvsError> {
        let path = path.as_ref();
        let with_path = |kind| PvsError {
            path: Some(path.to_path_buf()),
            kind,
        };
        let bytes = std::fs::read(path).map_err(|e| with_path(PvsErrorKind::Io(e.to_string())))?;
        Self::from_bytes(&bytes).map_err(|e| with_path(e.kind))
    }

    /// Reads and checks the bytes of a `.pvs` file (copying what it keeps).
    ///
    /// # Errors
    /// As [`PvsDatabase::open`], without a path.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PvsError> {
        Self::parse(bytes).map_err(|kind| PvsError { path: None, kind })
    }

    fn parse(bytes: &[u8]) -> Result<Self, PvsErrorKind> {
        let actual = bytes.len() as u64;
        let head = bytes.len().min(MAGIC.len());
        if bytes[..head] != MAGIC[..head] {
            return Err(PvsErrorKind::BadMagic {
                looks_like_json: bytes.trim_ascii_start().starts_with(b"{"),
            });
        }
        let truncated = |expected: usize| PvsErrorKind::Truncated {
            expected: expected as u64,
            actual,
        };
        if bytes.len() < 12 {
            return Err(truncated(HEADER_LEN));
        }
        let u32_at =
            |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
        let version = u32_at(8);
        if !(1..=LATEST_FORMAT_VERSION).contains(&version) {
            return Err(PvsErrorKind::UnsupportedVersion { found: version });
        }
        if bytes.len() < HEADER_LEN {
            return Err(truncated(HEADER_LEN));
        }
        let stored = u32_at(12);
        let payload_len = u64::from_le_bytes(bytes[16..24].try_into().unwrap_or([0; 8]));
        let expected = (HEADER_LEN as u64).saturating_add(payload_len);
        if actual < expected {
            return Err(PvsErrorKind::Truncated { expected, actual });
        }
        if actual > expected {
            return Err(PvsErrorKind::TrailingBytes { expected, actual });
        }
        let payload = &bytes[HEADER_LEN..];
        let computed = crc32(payload);
        if computed != stored {
            return Err(PvsErrorKind::Checksum { stored, computed });
        }
        let mut db = Self::parse_payload(payload, version)?;
        db.file_bytes = bytes.len();
        Ok(db)
    }

    fn parse_payload(payload: &[u8], version: u32) -> Result<Self, PvsErrorKind> {
        let mut r = Rd { b: payload, pos: 0 };
        let objects = r.u32("the object count")?;
        let ncells = r.u32("the cell count")?;
        if objects == u32::MAX || ncells == u32::MAX {
            return Err(corrupt("object or cell count is 0xFFFFFFFF"));
        }
        let scene = r.str("the scene path")?;
        let mut settings = PvsSettings {
            backend: r.str("settings.backend")?,
            ..PvsSettings::default()
        };
        let s = &mut settings.bake;
        s.resolution = r.u32("settings.resolution")?;
        s.extend = r.f64("settings.extend")?;
        s.planes = r.u32("settings.planes")?;
        s.slice_planes = r.u32("settings.slice_planes")?;
        s.placement = match r.str("settings.placement")?.as_str() {
            "" | "geometric" => Placement::Geometric,
            "quantile" => Placement::Quantile,
            _ => return Err(corrupt("settings.placement is not geometric or quantile")),
        };
        s.alpha_occluders = r.bool("settings.alpha_occluders")?;
        s.occluders = r.opt_str("settings.occluders")?;
        s.improved_projection = r.bool("settings.improved_projection")?;
        // Files before version 2 were baked without the sweep and sub-cells, before version 3
        // with square maps.
        s.sweep = SweepChoice::Off;
        s.max_stretch = 1;
        if version >= 2 {
            if r.bool("settings.sweep")? {
                s.sweep = SweepChoice::On;
            }
            s.sweep_settings.planes = r.u32("settings.sweep_planes")?;
            s.sweep_settings.kernel = r.u32("settings.kernel")?;
            s.sweep_settings.spacing = match r.str("settings.sweep_spacing")?.as_str() {
                "" | "geometric" => Spacing::Geometric,
                "kernel" => Spacing::Kernel,
                _ => return Err(corrupt("settings.sweep_spacing is not geometric or kernel")),
            };
            let has_subcell = r.bool("settings.subcell flag")?;
            let size = r.f64("settings.subcell")?;
            s.subcell = has_subcell.then_some(size);
        }
        if version >= 3 {
            s.max_stretch = r.u32("settings.max_stretch")?.max(1);
        }
        let summary = if r.bool("the summary flag")? {
            Some(PvsSummary {
                cells: r.usize_u64("summary.cells")?,
                objects: r.usize_u64("summary.objects")?,
                triangles: r.usize_u64("summary.triangles")?,
                occluder_triangles: r.usize_u64("summary.occluder_triangles")?,
                degenerate_triangles: r.usize_u64("summary.degenerate_triangles")?,
                backend: r.str("summary.backend")?,
                adapter: r.opt_str("summary.adapter")?,
                objects_culled_percent: r.f64("summary.objects_culled_percent")?,
                triangles_culled_percent: r.f64("summary.triangles_culled_percent")?,
                median_ms_per_cell: r.f64("summary.median_ms_per_cell")?,
                total_seconds: r.f64("summary.total_seconds")?,
                cullers: Vec::new(),
                alpha_cards: None,
            })
        } else {
            None
        };
        let mut summary = summary;
        if version >= 4
            && let Some(s) = &mut summary
        {
            let count = r.u32("summary.cullers count")?;
            // Each entry takes at least 36 bytes: refuse counts the payload cannot hold.
            if (count as usize).saturating_mul(36) > payload.len() - r.pos {
                return Err(corrupt("the culler list runs past the end of the payload"));
            }
            for _ in 0..count {
                s.cullers.push(crate::pvs::PvsCullerSummary {
                    name: r.str("summary.cullers name")?,
                    hidden: r.f64("summary.cullers hidden")?,
                    only: r.f64("summary.cullers only")?,
                    ms: r.f64("summary.cullers ms")?,
                    planes: r.f64("summary.cullers planes")?,
                    ..Default::default()
                });
            }
        }
        // The sampler's and ray space factorization's switches are not stored: each ran when
        // the cullers' accounts name it (the sampler's parameters read as the defaults; ray
        // space factorization's are in the culling section when not the defaults).
        let ran = |name: &str| {
            if summary
                .as_ref()
                .is_some_and(|s| s.cullers.iter().any(|c| c.name == name))
            {
                SweepChoice::On
            } else {
                SweepChoice::Off
            }
        };
        settings.bake.sampling = ran(super::SHRUNK_SAMPLING);
        settings.bake.rsf = ran(super::RAY_SPACE_FACTORIZATION);
        // Check sizes before allocating from counts.
        let left = payload.len() - r.pos;
        if (objects as usize).saturating_mul(OBJECT_RECORD_LEN + 4) > left {
            return Err(corrupt("the object table runs past the end of the payload"));
        }
        let mut object_table = Vec::with_capacity(objects as usize);
        for _ in 0..objects {
            object_table.push((
                r.u32("an object")?,
                r.vec3("an object")?,
                r.vec3("an object")?,
            ));
        }
        let mut names = Vec::with_capacity(objects as usize);
        for _ in 0..objects {
            names.push(r.str("an object name")?);
        }
        let left = payload.len() - r.pos;
        if (ncells as usize).saturating_mul(CELL_RECORD_LEN + 8) > left {
            return Err(corrupt("the cell table runs past the end of the payload"));
        }
        let mut cells = Vec::with_capacity(ncells as usize);
        let mut start = 0usize;
        for i in 0..ncells {
            let min = r.vec3("a cell")?;
            let max = r.vec3("a cell")?;
            if min.iter().chain(&max).any(|v| !v.is_finite()) {
                return Err(corrupt(format!("cell {i} has non-finite bounds")));
            }
            let parent = r.u32("a cell")?;
            if parent != NO_PARENT && parent >= ncells {
                return Err(corrupt(format!(
                    "cell {i} refers to a missing cell {parent}"
                )));
            }
            let count = r.u32("a cell")?;
            let len = r.u32("a cell")? as usize;
            let [enc, _, _, _] = r.arr::<4>("a cell")?;
            cells.push(Cell {
                min,
                max,
                parent,
                depth: 0,
                count,
                start,
                len,
                enc,
            });
            start = start.saturating_add(len);
        }
        let mut ms = Vec::with_capacity(ncells as usize);
        for _ in 0..ncells {
            ms.push(r.f64("the cell timings")?);
        }
        let data_len = r.u32("the PVS data length")? as usize;
        let data = r.take(data_len, "the PVS data")?.to_vec();
        let mut shard = if version == 5 {
            Some(r.str("the shard's description")?)
        } else {
            None
        };
        let (mut split, mut up) = (None, Vec::new());
        if version >= 6 {
            let count = r.u32("the extension count")?;
            for _ in 0..count {
                let tag = r.u32("an extension tag")?;
                let len = r.u32("an extension length")? as usize;
                let bytes = r.take(len, "an extension section")?;
                match tag {
                    TAG_SHARD => {
                        shard = Some(
                            String::from_utf8(bytes.to_vec())
                                .map_err(|_| corrupt("the shard's description is not UTF-8"))?,
                        );
                    }
                    TAG_SPLIT => split = Some(read_split(bytes, objects)?),
                    TAG_HIERARCHY => {
                        let (max, min, parents) = read_hierarchy(bytes, ncells)?;
                        settings.bake.max_pvs_triangles = (max > 0).then_some(max);
                        settings.bake.min_cell_size = (min > 0.0).then_some(min);
                        up = parents;
                    }
                    TAG_CULLING => read_culling(bytes, &mut settings.bake)?,
                    // Sections of later writers that this reader does not know: skipped.
                    _ => {}
                }
            }
        }
        if r.pos != payload.len() {
            return Err(corrupt(format!(
                "{} bytes after the PVS data",
                payload.len() - r.pos
            )));
        }
        if start != data_len {
            return Err(corrupt(format!(
                "the records add up to {start} bytes, the PVS data has {data_len}"
            )));
        }
        // Depths (1 for key cells), refusing cycles.
        let n = cells.len();
        let mut path = Vec::new();
        for i in 0..n {
            let mut j = i as u32;
            while j != NO_PARENT && cells[j as usize].depth == 0 {
                if path.len() > n {
                    return Err(corrupt(format!("cell {i}'s chain of parents has a cycle")));
                }
                path.push(j);
                j = cells[j as usize].parent;
            }
            let mut d = if j == NO_PARENT {
                0
            } else {
                cells[j as usize].depth
            };
            while let Some(k) = path.pop() {
                d += 1;
                cells[k as usize].depth = d;
            }
        }
        // Halves inside the cell they halve.
        for (i, &p) in up.iter().enumerate() {
            if p != NO_PARENT {
                let (c, q) = (&cells[i], &cells[p as usize]);
                if (0..3).any(|k| c.min[k] < q.min[k] || c.max[k] > q.max[k]) {
                    return Err(corrupt(format!(
                        "cell {i} is a half of cell {p} but does not lie inside it"
                    )));
                }
            }
        }
        let mut halves_start = vec![0u32; if up.is_empty() { 0 } else { cells.len() + 1 }];
        for &p in up.iter().filter(|&&p| p != NO_PARENT) {
            halves_start[p as usize + 1] += 1;
        }
        for i in 1..halves_start.len() {
            halves_start[i] += halves_start[i - 1];
        }
        let mut halves = vec![0u32; halves_start.last().copied().unwrap_or(0) as usize];
        let mut fill = halves_start.clone();
        for (i, &p) in up.iter().enumerate().filter(|(_, p)| **p != NO_PARENT) {
            halves[fill[p as usize] as usize] = i as u32;
            fill[p as usize] += 1;
        }
        let words = objects.div_ceil(64) as usize;
        let grid = CellGrid::new(&cells, |i| up.get(i).is_none_or(|&p| p == NO_PARENT));
        let mut db = PvsDatabase {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            objects,
            words,
            scene,
            settings,
            summary,
            object_table,
            names,
            grid,
            cells,
            ms,
            data,
            shard,
            split,
            up,
            halves_start,
            halves,
            file_bytes: 0,
        };
        db.check_records()?;
        Ok(db)
    }

    /// Decodes every cell once (depth-first over the delta tree) and checks each record's
    /// structure and each set's size against the stored count.
    fn check_records(&mut self) -> Result<(), PvsErrorKind> {
        let n = self.cells.len();
        // Children lists (CSR), then an explicit-stack DFS from the key cells.
        let mut first = vec![0u32; n + 1];
        for c in &self.cells {
            if c.parent != NO_PARENT {
                first[c.parent as usize + 1] += 1;
            }
        }
        for i in 1..=n {
            first[i] += first[i - 1];
        }
        let mut fill = first.clone();
        let mut kids = vec![0u32; first[n] as usize];
        for (i, c) in self.cells.iter().enumerate() {
            if c.parent != NO_PARENT {
                kids[fill[c.parent as usize] as usize] = i as u32;
                fill[c.parent as usize] += 1;
            }
        }
        let mut bits = vec![0u64; self.words];
        // (cell, entering?)
        let mut stack: Vec<(u32, bool)> = (0..n as u32)
            .rev()
            .filter(|&i| self.cells[i as usize].parent == NO_PARENT)
            .map(|i| (i, true))
            .collect();
        while let Some((i, enter)) = stack.pop() {
            let c = &self.cells[i as usize];
            let rec = &self.data[c.start..c.start + c.len];
            xor_record(rec, c.enc, self.objects, &mut bits)
                .map_err(|e| corrupt(format!("cell {i}: {e}")))?;
            if enter {
                let count: u32 = bits.iter().map(|w| w.count_ones()).sum();
                if count != c.count {
                    return Err(corrupt(format!(
                        "cell {i} decodes to {count} objects, its count says {}",
                        c.count
                    )));
                }
                stack.push((i, false));
                let (a, b) = (first[i as usize] as usize, first[i as usize + 1] as usize);
                stack.extend(kids[a..b].iter().rev().map(|&k| (k, true)));
            }
        }
        Ok(())
    }

    /// The shard's description (JSON, read by `umbrasweep merge`) when the file is a shard of
    /// a bake (`bake --shard I/N -o SHARD.pvs`, format version 5), else `None`.
    pub fn shard(&self) -> Option<&str> {
        self.shard.as_deref()
    }

    /// The number of cells.
    pub fn cell_count(&self) -> usize {
        self.cells.len()
    }

    /// The number of objects (ids are `0..object_count()`).
    pub fn object_count(&self) -> usize {
        self.objects as usize
    }

    /// The scene file the PVS was baked from.
    pub fn scene(&self) -> &str {
        &self.scene
    }

    /// An object's name, triangle count and bounds; `None` for an id out of range.
    pub fn object(&self, id: u32) -> Option<ObjectInfo<'_>> {
        let (triangles, min, max) = *self.object_table.get(id as usize)?;
        Some(ObjectInfo {
            name: &self.names[id as usize],
            triangles,
            min,
            max,
        })
    }

    /// A cell's bounds `(min, max)`.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn cell_bounds(&self, cell: CellId) -> ([f32; 3], [f32; 3]) {
        let c = &self.cells[cell.index()];
        (c.min, c.max)
    }

    /// How many objects a cell sees (stored, so no decoding).
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn visible_count(&self, cell: CellId) -> usize {
        self.cells[cell.index()].count as usize
    }

    /// How a cell's PVS is stored.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn cell_record(&self, cell: CellId) -> CellRecordInfo {
        let c = &self.cells[cell.index()];
        CellRecordInfo {
            parent: (c.parent != NO_PARENT).then_some(CellId(c.parent)),
            encoding: c.enc,
            bytes: c.len,
            depth: c.depth,
        }
    }

    /// The cell holding `point` (boxes are closed; where cells overlap, the lowest index),
    /// found through a uniform grid over the cells; `None` outside every cell or for NaN.
    /// With adaptive subdivision the lookup then descends to the smallest cell holding the
    /// point: of the cell's halves the first that holds it, and so on.
    pub fn cell_at(&self, point: impl Into<Vec3>) -> Option<CellId> {
        let p = point.into();
        let mut at = *self
            .grid
            .candidates(p)
            .iter()
            .find(|&&i| self.cells[i as usize].contains(p))?;
        while let Some(&h) = self
            .halves_of(at)
            .iter()
            .find(|&&h| self.cells[h as usize].contains(p))
        {
            at = h;
        }
        Some(CellId(at))
    }

    fn halves_of(&self, cell: u32) -> &[u32] {
        match self.halves_start.get(cell as usize..cell as usize + 2) {
            Some(&[a, b]) => &self.halves[a as usize..b as usize],
            _ => &[],
        }
    }

    /// The halves a cell was split into by adaptive subdivision (`bake --max-pvs-triangles`),
    /// empty when it was not split (and in files without subdivision).
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn cell_halves(&self, cell: CellId) -> impl Iterator<Item = CellId> + '_ {
        assert!(
            cell.index() < self.cells.len(),
            "cell {} out of range",
            cell.0
        );
        self.halves_of(cell.0).iter().map(|&h| CellId(h))
    }

    /// The cell that `cell` is a half of (adaptive subdivision), `None` for a cell given to
    /// the bake.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn cell_parent(&self, cell: CellId) -> Option<CellId> {
        assert!(
            cell.index() < self.cells.len(),
            "cell {} out of range",
            cell.0
        );
        self.up
            .get(cell.index())
            .filter(|&&p| p != NO_PARENT)
            .map(|&p| CellId(p))
    }

    /// With `bake --split-objects`: how the objects (clusters) map to the objects of the
    /// scene file; `None` otherwise.
    pub fn split(&self) -> Option<&PvsSplit> {
        self.split.as_ref()
    }

    /// Whether `object` is in `cell`'s PVS, without decoding the set or allocating (false
    /// for an object id out of range).
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn is_visible(&self, cell: CellId, object: u32) -> bool {
        let mut c = &self.cells[cell.index()];
        if object >= self.objects {
            return false;
        }
        let mut inside = false;
        loop {
            inside ^= record_has(&self.data[c.start..c.start + c.len], c.enc, object);
            if c.parent == NO_PARENT {
                return inside;
            }
            c = &self.cells[c.parent as usize];
        }
    }

    /// A cell's visible object ids, ascending. Decodes the cell from scratch into a new
    /// set; use a [`PvsCursor`] to walk from cell to cell without allocating.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn visible(&self, cell: CellId) -> VisibleSet {
        let mut words = vec![0u64; self.words];
        let mut c = cell.0;
        while c != NO_PARENT {
            self.xor(c, &mut words);
            c = self.cells[c as usize].parent;
        }
        let cur = words.first().copied().unwrap_or(0);
        VisibleSet { words, w: 0, cur }
    }

    /// A cursor for walking from cell to cell (its set is allocated once, here).
    pub fn cursor(&self) -> PvsCursor {
        PvsCursor {
            db: self.id,
            bits: vec![0; self.words],
            cell: NO_PARENT,
        }
    }

    fn xor(&self, cell: u32, bits: &mut [u64]) {
        let c = &self.cells[cell as usize];
        // Checked when the file was opened.
        let _ = xor_record(
            &self.data[c.start..c.start + c.len],
            c.enc,
            self.objects,
            bits,
        );
    }

    /// Sizes and shape of the file.
    pub fn stats(&self) -> PvsStats {
        let n = self.cells.len();
        let mut by_enc = [0usize; 3];
        for c in &self.cells {
            by_enc[(c.enc as usize).min(2)] += 1;
        }
        let per = |f: &dyn Fn(&Cell) -> f64| {
            if n == 0 {
                0.0
            } else {
                self.cells.iter().map(f).sum::<f64>() / n as f64
            }
        };
        PvsStats {
            cells: n,
            objects: self.objects as usize,
            key_cells: self.cells.iter().filter(|c| c.parent == NO_PARENT).count(),
            records_by_encoding: by_enc,
            pvs_data_bytes: self.data.len(),
            cell_table_bytes: n * CELL_RECORD_LEN,
            file_bytes: self.file_bytes,
            plain_bitset_bytes: n * self.objects.div_ceil(8) as usize,
            mean_visible: per(&|c| c.count as f64),
            max_depth: self.cells.iter().map(|c| c.depth).max().unwrap_or(0),
            mean_depth: per(&|c| c.depth as f64),
        }
    }

    /// The JSON document `bake -o OUT.json` writes for the same bake.
    pub fn to_document(&self) -> PvsDocument {
        let mut cur = self.cursor();
        PvsDocument {
            format: FORMAT.into(),
            version: VERSION,
            scene: self.scene.clone(),
            settings: self.settings.clone(),
            objects: (0..self.objects)
                .map(|i| {
                    let (triangles, min, max) = self.object_table[i as usize];
                    PvsObject {
                        id: i,
                        name: self.names[i as usize].clone(),
                        triangles,
                        min,
                        max,
                    }
                })
                .collect(),
            cells: (0..self.cells.len())
                .map(|i| {
                    let c = &self.cells[i];
                    PvsCell {
                        min: c.min,
                        max: c.max,
                        visible: cur.visible(self, CellId(i as u32)).collect(),
                        ms: self.ms[i],
                        cullers: Vec::new(),
                        parent: self.cell_parent(CellId(i as u32)).map(|p| p.0),
                    }
                })
                .collect(),
            summary: self.summary.clone(),
            split: self.split.clone(),
        }
    }
}

/// Reads the split section (`docs/pvs-format.md`), checking that the sources' clusters follow
/// each other and cover the `objects`.
fn read_split(bytes: &[u8], objects: u32) -> Result<PvsSplit, PvsErrorKind> {
    let mut r = Rd { b: bytes, pos: 0 };
    let size = r.f32("the split size")?;
    let count = r.u32("the split source count")?;
    // Each entry takes at least 36 bytes.
    if (count as usize).saturating_mul(36) > bytes.len() - r.pos {
        return Err(corrupt("the split table runs past its section"));
    }
    let mut sources = Vec::with_capacity(count as usize);
    let mut next = 0u32;
    for id in 0..count {
        let s = PvsSource {
            id,
            name: r.str("a split source's name")?,
            triangles: r.u32("a split source")?,
            min: r.vec3("a split source")?,
            max: r.vec3("a split source")?,
            first: r.u32("a split source")?,
            count: r.u32("a split source")?,
        };
        if s.first != next || s.first.checked_add(s.count).is_none_or(|e| e > objects) {
            return Err(corrupt(format!(
                "split source {id}: clusters {}..+{} do not follow the previous source's",
                s.first, s.count
            )));
        }
        next = s.first + s.count;
        sources.push(s);
    }
    if next != objects || r.pos != bytes.len() {
        return Err(corrupt(
            "the split table does not cover the objects exactly",
        ));
    }
    Ok(PvsSplit { size, sources })
}

/// Reads the culling section: the occluders' minimum solid angle, then (when present) ray
/// space factorization's resolution and the up axis, then (when present) the alpha-card
/// settings (`docs/pvs-format.md`).
fn read_culling(bytes: &[u8], s: &mut crate::settings::BakeSettings) -> Result<(), PvsErrorKind> {
    let mut r = Rd { b: bytes, pos: 0 };
    let angle = r.f64("the culling section's solid angle")?;
    if !(angle.is_finite() && (0.0..4.0 * std::f64::consts::PI).contains(&angle)) {
        return Err(corrupt(format!(
            "the occluder solid angle {angle} is not a solid angle"
        )));
    }
    s.occluder_min_solid_angle = angle;
    if r.pos < r.b.len() {
        s.rsf_resolution = r.u32("the culling section's rsf resolution")?;
        s.up = match r.u8("the culling section's up axis")? {
            1 => crate::settings::UpAxis::Y,
            2 => crate::settings::UpAxis::Z,
            k => return Err(corrupt(format!("up axis {k} (expected 1 for y, 2 for z)"))),
        };
    }
    if r.pos < r.b.len() {
        s.alpha_cards = match r.u8("the culling section's alpha cards")? {
            0 => crate::settings::AlphaCards::Coverage,
            1 => crate::settings::AlphaCards::Ignore,
            k => return Err(corrupt(format!("alpha cards {k} (expected 0 or 1)"))),
        };
        s.alpha_mips = r.u32("the culling section's alpha mips")?;
        s.alpha_card_polygons = r.u32("the culling section's alpha card polygons")?;
        s.alpha_missing = match r.u8("the culling section's alpha missing")? {
            0 => crate::settings::AlphaMissing::Error,
            1 => crate::settings::AlphaMissing::Transparent,
            k => return Err(corrupt(format!("alpha missing {k} (expected 0 or 1)"))),
        };
    }
    Ok(())
}

/// Reads the hierarchy section: the subdivision settings and per cell its parent (an earlier
/// cell) or `NO_PARENT`.
fn read_hierarchy(bytes: &[u8], cells: u32) -> Result<(u64, f64, Vec<u32>), PvsErrorKind> {
    let mut r = Rd { b: bytes, pos: 0 };
    let max = r.u64("the subdivision's max_pvs_triangles")?;
    let min = r.f64("the subdivision's min_cell_size")?;
    if bytes.len() - r.pos != 4 * cells as usize {
        return Err(corrupt(
            "the cell hierarchy does not hold one entry per cell",
        ));
    }
    let mut up = Vec::with_capacity(cells as usize);
    for i in 0..cells {
        let p = r.u32("the cell hierarchy")?;
        if p != NO_PARENT && p >= i {
            return Err(corrupt(format!(
                "cell {i} is a half of cell {p}, which does not come before it"
            )));
        }
        up.push(p);
    }
    Ok((max, min, up))
}

/// One decoded visible set that moves from cell to cell by applying only the delta records on
/// the path between the two cells in the delta tree. Queries do not allocate. Made by
/// [`PvsDatabase::cursor`]; used with another database it starts over (allocating once).
#[derive(Clone, Debug)]
pub struct PvsCursor {
    db: u64,
    bits: Vec<u64>,
    cell: u32,
}

impl PvsCursor {
    /// Moves to `cell`, decoding incrementally from the current cell.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn move_to(&mut self, db: &PvsDatabase, cell: CellId) {
        assert!(
            cell.index() < db.cells.len(),
            "cell {cell} out of range ({} cells)",
            db.cells.len()
        );
        if self.db != db.id {
            *self = db.cursor();
        }
        let depth = |c: u32| {
            if c == NO_PARENT {
                0
            } else {
                db.cells[c as usize].depth
            }
        };
        let (mut a, mut b) = (self.cell, cell.0);
        while a != b {
            if depth(a) >= depth(b) {
                db.xor(a, &mut self.bits);
                a = db.cells[a as usize].parent;
            } else {
                db.xor(b, &mut self.bits);
                b = db.cells[b as usize].parent;
            }
        }
        self.cell = cell.0;
    }

    /// Moves to `cell` and iterates its visible object ids, ascending.
    ///
    /// # Panics
    /// When `cell` is out of range.
    pub fn visible(&mut self, db: &PvsDatabase, cell: CellId) -> Visible<'_> {
        self.move_to(db, cell);
        self.iter()
    }

    /// The visible object ids of the current cell (none before the first move).
    pub fn iter(&self) -> Visible<'_> {
        Visible {
            words: &self.bits,
            w: 0,
            cur: self.bits.first().copied().unwrap_or(0),
        }
    }

    /// The current cell.
    pub fn cell(&self) -> Option<CellId> {
        (self.cell != NO_PARENT).then_some(CellId(self.cell))
    }

    /// Whether the current cell sees `object`.
    pub fn contains(&self, object: u32) -> bool {
        self.bits
            .get((object / 64) as usize)
            .is_some_and(|w| w >> (object % 64) & 1 != 0)
    }

    /// The current set's size.
    pub fn visible_count(&self) -> usize {
        self.bits.iter().map(|w| w.count_ones() as usize).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xor_range_edges() {
        for (s, e) in [
            (0, 0),
            (0, 1),
            (3, 64),
            (63, 65),
            (0, 128),
            (64, 128),
            (5, 190),
        ] {
            let mut bits = vec![0u64; 3];
            xor_range(&mut bits, s, e);
            for i in 0..192 {
                assert_eq!(
                    bits[i / 64] >> (i % 64) & 1 == 1,
                    (s..e).contains(&i),
                    "{s}..{e} {i}"
                );
            }
        }
    }
}
