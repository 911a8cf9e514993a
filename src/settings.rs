//! The bake settings as data: one serde type, [`BakeSettings`], that the CLI fills, the bake
//! checks ([`BakeSettings::check`], a typed [`SettingsError`]), the PVS document records as it
//! is (`settings` in the JSON document, flattened beside `backend`) and `report` and `bench`
//! read back. Its defaults are written once ([`BakeSettings::default_settings`]).
//!
//! Built with the `runtime` feature too (serde only), since the PVS document holds it.
//!
//! Reading documents written by older versions: a field they lack takes the value the bake
//! that wrote them used — `sweep` false, `subcell` none, `max_stretch` 1 (square maps; older
//! documents wrote 0 for it, read as 1 too) — and every other absent field its default.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Everything that shapes a bake.
///
/// ```
/// use umbrasweep::settings::{BakeSettings, SweepChoice};
/// let s = BakeSettings { resolution: 512, sweep: SweepChoice::On, ..BakeSettings::default() };
/// assert!(s.check().is_ok());
/// let json = serde_json::to_string(&s).unwrap();
/// assert!(json.contains(r#""resolution":512"#) && json.contains(r#""sweep":true"#));
/// assert_eq!(serde_json::from_str::<BakeSettings>(&json).unwrap(), s);
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BakeSettings {
    /// Depth Map resolution per side (a power of two): each plane's map has `resolution²`
    /// pixels. Default 256.
    pub resolution: u32,
    /// How much wider than tall, or taller than wide, an occlusion sweep plane's Depth Map may
    /// be (a power of two): each map follows its rectangle's shape, keeping `resolution²`
    /// pixels (`plane::map_size`); 1 keeps every map square. Separate planes (no
    /// sweep) stay square: on Munich's street cells stretched maps culled 86.7 % against
    /// 90.0 %. Default 2: on the coarse forest 2, 4 and 8 cull the same (86.7 % against
    /// 84.5 % for square maps), and more stretch lets more small Projections cover a whole
    /// pixel, which costs time where they fuse into nothing (the fine forest: 0.99 s per cell
    /// at 2, 1.28 s at 8, 0.81 s square).
    #[serde(default = "square_maps", deserialize_with = "stretch_of_old_documents")]
    pub max_stretch: u32,
    /// The plane rectangle is at most the 90° frustum from the cell's face scaled by this.
    /// Default 1.5 (the paper's).
    pub extend: f64,
    /// Projection planes per direction just behind occluders (all used). Default 4.
    pub planes: u32,
    /// Further planes per direction through the middle of the heaviest closed occluders,
    /// receiving their slices. Default 1.
    pub slice_planes: u32,
    /// Where the planes of a direction go. Default geometric spacing.
    pub placement: Placement,
    /// Treat non-opaque (alpha-tested, blended) triangles as occluders. May cull visible
    /// objects. Default false.
    pub alpha_occluders: bool,
    /// Only objects whose name matches this glob are occluders (all stay occludees).
    pub occluders: Option<String>,
    /// Use the improved occludee Projection of §4 for boxes in front of a plane. Default true.
    pub improved_projection: bool,
    /// Occlusion sweep (§5) instead of separate planes: on, off, or chosen per scene
    /// ([`SweepChoice::Auto`], the default). A PVS document records what the bake chose
    /// (`true` or `false`).
    #[serde(default = "sweep_of_old_documents")]
    pub sweep: SweepChoice,
    /// The sweep's planes per direction (at most), kernel size and spacing (recorded as
    /// `sweep_planes`, `kernel` and `sweep_spacing`).
    #[serde(flatten)]
    pub sweep_settings: SweepSettings,
    /// Bake each cell as the union of the PVS of sub-cells no larger than this along any axis
    /// (exact, and conservative: a point of the cell lies in one of its sub-cells). Default none.
    pub subcell: Option<f64>,
    /// The shrunk-occluder sampler (fine foliage, `bake::sampling`): on, off, or chosen per
    /// scene ([`SweepChoice::Auto`], the default: off for now, as it does not yet pay for its
    /// time; see `bake::SAMPLING_AUTO_NOTE`). A PVS document records what the bake chose
    /// (`true` or `false`); documents from before the sampler read as `false`.
    #[serde(default = "sampling_of_old_documents")]
    pub sampling: SamplingChoice,
    /// The sampler's finest ε, budget, resolution and certification rays (recorded as
    /// `sampling_eps`, `sampling_levels`, `sampling_max_eps`, `sampling_probe`,
    /// `sampling_probe_cull`, `sampling_probe_pay`,
    /// `sampling_budget_points`,
    /// `sampling_budget_seconds`, `sampling_resolution`, `sampling_rays`,
    /// `sampling_band_ratio`).
    #[serde(flatten)]
    pub sampling_settings: SamplingSettings,
    /// Adaptive subdivision: a cell whose PVS holds more triangles than this is split in two
    /// along its longest axis and its halves baked, testing only the objects of its PVS, down
    /// to [`min_cell_size`](Self::min_cell_size). Default none (cells are baked as given).
    pub max_pvs_triangles: Option<u64>,
    /// The smallest cell adaptive subdivision makes: a cell is not split when its longest
    /// side is at most this. Default none: 1/8 of the longest side of the cell being
    /// subdivided.
    pub min_cell_size: Option<f64>,
    /// Occluder selection by solid angle (steradians): an occluder part whose bounding sphere
    /// subtends less than this from every point of the cell is not projected
    /// ([`crate::geom::DAabb::max_solid_angle_from`]). Lossy but conservative (an occluder
    /// left out only keeps more objects visible); it trades PVS for time on large scenes.
    /// Default 0: every part that may project is projected.
    pub occluder_min_solid_angle: f64,
    /// Ray space factorization (`bake::rsf`, the half umbra of 2.5D occluders), run before
    /// the planes: on, off, or chosen per scene ([`SweepChoice::Auto`], the default: on when
    /// most of the occluder area stands upright, `bake::choose_rsf`). A PVS document records
    /// what the bake chose; documents from before it read as `false`.
    #[serde(default = "rsf_of_old_documents")]
    pub rsf: SweepChoice,
    /// Pixels per side of each of the four ray-space charts. Default 256: on Munich's 50 street
    /// cells 128, 160, 256 and 512 (the paper's) give PVS/VS 2.52, 2.44, 2.29 and 2.17 for
    /// 46, 55, 76 and 199–211 ms per cell with the planes (CPU, two cores).
    pub rsf_resolution: u32,
    /// The scene's up axis: ray space factorization works in vertical planes. Default y
    /// (glTF's).
    pub up: UpAxis,
    /// Alpha-tested cards (glTF `MASK`) as occluders: [`AlphaCards::Coverage`] (the default)
    /// uses the parts of each card that are opaque at every trusted mip level
    /// (`scene::alpha`); [`AlphaCards::Ignore`]: cards never occlude. Documents from before
    /// read as `ignore`.
    #[serde(default = "cards_of_old_documents")]
    pub alpha_cards: AlphaCards,
    /// Mip levels the card coverage trusts: 0 (the default) means all of them, down to 1×1;
    /// N trusts levels `0..N` only, which is right for engines that never sample far levels
    /// of foliage (alpha-to-coverage, coverage-preserving mips, a LOD clamp).
    pub alpha_mips: u32,
    /// Most polygons per card (rectangles of surely opaque texels, largest first). Default 4.
    pub alpha_card_polygons: u32,
    /// What scene import does with an alpha-tested material's missing image.
    pub alpha_missing: AlphaMissing,
}

