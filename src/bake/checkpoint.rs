//! Sampler checkpoints: the shrunk-occluder sampler's progress inside one cell saved to a file
//! beside the output, so that `bake --resume` continues a cell that takes hours (the fine
//! forest's 4×2×4 cells) from its last saved chunk of rectangles instead of from scratch. The
//! journal (`journal.rs`) only records finished cells.
//!
//! **What is saved.** The sampler samples a level's rectangles in chunks, each chunk's lanes
//! starting from what was known visible when the chunk began (`bake::sampling`), so a chunk
//! boundary is a clean cut: the file holds, per level, every finished rectangle's outcome
//! (the objects it left undecided, in order, and what it counted: objects tested and hidden,
//! its sample point, polygons drawn), the level's probe decision and cost-curve entry once
//! made, the objects known visible at the cut, and the seconds spent. A resumed cell runs the
//! same control flow and replays each recorded chunk instead of rendering it, so it reaches
//! the cut with the same rectangles, lists, counters and known-visible set as the
//! interrupted one, and the PVS comes out the same as an uninterrupted bake's (the tests
//! compare them byte for byte with `--reproducible`).
//!
//! **When it is used.** Only with `--resume`, and only a file whose inputs (the journal's
//! hash of scene, cells and settings), cell and finest ε match; anything else is replaced.
//! The finest ε fixes the cell's rectangles (every level's grid is cut from it), so a file
//! written by a build that laid the cell out otherwise (version 1 files, before a cell's
//! finest ε could differ from the settings') is never replayed onto other rectangles: its
//! outcomes would stand for points the new rectangles do not hold. Files are
//! written to a temporary name and renamed, at most every `every_seconds` (after a chunk
//! ends), and removed when their cell is finished.
//!
//! Format: JSON, `{"format": "umbrasweep-sampler-checkpoint", "version": 4, "inputs": …,
//! "cell": [min, max], "finest_eps": …, "seconds": …, "known": "<hex bits per object>",
//! "levels": [{"probe_only": …, "probe_rounds": …, "probe_cell": [hidden, tested], "pilot": [cost,
//! saving], "curve": …, "rects": {"<index>": {"open": [ids] | null, "tested": …, "hid": …,
//! "point": …, "polygons": …}}}]}` (`pilot` only where the level's pilot ran: a resumed level
//! takes its decision and figures; `probe_rounds` only where a probe went on after a round;
//! `probe_cell` with the probe's decision: what it proved of the objects still undecided, which
//! a run resumed after the probe would count against the cut's known set, not the probe's).
//! Version 3 (December 7): a level's probe runs in rounds and may stop early, so version 2
//! files, whose probes ran whole, are not resumed. Version 4 (December 7, later): a level is
//! split into at most four rectangles per point the budget has left (`bake::sampling`), so a
//! version 3 file may index a longer level than the one it would be replayed onto. Numbers are read back to the bits written
//! (serde_json's `float_roundtrip`): the finest ε is compared bit for bit and the finished
//! levels' cost-curve entries are copied into the PVS document.

use super::BakeError;
use crate::geom::Aabb;
use crate::pvs::SamplingLevel;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::Instant;

/// The first field of a checkpoint file.
pub const CHECKPOINT_FORMAT: &str = "umbrasweep-sampler-checkpoint";
/// The checkpoint format's version.
pub const CHECKPOINT_VERSION: u32 = 4;

/// Where and how often the sampler saves its progress inside a cell
/// ([`super::BakeHooks::sampler_checkpoints`]).
#[derive(Debug)]
pub struct SamplerCheckpoints {
    /// Files are `<base>.sampler-<16 hex digits naming the cell>` (the bake's output path).
    pub base: PathBuf,
    /// The bake's inputs ([`super::inputs_hash`]): a file with others is not resumed.
    pub inputs: String,
    /// Resume from the files found (`--resume`); otherwise they are replaced.
    pub resume: bool,
    /// Seconds at least between two writes of one cell's file (0: after every chunk).
    pub every_seconds: f64,
    /// Tests only: the cell fails with [`BakeError::Interrupted`] right after this many
    /// writes of its file, as if the bake had been killed there.
    #[doc(hidden)]
    pub stop_after_writes: Option<u32>,
    /// Rectangles replayed from files instead of rendered, over the bake.
    pub replayed: AtomicU64,
    /// Keep each cell's file when the cell finishes, complete, instead of removing it
    /// ([`Self::kept`]): a later run with `resume` replays the whole cell. `bench
    /// --checkpoint-dir` keeps them, so that a rerun of a killed bench redoes no finished
    /// sampler row.
    pub keep: bool,
}

