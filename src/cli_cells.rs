//! `umbrasweep cells`: automatic view cells for a scene ([`umbrasweep::cells::auto`]) written
//! as a cells file, and the options it shares with `bake --cells auto`.

use anyhow::{Context, bail};
use glam::DVec3;
use std::path::PathBuf;
use umbrasweep::cells::{self, AutoCellOptions, AutoCells};
use umbrasweep::geom::Aabb;
use umbrasweep::scene::{self, Scene};

/// The help heading of the options of automatic cells.
const HEADING: &str = "Automatic cells";

/// The options of automatic cells, shared by `umbrasweep cells` and `bake --cells auto`.
/// Each also answers to its name with `auto-` in front (`--auto-region`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct AutoCellArgs {
    /// Side of a grid column in x and z, in scene units [default: the larger horizontal
    /// extent of the scene, or of --region, / 32].
    #[arg(
        long,
        help_heading = HEADING,
        value_name = "SIZE",
        alias = "auto-cell-size",
        allow_negative_numbers = true
    )]
    pub cell_size: Option<f32>,
    /// Height of the camera band above a walkable surface (in --region: the most a layer of
    /// cells is tall) [default: 2].
    #[arg(
        long,
        help_heading = HEADING,
        value_name = "H",
        alias = "auto-band",
        allow_negative_numbers = true
    )]
    pub band: Option<f32>,
    /// Free space a surface needs above it to be walkable [default: 1.8].
    #[arg(
        long,
        help_heading = HEADING,
        value_name = "H",
        alias = "auto-headroom",
        allow_negative_numbers = true
    )]
    pub headroom: Option<f32>,
    /// Steepest walkable surface, in degrees from horizontal [default: 45].
    #[arg(
        long,
        help_heading = HEADING,
        value_name = "DEGREES",
        alias = "auto-max-slope",
        allow_negative_numbers = true
    )]
    pub max_slope: Option<f32>,
    /// Only front faces (counter-clockwise seen from above) are walkable: for consistently
    /// wound scenes (game levels), where a back face seen from above is a ceiling under rock.
    #[arg(long, help_heading = HEADING, alias = "auto-one-sided")]
    pub one_sided: bool,
    /// Down-rays per column side: N² rays per column [default: 4].
    #[arg(long, help_heading = HEADING, value_name = "N", alias = "auto-rays")]
    pub rays: Option<u32>,
    /// Fill this box with cells instead of looking for floors: every cell of the grid over it
    /// that is not inside closed geometry: minx,miny,minz,maxx,maxy,maxz.
    #[arg(
        long,
        help_heading = HEADING,
        value_name = "BOX",
        value_delimiter = ',',
        allow_hyphen_values = true,
        alias = "auto-region"
    )]
    pub region: Option<Vec<f64>>,
    /// Keep one cell per column and floor (do not merge empty neighbours).
    #[arg(long, help_heading = HEADING, alias = "auto-no-merge")]
    pub no_merge: bool,
    /// At most this many columns per side in a merged cell [default: 4].
    #[arg(long, help_heading = HEADING, value_name = "N", alias = "auto-max-merge")]
    pub max_merge: Option<u32>,
}

impl AutoCellArgs {
    /// The first option given on the command line, as its flag (for "only with --cells auto").
    pub fn first_given(&self) -> Option<&'static str> {
        [
            (self.cell_size.is_some(), "--cell-size"),
            (self.band.is_some(), "--band"),
            (self.headroom.is_some(), "--headroom"),
            (self.max_slope.is_some(), "--max-slope"),
            (self.one_sided, "--one-sided"),
            (self.rays.is_some(), "--rays"),
            (self.region.is_some(), "--region"),
            (self.no_merge, "--no-merge"),
            (self.max_merge.is_some(), "--max-merge"),
        ]
        .into_iter()
        .find_map(|(given, name)| given.then_some(name))
    }

    /// The library's options: the defaults, overridden by what was given.
    pub fn options(&self) -> anyhow::Result<AutoCellOptions> {
        let d = AutoCellOptions::default();
        let region = match &self.region {
            None => None,
            Some(b) if b.len() == 6 => Some(Aabb::outward(
                DVec3::new(b[0], b[1], b[2]),
                DVec3::new(b[3], b[4], b[5]),
            )),
            Some(b) => bail!(
                "--region takes 6 numbers: minx,miny,minz,maxx,maxy,maxz (got {})",
                b.len()
            ),
        };
        Ok(AutoCellOptions {
            cell_size: self.cell_size,
            band: self.band.unwrap_or(d.band),
            headroom: self.headroom.unwrap_or(d.headroom),
            max_slope_deg: self.max_slope.unwrap_or(d.max_slope_deg),
            one_sided: self.one_sided,
            rays_per_side: self.rays.unwrap_or(d.rays_per_side),
            region,
            merge: !self.no_merge,
            max_merge: self.max_merge.unwrap_or(d.max_merge),
        })
    }

    /// Computes the cells of `scene` (loaded from `path`); errors name the file.
    pub fn compute(&self, scene: &Scene, path: &std::path::Path) -> anyhow::Result<AutoCells> {
        let opts = self.options()?;
        cells::auto_cells(scene, &opts)
            .with_context(|| format!("{}: automatic cells", path.display()))
    }
}

