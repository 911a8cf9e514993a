//! The binary PVS file (`.pvs`): a versioned, checksummed, delta-compressed form of the
//! [`PvsDocument`], laid out in `docs/pvs-format.md` so that engines in any language can read
//! it.
//!
//! This module is the writer: the encoder ([`encode`], and `write` with the `bake`
//! feature) and the choice of each cell's parent. The format's constants and checksum are
//! defined in [`format`](super::format) (and re-exported here). Reading a file is
//! [`PvsDatabase::open`]; [`read`] turns it back into the document.
//!
//! # Delta-PVS
//!
//! Each cell's record holds its visible set XOR-ed with its *parent* cell's set (Durand et al.
//! 2000, §6.1; Yagel and Ray's difference lists), or the full set for a *key* cell (no parent).
//! Parents are chosen by a minimum spanning tree over each cell's nearest cells, weighted by the
//! encoded size of the difference, with an edge to "no parent" weighted by the full set's size,
//! and the tree's depth is capped at [`MAX_DEPTH`]. Each record is stored as a bitset, as
//! run lengths or as a list of ids, whichever is smallest.

// The format's constants and checksum, at their old paths (`pvs::binary::FORMAT_VERSION`…).
pub use super::format::{
    CELL_RECORD_LEN, ENC_BITSET, ENC_LIST, ENC_RUNS, EXTENDED_FORMAT_VERSION, FORMAT_VERSION,
    HEADER_LEN, LATEST_FORMAT_VERSION, MAGIC, MAX_DEPTH, NO_PARENT, NO_STRING, OBJECT_RECORD_LEN,
    SHARD_FORMAT_VERSION, TAG_CULLING, TAG_HIERARCHY, TAG_SHARD, TAG_SPLIT, crc32,
};

use super::PvsDocument;
use super::database::PvsDatabase;
use super::error::{EncodeError, PvsError};
#[cfg(feature = "bake")]
use super::error::{PvsWriteError, PvsWriteErrorKind};
use super::format::{put_varint, varint_len};
use crate::settings::{Placement, Spacing, SweepChoice};
#[cfg(feature = "bake")]
use std::path::Path;

/// How many nearest cells (by centre distance) are parent candidates of each cell.
const NEIGHBOURS: usize = 10;

/// Calls `f(start, len)` for each maximal run of set bits, in ascending order.
pub(crate) fn for_each_run(bits: &[u64], mut f: impl FnMut(u32, u32)) {
    let mut run: Option<(u32, u32)> = None;
    for (w, &word) in bits.iter().enumerate() {
        let mut x = word;
        let base = (w * 64) as u32;
        while x != 0 {
            let tz = x.trailing_zeros();
            let start = base + tz;
            let ones = (x >> tz).trailing_ones();
            match &mut run {
                Some((s, l)) if *s + *l == start => *l += ones,
                _ => {
                    if let Some((s, l)) = run {
                        f(s, l);
                    }
                    run = Some((start, ones));
                }
            }
            if tz + ones >= 64 {
                break;
            }
            x &= !(((1u64 << ones) - 1) << tz);
        }
    }
    if let Some((s, l)) = run {
        f(s, l);
    }
}

/// Encoded sizes of one set of `objects` bits: (bitset, runs, list).
fn sizes(bits: &[u64], objects: u32) -> [usize; 3] {
    let (mut runs, mut list) = (0usize, 0usize);
    let mut end = 0u32; // end of the previous set run
    let mut next = 0u32; // the smallest id the next list entry may have
    for_each_run(bits, |s, l| {
        runs += varint_len(s - end) + varint_len(l);
        end = s + l;
        list += varint_len(s - next) + (l as usize - 1);
        next = s + l;
    });
    [objects.div_ceil(8) as usize, runs, list]
}