fn cards_of_old_documents() -> AlphaCards {
    AlphaCards::Ignore
}

/// How alpha-tested cards occlude.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlphaCards {
    /// The surely opaque parts of each card occlude (conservative).
    #[default]
    Coverage,
    /// Cards never occlude (the behaviour before card coverage existed).
    Ignore,
}

/// What scene import does with an alpha-tested (`MASK`) material whose image cannot be read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlphaMissing {
    /// Refuse the scene, naming the file and the image (the default).
    #[default]
    Error,
    /// Keep its cards as non-occluders (they never hide anything), with a warning.
    Transparent,
}

fn rsf_of_old_documents() -> SweepChoice {
    SweepChoice::Off
}

/// The scene's up axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    /// y is up (glTF, most OBJ exports).
    #[default]
    Y,
    /// z is up (CAD, GIS, Blender's own axes).
    Z,
}

impl UpAxis {
    /// The axis index: 1 for y, 2 for z.
    pub const fn index(self) -> usize {
        match self {
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        }
    }
}

fn sampling_of_old_documents() -> SamplingChoice {
    SweepChoice::Off
}

/// Whether a bake runs the shrunk-occluder sampler: the same three choices as the sweep.
pub type SamplingChoice = SweepChoice;

/// The shrunk-occluder sampler's parameters (see `bake::sampling`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SamplingSettings {
    /// The finest ε: the radius of the balls that sample points stand for. `None` (the
    /// default) chooses it from the occluders: [`SamplingSettings::EPS_PER_INRADIUS`] × the
    /// median in-plane inradius of the occluder polygons that are not slivers
    /// ([`crate::sampler::SLIVER_RATIO`]).
    #[serde(rename = "sampling_eps")]
    pub eps: Option<f64>,
    /// Refinement levels: faces are first sampled with balls `2^levels` times the finest ε
    /// (or larger: see `bake::sampling::top_eps`) and a ball is split in four only where some
    /// object is still undecided. Default 2.
    #[serde(rename = "sampling_levels")]
    pub levels: u32,
    /// The coarsest ε that is sampled: a level whose balls are larger is not rendered, its
    /// rectangles are split at once (the finest level is always sampled). `None` (the
    /// default) samples every level: on the coarse forest the coarsest level proves no object
    /// hidden from the cell, but what it proves per rectangle prunes the next level's lists,
    /// and skipping it cost time (4×2×4 cell: 742 s instead of 680 s; 1×1×1: 61 s, 59 s).
    #[serde(rename = "sampling_max_eps")]
    pub max_eps: Option<f64>,
    /// Levels other than the finest are first sampled at a probe of their rectangles (every
    /// [`SamplingSettings::PROBE_STRIDE`]-th, at least [`SamplingSettings::PROBE_MIN`], about
    /// [`SamplingSettings::PROBE_MAX`] at most); when
    /// the probe proves hidden less than this fraction of the objects it tests, or hides no
    /// undecided object at every probed rectangle that tests it, the rest of the level is
    /// split without sampling. Default 0.01; 0 samples every level whole. A probe runs in
    /// rounds of a few rectangles and stops early once the rest of it could prove nothing
    /// (the level's `probe_rects` says how many it sampled).
    #[serde(rename = "sampling_probe", default = "default_probe")]
    pub probe: f64,
    /// A level's probe must also prove hidden for the cell — at every probed rectangle that
    /// tests them — at least this share of the undecided objects it tests, or the rest of the
    /// level is split without sampling. A coarse level pays for its points by pruning the
    /// finer levels' lists only where its balls fuse the leaves; where they do not it costs
    /// far more per point than the finest level (its open objects go down to its quadrants
    /// instead of leaving every list as visible). Measured probes (with each edge shrunk by the
    /// rectangle's support, `sampler::Hemicube::begin_patch`): the coarse forest's levels that
    /// paid proved 50 % (1×1×1 cell, ε 0.177: 426 of 850) and 74 % (4×2×4 cell, ε 0.236: 4,459
    /// of 5,995); those that did not, 17 % and 21 % (the same cells' coarsest levels, ε 0.354
    /// and 0.471: the latter sampled whole took 47 s and proved nothing for the cell) and the
    /// fine forest's 30 % (1×1×1, ε 0.0707: 2,167 of 7,272; sampled whole it took 191 s for
    /// 600 points, where the cell's finest level alone takes about 100 s). Default 0.4; 0
    /// keeps only the rule that some object be proved. Documents written before it read as 0.
    #[serde(rename = "sampling_probe_cull", default)]
    pub probe_cull: f64,
    /// The level just above the finest, when it passes both probe rules, is sampled whole
    /// only when what one of its rectangles is expected to save the finest level is at least
    /// this many times what it costs, both in polygons drawn (what a sample point's time
    /// follows) weighted by resolution ([`SamplingSettings::polygon_weight`]). A pilot renders
    /// a few probed rectangles again as trials, and one quadrant of each twice: with the
    /// candidates it inherits were the level split unsampled, and with what the rectangle
    /// left open; the saving is four times the quadrant's difference. Counted, not timed, so
    /// that the decision, hence the PVS, is the same on any machine, thread count and
    /// backend. Coarser levels have no pilot (they save the finest level through the levels
    /// between, which the trials do not see). A level whose balls are too coarse to fuse the
    /// leaves (fine foliage at twice a fine ε) costs more per rectangle than the finest points
    /// it prunes; measured in `docs/sampling.md` ("A pilot for the level above the finest"):
    /// the coarse forest's 4×2×4 cell at ε 0.059 with three levels sampled in 174 s instead
    /// of 257 s for one object fewer. Default 1; 0 turns the estimate off. Documents written
    /// before it read as 0.
    #[serde(rename = "sampling_probe_pay", default)]
    pub probe_pay: f64,
    /// At most this many sample points per cell; objects still undecided then stay visible.
    /// Default 50,000.
    #[serde(rename = "sampling_budget_points")]
    pub budget_points: u64,
    /// At most this many seconds of sampling per cell (wall clock; none by default). Makes the
    /// result depend on the machine's speed.
    #[serde(rename = "sampling_budget_seconds")]
    pub budget_seconds: Option<f64>,
    /// Pixels across each 90° view of the hemicube rendered per sample point, the same at
    /// every level; `None` (the default, recorded as `null`) chooses it per cell and level
    /// from ε: see [`SamplingSettings::auto_resolution`].
    #[serde(rename = "sampling_resolution")]
    pub resolution: Option<u32>,
    /// Rays cast from the cell before sampling (the validator's sampler): objects they see are
    /// visible for sure and are not sampled. Default 100,000.
    #[serde(rename = "sampling_rays")]
    pub rays: u64,
    /// Occludee distance bands per sample point: the objects are rendered for in groups whose
    /// farthest distances from the point grow by at most this ratio, each group with its edges
    /// shrunk only as much as occludees that near need (leaves near an occludee shrink
    /// little). 0 renders once per point for all of them. Default √2 (≈ 1.41).
    #[serde(rename = "sampling_band_ratio")]
    pub band_ratio: f64,
    /// With several distance bands, each point first renders once for all its candidates,
    /// edges shrunk for the farthest of them: what that render hides is decided, and only
    /// what it leaves open is rendered for again by band (`--sampling-bands-only` turns it
    /// off). The bands then form over those few objects only, so each band's farthest
    /// distance, which sets its shrinks, lies closer to its objects' own. On by default: on
    /// the fine forest's 4×2×4 cell at ε 0.0625 it hid 961 objects in 545 s against 634 in
    /// 669 s with the tuck pass, 567 in 261 s against 310 in 241 s without (`docs/sampling.md`).
    /// Documents written before it existed read as off.
    #[serde(rename = "sampling_whole_first", default)]
    pub whole_first: bool,
    /// The tuck pass (`crate::sampler::Hemicube::set_tuck`): as each leaf is drawn, nearest
    /// first, every edge of it whose whole image already lies beyond what was drawn is drawn
    /// without its shrink, so that leaves fuse across the edges nearer leaves cover. Off by
    /// default: a finer ε buys as much or more for its time, and it has no GPU twin. On the
    /// fine forest's 1×1×1 cell at 512 px it hid 3 % more objects at ε 0.0312 (72.4 % culled
    /// against 70.0 %) for 1.4× the time (154 s against 108 s), and without it ε 0.0221 culled
    /// 77.1 % in 160 s; on its 4×2×4 cell, 54.3 % against 51.8 % for 1.2× the time (`docs/sampling.md`,
    /// "The tuck pass, measured", and "Defaults on fine foliage"; measured before edges were
    /// shrunk by the rectangle's support, which took those cells to 74.5 % and 58.5 % without
    /// the pass in about the same time).
    /// Renders on the CPU's hemicube only (a GPU backend samples on the CPU with it).
    /// Documents written before it existed read as off.
    #[serde(rename = "sampling_tuck", default)]
    pub tuck: bool,
    /// How a sample rectangle's render fuses the leaves ([`SamplingFusion`]). Documents
    /// written before it existed read as [`SamplingFusion::Shrink`].
    #[serde(rename = "sampling_fusion", default)]
    pub fusion: SamplingFusion,
}