impl SamplerCheckpoints {
    /// Checkpoints beside `output` for a bake of `inputs`, written at most every
    /// `every_seconds`.
    pub fn new(output: &Path, inputs: &str, resume: bool, every_seconds: f64) -> Self {
        SamplerCheckpoints {
            base: output.to_path_buf(),
            inputs: inputs.to_string(),
            resume,
            every_seconds,
            stop_after_writes: None,
            replayed: AtomicU64::new(0),
            keep: false,
        }
    }

    /// The same, keeping each finished cell's file ([`Self::keep`]).
    #[must_use]
    pub fn kept(mut self) -> Self {
        self.keep = true;
        self
    }

    /// The file of the cell whose sampler seed is `key`.
    pub fn path(&self, key: u64) -> PathBuf {
        let mut name = self.base.as_os_str().to_owned();
        name.push(format!(".sampler-{key:016x}"));
        PathBuf::from(name)
    }
}

/// One finished rectangle: what `Shared::patch` returned and counted.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(super) struct RectRecord {
    /// The objects left undecided for its quadrants, in order (`None`: nothing to refine).
    pub open: Option<Vec<u32>>,
    /// Objects it tested and those it proved hidden.
    pub tested: u64,
    pub hid: u64,
    /// Whether it took a sample point.
    pub point: bool,
    /// Polygons drawn.
    pub polygons: u64,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// One level's records.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub(super) struct LevelRecord {
    /// The probe's decision, once made.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_only: Option<bool>,
    /// How many of the probe's rounds were followed by another (`bake::sampling`: a probe
    /// stops early once its rest could prove nothing): a resumed probe goes on after as many
    /// without asking again, since the objects known visible then are not in the file.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub probe_rounds: u32,
    /// The probe's count of the objects still undecided that it tested and of those every
    /// probed rectangle hid (`SamplingLevel::probe_objects`, `probe_cell_hidden`), recorded
    /// with the decision: a resumed run counts after a later file's known objects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_cell: Option<(u32, u32)>,
    /// The pilot's estimates per rectangle (cost, saving), when one ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pilot: Option<(f64, f64)>,
    /// The level's cost-curve entry, once the level is finished.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curve: Option<SamplingLevel>,
    /// Finished rectangles by their index in the level.
    pub rects: BTreeMap<u32, RectRecord>,
}

#[derive(Debug, Serialize, Deserialize)]
struct CheckpointFile {
    format: String,
    version: u32,
    inputs: String,
    cell: [[f32; 3]; 2],
    /// The cell's finest ε, which fixes its rectangles.
    finest_eps: f64,
    seconds: f64,
    known: String,
    levels: Vec<LevelRecord>,
}

/// One cell's checkpoint while the sampler runs: the records loaded (if resumed) and those
/// made since.
pub(super) struct CellCheckpoint<'a> {
    spec: &'a SamplerCheckpoints,
    path: PathBuf,
    cell: [[f32; 3]; 2],
    finest_eps: f64,
    levels: Mutex<Vec<LevelRecord>>,
    last_write: Mutex<Instant>,
    writes: AtomicU32,
}

/// What a resumed cell starts from.
pub(super) struct Resumed {
    /// Seconds the interrupted runs spent.
    pub seconds: f64,
    /// Objects known visible at the cut.
    pub known: Vec<bool>,
}