/// Appends the record of `bits` in `enc`.
fn put_record(out: &mut Vec<u8>, bits: &[u64], objects: u32, enc: u8) {
    match enc {
        ENC_BITSET => {
            let n = objects.div_ceil(8) as usize;
            let start = out.len();
            for w in bits {
                out.extend_from_slice(&w.to_le_bytes());
            }
            out.truncate(start + n);
        }
        ENC_RUNS => {
            let mut end = 0;
            for_each_run(bits, |s, l| {
                put_varint(out, s - end);
                put_varint(out, l);
                end = s + l;
            });
        }
        _ => {
            let mut next = 0;
            for_each_run(bits, |s, l| {
                put_varint(out, s - next);
                for _ in 1..l {
                    out.push(0);
                }
                next = s + l;
            });
        }
    }
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_str(out: &mut Vec<u8>, s: &str) -> Result<(), EncodeError> {
    let n = u32::try_from(s.len())
        .ok()
        .filter(|&n| n != NO_STRING)
        .ok_or(EncodeError::StringTooLong { len: s.len() })?;
    put_u32(out, n);
    out.extend_from_slice(s.as_bytes());
    Ok(())
}

fn put_opt_str(out: &mut Vec<u8>, s: Option<&str>) -> Result<(), EncodeError> {
    match s {
        Some(s) => put_str(out, s),
        None => {
            put_u32(out, NO_STRING);
            Ok(())
        }
    }
}

/// The delta tree: each cell's parent (or [`NO_PARENT`]), chosen by a minimum spanning tree
/// over nearest neighbours with a virtual root for "store in full", depth-capped.
fn choose_parents(doc: &PvsDocument, sets: &[Vec<u64>], objects: u32) -> Vec<u32> {
    let n = sets.len();
    let centre = |i: usize| {
        let c = &doc.cells[i];
        [0, 1, 2].map(|k| 0.5 * (c.min[k] as f64 + c.max[k] as f64))
    };
    let centres: Vec<[f64; 3]> = (0..n).map(centre).collect();
    // Nearest cells by centre distance (ties by index), as an undirected candidate graph.
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut near: Vec<(f64, u32)> = Vec::with_capacity(n);
    for i in 0..n {
        near.clear();
        for j in 0..n {
            if j != i {
                let d: f64 = (0..3)
                    .map(|k| (centres[i][k] - centres[j][k]).powi(2))
                    .sum();
                near.push((if d.is_nan() { f64::INFINITY } else { d }, j as u32));
            }
        }
        let k = NEIGHBOURS.min(near.len());
        if k < near.len() {
            near.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
        for &(_, j) in &near[..k] {
            adj[i].push(j);
            adj[j as usize].push(i as u32);
        }
    }
    let mut scratch = vec![0u64; objects.div_ceil(64) as usize];
    let mut delta_cost = |a: usize, b: usize| {
        for (s, (x, y)) in scratch.iter_mut().zip(sets[a].iter().zip(&sets[b])) {
            *s = x ^ y;
        }
        sizes(&scratch, objects).into_iter().min().unwrap_or(0)
    };
    // Lazy Prim from the virtual root; the heap holds (cost, cell, parent).
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let mut heap = BinaryHeap::new();
    let mut best = vec![0usize; n];
    for (i, s) in sets.iter().enumerate() {
        best[i] = sizes(s, objects).into_iter().min().unwrap_or(0);
        heap.push(Reverse((best[i], i as u32, NO_PARENT)));
    }
    let mut parent = vec![NO_PARENT; n];
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while let Some(Reverse((_, i, p))) = heap.pop() {
        let i = i as usize;
        if done[i] {
            continue;
        }
        done[i] = true;
        parent[i] = p;
        order.push(i);
        adj[i].sort_unstable();
        adj[i].dedup();
        for &j in &adj[i] {
            let j = j as usize;
            if done[j] {
                continue;
            }
            let c = delta_cost(i, j);
            if c < best[j] {
                best[j] = c;
                heap.push(Reverse((c, j as u32, i as u32)));
            }
        }
    }
    // Cap the depth: parents come before their children in `order`.
    let mut depth = vec![0u32; n];
    for &i in &order {
        let p = parent[i];
        depth[i] = if p == NO_PARENT {
            1
        } else {
            depth[p as usize] + 1
        };
        if depth[i] > MAX_DEPTH {
            parent[i] = NO_PARENT;
            depth[i] = 1;
        }
    }
    parent
}

/// Encodes `doc` as the bytes of a `.pvs` file.
///
/// # Errors
/// An [`EncodeError`] for a document the format cannot hold: object ids that are not
/// `0, 1, 2…` in order, a cell whose visible ids are not strictly ascending or name a missing
/// object, or more than `u32::MAX - 1` cells or objects.
pub fn encode(doc: &PvsDocument) -> Result<Vec<u8>, EncodeError> {
    encode_with(doc, None)
}

/// [`encode`] for a shard of a bake (`bake --shard I/N -o SHARD.pvs`): format version 5, the
/// document's cells followed by `shard`, the shard's description (JSON) that `umbrasweep
/// merge` reads back ([`PvsDatabase::shard`](super::PvsDatabase::shard)).
///
/// # Errors
/// As [`encode`].
pub fn encode_shard(doc: &PvsDocument, shard: &str) -> Result<Vec<u8>, EncodeError> {
    encode_with(doc, Some(shard))
}

fn encode_with(doc: &PvsDocument, shard: Option<&str>) -> Result<Vec<u8>, EncodeError> {
    let objects = u32::try_from(doc.objects.len())
        .ok()
        .filter(|&n| n != u32::MAX)
        .ok_or(EncodeError::TooManyObjects {
            objects: doc.objects.len(),
        })?;
    let cells = u32::try_from(doc.cells.len())
        .ok()
        .filter(|&n| n != u32::MAX)
        .ok_or(EncodeError::TooManyCells {
            cells: doc.cells.len(),
        })?;
    if let Some((i, o)) = doc
        .objects
        .iter()
        .enumerate()
        .find(|(i, o)| o.id as usize != *i)
    {
        return Err(EncodeError::ObjectOutOfOrder { index: i, id: o.id });
    }
    let words = objects.div_ceil(64) as usize;
    let mut sets = Vec::with_capacity(doc.cells.len());
    for (i, c) in doc.cells.iter().enumerate() {
        let mut bits = vec![0u64; words];
        let mut prev: Option<u32> = None;
        for &id in &c.visible {
            if id >= objects {
                return Err(EncodeError::MissingObject {
                    cell: i,
                    object: id,
                    objects,
                });
            }
            if let Some(previous) = prev.filter(|&p| p >= id) {
                return Err(EncodeError::NotAscending {
                    cell: i,
                    previous,
                    id,
                });
            }
            prev = Some(id);
            bits[(id / 64) as usize] |= 1 << (id % 64);
        }
        sets.push(bits);
    }
    let parent = choose_parents(doc, &sets, objects);

    let mut p = Vec::new();
    put_u32(&mut p, objects);
    put_u32(&mut p, cells);
    put_str(&mut p, &doc.scene)?;
    put_str(&mut p, &doc.settings.backend)?;
    let s = &doc.settings.bake;
    put_u32(&mut p, s.resolution);
    p.extend_from_slice(&s.extend.to_le_bytes());
    put_u32(&mut p, s.planes);
    put_u32(&mut p, s.slice_planes);
    put_str(
        &mut p,
        match s.placement {
            Placement::Geometric => "geometric",
            Placement::Quantile => "quantile",
        },
    )?;
    p.push(s.alpha_occluders as u8);
    put_opt_str(&mut p, s.occluders.as_deref())?;
    p.push(s.improved_projection as u8);
    // The sweep as the bake chose it (a document with `"auto"` was not written by a bake).
    p.push((s.sweep == SweepChoice::On) as u8);
    put_u32(&mut p, s.sweep_settings.planes);
    put_u32(&mut p, s.sweep_settings.kernel);
    put_str(
        &mut p,
        match s.sweep_settings.spacing {
            Spacing::Geometric => "geometric",
            Spacing::Kernel => "kernel",
        },
    )?;
    p.push(s.subcell.is_some() as u8);
    p.extend_from_slice(&s.subcell.unwrap_or(0.0).to_le_bytes());
    put_u32(&mut p, s.max_stretch);
    match &doc.summary {
        None => p.push(0),
        Some(m) => {
            p.push(1);
            for v in [
                m.cells,
                m.objects,
                m.triangles,
                m.occluder_triangles,
                m.degenerate_triangles,
            ] {
                p.extend_from_slice(&(v as u64).to_le_bytes());
            }
            put_str(&mut p, &m.backend)?;
            put_opt_str(&mut p, m.adapter.as_deref())?;
            for v in [
                m.objects_culled_percent,
                m.triangles_culled_percent,
                m.median_ms_per_cell,
                m.total_seconds,
            ] {
                p.extend_from_slice(&v.to_le_bytes());
            }
            // From version 4 on: the cullers' accounts.
            put_u32(&mut p, m.cullers.len() as u32);
            for c in &m.cullers {
                put_str(&mut p, &c.name)?;
                for v in [c.hidden, c.only, c.ms, c.planes] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    for o in &doc.objects {
        put_u32(&mut p, o.triangles);
        for v in o.min.iter().chain(&o.max) {
            p.extend_from_slice(&v.to_le_bytes());
        }
    }
    for o in &doc.objects {
        put_str(&mut p, &o.name)?;
    }
    // Records first (to know their lengths), then the cell table that precedes them.
    let mut data = Vec::new();
    let mut table = Vec::with_capacity(doc.cells.len() * CELL_RECORD_LEN);
    let mut delta = vec![0u64; words];
    for (i, c) in doc.cells.iter().enumerate() {
        let set: &[u64] = if parent[i] == NO_PARENT {
            &sets[i]
        } else {
            for (d, (x, y)) in delta
                .iter_mut()
                .zip(sets[i].iter().zip(&sets[parent[i] as usize]))
            {
                *d = x ^ y;
            }
            &delta
        };
        let sz = sizes(set, objects);
        // Smallest wins; ties prefer the bitset, then the list (both decode fastest).
        let enc = [ENC_BITSET, ENC_LIST, ENC_RUNS]
            .into_iter()
            .min_by_key(|&e| sz[e as usize])
            .unwrap_or(ENC_BITSET);
        let start = data.len();
        put_record(&mut data, set, objects, enc);
        let len = u32::try_from(data.len() - start)
            .map_err(|_| EncodeError::RecordTooLarge { cell: i })?;
        for v in c.min.iter().chain(&c.max) {
            table.extend_from_slice(&v.to_le_bytes());
        }
        put_u32(&mut table, parent[i]);
        put_u32(&mut table, c.visible.len() as u32);
        put_u32(&mut table, len);
        table.extend_from_slice(&[enc, 0, 0, 0]);
    }
    p.extend_from_slice(&table);
    for c in &doc.cells {
        p.extend_from_slice(&c.ms.to_le_bytes());
    }
    put_u32(
        &mut p,
        u32::try_from(data.len()).map_err(|_| EncodeError::DataTooLarge)?,
    );
    p.extend_from_slice(&data);
    let hierarchy = doc.cells.iter().any(|c| c.parent.is_some());
    let d = crate::settings::BakeSettings::default_settings();
    let b = &doc.settings.bake;
    let culling = b.occluder_min_solid_angle != 0.0
        || b.rsf_resolution != d.rsf_resolution
        || b.up != d.up
        || b.alpha_cards != d.alpha_cards
        || b.alpha_mips != d.alpha_mips
        || b.alpha_card_polygons != d.alpha_card_polygons
        || b.alpha_missing != d.alpha_missing;
    let version = if doc.split.is_some() || hierarchy || culling {
        // Version 6: tagged extension sections.
        let mut sections: Vec<(u32, Vec<u8>)> = Vec::new();
        if let Some(shard) = shard {
            sections.push((TAG_SHARD, shard.as_bytes().to_vec()));
        }
        if let Some(split) = &doc.split {
            sections.push((TAG_SPLIT, encode_split(split, objects)?));
        }
        if hierarchy {
            sections.push((TAG_HIERARCHY, encode_hierarchy(doc, cells)?));
        }
        if culling {
            let mut c = b.occluder_min_solid_angle.to_le_bytes().to_vec();
            put_u32(&mut c, b.rsf_resolution);
            c.push(b.up.index() as u8);
            c.push(match b.alpha_cards {
                crate::settings::AlphaCards::Coverage => 0,
                crate::settings::AlphaCards::Ignore => 1,
            });
            put_u32(&mut c, b.alpha_mips);
            put_u32(&mut c, b.alpha_card_polygons);
            c.push(match b.alpha_missing {
                crate::settings::AlphaMissing::Error => 0,
                crate::settings::AlphaMissing::Transparent => 1,
            });
            sections.push((TAG_CULLING, c));
        }
        put_u32(&mut p, sections.len() as u32);
        for (tag, bytes) in sections {
            put_u32(&mut p, tag);
            put_u32(
                &mut p,
                u32::try_from(bytes.len()).map_err(|_| EncodeError::DataTooLarge)?,
            );
            p.extend_from_slice(&bytes);
        }
        EXTENDED_FORMAT_VERSION
    } else if let Some(shard) = shard {
        put_str(&mut p, shard)?;
        SHARD_FORMAT_VERSION
    } else {
        FORMAT_VERSION
    };

    let mut out = Vec::with_capacity(HEADER_LEN + p.len());
    out.extend_from_slice(&MAGIC);
    put_u32(&mut out, version);
    put_u32(&mut out, crc32(&p));
    out.extend_from_slice(&(p.len() as u64).to_le_bytes());
    out.extend_from_slice(&p);
    Ok(out)
}

/// The split section: the cluster size, then per object of the file its name, triangle
/// count, bounds and range of clusters (which must follow each other and cover the objects).
fn encode_split(split: &super::PvsSplit, objects: u32) -> Result<Vec<u8>, EncodeError> {
    let mut b = Vec::new();
    b.extend_from_slice(&split.size.to_le_bytes());
    put_u32(&mut b, split.sources.len() as u32);
    let mut next = 0u32;
    for (i, s) in split.sources.iter().enumerate() {
        if s.id as usize != i || s.first != next {
            return Err(EncodeError::BadSplit {
                index: i,
                why: format!("its clusters start at {}, expected {next}", s.first),
            });
        }
        next = s.first.saturating_add(s.count);
        put_str(&mut b, &s.name)?;
        put_u32(&mut b, s.triangles);
        for v in s.min.iter().chain(&s.max) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        put_u32(&mut b, s.first);
        put_u32(&mut b, s.count);
    }
    if next != objects {
        return Err(EncodeError::BadSplit {
            index: split.sources.len(),
            why: format!("the clusters cover {next} objects, the PVS has {objects}"),
        });
    }
    Ok(b)
}

/// The hierarchy section: the subdivision settings, then per cell the cell it is a half of
/// (an earlier cell) or `0xFFFFFFFF`.
fn encode_hierarchy(doc: &PvsDocument, cells: u32) -> Result<Vec<u8>, EncodeError> {
    let mut b = Vec::with_capacity(16 + 4 * cells as usize);
    let s = &doc.settings.bake;
    b.extend_from_slice(&s.max_pvs_triangles.unwrap_or(0).to_le_bytes());
    b.extend_from_slice(&s.min_cell_size.unwrap_or(0.0).to_le_bytes());
    for (i, c) in doc.cells.iter().enumerate() {
        match c.parent {
            None => put_u32(&mut b, NO_PARENT),
            Some(p) if (p as usize) < i => put_u32(&mut b, p),
            Some(p) => return Err(EncodeError::BadParent { cell: i, parent: p }),
        }
    }
    Ok(b)
}

/// Writes `doc` as a binary `.pvs` file, atomically (temporary file, then rename).
///
/// # Errors
/// A [`PvsWriteError`] naming the file: [`PvsWriteErrorKind::Encode`] for a document the
/// format cannot hold (see [`encode`]; nothing is written), [`PvsWriteErrorKind::Io`] when
/// the file cannot be written.
#[cfg(feature = "bake")]
pub fn write(path: &Path, doc: &PvsDocument) -> Result<(), PvsWriteError> {
    let bytes = encode(doc).map_err(|e| PvsWriteError {
        path: path.to_path_buf(),
        kind: PvsWriteErrorKind::Encode(e),
    })?;
    crate::util::write_atomic(path, &bytes).map_err(|m| PvsWriteError::io(path, m.to_string()))
}

/// Writes a shard's `.pvs` file ([`encode_shard`]), atomically.
///
/// # Errors
/// As [`write()`].
#[cfg(feature = "bake")]
pub fn write_shard(path: &Path, doc: &PvsDocument, shard: &str) -> Result<(), PvsWriteError> {
    let bytes = encode_shard(doc, shard).map_err(|e| PvsWriteError {
        path: path.to_path_buf(),
        kind: PvsWriteErrorKind::Encode(e),
    })?;
    crate::util::write_atomic(path, &bytes).map_err(|m| PvsWriteError::io(path, m.to_string()))
}

/// Reads a `.pvs` file back into the document `bake -o OUT.json` would have written.
///
/// # Errors
/// Any [`PvsError`] of [`PvsDatabase::open`], naming the file.
pub fn read(path: &std::path::Path) -> Result<PvsDocument, PvsError> {
    PvsDatabase::open(path).map(|db| db.to_document())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_are_maximal() {
        let mut bits = vec![0u64; 3];
        for i in (3..70).chain(100..101).chain(127..130) {
            bits[i / 64] |= 1 << (i % 64);
        }
        let mut runs = Vec::new();
        for_each_run(&bits, |s, l| runs.push((s, l)));
        assert_eq!(runs, vec![(3, 67), (100, 1), (127, 3)]);
        bits = vec![u64::MAX; 2];
        runs.clear();
        for_each_run(&bits, |s, l| runs.push((s, l)));
        assert_eq!(runs, vec![(0, 128)]);
    }
}