/// How the sampler's render of one face rectangle fuses the occluders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplingFusion {
    /// Every polygon's silhouette shrunk for the whole rectangle's parallax, the union kept
    /// per sub-pixel with its depths ([`crate::sampler::Hemicube`]). Renders on the GPU too.
    #[default]
    Shrink,
    /// The per-rectangle occlusion sweep ([`crate::sampler::RectSweep`]): each polygon's
    /// extended projection onto a plane just behind it, the union eroded as the sweep moves
    /// away. Leaves that fuse stay fused at a far coarser ε. CPU only.
    Sweep,
}

impl SamplingFusion {
    /// The name `--sampling-fusion` takes.
    pub fn name(self) -> &'static str {
        match self {
            SamplingFusion::Shrink => "shrink",
            SamplingFusion::Sweep => "sweep",
        }
    }
}

impl SamplingSettings {
    /// The default finest ε is this × the median inradius of the occluder polygons.
    pub const EPS_PER_INRADIUS: f64 = 0.35;

    /// A level's probe takes every this-many-th rectangle ([`SamplingSettings::probe`]).
    pub const PROBE_STRIDE: usize = 16;
    /// A level's probe takes at least this many rectangles (all when it has fewer).
    pub const PROBE_MIN: usize = 8;
    /// A level's probe takes about this many rectangles at most (a larger stride on large
    /// levels): a probe is wasted work when the level stops there, and its decision needs no
    /// more. On the fine forest's 4×2×4 cell the defaults' level at ε 0.0832 (4,760
    /// rectangles) probed 298 of them in 141 s, at 0.47 s each, before stopping.
    pub const PROBE_MAX: usize = 64;

