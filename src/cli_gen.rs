//! `umbrasweep gen`: the flags of each kind of scene, their mapping to the generator options
//! of [`umbrasweep::generate`], checks of the output paths before any long generation, the
//! writes and the one-line summary.

use anyhow::{Context, bail};
use glam::Vec3;
use std::path::{Path, PathBuf};
use umbrasweep::generate::{
    BoxfieldOptions, CityOptions, CrownShape, ForestOptions, TreeModel, boxfield, city, forest,
    forest_of_models, mtl_path, write_obj,
};

/// Options of `umbrasweep gen`: the kind of scene is a subcommand.
#[derive(clap::Args, Debug, Clone)]
pub struct GenArgs {
    /// What to generate.
    #[command(subcommand)]
    pub kind: GenKind,
}

/// The kinds of scene `umbrasweep gen` makes.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum GenKind {
    /// Trees (trunk + leaf crowns, or instances of --tree-model) on a ground plane, with
    /// view cells along a path through the middle.
    Forest(ForestArgs),
    /// Blocks of box buildings with streets between them, with view cells along the streets.
    City(CityArgs),
    /// Randomly oriented boxes in a cube, with view cells in free space.
    Boxfield(BoxfieldArgs),
}

/// Options shared by every kind.
#[derive(clap::Args, Debug, Clone)]
pub struct CommonArgs {
    /// The file to write: OBJ (an MTL file beside it too when some faces are translucent), or
    /// glTF binary (`.glb`), which keeps a textured `--tree-model`'s alpha-tested cards
    /// (materials, texture coordinates, textures' alpha) so that they occlude when baked.
    #[arg(short = 'o', long = "output", value_name = "FILE.obj|FILE.glb")]
    pub output: PathBuf,
    /// Seed of the random generator: the same seed and options give identical files.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write the matching view cells to this JSON file.
    #[arg(long, value_name = "CELLS.json")]
    pub cells_out: Option<PathBuf>,
    /// Keep at most N cells, spread evenly over the path, streets or free grid cells.
    #[arg(long, value_name = "N")]
    pub cells: Option<usize>,
    /// Size of the cells: X (a cube) or X,Y,Z (default forest: 1,1,1; city: 3,2,3; boxfield: 5).
    #[arg(long, value_name = "X[,Y,Z]", value_parser = parse_size3)]
    pub cell_size: Option<Vec3>,
}

/// A named set of forest options.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForestPreset {
    /// 1,500 trees × 1,000 leaves ~1.5 across from 0.3 up, 17 m² per tree, 4 crown objects.
    Coarse,
    /// The coarse forest with leaves ~0.5 across.
    Fine,
    /// The paper's forest: the coarse forest with 7,750 trees (7.8 M triangles).
    Paper,
    /// The shipped demo: 60 trees × 200 leaves, 10 cells.
    Demo,
}

/// The volume a procedural crown's leaves fill (`--crown-shape`); maps to [`CrownShape`].
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum CrownShapeArg {
    /// A vertical cylinder: the canopy reaches down to --crown-base at its full width.
    Cylinder,
    /// An ellipsoid: round at the top and bottom, so the crowns leave an open band below eye
    /// level between the trunks.
    Ellipsoid,
}

impl From<CrownShapeArg> for CrownShape {
    fn from(a: CrownShapeArg) -> Self {
        match a {
            CrownShapeArg::Cylinder => CrownShape::Cylinder,
            CrownShapeArg::Ellipsoid => CrownShape::Ellipsoid,
        }
    }
}

