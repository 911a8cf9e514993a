//! Shards (`bake --shard i/N`) and their merge (`umbrasweep merge`): a deterministic subset
//! of the cells per shard, a shard file that holds its cells' full results, and the merge
//! that checks the shards belong together and rebuilds the document one bake of all cells
//! would have written.
//!
//! Shard `i` of `N` bakes the cells `i, i + N, i + 2N, …` (interleaved, so that neighbouring
//! cells — which cost about the same — spread over the shards). The shard file is JSON:
//! `{"format": "umbrasweep-shard", "version": 1, "inputs": HASH, "index": i, "count": N,
//! "cells_total": C, "cell_indices": […], "document": {the PVS document of its cells},
//! "bake": {the bake's outcome, `BakeResult`, with every cell's result}}`. `inputs` is
//! [`super::inputs_hash`] of the scene, all cells, the settings and the backend: shards of
//! different bakes are refused.

use super::{BakeResult, BakeSettings, CellResult, document};
use crate::geom::Aabb;
use crate::pvs::PvsDocument;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The `format` of a shard file.
pub const SHARD_FORMAT: &str = "umbrasweep-shard";
/// The shard file's version.
pub const SHARD_VERSION: u32 = 1;

/// Which shard of how many (`--shard i/N`, `i` from 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShardSpec {
    /// This shard, `0 ≤ index < count`.
    pub index: usize,
    /// The number of shards.
    pub count: usize,
}

impl std::str::FromStr for ShardSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || {
            format!(
                "--shard {s:?}: expected I/N with 0 ≤ I < N (e.g. 0/4; Slurm: \
                 $SLURM_ARRAY_TASK_ID/N with --array=0-(N-1))"
            )
        };
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(ShardSpec { index, count })
    }
}

impl std::fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl ShardSpec {
    /// The cells of this shard among `total`: `index, index + count, …`.
    pub fn cells(&self, total: usize) -> Vec<usize> {
        (self.index..total).step_by(self.count).collect()
    }
}

/// A shard's output file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShardFile {
    /// [`SHARD_FORMAT`].
    pub format: String,
    /// [`SHARD_VERSION`].
    pub version: u32,
    /// The bake's inputs hash (scene, all cells, settings, backend).
    pub inputs: String,
    /// This shard.
    pub index: usize,
    /// The number of shards.
    pub count: usize,
    /// Cells of the whole bake.
    pub cells_total: usize,
    /// The cells this shard baked (indices into the whole bake's cells).
    pub cell_indices: Vec<usize>,
    /// The PVS document of this shard's cells alone.
    pub document: PvsDocument,
    /// The shard's bake: its outcome and its cells' full results, in the order of
    /// `cell_indices`.
    pub bake: BakeResult,
}

impl ShardFile {
    /// The shard file of shard `spec` of a bake of `cells_total` cells: `document` is the PVS
    /// document of its cells, `result` their bake (cells in the order of `spec.cells`).
    pub fn new(
        spec: ShardSpec,
        inputs: String,
        cells_total: usize,
        document: PvsDocument,
        result: &BakeResult,
    ) -> ShardFile {
        ShardFile {
            format: SHARD_FORMAT.into(),
            version: SHARD_VERSION,
            inputs,
            index: spec.index,
            count: spec.count,
            cells_total,
            cell_indices: spec.cells(cells_total),
            document,
            bake: result.clone(),
        }
    }
}

/// Why shards could not be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// No shard given.
    #[error("no shard files given")]
    Empty,
    /// A file is not a shard, or is inconsistent in itself.
    #[error("{path}: {message}")]
    Invalid {
        /// The shard file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Two shards of different bakes.
    #[error(
        "{path}: belongs to another bake than {first} ({what} differ); merge only the shards of \
         one `bake --shard` run"
    )]
    Mismatch {
        /// The shard that differs.
        path: PathBuf,
        /// The first shard given.
        first: PathBuf,
        /// What differs.
        what: String,
    },
    /// Some shards are missing or given twice.
    #[error("{0}")]
    Incomplete(String),
}

