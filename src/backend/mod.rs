//! The raster work of a bake — occluder extended projections, Depth Maps — behind one trait,
//! so that the CPU backend ([`cpu`]) and the wgpu backend ([`gpu`]) give the same answers.
//!
//! Every backend implements the raster contract stated in [`crate::plane`]: a
//! [`plane::PlaneJob`] in, a [`plane::DepthMap`] out, occluders covering only whole pixels
//! inside all 8 views, slices, and the exact reprojection filter. The part of the work both
//! backends share — the occluder's Projection polygon, the slice fill and the contract's
//! brute-force definition — is [`coverage`]; each backend only rasterises the polygons its own
//! way (spans on the CPU, a fragment shader on the GPU).
//!
//! The result may differ between backends only on pixels where a view's edge passes within a
//! rounding error of a pixel corner.

pub mod coverage;
pub mod cpu;
pub mod gpu;

use crate::plane;

/// Backend failures (device lost, out of memory, no adapter…).
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// No usable GPU adapter; the message says why (none found, or none with the needed features).
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// The device failed while rendering (device lost, out of memory, failed read-back…).
    #[error("GPU error: {0}")]
    Device(String),
}

/// The raster work of a bake.
pub trait RasterBackend: Send + Sync {
    /// Short name for summaries: `cpu` or `gpu`.
    fn name(&self) -> &'static str;
    /// The adapter's name where there is one (e.g. `llvmpipe (LLVM 15.0.7, 256 bits)`).
    fn adapter(&self) -> Option<String> {
        None
    }
    /// A line of counters for the bake summary (passes, draws, bytes read back per cell), where
    /// the backend keeps them.
    fn stats_summary(&self, _cells: usize) -> Option<String> {
        None
    }
    /// Rasterises the jobs' occluder Projections and slices into one Depth Map per job, in
    /// order. Jobs are independent; a backend may run them in any order or concurrently.
    ///
    /// # Errors
    /// [`BackendError`] when the device fails; never a partial result.
    fn render(&self, jobs: &[plane::PlaneJob]) -> Result<Vec<plane::DepthMap>, BackendError>;
}
