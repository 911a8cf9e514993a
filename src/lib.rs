//! # umbrasweep
//!
//! Conservative from-region visibility: for each view cell (a box the camera may be anywhere
//! inside) umbrasweep computes the potentially visible set (PVS) of scene objects, using the
//! extended projections of Durand et al. (SIGGRAPH 2000).
//!
//! Data flows one way: [`scene`] → [`cells`] → per-cell culling → [`pvs`] → files, and [`bake`](mod@bake)
//! ties the stages together. Per cell, [`project`] lays out the projection planes and the
//! occlusion [`sweep`] carries umbra from one plane to the next; both describe their work as the
//! data of the raster contract, [`plane`], which a [`backend`] (CPU or GPU) turns into Depth
//! Maps that [`hdm`] tests occludees against. The imports follow the same direction: [`plane`]
//! depends only on [`geom`], and [`project`], [`sweep`], [`backend`] and [`hdm`] each depend on
//! [`plane`], never on one another.
//!
//! Features: `cli` (the default) adds the `umbrasweep` command; `bake` is this whole library
//! without the command's dependencies; `runtime` alone (`--no-default-features --features
//! runtime`) builds only [`geom`], [`settings`] and [`pvs`], the parts an engine needs at run
//! time.
//!
//! ```no_run
//! # #[cfg(feature = "bake")] {
//! use umbrasweep::{BakeSettings, CpuBackend, bake, cells, scene};
//! let scene = scene::load("data/demo_city.obj".as_ref()).unwrap();
//! let cells = cells::load_json("data/demo_city_cells.json".as_ref()).unwrap();
//! let result = bake(&scene, &cells, &BakeSettings::default(), &CpuBackend::new(), None).unwrap();
//! println!("{} cells baked", result.cells.len());
//! # }
//! ```

pub mod geom;
pub mod pvs;
pub mod settings;

pub use pvs::{PvsDatabase, PvsDocument};

#[cfg(feature = "bake")]
pub use backend::{RasterBackend, cpu::CpuBackend, gpu::GpuBackend};
#[cfg(feature = "bake")]
pub use bake::{BakeError, BakeResult, BakeSettings, Culler, SweepChoice, bake, to_document};
#[cfg(feature = "bake")]
pub use scene::Scene;

#[cfg(feature = "bake")]
pub mod backend;
#[cfg(feature = "bake")]
pub mod bake;
#[cfg(feature = "bake")]
pub mod bench;
#[cfg(feature = "bake")]
pub mod cells;
/// Scene generators (`umbrasweep gen`); files live in `src/gen/` (`gen` is reserved in Rust 2024).
#[cfg(feature = "bake")]
#[path = "gen/mod.rs"]
pub mod generate;
#[cfg(feature = "bake")]
pub mod hdm;
#[cfg(feature = "bake")]
pub mod inspect;
#[cfg(feature = "bake")]
pub mod plane;
#[cfg(feature = "bake")]
pub mod project;
#[cfg(feature = "bake")]
pub mod rsf;
#[cfg(feature = "bake")]
pub mod sampler;
#[cfg(feature = "bake")]
pub mod scene;
#[cfg(feature = "bake")]
pub mod sweep;
#[cfg(feature = "bake")]
pub mod util;
#[cfg(feature = "bake")]
pub mod validate;