/// Options of `umbrasweep gen forest` (unset values come from --preset or the defaults).
#[derive(clap::Args, Debug, Clone)]
pub struct ForestArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Start from these options (other flags override single values).
    #[arg(long, value_enum)]
    pub preset: Option<ForestPreset>,
    /// Number of trees (default 100).
    #[arg(long)]
    pub trees: Option<u32>,
    /// Leaves per tree (default 1000).
    #[arg(long)]
    pub leaves: Option<u32>,
    /// Leaf diameter: MIN,MAX, or S for 0.8·S,1.2·S (default 1.5).
    #[arg(long, value_name = "S|MIN,MAX", value_parser = parse_pair)]
    pub leaf_size: Option<Pair>,
    /// Emit leaves as planar quads instead of triangles.
    #[arg(long)]
    pub leaf_quads: bool,
    /// Vertical extent of the crowns (default 4.5).
    #[arg(long)]
    pub crown_height: Option<f32>,
    /// Height where the crowns start (default 0.3).
    #[arg(long)]
    pub crown_base: Option<f32>,
    /// Horizontal radius of the crowns (default 2.2).
    #[arg(long)]
    pub crown_radius: Option<f32>,
    /// Volume the leaves of a crown fill (default cylinder).
    #[arg(long, value_enum)]
    pub crown_shape: Option<CrownShapeArg>,
    /// Split each crown into N objects (angular sectors around the trunk) (default 4).
    #[arg(long, value_name = "N")]
    pub crown_split: Option<u32>,
    /// With --tree-model: split each tree into N objects, angular sectors around its trunk
    /// (default 1: one object per tree).
    #[arg(long, value_name = "N", requires = "tree_model")]
    pub model_split: Option<u32>,
    /// Trunk radius (default 0.15).
    #[arg(long)]
    pub trunk_radius: Option<f32>,
    /// Sides of the trunk prism (default 6).
    #[arg(long)]
    pub trunk_sides: Option<u32>,
    /// Side of the square forest (instead of --area-per-tree).
    #[arg(long, conflicts_with = "area_per_tree")]
    pub extent: Option<f32>,
    /// Ground area per tree in m², giving the side of the forest (default 17; tree models: from the model).
    #[arg(long)]
    pub area_per_tree: Option<f32>,
    /// Width of the trunk-free lane around the path's centre line (default 4).
    #[arg(long)]
    pub path_width: Option<f32>,
    /// Amplitude of the path's sine, as a fraction of the extent (0: straight) (default 0.05).
    #[arg(long)]
    pub path_curve: Option<f32>,
    /// No path: trees anywhere, no cells.
    #[arg(long)]
    pub no_path: bool,
    /// Instance this tree model (OBJ, glTF; Y up, trunk at the origin) instead of making trees.
    #[arg(long, value_name = "FILE")]
    pub tree_model: Option<PathBuf>,
    /// Scale the tree model to this height (before --scale-jitter).
    #[arg(long, requires = "tree_model")]
    pub model_height: Option<f32>,
    /// Random scale of each model instance: 1 ± this (default 0.2).
    #[arg(long, requires = "tree_model")]
    pub scale_jitter: Option<f32>,
}

/// Options of `umbrasweep gen city` (defaults: [`CityOptions::default`]).
#[derive(clap::Args, Debug, Clone)]
pub struct CityArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Blocks: N (N×N) or NX,NZ (default 12).
    #[arg(long, value_name = "N|NX,NZ", value_parser = parse_count2)]
    pub blocks: Option<[u32; 2]>,
    /// Width of the streets between blocks (default 10).
    #[arg(long)]
    pub street_width: Option<f32>,
    /// Buildings per block: N (N×N) or NX,NZ (default 2).
    #[arg(long, value_name = "N|NX,NZ", value_parser = parse_count2)]
    pub buildings_per_block: Option<[u32; 2]>,
    /// Width and depth of buildings: MIN,MAX (default 9,12).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub building_width: Option<Pair>,
    /// Heights of buildings: MIN,MAX (default 6,36).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub heights: Option<Pair>,
    /// Storey height; a tower's setback happens at a whole storey (default 3).
    #[arg(long)]
    pub floor_height: Option<f32>,
    /// Largest rotation of a building about the vertical, in degrees (default 30).
    #[arg(long)]
    pub max_rotation: Option<f32>,
    /// Fraction of H- and T-shaped buildings (default 0.4).
    #[arg(long)]
    pub shaped: Option<f32>,
}

/// Options of `umbrasweep gen boxfield` (defaults: [`BoxfieldOptions::default`]).
#[derive(clap::Args, Debug, Clone)]
pub struct BoxfieldArgs {
    #[command(flatten)]
    pub common: CommonArgs,
    /// Number of boxes (default 200).
    #[arg(long)]
    pub boxes: Option<u32>,
    /// Side of the cube holding the box centres (default 100).
    #[arg(long)]
    pub extent: Option<f32>,
    /// Box side lengths: MIN,MAX (or S for S,S) (default 1,10).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair)]
    pub box_size: Option<Pair>,
}

/// A value `A` or `A,B` of the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair(pub f32, pub Option<f32>);

fn parse_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("'{s}' is not a finite number"))
    }
}

fn parse_pair(s: &str) -> Result<Pair, String> {
    match s.split(',').collect::<Vec<_>>()[..] {
        [a] => Ok(Pair(parse_f32(a)?, None)),
        [a, b] => Ok(Pair(parse_f32(a)?, Some(parse_f32(b)?))),
        _ => Err(format!("'{s}': expected A or A,B")),
    }
}

fn parse_size3(s: &str) -> Result<Vec3, String> {
    match s.split(',').map(parse_f32).collect::<Result<Vec<_>, _>>()?[..] {
        [a] => Ok(Vec3::splat(a)),
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("'{s}': expected X or X,Y,Z")),
    }
}

