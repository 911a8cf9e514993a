//! Checking a PVS against ray-sampled ground truth: the library side of `umbrasweep validate`
//! (the command itself, its flags, table printing and exit codes, lives in the binary). No
//! output of its own: progress goes to an optional [`CheckOptions::progress`] callback.
//!
//! For every cell, [`sample_cell`] casts rays from points strictly inside the cell through a
//! BVH of the whole scene ([`SceneRays`]); the first triangle a ray hits names a visible object
//! (see-through triangles name theirs and let the ray go on, unless the PVS was baked with
//! `alpha_occluders`). The sampled visible set (VS) can only under-estimate the exact one, so
//! an object in the VS but not in the PVS is a proven false cull, reported with the ray that
//! proves it. [`check`] does this for a whole [`PvsDocument`](crate::pvs::PvsDocument) and
//! returns a [`Report`].
//!
//! With [`CheckOptions::hunt`] (`--hunt`) the visible set is not sampled: each cell's budget
//! is split evenly between the objects its PVS culls ([`rays_per_culled_object`]), and rays
//! from the cell are aimed at points of each (on its surface, inside its bounds, near its
//! triangles' edges and vertices); one that reaches the culled object proves a false cull.
//! The plain sampling finds a false cull only if it finds the object among all the visible
//! ones; the hunt gives every culled object its share of the whole budget.
//!
//! With [`CheckOptions::confirm_rays`] (`--confirm-rays`) the plain sampling is followed by
//! rays aimed, the hunt's way, at the objects of each cell's PVS that the sample did not see:
//! those they reach are visible too, and `PVS/VS+` measures the PVS against that fuller
//! visible set (the sample alone misses objects seen through slits, so `PVS/VS` over-states
//! how loose a tight PVS is).
//!
//! * `trace` — the BVH, the watertight ray/triangle test, point sampling on objects;
//! * `sample` — ray budget, phases, random streams, deterministic merge;
//! * `hunt` — `--hunt`: rays aimed at the culled objects, in deterministic waves;
//! * `confirm` — `--confirm-rays`: rays aimed at the PVS objects the sample did not see;
//! * `check` — input checks, the report and its table.
//!
//! ```no_run
//! use umbrasweep::validate::{CheckOptions, SceneRays, check_with, sample_cell};
//! # fn f(scene: &umbrasweep::scene::Scene, doc: &umbrasweep::pvs::PvsDocument) {
//! let rays = SceneRays::new(scene);
//! let cell = umbrasweep::geom::Aabb::new(glam::Vec3::ZERO, glam::Vec3::ONE);
//! let vs = sample_cell(&rays, scene, cell, 100_000, 1, 0, false);
//! println!("{} objects seen", vs.visible.len());
//! let report = check_with(&rays, scene, doc, &CheckOptions::default()).unwrap();
//! assert_eq!(report.false_culls, 0);
//! # }
//! ```

mod check;
mod confirm;
mod hunt;
mod sample;
mod trace;

pub use check::{
    CellReport, CheckOptions, FalseCull, Progress, ProgressFn, Report, ValidateError, cell_report,
    check, check_input, check_with,
};
pub use confirm::CONFIRM_ROUNDS;
pub use hunt::{HUNT_PHASE, rays_per_culled_object};
pub use sample::{CHUNK, CellSample, Witness, sample_cell};
pub(crate) use sample::{chunk_rng, sphere_direction, uniform_origin};
pub use trace::{SLOW_BUILD_RAYS_PER_TRIANGLE, SceneRays, TraceHit};
