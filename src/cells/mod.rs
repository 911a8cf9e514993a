//! View cells: boxes the camera may be anywhere inside. Read from a JSON file
//! (`{"cells": [{"min": [x,y,z], "max": [x,y,z]}, …]}`) or laid out as a regular grid.

pub mod auto;

pub use auto::{AutoCellOptions, AutoCellStats, AutoCells, CellClass, auto_cells};

use crate::geom::Aabb;
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors for cell input; each names the file or option at fault.
#[derive(Debug, thiserror::Error)]
pub enum CellError {
    /// The cells file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The cells file is not JSON of the cells-file shape; `message` is the parser's.
    #[error(
        "{path}: not a cells file: {message} (expected {{\"cells\": [{{\"min\": [x,y,z], \"max\": [x,y,z]}}, …]}})"
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// The JSON parser's message.
        message: String,
    },
    /// Cell `index` (0-based) of `origin` (a file or option) is not a valid box.
    #[error("{origin}: cell {index}: {message}")]
    BadCell {
        /// The file or option the cell came from.
        origin: String,
        /// The cell's position in its list, 0-based.
        index: usize,
        /// What is wrong with it.
        message: String,
    },
    /// A cell grid option is invalid (the message names the option and the fault).
    #[error("{0}")]
    BadGrid(String),
    /// A cells file could not be written (the message names it).
    #[error(transparent)]
    Write(#[from] crate::util::WriteError),
}

/// The cells file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CellsFile {
    /// The cells, in bake order (cell `i` of the PVS is entry `i`).
    pub cells: Vec<CellBox>,
}

/// One cell as written in a cells file. Coordinates are read in `f64` and rounded outward to
/// the `f32` cell that is baked; a cell made from an `f32` box is written with its exact
/// values, so it reads back unchanged.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct CellBox {
    /// Lower corner, in scene units.
    pub min: [f64; 3],
    /// Upper corner, in scene units (`max >= min` on every axis).
    pub max: [f64; 3],
}

impl From<Aabb> for CellBox {
    fn from(b: Aabb) -> Self {
        CellBox {
            min: b.min.as_dvec3().to_array(),
            max: b.max.as_dvec3().to_array(),
        }
    }
}

/// Checks that every cell is finite with positive extent on each axis.
///
/// # Errors
/// [`CellError::BadCell`] for the first inverted, flat or non-finite cell.
pub fn check(cells: &[Aabb], origin: &str) -> Result<(), CellError> {
    for (index, c) in cells.iter().enumerate() {
        let bad = |message: String| CellError::BadCell {
            origin: origin.to_string(),
            index,
            message,
        };
        if !c.min.is_finite() || !c.max.is_finite() {
            return Err(bad("coordinates must be finite numbers".into()));
        }
        if c.min.cmpge(c.max).any() {
            return Err(bad(format!(
                "min {:?} must be below max {:?} on every axis (the cell is inverted or has zero volume)",
                c.min.to_array(),
                c.max.to_array()
            )));
        }
    }
    Ok(())
}

