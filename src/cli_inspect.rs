//! `umbrasweep inspect FILE.pvs`: a summary of a binary PVS file (cells, objects, average
//! PVS size, file size, compression against plain bitsets), one cell's objects with
//! `--cell N`, or with `--json` the same JSON document `bake -o OUT.json` writes.

use anyhow::{Context, bail};
use std::io::Write;
use std::path::PathBuf;
use umbrasweep::pvs::binary::{ENC_BITSET, ENC_LIST, ENC_RUNS};
use umbrasweep::pvs::{CellId, PvsDatabase};

/// Options of `umbrasweep inspect`.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:
  umbrasweep inspect city.pvs
  umbrasweep inspect city.pvs --cell 3
  umbrasweep inspect city.pvs --json > city.json")]
pub struct InspectArgs {
    /// The binary PVS file (`bake -o OUT.pvs`).
    pub file: PathBuf,
    /// List the objects cell N sees (id and name, one a line).
    #[arg(long, value_name = "N", conflicts_with = "json")]
    pub cell: Option<u32>,
    /// Print the PVS as the JSON document `bake -o OUT.json` writes, byte for byte.
    #[arg(long)]
    pub json: bool,
}

fn encoding_name(e: u8) -> &'static str {
    match e {
        ENC_BITSET => "bitset",
        ENC_RUNS => "runs",
        ENC_LIST => "list",
        _ => "unknown",
    }
}

/// Runs `umbrasweep inspect`.
///
/// # Errors
/// An unreadable or invalid file (bad magic, other version, truncated, checksum mismatch),
/// a cell out of range, or a failed write to standard output.
pub fn run(a: &InspectArgs) -> anyhow::Result<()> {
    let db = PvsDatabase::open(&a.file).map_err(anyhow::Error::msg)?;
    let mut out = std::io::stdout().lock();
    if a.json {
        let text = serde_json::to_vec_pretty(&db.to_document())?;
        out.write_all(&text).context("writing to standard output")?;
        return Ok(());
    }
    if let Some(n) = a.cell {
        if n as usize >= db.cell_count() {
            bail!(
                "{}: no cell {n} (the file has {} cells, 0 to {})",
                a.file.display(),
                db.cell_count(),
                db.cell_count().saturating_sub(1)
            );
        }
        let cell = CellId(n);
        let (min, max) = db.cell_bounds(cell);
        let rec = db.cell_record(cell);
        writeln!(out, "cell {n}: min {min:?} max {max:?}")?;
        if let Some(p) = db.cell_parent(cell) {
            writeln!(out, "a half of cell {}", p.0)?;
        }
        let halves: Vec<String> = db.cell_halves(cell).map(|h| h.0.to_string()).collect();
        if !halves.is_empty() {
            writeln!(out, "split into cells {}", halves.join(" and "))?;
        }
        writeln!(
            out,
            "stored as {} of {} bytes, {}; {} records to decode from scratch",
            encoding_name(rec.encoding),
            rec.bytes,
            match rec.parent {
                Some(p) => format!("difference from cell {p}"),
                None => "key cell (full set)".into(),
            },
            rec.depth
        )?;
        writeln!(
            out,
            "{} of {} objects visible:",
            db.visible_count(cell),
            db.object_count()
        )?;
        for id in db.visible(cell) {
            let name = db.object(id).map(|o| o.name).unwrap_or("?");
            writeln!(out, "{id}\t{name}")?;
        }
        return Ok(());
    }
    let s = db.stats();
    let pct = |a: usize, b: usize| {
        if b == 0 {
            0.0
        } else {
            100.0 * a as f64 / b as f64
        }
    };
    let ratio = |a: usize, b: usize| {
        if b == 0 {
            f64::INFINITY
        } else {
            a as f64 / b as f64
        }
    };
    writeln!(out, "file            {}", a.file.display())?;
    writeln!(out, "scene           {}", db.scene())?;
    let halves = (0..s.cells as u32)
        .filter(|&c| db.cell_parent(umbrasweep::pvs::CellId(c)).is_some())
        .count();
    if halves > 0 {
        let leaves = (0..s.cells as u32)
            .filter(|&c| db.cell_halves(umbrasweep::pvs::CellId(c)).next().is_none())
            .count();
        writeln!(
            out,
            "cells           {} ({} given to the bake, {halves} made by subdivision; {leaves} leaves)",
            s.cells,
            s.cells - halves
        )?;
    } else {
        writeln!(out, "cells           {}", s.cells)?;
    }
    match db.split() {
        Some(t) => writeln!(
            out,
            "objects         {} clusters of {} objects of the scene file (--split-objects {})",
            s.objects,
            t.sources.len(),
            t.size
        )?,
        None => writeln!(out, "objects         {}", s.objects)?,
    }
    writeln!(
        out,
        "average PVS     {:.1} objects ({:.1} % of the scene)",
        s.mean_visible,
        if s.objects == 0 {
            0.0
        } else {
            100.0 * s.mean_visible / s.objects as f64
        }
    )?;
    writeln!(
        out,
        "delta tree      {} key cells, {} differences; depth mean {:.2}, max {}",
        s.key_cells,
        s.cells - s.key_cells,
        s.mean_depth,
        s.max_depth
    )?;
    writeln!(
        out,
        "records         {} bitset, {} runs, {} list",
        s.records_by_encoding[0], s.records_by_encoding[1], s.records_by_encoding[2]
    )?;
    writeln!(out, "file size       {} bytes", s.file_bytes)?;
    writeln!(
        out,
        "PVS records     {} bytes ({:.1} % of plain bitsets: {} cells x {} objects / 8 = {} bytes; {:.1}x smaller)",
        s.pvs_data_bytes,
        pct(s.pvs_data_bytes, s.plain_bitset_bytes),
        s.cells,
        s.objects,
        s.plain_bitset_bytes,
        ratio(s.plain_bitset_bytes, s.pvs_data_bytes)
    )?;
    writeln!(
        out,
        "cell table      {} bytes (bounds, parent, count, length, encoding)",
        s.cell_table_bytes
    )?;
    Ok(())
}