fn parse_count2(s: &str) -> Result<[u32; 2], String> {
    let n = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| format!("'{t}' is not a count"))
    };
    match s.split(',').collect::<Vec<_>>()[..] {
        [a] => Ok([n(a)?; 2]),
        [a, b] => Ok([n(a)?, n(b)?]),
        _ => Err(format!("'{s}': expected N or NX,NZ")),
    }
}

/// A required `MIN,MAX` pair (one value `S` means `S,S`).
fn min_max(p: Pair, flag: &str) -> anyhow::Result<[f32; 2]> {
    let [a, b] = [p.0, p.1.unwrap_or(p.0)];
    if a > b {
        bail!("{flag} {a},{b}: MIN must not exceed MAX");
    }
    Ok([a, b])
}

impl ForestArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// Inconsistent flags (e.g. leaf flags with `--tree-model`), naming the flag.
    pub fn options(&self) -> anyhow::Result<ForestOptions> {
        let mut o = match self.preset {
            None => ForestOptions::default(),
            Some(ForestPreset::Coarse) => ForestOptions::coarse(),
            Some(ForestPreset::Fine) => ForestOptions::fine(),
            Some(ForestPreset::Paper) => ForestOptions::paper(),
            Some(ForestPreset::Demo) => ForestOptions::demo(),
        };
        if self.tree_model.is_some() {
            let procedural = [
                ("--leaves", self.leaves.is_some()),
                ("--leaf-size", self.leaf_size.is_some()),
                ("--leaf-quads", self.leaf_quads),
                ("--crown-height", self.crown_height.is_some()),
                ("--crown-base", self.crown_base.is_some()),
                ("--crown-radius", self.crown_radius.is_some()),
                ("--crown-shape", self.crown_shape.is_some()),
                ("--crown-split", self.crown_split.is_some()),
                ("--trunk-radius", self.trunk_radius.is_some()),
                ("--trunk-sides", self.trunk_sides.is_some()),
            ];
            if let Some((flag, _)) = procedural.iter().find(|(_, given)| *given) {
                bail!("{flag} shapes procedural trees and does not apply with --tree-model");
            }
        }
        o.seed = self.common.seed;
        if let Some(v) = self.trees {
            o.trees = v;
        }
        if let Some(v) = self.leaves {
            o.leaves = v;
        }
        if let Some(p) = self.leaf_size {
            o.leaf_size = match p.1 {
                Some(_) => min_max(p, "--leaf-size")?,
                // In f64, so `1.5` gives exactly the presets' `[1.2, 1.8]`.
                None => [(0.8 * p.0 as f64) as f32, (1.2 * p.0 as f64) as f32],
            };
        }
        o.leaf_quads |= self.leaf_quads;
        set(&mut o.crown_height, self.crown_height);
        set(&mut o.crown_base, self.crown_base);
        set(&mut o.crown_radius, self.crown_radius);
        set(&mut o.crown_shape, self.crown_shape.map(CrownShape::from));
        set(&mut o.crown_split, self.crown_split);
        set(&mut o.trunk_radius, self.trunk_radius);
        set(&mut o.trunk_sides, self.trunk_sides);
        if let Some(n) = self.model_split {
            if !(1..=64).contains(&n) {
                bail!("--model-split {n}: must be between 1 and 64");
            }
            o.model_split = n;
        }
        if self.tree_model.is_some() {
            // The model's footprint gives the spacing unless a flag sets it.
            o.area_per_tree = None;
        }
        if self.extent.is_some() {
            o.extent = self.extent;
            o.area_per_tree = None;
        }
        if self.area_per_tree.is_some() {
            o.area_per_tree = self.area_per_tree;
            o.extent = None;
        }
        set(&mut o.path_width, self.path_width);
        set(&mut o.path_curve, self.path_curve);
        o.path &= !self.no_path;
        if let Some(c) = self.common.cell_size {
            o.cell_size = c;
        }
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        if self.model_height.is_some() {
            o.model_height = self.model_height;
        }
        set(&mut o.scale_jitter, self.scale_jitter);
        Ok(o)
    }
}

impl CityArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// A `MIN,MAX` flag with MIN above MAX.
    pub fn options(&self) -> anyhow::Result<CityOptions> {
        let mut o = CityOptions {
            seed: self.common.seed,
            ..CityOptions::default()
        };
        set(&mut o.blocks, self.blocks);
        set(&mut o.street_width, self.street_width);
        set(&mut o.buildings_per_block, self.buildings_per_block);
        if let Some(p) = self.building_width {
            o.building_width = min_max(p, "--building-width")?;
        }
        if let Some(p) = self.heights {
            o.heights = min_max(p, "--heights")?;
        }
        set(&mut o.floor_height, self.floor_height);
        set(&mut o.max_rotation_deg, self.max_rotation);
        set(&mut o.shaped_fraction, self.shaped);
        set(&mut o.cell_size, self.common.cell_size);
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        Ok(o)
    }
}