    /// The most refinement levels (`--sampling-levels`): each costs about 4× the points of
    /// the one before.
    pub const MAX_LEVELS: u32 = 12;

    /// Why these settings keep the sampler off the GPU whatever the device offers (`None`:
    /// they do not). The one place that decides it: the bake's summary line and the
    /// sampler's choice of renderer both ask here.
    pub fn gpu_refusal(&self) -> Option<&'static str> {
        if self.fusion == SamplingFusion::Sweep {
            return Some("the per-rectangle sweep (--sampling-fusion sweep) has no GPU twin yet");
        }
        self.tuck
            .then_some("the tuck pass (--sampling-tuck) has no GPU twin yet")
    }

    /// Pixels per view of the per-rectangle sweep ([`SamplingFusion::Sweep`]) when
    /// `--sampling-resolution` is not given, at every level: its fusion needs sub-pixels
    /// fine next to the leaves' seams, not next to ε.
    pub const SWEEP_RESOLUTION: u32 = 512;

    /// The automatic resolution's pixels per unit of `h/ε` (see [`Self::auto_resolution`]).
    pub const AUTO_PIXELS: f64 = 8.0;
    /// The automatic resolution's least and greatest values.
    pub const AUTO_RESOLUTION: (u32, u32) = (256, 1024);

    /// Pixels traded for points: where both ε and the resolution are automatic, a cell whose
    /// finest level the automatic rule would render at more than this many pixels per view
    /// renders every level at this many at most, with its finest ε `1/√2` smaller (about
    /// twice the points) — see [`Self::cell_finest`].
    pub const TRADE_RESOLUTION: u32 = 512;

    /// A cell's finest ε and the most pixels per view its levels render at (`None`: no cap
    /// beyond the automatic rule's), for the settings' finest ε `eps` and the cell's median
    /// ray hit distance `h` (the scale of [`Self::auto_resolution`]).
    ///
    /// With `--sampling-eps` or `--sampling-resolution` given, they are the user's. Otherwise,
    /// where the automatic rule would render the finest level at more than
    /// [`Self::TRADE_RESOLUTION`] pixels, the cell renders at that many with ε `eps/√2`: for
    /// a budget of time, points pay more than pixels on such cells (large cells in fine
    /// foliage). The fine forest's 4×2×4 cell, whole bakes on two cores: the automatic
    /// choice (ε 0.0405, 1,024 px) culled 54.8 % in 825 s of sampling, the trade (ε 0.0286,
    /// 512 px) 59.6 % in 791 s, with the level at twice its ε stopped by its pilot
    /// ([`Self::probe_pay`]; without that it passes its probe and costs more than the whole
    /// finest level). `docs/sampling.md`, "A pilot for the level above the finest; pixels
    /// traded for points".
    ///
    /// ```
    /// use umbrasweep::settings::SamplingSettings;
    /// let auto = SamplingSettings::default();
    /// // A large cell in fine foliage: 1,024 px wanted, 512 px and a √2 finer ε instead.
    /// let (eps, cap) = auto.cell_finest(0.04, 5.0);
    /// assert!((eps - 0.04 / 2f64.sqrt()).abs() < 1e-12);
    /// assert_eq!(cap, Some(512));
    /// // Coarse foliage: 256 px wanted, nothing traded.
    /// assert_eq!(auto.cell_finest(0.12, 4.0), (0.12, None));
    /// // An ε the user gave is kept.
    /// let given = SamplingSettings { eps: Some(0.04), ..auto };
    /// assert_eq!(given.cell_finest(0.04, 5.0), (0.04, None));
    /// ```
    pub fn cell_finest(&self, eps: f64, h: f64) -> (f64, Option<u32>) {
        if self.eps.is_none()
            && self.fusion == SamplingFusion::Shrink
            && self.resolution.is_none()
            && Self::auto_resolution(h, eps) > Self::TRADE_RESOLUTION
        {
            (eps / std::f64::consts::SQRT_2, Some(Self::TRADE_RESOLUTION))
        } else {
            (eps, None)
        }
    }

    /// Bytes of one sample point's hemicube at resolution `res` (per worker thread): three
    /// `res²` views' worth of pixels, each with a depth and eight sub-pixel layers.
    pub const fn hemicube_bytes(res: u32) -> u64 {
        let r = res as u64;
        3 * r * r * (4 + 8 * 8 + 8 * 4)
    }

    /// The largest resolution these settings may render at (the fixed one, or the automatic
    /// rule's greatest).
    pub fn max_resolution(&self) -> u32 {
        self.resolution.unwrap_or(Self::AUTO_RESOLUTION.1)
    }

    /// The resolution rendered at a level of ball radius `eps` for a cell whose rays' median
    /// first-hit distance is `h`: the power of two nearest (in ratio) to `AUTO_PIXELS · h/ε`,
    /// within [`Self::AUTO_RESOLUTION`]. A hemicube pixel at the view's centre spans `2/N`
    /// radians, so this makes it about a quarter of the shrink `ε/h` of a leaf at the median
    /// distance (a sub-pixel 1/32 of it): finer pixels for finer ε and more open scenes,
    /// whatever the scene's units.
    ///
    /// Measured (12 random sample points of one cell's faces, objects never open at any, and
    /// the time): fine forest, 4×2×4 cell, ε 0.05: 256 px 1,589 in 7.0 s, 512 px 3,083 in
    /// 4.9 s, 1,024 px 3,659 in 7.1 s, 2,048 px 3,915 in 15.6 s (the rule picks 1,024);
    /// coarse forest, the same cell, ε 0.118: 256 px 5,942 in 3.9 s, 512 px 6,039 in 7.9 s
    /// (the rule picks 256). Outside the least and greatest values pixels stop paying: coarser
    /// maps cover too little for the hierarchical culling to skip far leaves, and 2,048 px
    /// cost twice the time of 1,024 for 7 % more, with 1.2 GB of hemicube per thread
    /// ([`Self::hemicube_bytes`]). For a budget of time rather than of points the rule is not
    /// the best: whole bakes of the fine forest's 4×2×4 cell culled more at 512 px with a √2
    /// finer ε than at the 1,024 px it picks (54.3 % in 915 s at ε 0.0312 against 46.9 % in
    /// 990 s at ε 0.0442; `docs/sampling.md`, "Pixels against points"), so where ε is
    /// automatic too a cell trades them ([`Self::cell_finest`]).
    ///
    /// ```
    /// use umbrasweep::settings::SamplingSettings;
    /// assert_eq!(SamplingSettings::auto_resolution(4.25, 0.035), 1024);
    /// assert_eq!(SamplingSettings::auto_resolution(4.2, 0.118), 256);
    /// // Scale-free: the same scene in millimetres.
    /// assert_eq!(SamplingSettings::auto_resolution(4250.0, 35.0), 1024);
    /// ```
    pub fn auto_resolution(h: f64, eps: f64) -> u32 {
        let (lo, hi) = Self::AUTO_RESOLUTION;
        let want = Self::AUTO_PIXELS * h / eps;
        if !(want.is_finite() && want > 0.0) {
            return lo;
        }
        let k = want
            .log2()
            .round()
            .clamp(f64::from(lo).log2(), f64::from(hi).log2());
        1u32 << (k as u32)
    }

    /// The relative cost of drawing one polygon in a hemicube of `res` pixels, 1 up to
    /// 512 px, for comparing levels at different resolutions ([`SamplingSettings::probe_pay`]):
    /// `max(1, 0.28 + 0.72·res/512)`. Measured on the fine forest's 4×2×4 cell
    /// (`examples/sampler_render_bench`, 6 points at ε 0.0286, one thread): 11.7, 10.4 and
    /// 17.9 µs per polygon drawn at 256, 512 and 1,024 px; 2,048 px costs about twice 1,024.
    ///
    /// ```
    /// use umbrasweep::settings::SamplingSettings;
    /// assert_eq!(SamplingSettings::polygon_weight(512), 1.0);
    /// assert_eq!(SamplingSettings::polygon_weight(256), 1.0);
    /// assert!((SamplingSettings::polygon_weight(1024) - 1.72).abs() < 1e-9);
    /// ```
    pub fn polygon_weight(res: u32) -> f64 {
        (0.28 + 0.72 * f64::from(res) / 512.0).max(1.0)
    }

    /// The defaults, as a `const fn` for presets.
    pub const fn default_settings() -> Self {
        SamplingSettings {
            eps: None,
            levels: 2,
            max_eps: None,
            probe: 0.01,
            probe_cull: 0.4,
            probe_pay: 1.0,
            budget_points: 50_000,
            budget_seconds: None,
            resolution: None,
            rays: 100_000,
            band_ratio: std::f64::consts::SQRT_2,
            whole_first: true,
            tuck: false,
            fusion: SamplingFusion::Shrink,
        }
    }
}