impl<'a> CellCheckpoint<'a> {
    /// The checkpoint of `cell` (sampler seed `key`, `objects` scene objects, finest ε
    /// `finest_eps`): with `--resume` and a matching file, what it recorded.
    pub fn open(
        spec: &'a SamplerCheckpoints,
        cell: &Aabb,
        key: u64,
        objects: usize,
        finest_eps: f64,
    ) -> (Self, Option<Resumed>) {
        let path = spec.path(key);
        let cell = [cell.min.to_array(), cell.max.to_array()];
        let loaded = spec
            .resume
            .then(|| std::fs::read(&path).ok())
            .flatten()
            .and_then(|bytes| serde_json::from_slice::<CheckpointFile>(&bytes).ok())
            .filter(|f| {
                f.format == CHECKPOINT_FORMAT
                    && f.version == CHECKPOINT_VERSION
                    && f.inputs == spec.inputs
                    && f.finest_eps.to_bits() == finest_eps.to_bits()
                    && f.cell
                        .iter()
                        .flatten()
                        .map(|v| v.to_bits())
                        .eq(cell.iter().flatten().map(|v| v.to_bits()))
            })
            .and_then(|f| {
                let known = from_hex(&f.known, objects)?;
                Some((
                    f.levels,
                    Resumed {
                        seconds: f.seconds,
                        known,
                    },
                ))
            });
        let (levels, resumed) = match loaded {
            Some((l, r)) => (l, Some(r)),
            None => (Vec::new(), None),
        };
        (
            CellCheckpoint {
                spec,
                path,
                cell,
                finest_eps,
                levels: Mutex::new(levels),
                last_write: Mutex::new(Instant::now()),
                writes: AtomicU32::new(0),
            },
            resumed,
        )
    }

    /// Runs `f` on level `level`'s records (made empty when new).
    pub fn with_level<T>(&self, level: usize, f: impl FnOnce(&mut LevelRecord) -> T) -> T {
        let mut l = self.levels.lock().unwrap_or_else(|e| e.into_inner());
        if l.len() <= level {
            l.resize_with(level + 1, LevelRecord::default);
        }
        f(&mut l[level])
    }

    /// The records of every rectangle of `chunk` (indices into level `level`), when all were
    /// recorded; the chunk is then replayed instead of sampled.
    pub fn replay(&self, level: usize, chunk: &[usize]) -> Option<Vec<RectRecord>> {
        self.with_level(level, |l| {
            chunk
                .iter()
                .map(|&i| l.rects.get(&(i as u32)).cloned())
                .collect::<Option<Vec<RectRecord>>>()
        })
        .inspect(|r| {
            self.spec
                .replayed
                .fetch_add(r.len() as u64, Ordering::Relaxed);
        })
    }

    /// Records a finished chunk of level `level`, then writes the file when `every_seconds`
    /// have passed since the last write (`known`: the objects known visible now; `seconds`:
    /// the sampling's seconds so far). Returns whether the cell must stop here (tests).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn record(
        &self,
        level: usize,
        rects: impl IntoIterator<Item = (usize, RectRecord)>,
        known: impl FnOnce() -> Vec<bool>,
        seconds: f64,
    ) -> Result<bool, BakeError> {
        self.with_level(level, |l| {
            l.rects
                .extend(rects.into_iter().map(|(i, r)| (i as u32, r)));
        });
        let mut last = self.last_write.lock().unwrap_or_else(|e| e.into_inner());
        if last.elapsed().as_secs_f64() < self.spec.every_seconds {
            return Ok(false);
        }
        self.write(known, seconds)?;
        *last = Instant::now();
        let n = self.writes.fetch_add(1, Ordering::Relaxed) + 1;
        Ok(self.spec.stop_after_writes.is_some_and(|s| n >= s))
    }

    /// Writes the file now (atomically: a temporary file, then a rename).
    fn write(&self, known: impl FnOnce() -> Vec<bool>, seconds: f64) -> Result<(), BakeError> {
        let file = CheckpointFile {
            format: CHECKPOINT_FORMAT.into(),
            version: CHECKPOINT_VERSION,
            inputs: self.spec.inputs.clone(),
            cell: self.cell,
            finest_eps: self.finest_eps,
            seconds,
            known: to_hex(&known()),
            levels: self
                .levels
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone(),
        };
        let bytes = serde_json::to_vec(&file).expect("a checkpoint serialises");
        crate::util::write_atomic(&self.path, &bytes).map_err(BakeError::Checkpoint)
    }

    /// The cell is finished: its file is removed, or, when [`SamplerCheckpoints::keep`],
    /// written complete (every rectangle, `known` the objects known visible at the end).
    ///
    /// # Errors
    /// A kept file cannot be written.
    pub fn finish(&self, known: impl FnOnce() -> Vec<bool>, seconds: f64) -> Result<(), BakeError> {
        if self.spec.keep {
            return self.write(known, seconds);
        }
        let _ = std::fs::remove_file(&self.path);
        Ok(())
    }
}

