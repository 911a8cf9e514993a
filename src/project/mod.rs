//! Extended projections (Durand et al. 2000): occluders cut into convex parts
//! ([`occluders`]), occludee Projections ([`occludee`]), slices of closed objects ([`slice`](mod@slice)),
//! and the placement and fitting of each cell's projection planes ([`planes`]).

pub mod occludee;
pub mod occluders;
pub mod planes;
pub mod slice;