impl Default for SamplingSettings {
    fn default() -> Self {
        Self::default_settings()
    }
}

/// Documents written before level probes sampled every level whole.
fn default_probe() -> f64 {
    0.0
}

fn square_maps() -> u32 {
    1
}

/// Documents written before stretched maps recorded `max_stretch` 0: their maps were square.
fn stretch_of_old_documents<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    Ok(u32::deserialize(d)?.max(1))
}

fn sweep_of_old_documents() -> SweepChoice {
    SweepChoice::Off
}

/// Whether a bake sweeps. Serialized as `true` (on), `false` (off) or `"auto"`; read from those
/// or from `"on"`, `"off"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SweepChoice {
    /// The sweep for scenes dominated by small occluders (`bake::choose_sweep`).
    #[default]
    Auto,
    /// Always the occlusion sweep.
    On,
    /// Never the occlusion sweep: extended projections on separate planes.
    Off,
}

impl Serialize for SweepChoice {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            SweepChoice::Auto => s.serialize_str("auto"),
            SweepChoice::On => s.serialize_bool(true),
            SweepChoice::Off => s.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for SweepChoice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Bool(bool),
            Name(String),
        }
        match Repr::deserialize(d)? {
            Repr::Bool(true) => Ok(SweepChoice::On),
            Repr::Bool(false) => Ok(SweepChoice::Off),
            Repr::Name(n) => match n.as_str() {
                "auto" => Ok(SweepChoice::Auto),
                "on" => Ok(SweepChoice::On),
                "off" => Ok(SweepChoice::Off),
                other => Err(serde::de::Error::custom(format!(
                    "{other:?}: expected true, false or \"auto\""
                ))),
            },
        }
    }
}