/// Options of `umbrasweep cells`.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  umbrasweep cells data/demo_city.obj -o city_cells.json\n  umbrasweep cells level.obj -o cells.json --cell-size 64 --band 32 --headroom 24\n  umbrasweep cells station.glb -o cells.json --region -50,-20,-50,50,20,50 --cell-size 10 --band 10\n  umbrasweep bake data/demo_city.obj --cells auto -o demo.json     (the same cells, inside the bake)\n\nThe rule: square columns over the scene's x-z bounds; N×N rays down per column find the\nwalkable surfaces (slope ≤ --max-slope, ≥ --headroom free above); heights closer than\nheadroom/2 make one floor, whose cell is the column × [lowest, highest + --band]. A cell\nwhose centre is inside closed geometry is dropped; one holding geometry is a wall cell;\nneighbouring empty cells merge (up to --max-merge columns per side). The up axis is +y."
)]
pub struct CellsArgs {
    /// The scene: .obj, .gltf or .glb.
    pub scene: PathBuf,
    /// The cells file to write ({"cells": [{"min": […], "max": […]}, …]}, for bake --cells).
    #[arg(short, long, value_name = "CELLS.json")]
    pub output: PathBuf,
    /// The options of the rule.
    #[command(flatten)]
    pub auto: AutoCellArgs,
}

/// Runs `umbrasweep cells`.
pub fn run(a: &CellsArgs) -> anyhow::Result<()> {
    // Bad options fail before the scene is read.
    a.auto.options()?;
    let t = std::time::Instant::now();
    let scene = scene::load(&a.scene)?;
    let load_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let auto = a.auto.compute(&scene, &a.scene)?;
    let cells_s = t.elapsed().as_secs_f64();
    cells::save_json(&a.output, &auto.cells)
        .with_context(|| format!("{}: cannot write the cells", a.output.display()))?;
    let s = &auto.stats;
    eprintln!(
        "scene       {}: {} objects, {} triangles (read in {load_s:.2} s)",
        a.scene.display(),
        scene.objects.len(),
        scene.triangles.len()
    );
    if s.rays > 0 {
        eprintln!(
            "columns     {} ({}×{} of {}), {} rays down ({} traces, {} walkable hits)",
            s.columns,
            s.grid[0],
            s.grid[1],
            size(s.cell_size),
            s.rays,
            s.traces,
            s.walkable_hits
        );
        eprintln!(
            "floors      {}: {} solid (dropped), {} wall, {} empty",
            s.floors, s.solid, s.wall, s.empty
        );
    } else {
        eprintln!(
            "region      {} columns ({}×{} of {}), {} cells: {} solid (dropped), {} wall, \
             {} empty",
            s.columns,
            s.grid[0],
            s.grid[1],
            size(s.cell_size),
            s.floors,
            s.solid,
            s.wall,
            s.empty
        );
    }
    eprintln!(
        "cells       {} ({} wall, {} empty{})",
        s.cells,
        s.wall,
        s.cells - s.wall,
        if s.cells < s.before_merge {
            format!("; {} empty cells merged into {}", s.empty, s.cells - s.wall)
        } else {
            String::new()
        }
    );
    eprintln!("time        {cells_s:.2} s");
    eprintln!("wrote       {}", a.output.display());
    Ok(())
}

/// A length with at most 3 decimals, trailing zeros dropped.
fn size(x: f64) -> String {
    let s = format!("{x:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}