/// Merges the shard files `shards` (path, contents) of one bake into the PVS document one
/// bake of all its cells writes (identical, timings aside: the total seconds are the
/// shards' sum).
///
/// # Errors
/// No shard, a file that is not a consistent shard, shards of different bakes, missing or
/// duplicated shards.
pub fn merge(shards: &[(PathBuf, ShardFile)]) -> Result<PvsDocument, MergeError> {
    let (first_path, first) = shards.first().ok_or(MergeError::Empty)?;
    for (path, s) in shards {
        let invalid = |message: String| MergeError::Invalid {
            path: path.clone(),
            message,
        };
        if s.format != SHARD_FORMAT {
            return Err(invalid(format!(
                "format {:?} is not a shard ({SHARD_FORMAT:?}): write shards with `bake --shard I/N`",
                s.format
            )));
        }
        if s.version != SHARD_VERSION {
            return Err(invalid(format!(
                "shard version {} (this build reads {SHARD_VERSION})",
                s.version
            )));
        }
        if s.count == 0 || s.index >= s.count {
            return Err(invalid(format!(
                "shard {}/{} is out of range",
                s.index, s.count
            )));
        }
        let spec = ShardSpec {
            index: s.index,
            count: s.count,
        };
        if s.cell_indices != spec.cells(s.cells_total)
            || s.bake.cells.len() != s.cell_indices.len()
            || s.document.cells.len() != s.cell_indices.len()
        {
            return Err(invalid(format!(
                "its cells do not match shard {spec} of {} cells",
                s.cells_total
            )));
        }
        let mismatch = |what: &str| MergeError::Mismatch {
            path: path.clone(),
            first: first_path.clone(),
            what: what.into(),
        };
        if s.inputs != first.inputs {
            return Err(mismatch("the scene, cells, settings or backend"));
        }
        if s.count != first.count || s.cells_total != first.cells_total {
            return Err(mismatch("the shard count or cell count"));
        }
    }
    let n = first.count;
    let mut seen: Vec<Vec<&PathBuf>> = vec![Vec::new(); n];
    for (path, s) in shards {
        seen[s.index].push(path);
    }
    let missing: Vec<String> = (0..n)
        .filter(|&i| seen[i].is_empty())
        .map(|i| format!("{i}/{n}"))
        .collect();
    let twice: Vec<String> = (0..n)
        .filter(|&i| seen[i].len() > 1)
        .map(|i| {
            let files: Vec<String> = seen[i].iter().map(|p| p.display().to_string()).collect();
            format!("{i}/{n} ({})", files.join(", "))
        })
        .collect();
    if !missing.is_empty() || !twice.is_empty() {
        let mut msg = String::new();
        if !missing.is_empty() {
            msg += &format!("missing shards: {}", missing.join(", "));
        }
        if !twice.is_empty() {
            if !msg.is_empty() {
                msg += "; ";
            }
            msg += &format!("shards given twice: {}", twice.join("; "));
        }
        return Err(MergeError::Incomplete(msg));
    }
    let total = first.cells_total;
    let mut results: Vec<Option<CellResult>> = vec![None; total];
    let mut boxes: Vec<Aabb> = vec![Aabb::EMPTY; total];
    let mut seconds = 0.0;
    for (_, s) in shards {
        seconds += s.bake.seconds;
        for (k, &ci) in s.cell_indices.iter().enumerate() {
            results[ci] = Some(s.bake.cells[k].clone());
            let c = &s.document.cells[k];
            boxes[ci] = Aabb {
                min: c.min.into(),
                max: c.max.into(),
            };
        }
    }
    let result = BakeResult {
        cells: results
            .into_iter()
            .map(|r| r.expect("every cell is in one shard"))
            .collect(),
        seconds,
        ..first.bake.clone()
    };
    let d = &first.document;
    let triangles = d.summary.as_ref().map_or_else(
        || d.objects.iter().map(|o| o.triangles as usize).sum(),
        |s| s.triangles,
    );
    let settings: BakeSettings = d.settings.bake.clone();
    let mut doc = document(
        d.scene.clone(),
        d.objects.clone(),
        triangles,
        &boxes,
        &result,
        &settings,
    );
    doc.split = d.split.clone();
    Ok(doc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bake's outcome reads back with its culler names as the pipeline's; an unknown name
    /// is refused.
    #[test]
    fn bake_results_round_trip_and_unknown_cullers_are_refused() {
        let r = BakeResult {
            cells: Vec::new(),
            backend: "cpu".into(),
            adapter: None,
            occluder_triangles: 3,
            cards: None,
            degenerate_triangles: 0,
            seconds: 0.5,
            sweep: true,
            sweep_reason: "why".into(),
            rsf: false,
            rsf_reason: "off".into(),
            sampling: false,
            sampling_reason: "off".into(),
            sampling_device: None,
            notes: Vec::new(),
            cullers: vec!["occlusion_sweep"],
        };
        let json = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<BakeResult>(&json).unwrap(), r);
        let bad = json.replace("occlusion_sweep", "mystery");
        let e = serde_json::from_str::<BakeResult>(&bad).unwrap_err();
        assert!(e.to_string().contains("unknown culler \"mystery\""), "{e}");
    }

    #[test]
    fn shard_specs_parse_and_split_cells() {
        let s: ShardSpec = "1/3".parse().unwrap();
        assert_eq!(s, ShardSpec { index: 1, count: 3 });
        assert_eq!(s.cells(8), vec![1, 4, 7]);
        assert_eq!("0/1".parse::<ShardSpec>().unwrap().cells(3), vec![0, 1, 2]);
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2", "1/2/3"] {
            let e = bad.parse::<ShardSpec>().unwrap_err();
            assert!(e.contains("expected I/N"), "{bad}: {e}");
        }
        // Every cell in exactly one shard.
        let mut all: Vec<usize> = (0..5)
            .flat_map(|i| ShardSpec { index: i, count: 5 }.cells(23))
            .collect();
        all.sort_unstable();
        assert_eq!(all, (0..23).collect::<Vec<_>>());
    }
}