/// Where the planes of a direction go.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Geometric spacing between the nearest and the far occluders (default: measured best).
    #[default]
    Geometric,
    /// Weighted quantiles of the occluders' far distances (weight `extent² / distance²`).
    Quantile,
}

/// How the planes of an occlusion sweep are spaced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Spacing {
    /// The paper's rule: each step is as long as makes the kernel (the inverse image of the cell
    /// seen through one pixel of the previous plane) `K` pixels wide on the next,
    /// `ΔD = D·(K−1)·P / (C·N)` — with the resolution `N`, which the printed formula lacks.
    Kernel,
    /// `planes` planes spaced geometrically between the nearest occluders and the far ones.
    #[default]
    Geometric,
}

/// The layout of an occlusion sweep (one per direction).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SweepSettings {
    /// The most planes per direction (both spacings). Default 24.
    #[serde(rename = "sweep_planes")]
    pub planes: u32,
    /// Kernel size `K` in pixels for [`Spacing::Kernel`]. Default 5 (the paper's).
    pub kernel: u32,
    /// How the planes are spaced. Default geometric.
    #[serde(rename = "sweep_spacing")]
    pub spacing: Spacing,
}

impl SweepSettings {
    /// The defaults, as a `const fn` for presets.
    pub const fn default_settings() -> Self {
        SweepSettings {
            planes: 24,
            kernel: 5,
            spacing: Spacing::Geometric,
        }
    }
}

impl Default for SweepSettings {
    fn default() -> Self {
        Self::default_settings()
    }
}

/// A setting out of its range: the option (as the CLI spells it, without `--`), the value
/// given and what is expected. Its message reads `--OPTION VALUE: EXPECTED`.
///
/// When this occurs: [`BakeSettings::check`] (every bake calls it) found a value the baker
/// cannot use. How to handle: change that option as the message says.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("--{option} {value}: {expected}")]
pub struct SettingsError {
    /// The option, as the CLI spells it without `--` (`resolution`, `sweep-planes`, …).
    pub option: &'static str,
    /// The value given.
    pub value: String,
    /// What is expected.
    pub expected: String,
}

impl SettingsError {
    fn new(option: &'static str, value: impl ToString, expected: &str) -> Self {
        SettingsError {
            option,
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }
}

impl BakeSettings {
    /// The defaults, as a `const fn` for presets.
    pub const fn default_settings() -> Self {
        BakeSettings {
            resolution: 256,
            max_stretch: 2,
            extend: 1.5,
            planes: 4,
            slice_planes: 1,
            placement: Placement::Geometric,
            alpha_occluders: false,
            occluders: None,
            improved_projection: true,
            sweep: SweepChoice::Auto,
            sweep_settings: SweepSettings::default_settings(),
            subcell: None,
            sampling: SweepChoice::Auto,
            sampling_settings: SamplingSettings::default_settings(),
            max_pvs_triangles: None,
            min_cell_size: None,
            occluder_min_solid_angle: 0.0,
            rsf: SweepChoice::Auto,
            rsf_resolution: 256,
            up: UpAxis::Y,
            alpha_cards: AlphaCards::Coverage,
            alpha_mips: 0,
            alpha_card_polygons: 4,
            alpha_missing: AlphaMissing::Error,
        }
    }