/// Reads and checks a cells file.
///
/// # Errors
/// Unreadable file, malformed JSON, no cells, or a bad cell; the message names the file.
pub fn load_json(path: &Path) -> Result<Vec<Aabb>, CellError> {
    let text = std::fs::read_to_string(path).map_err(|source| CellError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_json(&text, path)
}

/// Parses and checks the text of a cells file; `path` names it in errors.
///
/// # Errors
/// Malformed JSON, no cells, or a bad cell; the message names `path`.
pub fn parse_json(text: &str, path: &Path) -> Result<Vec<Aabb>, CellError> {
    // Read in f64 and round each cell outward to f32: nearest rounding could bake a cell
    // slightly smaller than written (100000.003 read as 100000.0).
    let file: CellsFile = serde_json::from_str(text).map_err(|e| CellError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if file.cells.is_empty() {
        return Err(CellError::Parse {
            path: path.to_path_buf(),
            message: "the \"cells\" list is empty".into(),
        });
    }
    let cells: Vec<Aabb> = file
        .cells
        .iter()
        .map(|c| Aabb::outward(DVec3::from(c.min), DVec3::from(c.max)))
        .collect();
    check(&cells, &path.display().to_string())?;
    Ok(cells)
}

/// Writes a cells file atomically.
///
/// # Errors
/// I/O errors, with the path.
pub fn save_json(path: &Path, cells: &[Aabb]) -> Result<(), CellError> {
    let file = CellsFile {
        cells: cells.iter().map(|&c| c.into()).collect(),
    };
    // Plain numbers and lists: serialising cannot fail.
    let text = serde_json::to_string_pretty(&file).unwrap_or_default();
    Ok(crate::util::write_atomic(path, text.as_bytes())?)
}

/// A regular grid of `n[0] × n[1] × n[2]` cells filling `bounds`, x fastest, then y, then z.
///
/// # Errors
/// [`CellError::BadGrid`] when the box is inverted or flat, or a count is zero.
pub fn grid(bounds: Aabb, n: [u32; 3]) -> Result<Vec<Aabb>, CellError> {
    if n.contains(&0) {
        return Err(CellError::BadGrid(format!(
            "--grid-size {},{},{}: every count must be at least 1",
            n[0], n[1], n[2]
        )));
    }
    if !bounds.min.is_finite() || !bounds.max.is_finite() || bounds.min.cmpge(bounds.max).any() {
        return Err(CellError::BadGrid(format!(
            "--grid-box: min {:?} must be below max {:?} on every axis",
            bounds.min.to_array(),
            bounds.max.to_array()
        )));
    }
    let size = bounds.size() / Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32);
    let mut cells = Vec::with_capacity((n[0] * n[1] * n[2]) as usize);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let idx = Vec3::new(i as f32, j as f32, k as f32);
                let min = bounds.min + size * idx;
                // The last cell ends exactly on the box.
                let max = Vec3::new(
                    if i + 1 == n[0] {
                        bounds.max.x
                    } else {
                        bounds.min.x + size.x * (i + 1) as f32
                    },
                    if j + 1 == n[1] {
                        bounds.max.y
                    } else {
                        bounds.min.y + size.y * (j + 1) as f32
                    },
                    if k + 1 == n[2] {
                        bounds.max.z
                    } else {
                        bounds.min.z + size.z * (k + 1) as f32
                    },
                );
                cells.push(Aabb::new(min, max));
            }
        }
    }
    check(&cells, "--grid-box")?;
    Ok(cells)
}