/// `bits` as hex digits, four bits per digit, the first bit in the lowest bit of the first.
fn to_hex(bits: &[bool]) -> String {
    bits.chunks(4)
        .map(|c| {
            let v = c
                .iter()
                .enumerate()
                .fold(0u32, |v, (k, &b)| v | (u32::from(b) << k));
            char::from_digit(v, 16).expect("a nibble")
        })
        .collect()
}

/// [`to_hex`] read back as `n` bits; `None` when it does not hold exactly that many.
fn from_hex(s: &str, n: usize) -> Option<Vec<bool>> {
    if s.len() != n.div_ceil(4) {
        return None;
    }
    let mut bits = Vec::with_capacity(n);
    for c in s.chars() {
        let v = c.to_digit(16)?;
        for k in 0..4 {
            if bits.len() < n {
                bits.push(v >> k & 1 == 1);
            }
        }
    }
    Some(bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_bits_round_trip_and_refuse_the_wrong_length() {
        for n in [0usize, 1, 4, 5, 13] {
            let bits: Vec<bool> = (0..n).map(|i| i % 3 == 1).collect();
            let h = to_hex(&bits);
            assert_eq!(h.len(), n.div_ceil(4));
            assert_eq!(from_hex(&h, n), Some(bits));
        }
        assert_eq!(from_hex("f", 5), None);
        assert_eq!(from_hex("g", 4), None);
    }

    /// A checkpoint's numbers read back to the same bits: a resumed cell compares its finest
    /// ε bit by bit and copies the finished levels' cost-curve entries into the PVS document,
    /// so a number read back one unit in the last place off would refuse the file or change
    /// the document's bytes. serde_json's default parser was off by one unit for the level ε
    /// 0.11785113019775803 (`float_roundtrip` fixes that); also 20,000 random finite numbers.
    #[test]
    fn numbers_read_back_to_the_same_bits() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut values = vec![0.11785113019775803, 0.05 / 2f64.sqrt(), 1e-300, 5e-324];
        while values.len() < 20_000 {
            let v = f64::from_bits(rng.random());
            if v.is_finite() {
                values.push(v);
            }
        }
        for v in values {
            let level = LevelRecord {
                pilot: Some((v, -v)),
                curve: Some(SamplingLevel {
                    eps: v,
                    ..SamplingLevel::default()
                }),
                ..LevelRecord::default()
            };
            let file = CheckpointFile {
                format: CHECKPOINT_FORMAT.into(),
                version: CHECKPOINT_VERSION,
                inputs: String::new(),
                cell: [[0.0; 3]; 2],
                finest_eps: v,
                seconds: v,
                known: String::new(),
                levels: vec![level.clone()],
            };
            let back: CheckpointFile =
                serde_json::from_slice(&serde_json::to_vec(&file).unwrap()).unwrap();
            assert_eq!(back.finest_eps.to_bits(), v.to_bits(), "{v:e}");
            assert_eq!(back.seconds.to_bits(), v.to_bits(), "{v:e}");
            let curve = back.levels[0].curve.as_ref().unwrap();
            assert_eq!(curve.eps.to_bits(), v.to_bits(), "{v:e}");
            assert_eq!(
                back.levels[0].pilot.map(|p| p.0.to_bits()),
                Some(v.to_bits())
            );
        }
    }
}