    /// Checks the values.
    ///
    /// # Errors
    /// The first option out of its range, with its value and what is expected.
    pub fn check(&self) -> Result<(), SettingsError> {
        if !self.resolution.is_power_of_two() || !(4..=8192).contains(&self.resolution) {
            return Err(SettingsError::new(
                "resolution",
                self.resolution,
                "must be a power of two between 4 and 8192 (e.g. 256)",
            ));
        }
        if !self.max_stretch.is_power_of_two() || self.max_stretch > 64 {
            return Err(SettingsError::new(
                "max-stretch",
                self.max_stretch,
                "must be a power of two between 1 (square maps) and 64",
            ));
        }
        if !(self.extend.is_finite() && self.extend >= 1.0) {
            return Err(SettingsError::new(
                "extend",
                self.extend,
                "must be a number ≥ 1 (e.g. 1.5)",
            ));
        }
        if self.planes == 0 || self.planes > 64 {
            return Err(SettingsError::new(
                "planes",
                self.planes,
                "must be between 1 and 64",
            ));
        }
        let sw = &self.sweep_settings;
        if sw.planes == 0 || sw.planes > 256 {
            return Err(SettingsError::new(
                "sweep-planes",
                sw.planes,
                "must be between 1 and 256",
            ));
        }
        if !(2..=64).contains(&sw.kernel) {
            return Err(SettingsError::new(
                "kernel",
                sw.kernel,
                "must be between 2 and 64 pixels (the paper uses 5)",
            ));
        }
        if let Some(s) = self.subcell
            && !(s.is_finite() && s > 0.0)
        {
            return Err(SettingsError::new(
                "subcell",
                s,
                "must be a positive size in scene units (e.g. 1)",
            ));
        }
        let sa = &self.sampling_settings;
        if let Some(e) = sa.eps
            && !(e.is_finite() && e > 0.0)
        {
            return Err(SettingsError::new(
                "sampling-eps",
                e,
                "must be a positive distance in scene units (e.g. 0.05 for leaves 0.5 across)",
            ));
        }
        if !(0.0..=1.0).contains(&sa.probe) {
            return Err(SettingsError::new(
                "sampling-probe",
                sa.probe,
                "must be a fraction between 0 (sample every level whole) and 1 (e.g. 0.01)",
            ));
        }
        if !(0.0..=1.0).contains(&sa.probe_cull) {
            return Err(SettingsError::new(
                "sampling-probe-cull",
                sa.probe_cull,
                "must be a fraction between 0 (a probe need prove only one object) and 1 (e.g. 0.4)",
            ));
        }
        if !(sa.probe_pay.is_finite() && sa.probe_pay >= 0.0) {
            return Err(SettingsError::new(
                "sampling-probe-pay",
                sa.probe_pay,
                "must be a ratio of at least 0 (0: no estimate of what a level saves; e.g. 1)",
            ));
        }
        if let Some(e) = sa.max_eps
            && !(e.is_finite() && e > 0.0)
        {
            return Err(SettingsError::new(
                "sampling-max-eps",
                e,
                "must be a positive distance in scene units (e.g. 0.2 for leaves 0.5 across)",
            ));
        }
        if sa.levels > SamplingSettings::MAX_LEVELS {
            return Err(SettingsError::new(
                "sampling-levels",
                sa.levels,
                "must be between 0 and 12",
            ));
        }
        if let Some(t) = sa.budget_seconds
            && !(t.is_finite() && t > 0.0)
        {
            return Err(SettingsError::new(
                "sampling-budget",
                format!("{t}s"),
                "must be a positive number of points (e.g. 50000) or seconds (e.g. 30s)",
            ));
        }
        if sa.budget_points == 0 {
            return Err(SettingsError::new(
                "sampling-budget",
                0,
                "must be a positive number of points (e.g. 50000) or seconds (e.g. 30s)",
            ));
        }
        if let Some(r) = sa.resolution
            && !(16..=2048).contains(&r)
        {
            return Err(SettingsError::new(
                "sampling-resolution",
                r,
                "must be between 16 and 2048 pixels per 90° view (e.g. 128)",
            ));
        }
        if !(sa.band_ratio == 0.0 || (sa.band_ratio > 1.0 && sa.band_ratio <= 16.0)) {
            return Err(SettingsError::new(
                "sampling-band-ratio",
                sa.band_ratio,
                "must be 0 (one render per sample point) or a ratio above 1 and at most 16 (e.g. 1.41)",
            ));
        }
        if self.max_pvs_triangles == Some(0) {
            return Err(SettingsError::new(
                "max-pvs-triangles",
                0,
                "must be a positive number of triangles (e.g. 200000)",
            ));
        }
        if let Some(m) = self.min_cell_size
            && !(m.is_finite() && m > 0.0)
        {
            return Err(SettingsError::new(
                "min-cell-size",
                m,
                "must be a positive size in scene units (e.g. 1)",
            ));
        }
        let sa = self.occluder_min_solid_angle;
        if !(sa.is_finite() && (0.0..4.0 * std::f64::consts::PI).contains(&sa)) {
            return Err(SettingsError::new(
                "occluder-min-solid-angle",
                sa,
                "must be a solid angle in steradians from 0 (off) to below 4π (e.g. 0.001)",
            ));
        }
        if !(8..=4096).contains(&self.rsf_resolution) {
            return Err(SettingsError::new(
                "rsf-resolution",
                self.rsf_resolution,
                "must be between 8 and 4096 pixels per side (e.g. 512)",
            ));
        }
        if self.alpha_mips > 32 {
            return Err(SettingsError::new(
                "alpha-mips",
                self.alpha_mips,
                "must be 0 (all levels) or a number of mip levels up to 32 (e.g. 4)",
            ));
        }
        if !(1..=64).contains(&self.alpha_card_polygons) {
            return Err(SettingsError::new(
                "alpha-card-polygons",
                self.alpha_card_polygons,
                "must be between 1 and 64 polygons per card (e.g. 4)",
            ));
        }
        if self.slice_planes > 16 {
            return Err(SettingsError::new(
                "slice-planes",
                self.slice_planes,
                "must be between 0 and 16",
            ));
        }
        Ok(())
    }
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self::default_settings()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_automatic_sampling_resolution_follows_h_over_eps_within_its_bounds() {
        let (lo, hi) = SamplingSettings::AUTO_RESOLUTION;
        // Powers of two, nearest in ratio to 8·h/ε: 8·64 = 512; 8·90 = 720 → 512 (√2·512 = 724).
        assert_eq!(SamplingSettings::auto_resolution(64.0, 1.0), 512);
        assert_eq!(SamplingSettings::auto_resolution(90.0, 1.0), 512);
        assert_eq!(SamplingSettings::auto_resolution(91.0, 1.0), 1024);
        // Halving ε doubles it; clamped at both ends; no hit (NaN) or nonsense gives the least.
        let mut last = 0;
        for k in 0..16 {
            let r = SamplingSettings::auto_resolution(1.0, 0.5f64.powi(k));
            assert!(
                r.is_power_of_two() && (lo..=hi).contains(&r) && r >= last,
                "{k} {r}"
            );
            last = r;
        }
        assert_eq!(last, hi);
        assert_eq!(SamplingSettings::auto_resolution(1.0, 10.0), lo);
        for h in [f64::NAN, f64::INFINITY, 0.0, -1.0] {
            assert_eq!(SamplingSettings::auto_resolution(h, 0.1), lo, "{h}");
        }
    }