impl BoxfieldArgs {
    /// The generator options these flags ask for.
    ///
    /// # Errors
    /// `--box-size` with MIN above MAX.
    pub fn options(&self) -> anyhow::Result<BoxfieldOptions> {
        let mut o = BoxfieldOptions {
            seed: self.common.seed,
            ..BoxfieldOptions::default()
        };
        set(&mut o.boxes, self.boxes);
        set(&mut o.extent, self.extent);
        if let Some(p) = self.box_size {
            o.box_size = min_max(p, "--box-size")?;
        }
        set(&mut o.cell_size, self.common.cell_size);
        if self.common.cells.is_some() {
            o.max_cells = self.common.cells;
        }
        Ok(o)
    }
}

fn set<T>(dst: &mut T, v: Option<T>) {
    if let Some(v) = v {
        *dst = v;
    }
}

/// Checks that a file can be created at `path` (its folder exists and is writable), before
/// any long generation.
fn check_writable(path: &Path, what: &str) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if path.is_dir() {
        bail!("{what} {}: is a directory", path.display());
    }
    tempfile::NamedTempFile::new_in(dir).with_context(|| {
        format!(
            "{what} {}: cannot create a file in {}",
            path.display(),
            dir.display()
        )
    })?;
    Ok(())
}

/// Runs `umbrasweep gen`: generates the scene, writes the OBJ (and MTL) and the cells, and
/// prints a one-line summary.
///
/// # Errors
/// Bad options, an unloadable `--tree-model`, or an unwritable output; nothing is left
/// behind on error.
pub fn run(args: &GenArgs) -> anyhow::Result<()> {
    let common = match &args.kind {
        GenKind::Forest(a) => &a.common,
        GenKind::City(a) => &a.common,
        GenKind::Boxfield(a) => &a.common,
    };
    let ext = |x: &str| {
        common
            .output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case(x))
    };
    let glb = ext("glb");
    if !ext("obj") && !glb {
        bail!(
            "-o {}: the output must be an .obj or a .glb file",
            common.output.display()
        );
    }
    if common.cells == Some(0) {
        bail!("--cells 0: keep at least one cell");
    }
    check_writable(&common.output, "-o")?;
    if let Some(c) = &common.cells_out {
        if c == &common.output {
            bail!("--cells-out {}: same file as -o", c.display());
        }
        check_writable(c, "--cells-out")?;
    }

    if let GenKind::Forest(a) = &args.kind
        && a.no_path
        && common.cells_out.is_some()
    {
        bail!("--cells-out: the forest's cells lie on its path; drop --no-path");
    }
    let (mut generated, kind) = match &args.kind {
        GenKind::Forest(a) => {
            let o = a.options()?;
            let g = match &a.tree_model {
                Some(path) => {
                    let scene = umbrasweep::scene::load(path)?;
                    let model = TreeModel::from_scene(&scene);
                    forest_of_models(&o, &model)?
                }
                None => forest(&o)?,
            };
            (g, "forest")
        }
        GenKind::City(a) => (city(&a.options()?)?, "city"),
        GenKind::Boxfield(a) => (boxfield(&a.options()?)?, "boxfield"),
    };
    generated.comment = format!(
        "umbrasweep gen {kind} --seed {}: {}",
        common.seed, generated.comment
    );
    if common.cells_out.is_some() && generated.cells.is_empty() {
        bail!(
            "--cells-out: this {kind} has no room for view cells (see --cell-size and the {kind} options)"
        );
    }

    if glb {
        umbrasweep::generate::write_glb(&common.output, &generated)?;
    } else {
        write_obj(&common.output, &generated)?;
    }
    if let Some(c) = &common.cells_out
        && let Err(e) = umbrasweep::cells::save_json(c, &generated.cells)
    {
        let _ = std::fs::remove_file(&common.output);
        if generated.has_translucent() && !glb {
            let _ = std::fs::remove_file(mtl_path(&common.output));
        }
        bail!("{e}");
    }
    println!(
        "wrote {}: {} objects, {} triangles{}{}",
        common.output.display(),
        generated.objects.len(),
        generated.triangle_count(),
        if let Some(c) = generated.alpha.as_ref().filter(|_| glb) {
            format!(
                " ({} alpha-tested card triangles per tree model)",
                c.cards.len()
            )
        } else if generated.has_translucent() && !glb {
            format!(" (materials in {})", mtl_path(&common.output).display())
        } else {
            String::new()
        },
        match &common.cells_out {
            Some(c) => format!("; {} cells to {}", generated.cells.len(), c.display()),
            None => String::new(),
        }
    );
    Ok(())
}