/// Up to `count` cells of `size` at eye height in the free space of a scene: positions on a
/// seeded jittered grid over the scene's ground extent (the `up` axis is y), `height` above the
/// lowest point, kept when the cell overlaps no object's bounds except ground-like objects
/// (those spanning more than a quarter of the scene's ground area). For real scenes (a city's
/// streets) where no generator made cells. Deterministic for a seed.
pub fn free_cells(objects: &[Aabb], count: usize, size: Vec3, height: f32, seed: u64) -> Vec<Aabb> {
    let scene = objects
        .iter()
        .filter(|b| !b.is_empty())
        .fold(Aabb::EMPTY, |a, b| a.union(b));
    if scene.is_empty() || count == 0 {
        return Vec::new();
    }
    let ground_area = (scene.max.x - scene.min.x) * (scene.max.z - scene.min.z);
    let solid: Vec<&Aabb> = objects
        .iter()
        .filter(|b| !b.is_empty() && (b.max.x - b.min.x) * (b.max.z - b.min.z) < 0.25 * ground_area)
        .collect();
    // A fine jittered grid, visited in a seeded pseudo-random order.
    let n = 256usize;
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut order: Vec<usize> = (0..n * n).collect();
    for i in (1..order.len()).rev() {
        let j = (next() * (i + 1) as f64) as usize;
        order.swap(i, j.min(i));
    }
    let mut out = Vec::new();
    for k in order {
        let (i, j) = (k % n, k / n);
        let fx = (i as f64 + next()) / n as f64;
        let fz = (j as f64 + next()) / n as f64;
        let cx = scene.min.x + (scene.max.x - scene.min.x) * fx as f32;
        let cz = scene.min.z + (scene.max.z - scene.min.z) * fz as f32;
        let min = Vec3::new(cx - 0.5 * size.x, scene.min.y + height, cz - 0.5 * size.z);
        let cell = Aabb::new(min, min + size);
        // Keep a margin of half a cell around buildings.
        let probe = Aabb::new(cell.min - 0.5 * size, cell.max + 0.5 * size);
        if solid.iter().all(|b| !b.overlaps(&probe))
            && !out.iter().any(|c: &Aabb| c.overlaps(&probe))
        {
            out.push(cell);
            if out.len() == count {
                break;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_tiles_the_box_exactly() {
        let b = Aabb::new(Vec3::ZERO, Vec3::new(3.0, 1.0, 2.0));
        let cells = grid(b, [3, 1, 2]).unwrap();
        assert_eq!(cells.len(), 6);
        assert_eq!(cells[0].min, Vec3::ZERO);
        assert_eq!(cells[5].max, b.max);
        assert_eq!(cells[1].min.x, 1.0);
        assert_eq!(cells[3].min.z, 1.0);
    }

    #[test]
    fn free_cells_avoid_objects_and_are_deterministic() {
        let ground = Aabb::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(100.0, 0.1, 100.0));
        let block = Aabb::new(Vec3::new(30.0, 0.0, 30.0), Vec3::new(60.0, 30.0, 60.0));
        let objs = [ground, block];
        let a = free_cells(&objs, 20, Vec3::new(2.0, 2.0, 2.0), 1.0, 7);
        assert_eq!(a.len(), 20);
        assert_eq!(a, free_cells(&objs, 20, Vec3::new(2.0, 2.0, 2.0), 1.0, 7));
        for c in &a {
            assert!(!c.overlaps(&block));
            assert_eq!(c.min.y, 1.0);
        }
    }

    /// A cell written at a 1e5 offset is never read smaller than written (nearest rounding
    /// to f32 read 100000.003 as 100000.0 and 99999.996 as 100000.0).
    #[test]
    fn cells_files_are_rounded_outward_at_a_1e5_offset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cells.json");
        std::fs::write(
            &path,
            r#"{"cells":[{"min":[99999.996,-100000.003,0.1],"max":[100000.003,-99999.996,0.3]}]}"#,
        )
        .unwrap();
        let c = load_json(&path).unwrap()[0];
        let (min, max) = (c.min.as_dvec3(), c.max.as_dvec3());
        assert!(min.x <= 99999.996 && max.x >= 100000.003, "{c:?}");
        assert!(min.y <= -100000.003 && max.y >= -99999.996, "{c:?}");
        assert!(min.z <= 0.1 && max.z >= 0.3, "{c:?}");
        // One f32 step at most beyond what was written.
        assert!(
            max.x - 100000.003 < 0.0079 && 99999.996 - min.x < 0.0079,
            "{c:?}"
        );
    }

    /// Cells written by `save_json` (the generators' cells files) read back bit for bit.
    #[test]
    fn saved_cells_read_back_unchanged() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cells.json");
        let cells = vec![
            Aabb::new(
                Vec3::new(-22.392307, 0.1, 1e5),
                Vec3::new(-20.0, 0.3, 1e5 + 0.5),
            ),
            Aabb::new(Vec3::splat(-1.0 / 3.0), Vec3::splat(2.0 / 3.0)),
        ];
        save_json(&path, &cells).unwrap();
        assert_eq!(load_json(&path).unwrap(), cells);
    }

    #[test]
    fn inverted_and_flat_cells_are_refused() {
        let flat = [Aabb::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0))];
        assert!(check(&flat, "t").is_err());
        let inv = [Aabb::new(Vec3::ONE, Vec3::ZERO)];
        assert!(check(&inv, "t").is_err());
        assert!(grid(Aabb::new(Vec3::ZERO, Vec3::ONE), [0, 1, 1]).is_err());
    }
}