    #[test]
    fn errors_name_the_option_the_value_and_what_is_expected() {
        let s = BakeSettings {
            resolution: 300,
            ..BakeSettings::default()
        };
        let err = s.check().unwrap_err();
        assert_eq!(err.option, "resolution");
        assert_eq!(err.value, "300");
        assert_eq!(
            err.to_string(),
            "--resolution 300: must be a power of two between 4 and 8192 (e.g. 256)"
        );
        let s = BakeSettings {
            sweep_settings: SweepSettings {
                kernel: 1,
                ..SweepSettings::default()
            },
            ..BakeSettings::default()
        };
        assert_eq!(s.check().unwrap_err().option, "kernel");
        assert!(BakeSettings::default().check().is_ok());
    }

    #[test]
    fn the_recorded_form_has_the_documents_keys_and_reads_back() {
        let s = BakeSettings {
            sweep: SweepChoice::On,
            subcell: Some(2.0),
            placement: Placement::Quantile,
            ..BakeSettings::default()
        };
        let v = serde_json::to_value(&s).unwrap();
        for key in [
            "resolution",
            "max_stretch",
            "extend",
            "planes",
            "slice_planes",
            "placement",
            "alpha_occluders",
            "occluders",
            "improved_projection",
            "sweep",
            "sweep_planes",
            "kernel",
            "sweep_spacing",
            "subcell",
        ] {
            assert!(v.get(key).is_some(), "{key} in {v}");
        }
        assert_eq!(v["sweep"], true);
        assert_eq!(v["placement"], "quantile");
        assert_eq!(v["sweep_spacing"], "geometric");
        assert_eq!(serde_json::from_value::<BakeSettings>(v).unwrap(), s);
        let auto = serde_json::to_value(BakeSettings::default()).unwrap();
        assert_eq!(auto["sweep"], "auto");
    }

    #[test]
    fn documents_from_older_versions_read_as_their_bakes_ran() {
        // Before the sweep (no sweep fields) and before stretched maps (max_stretch 0).
        let old: BakeSettings =
            serde_json::from_str(r#"{"resolution": 512, "planes": 8, "max_stretch": 0}"#).unwrap();
        assert_eq!(old.resolution, 512);
        assert_eq!(old.planes, 8);
        assert_eq!(old.max_stretch, 1);
        assert_eq!(old.sweep, SweepChoice::Off);
        assert_eq!(old.subcell, None);
        assert_eq!(old.sweep_settings, SweepSettings::default());
        assert_eq!(old.extend, 1.5);
        let older: BakeSettings = serde_json::from_str("{}").unwrap();
        assert_eq!(older.max_stretch, 1);
        assert!(serde_json::from_str::<BakeSettings>(r#"{"sweep": "maybe"}"#).is_err());
        assert!(serde_json::from_str::<BakeSettings>(r#"{"placement": "random"}"#).is_err());
    }
}
