//! The extended-projection cullers (Durand et al. 2000): for every direction of a cell,
//! projection planes receive the extended Projections of the occluders beyond the cell's face
//! (separate planes, §2–4), or a sweep of parallel planes each carrying the umbra of the ones
//! in front (the occlusion sweep, §5, [`crate::sweep`]); the backend rasterises them, a
//! Hierarchical Depth Map is built per plane and the object BVH is walked against it, stopping
//! at hidden and at fully visible nodes.
//!
//! # Why it is conservative
//! A pixel of a Depth Map is set only where every ray from the cell through the whole pixel
//! square is blocked (one convex occluder's Projection covers it, or a reprojection proved it;
//! see [`crate::backend`] and [`crate::sweep`]), with the occluder's farthest Depth rounded up.
//! An occludee box is hidden when every pixel under a rectangle holding all its views (the
//! standard Projection, exact extremes) or satisfying Property 2 (the improved Projections,
//! [`crate::project::occludee::improved_rects`]) holds a Depth strictly below the box's nearest
//! Depth rounded down. Objects touching the cell are always visible.
//!
//! # Tests on the device
//! On a backend that answers occludee tests itself ([`RasterBackend::tests_on_device`]), when
//! nothing wants the maps ([`super::NoPlanes`]), each separate plane's walk is run twice: first
//! over every node, object and piece not yet decided, recording each box it tests
//! (`Prepared::record_queries`, each answered "partly covered" so that the walk goes on below
//! it — but for boxes answered without the map, [`answer_without_test`]: those touching the
//! cell or not beyond its face are open, and those whose Projection lies beside the plane
//! `Empty`, which prunes the walk there as it will prune the real walk), then, after the
//! backend has answered the boxes with its own pyramid of the map
//! ([`RasterBackend::render_tested`]: the device computes each box's rectangles itself,
//! `shaders/boxes.wgsl`), for real, reading each box's answer by its [`BoxId`]. The real walk
//! asks only recorded boxes (it skips more as it marks, never less), and each answer is the
//! one [`box_coverage`] gives on that map, so the result is the walk's on the CPU; a box it
//! did not record would stay open (a debug assertion catches it).
//!
//! # Sweep planes kept on the device
//! On a backend that also keeps maps ([`RasterBackend::keeps_maps`]) a sweep plane's map stays
//! there too ([`RasterBackend::render_kept`]): what the sweep needs of it comes back without
//! its pixels. Its walk is recorded as above (with the plane's usual reach), and so is every
//! test the next plane's planning may ask of it: leaving out occluders this plane proves
//! hidden walks the object hierarchy over the next slab (`Prepared::gather_slab`), and that
//! walk is run once in advance with every box answered "not hidden", recording each test
//! (`Prepared::record_leave_out`) — the real walk later asks a subset. The umbra's bounding
//! box and whether the umbra covers the whole plane come back as numbers, and later planes
//! reproject from the map where it lies. A plane that turns out to end its direction tests
//! every box behind it, not only those within reach: it is rendered again with those tests
//! (`Prepared::retest_ending`). Past a box test per
//! [`RasterBackend::pixels_per_device_test`] pixels the map comes back as before
//! ([`crate::backend::PIXELS_PER_DEVICE_TEST`]). So every answer is the one the map's
//! pyramid gives on the CPU, and the PVS is the CPU backend's.

use super::BakeError;
use super::pipeline::{CullState, Culler, CullerWork, PlaneSink};
use super::prepare::Prepared;
use crate::backend::RasterBackend;
use crate::geom::{Aabb, DAabb};
use crate::hdm::{Coverage, Hdm};
use crate::plane::{
    DepthMap, NOT_RESIDENT, OpenSides, PlaneFrame, PlaneJob, PlaneQueries, PlaneResult,
    Reprojection,
};
use crate::project::occludee::{BoxId, answer_without_test, box_coverage};
use crate::project::planes::{
    DirectionPlan, LeaveOut, PlaneSettings, SweepInputs, plan_directions, plane_job,
};
use obvhs::bvh2::Bvh2;
use rayon::prelude::*;
use std::cell::RefCell;
use std::sync::Arc;

/// Extended projections on a cell's planes: separate planes, or the occlusion sweep.
pub struct PlaneCuller {
    /// Sweep each direction (§5) instead of separate planes.
    pub sweep: bool,
}

impl Culler for PlaneCuller {
    fn name(&self) -> &'static str {
        if self.sweep {
            super::OCCLUSION_SWEEP
        } else {
            super::EXTENDED_PROJECTIONS
        }
    }

    fn cull(
        &self,
        prepared: &Prepared,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        state: &mut CullState,
        observe: &mut dyn PlaneSink,
    ) -> Result<CullerWork, BakeError> {
        prepared.cull_planes(cell, backend, state, observe, self.sweep)
    }
}

/// The most box tests a plane's recording may hold: one per
/// [`RasterBackend::pixels_per_device_test`] pixels of its map (at least 16).
fn max_recorded(frame: &PlaneFrame, share: usize) -> usize {
    (frame.width as usize * frame.height as usize / share.max(1)).max(16)
}

/// In a sweep, a plane at distance `t` beyond the face tests only boxes starting within
/// `SWEEP_TEST_REACH · t` (the last plane tests all). Measured on 5 path cells: reach 4, 8,
/// 16 and unbounded culled 67.0, 71.1, 72.0 and 72.1 % of the paper-size forest, with 16 as
/// fast as 8 and unbounded a fifth slower; the coarse forest gained 0.4 points from 8 to 16.
pub const SWEEP_TEST_REACH: f64 = 16.0;

impl Prepared<'_> {
    /// Extended projections on the planes of every direction of one (sub-)cell, separate
    /// planes or (`sweep`) an occlusion sweep: marks in `state.hidden` what they prove hidden
    /// and returns the planes rendered and the occluder Projections sent. Objects already
    /// hidden are not tested and do not occlude; objects in `state.known_visible` are not
    /// tested (their result does not matter to the caller) but still occlude.
    pub(super) fn cull_planes(
        &self,
        cell: &Aabb,
        backend: &dyn RasterBackend,
        state: &mut CullState,
        observe: &mut dyn PlaneSink,
        sweep: bool,
    ) -> Result<CullerWork, BakeError> {
        let known_visible = state.known_visible;
        let mut hidden = std::mem::take(&mut state.hidden);
        let mut node_done = vec![false; self.bvh.as_ref().map_or(0, |b| b.nodes.len())];
        if let Some(bvh) = &self.bvh
            && (known_visible.is_some() || hidden.contains(&true))
        {
            // Nodes whose objects are all hidden (by earlier cullers) or known visible.
            let done: Vec<bool> = match known_visible {
                Some(k) => hidden.iter().zip(k).map(|(&h, &v)| h || v).collect(),
                None => hidden.clone(),
            };
            mark_done(bvh, &done, &mut node_done);
        }
        let skip_test =
            |o: usize, hidden: &[bool]| hidden[o] || known_visible.is_some_and(|k| k[o]);
        let cell64 = cell.to_f64();
        let ps = PlaneSettings::of(&self.settings, sweep);
        let plans = plan_directions(&cell64, &self.occluders, &self.sliceable, &ps);
        let rounds = plans.iter().map(|p| p.distances.len()).max().unwrap_or(0);
        let mut work = CullerWork::default();
        let mut dirs: Vec<DirectionState> = (0..plans.len()).map(|_| Default::default()).collect();
        let mut piece_hidden = vec![false; self.piece_boxes.len()];
        // Round k renders the k-th plane of every direction (nearest first); occluders of
        // objects hidden by earlier rounds are left out of later ones.
        for k in 0..rounds {
            let round = Round {
                k,
                plans: &plans,
                settings: &ps,
                share: backend.pixels_per_device_test(),
            };
            let planned = self.plan_round(&round, &dirs, &hidden, &node_done);
            if planned.is_empty() {
                continue;
            }
            // Tests can be answered on the device when no map is wanted here: every test the
            // traversal may ask, from what is known now; and a sweep plane's map can stay
            // there with every test the next plane's planning may ask of it.
            let on_device = backend.tests_on_device() && !observe.wants_maps();
            let keep_maps = on_device && backend.keeps_maps();
            let queries: Vec<Option<Queries>> = if on_device {
                planned
                    .par_iter()
                    .map(|p| {
                        let sweep = plans[p.dir].is_sweep();
                        if sweep && !keep_maps {
                            return None;
                        }
                        let q = self.record_queries(
                            &p.job,
                            round.share,
                            round.range(p.dir, false),
                            &hidden,
                            &node_done,
                            &piece_hidden,
                            &skip_test,
                        )?;
                        if sweep {
                            self.record_leave_out(&round, p, &hidden, &node_done, q)
                        } else {
                            Some(q)
                        }
                    })
                    .collect()
            } else {
                planned.iter().map(|_| None).collect()
            };
            let keep: Vec<bool> = (planned.iter().zip(&queries))
                .map(|(p, q)| q.is_some() && plans[p.dir].is_sweep())
                .collect();
            let (queries, index) = split_queries(
                queries,
                self.settings.improved_projection,
                self.occludee_table,
            );
            let mut planned = planned;
            for p in &mut planned {
                p.job.occluders.table = self.occluder_table;
            }
            let mut rendered = render_round(&round, backend, planned, (queries, index), &keep)?;
            self.retest_ending(
                &round,
                backend,
                &mut rendered,
                (&hidden, &node_done, &piece_hidden),
                &skip_test,
            )?;
            for r in &rendered {
                if let Tested::Map { map, hdm } = &r.tested {
                    observe.plane(&r.job, map, hdm);
                }
                let after = round.range(r.dir, r.ends);
                self.traverse(
                    &r.job,
                    &r.tested.tests(),
                    after,
                    &mut hidden,
                    &mut node_done,
                    &mut piece_hidden,
                    &skip_test,
                );
            }
            work.planes += rendered.len();
            work.occluders_projected += rendered
                .iter()
                .map(|r| r.job.occluders.len())
                .sum::<usize>();
            carry_round(&round, &mut dirs, rendered);
        }
        state.hidden = hidden;
        Ok(work)
    }

    /// The planes of round `k`, one per direction that has a `k`-th plane and is not
    /// finished, planned in parallel: each plane's job (occluders, slices, reprojections) and
    /// its relevant region. A plane with nothing beyond it, and a sweep plane with nothing to
    /// render, are left out.
    fn plan_round(
        &self,
        round: &Round,
        dirs: &[DirectionState],
        hidden: &[bool],
        node_done: &[bool],
    ) -> Vec<PlannedPlane> {
        let k = round.k;
        round
            .plans
            .par_iter()
            .enumerate()
            .filter(|(d, p)| k < p.distances.len() && !dirs[*d].finished)
            .filter_map(|(d, p)| {
                let dir = &dirs[d];
                // The rectangle holds what the previous plane's umbra may carry (older
                // planes' umbra reaching further out is left out: it would cost
                // resolution everywhere for a few pixels at the edge).
                let relevant = p.relevant_rect(k, &self.bounds)?;
                let carried = dir.history.last().and_then(|e| {
                    crate::sweep::carried_rect(&e.frame, e.umbra?, e.open, p.distance(k))
                });
                let leave_out = LeaveOut {
                    object: &|o| hidden[o as usize],
                    // Occluders the previous plane already proves hidden add nothing (only the
                    // plane just in front: what a kept map answers was recorded for it).
                    hidden: &|id, b| {
                        dir.prev.as_ref().is_some_and(|prev| {
                            prev.index + 1 == k
                                && self.test_box(
                                    &prev.frame,
                                    &prev.tested.tests(),
                                    id,
                                    b,
                                    (0.0, f64::INFINITY),
                                ) == Coverage::Hidden
                        })
                    },
                };
                let slab = p
                    .is_sweep()
                    .then(|| self.gather_slab(p, k, &leave_out, hidden, node_done));
                let mut job = plane_job(
                    p,
                    k,
                    self.scene,
                    &self.sliceable,
                    round.settings,
                    &leave_out,
                    SweepInputs {
                        carried,
                        relevant: Some(relevant),
                        slab: slab.as_ref(),
                    },
                )?;
                if p.is_sweep() && carried.is_some() {
                    job.reproject = reprojections(&dir.history, &job.frame, p.distance(k));
                }
                if p.is_sweep()
                    && job.occluders.is_empty()
                    && job.slices.is_empty()
                    && job.reproject.is_empty()
                {
                    return None;
                }
                Some(PlannedPlane {
                    dir: d,
                    job,
                    relevant,
                })
            })
            .collect()
    }

    /// The occluder parts of sweep plane `k`'s slab: a walk of the object hierarchy that
    /// descends only into nodes overlapping the slab and its frustum and not proven hidden by
    /// the previous plane (their objects' occluders would add nothing), then the parts of the
    /// objects reached ([`crate::project::planes::gather_slab`] filters and cuts them).
    fn gather_slab(
        &self,
        plan: &crate::project::planes::DirectionPlan,
        k: usize,
        leave_out: &LeaveOut,
        hidden: &[bool],
        node_hidden: &[bool],
    ) -> crate::project::planes::SlabParts {
        let mut parts: Vec<u32> = Vec::new();
        if let Some(bvh) = &self.bvh {
            let start = plan.slab_start(k);
            let mut stack = vec![0u32];
            while let Some(ni) = stack.pop() {
                let node = &bvh.nodes[ni as usize];
                let b = DAabb {
                    min: glam::Vec3::from(node.aabb.min).as_dvec3(),
                    max: glam::Vec3::from(node.aabb.max).as_dvec3(),
                };
                // (Object bounds hold their parts: merged polygons are built within objects'
                // triangles or attributed to one of them, and a part left out only loosens.)
                if node_hidden[ni as usize] && self.settings.subcell.is_none() {
                    continue;
                }
                if !plan.slab_may_hold(k, &b) {
                    continue;
                }
                if plan.distances_of(&b).0 > start && (leave_out.hidden)(BoxId::Node(ni), &b) {
                    continue;
                }
                if node.is_leaf() {
                    for j in 0..node.prim_count {
                        let o = bvh.primitive_indices[(node.first_index + j) as usize] as usize;
                        if !hidden[o] {
                            parts.extend_from_slice(&self.object_parts[o]);
                        }
                    }
                } else {
                    stack.push(node.first_index);
                    stack.push(node.first_index + 1);
                }
            }
        }
        crate::project::planes::gather_slab(plan, k, &self.occluders, parts, leave_out)
    }

    /// Tests the object BVH against one plane, marking hidden objects, and nodes whose whole
    /// subtree is hidden (skipped on the following planes).
    #[expect(
        clippy::too_many_arguments,
        reason = "the BVH walk needs the plane job, its tests, the slab range and three output masks; bundling them into a struct would only move the list"
    )]
    fn traverse(
        &self,
        job: &PlaneJob,
        tests: &Tests,
        after: (f64, f64),
        hidden: &mut [bool],
        node_hidden: &mut [bool],
        piece_hidden: &mut [bool],
        skip_test: &dyn Fn(usize, &[bool]) -> bool,
    ) {
        let Some(bvh) = &self.bvh else { return };
        let mut stack = vec![0u32];
        while let Some(ni) = stack.pop() {
            if node_hidden[ni as usize] {
                continue;
            }
            let node = &bvh.nodes[ni as usize];
            let b = DAabb {
                min: glam::Vec3::from(node.aabb.min).as_dvec3(),
                max: glam::Vec3::from(node.aabb.max).as_dvec3(),
            };
            match self.test_box(&job.frame, tests, BoxId::Node(ni), &b, after) {
                Coverage::Hidden => {
                    mark_hidden(bvh, ni, hidden, node_hidden);
                    continue;
                }
                Coverage::Empty => continue,
                Coverage::Partial => {}
            }
            if node.is_leaf() {
                for k in 0..node.prim_count {
                    let o = bvh.primitive_indices[(node.first_index + k) as usize] as usize;
                    if skip_test(o, hidden) {
                        continue;
                    }
                    let ob = self.scene.objects[o].bounds.to_f64();
                    let id = BoxId::Object(o as u32);
                    match self.test_box(&job.frame, tests, id, &ob, after) {
                        Coverage::Hidden => hidden[o] = true,
                        Coverage::Empty => {}
                        Coverage::Partial => {
                            // Pieces of the object may be hidden on different planes.
                            let r = self.pieces[o].clone();
                            if r.is_empty() {
                                continue;
                            }
                            let mut all = true;
                            for pi in r {
                                let pi = pi as usize;
                                if !piece_hidden[pi] {
                                    piece_hidden[pi] = self.test_box(
                                        &job.frame,
                                        tests,
                                        BoxId::Piece(pi as u32),
                                        &self.piece_boxes[pi],
                                        after,
                                    ) == Coverage::Hidden;
                                }
                                all &= piece_hidden[pi];
                                if !all {
                                    // A piece left visible here: the object stays visible on
                                    // this plane, and its other pieces are tried on later
                                    // planes (testing them all here culled 0.2 points more
                                    // of the forests' objects for a fifth more bake time).
                                    break;
                                }
                            }
                            hidden[o] |= all;
                        }
                    }
                }
                node_hidden[ni as usize] = (0..node.prim_count).all(|k| {
                    skip_test(
                        bvh.primitive_indices[(node.first_index + k) as usize] as usize,
                        hidden,
                    )
                });
            } else {
                stack.push(node.first_index);
                stack.push(node.first_index + 1);
            }
        }
    }

    /// Every box [`Self::traverse`] may test on the plane of `job` from this state on: every
    /// node not done, every object of theirs still to test and every piece of those not yet
    /// hidden, except below boxes known `Empty` without the map — what the traversal reaches
    /// is a subset, as it only skips more while it marks. For a backend to answer on its
    /// device ([`RasterBackend::render_tested`]). `None` as soon as it records more box tests
    /// than one per `share` pixels of the plane's map (the map then comes back instead).
    #[expect(
        clippy::too_many_arguments,
        reason = "the traversal's own inputs, read-only here"
    )]
    fn record_queries(
        &self,
        job: &PlaneJob,
        share: usize,
        after: (f64, f64),
        hidden: &[bool],
        node_done: &[bool],
        piece_hidden: &[bool],
        skip_test: &(dyn Fn(usize, &[bool]) -> bool + Sync),
    ) -> Option<Queries> {
        let max = max_recorded(&job.frame, share);
        let queries = RefCell::new(Queries::new(self.box_counts()));
        let tests = Tests::Record(&queries);
        let Some(bvh) = &self.bvh else {
            return Some(Queries::new(self.box_counts()));
        };
        // The traversal's order does not matter here, but its pruning by reach does: a box
        // out of reach is answered `Empty` without a test, so the walk asks nothing below it
        // (a child's box lies inside its parent's, a piece's inside its object's).
        let frame = &job.frame;
        let mut stack = vec![0u32];
        while let Some(ni) = stack.pop() {
            let node = &bvh.nodes[ni as usize];
            if node_done[ni as usize] {
                continue;
            }
            let b = DAabb {
                min: glam::Vec3::from(node.aabb.min).as_dvec3(),
                max: glam::Vec3::from(node.aabb.max).as_dvec3(),
            };
            if !in_reach(frame, &b, after) {
                continue;
            }
            let c = self.test_box(frame, &tests, BoxId::Node(ni), &b, after);
            if queries.borrow().boxes.len() > max {
                return None;
            }
            if c == Coverage::Empty {
                // Beside the plane: so is everything below it, and the walk stops here too.
                continue;
            }
            if !node.is_leaf() {
                stack.push(node.first_index);
                stack.push(node.first_index + 1);
                continue;
            }
            for k in 0..node.prim_count {
                let o = bvh.primitive_indices[(node.first_index + k) as usize] as usize;
                if skip_test(o, hidden) {
                    continue;
                }
                let ob = self.scene.objects[o].bounds.to_f64();
                if !in_reach(frame, &ob, after) {
                    continue;
                }
                let c = self.test_box(frame, &tests, BoxId::Object(o as u32), &ob, after);
                if c == Coverage::Empty {
                    continue;
                }
                for pi in self.pieces[o].clone() {
                    let pi = pi as usize;
                    if !piece_hidden[pi] {
                        let id = BoxId::Piece(pi as u32);
                        self.test_box(frame, &tests, id, &self.piece_boxes[pi], after);
                    }
                }
                if queries.borrow().boxes.len() > max {
                    return None;
                }
            }
        }
        Some(queries.into_inner())
    }

    /// Adds to `queries` every test that planning sweep plane `k + 1` of `planned`'s direction
    /// may ask of plane `k` (`planned`) to leave out occluders it proves hidden: the walk of
    /// [`Self::gather_slab`] over that slab, run now with every box answered "not hidden"
    /// (so it descends everywhere the real walk may) and every test recorded. The real walk
    /// starts from a state with at least as many objects hidden and nodes done, so it asks a
    /// subset. `None` when the tests, with `queries`, would be more than the plane's share
    /// ([`Round::share`]; the map then comes back).
    fn record_leave_out(
        &self,
        round: &Round,
        planned: &PlannedPlane,
        hidden: &[bool],
        node_done: &[bool],
        queries: Queries,
    ) -> Option<Queries> {
        let plan = &round.plans[planned.dir];
        let next = round.k + 1;
        if next >= plan.distances.len() {
            return Some(queries);
        }
        let max = max_recorded(&planned.job.frame, round.share);
        let recorded = RefCell::new(queries);
        let tests = Tests::Record(&recorded);
        let leave_out = LeaveOut {
            object: &|o| hidden[o as usize],
            hidden: &|id, b| {
                // (Past the share the walk goes on, as planning will, recording nothing.)
                if recorded.borrow().boxes.len() <= max {
                    self.test_box(&planned.job.frame, &tests, id, b, (0.0, f64::INFINITY));
                }
                false
            },
        };
        self.gather_slab(plan, next, &leave_out, hidden, node_done);
        let recorded = recorded.into_inner();
        (recorded.boxes.len() <= max).then_some(recorded)
    }

    /// A kept sweep plane that turns out to end its direction ([`ends_sweep`]) tests every box
    /// behind it, not only those within its usual reach ([`Round::range`]), which is all its
    /// recorded tests cover: such planes are rendered again (one call for all), with their
    /// tests recorded for the whole range, or for their maps where too many boxes are
    /// undecided. They end their directions, so their kept maps are not needed any more.
    ///
    /// # Errors
    /// The backend's failure.
    fn retest_ending(
        &self,
        round: &Round,
        backend: &dyn RasterBackend,
        rendered: &mut [RenderedPlane],
        (hidden, node_done, piece_hidden): (&[bool], &[bool], &[bool]),
        skip_test: &(dyn Fn(usize, &[bool]) -> bool + Sync),
    ) -> Result<(), BakeError> {
        let again: Vec<usize> = (0..rendered.len())
            .filter(|&i| {
                let r = &rendered[i];
                matches!(r.tested, Tested::Kept { .. })
                    && r.ends
                    && round.range(r.dir, false) != round.range(r.dir, true)
            })
            .collect();
        if again.is_empty() {
            return Ok(());
        }
        let queries: Vec<Option<Queries>> = again
            .par_iter()
            .map(|&i| {
                let r = &rendered[i];
                self.record_queries(
                    &r.job,
                    round.share,
                    round.range(r.dir, true),
                    hidden,
                    node_done,
                    piece_hidden,
                    skip_test,
                )
            })
            .collect();
        let jobs: Vec<PlaneJob> = again.iter().map(|&i| rendered[i].job.clone()).collect();
        let (queries, index) = split_queries(
            queries,
            self.settings.improved_projection,
            self.occludee_table,
        );
        let results = backend.render_tested(&jobs, &queries)?;
        for ((&i, result), x) in again.iter().zip(results).zip(index) {
            rendered[i].tested = Tested::of(result, x);
        }
        Ok(())
    }

    /// The occlusion test of one box on one plane: `Hidden`; `Empty` when nothing inside the
    /// box can be hidden on this plane (it lies on the cell's side of the face, its Projection
    /// misses the plane's rectangle, or covers no occluded pixel of it — a child's Projection
    /// lies inside its parent's); `Partial` otherwise, including boxes touching the cell.
    ///
    /// `range.0` is the distance beyond the face before which nothing can be hidden on this
    /// plane: 0, or in a sweep the previous plane — every Depth of a sweep plane is at least the
    /// previous plane's, and a box entirely in front of it has a smaller Depth everywhere.
    /// Boxes starting beyond `range.1` are not tested (`Empty`, which is never a cull).
    fn test_box(
        &self,
        frame: &PlaneFrame,
        tests: &Tests,
        id: BoxId,
        b: &DAabb,
        range: (f64, f64),
    ) -> Coverage {
        if !in_reach(frame, b, range) {
            return Coverage::Empty;
        }
        match tests {
            Tests::Hdm(h) => {
                box_coverage(frame, b, self.settings.improved_projection, |q| h.answer(q))
            }
            Tests::Answers(a) => a.coverage(id),
            Tests::Record(r) => {
                // Answers known without the map are kept here (and an `Empty` one prunes the
                // walk, as it will the real walk); the others go to the device.
                let known = answer_without_test(frame, b);
                r.borrow_mut().record(id, b, known);
                known.unwrap_or(Coverage::Partial)
            }
        }
    }

    /// Every box a walk names by index ([`BoxId`] but parts), in [`BoxIndex`] slot order: the
    /// hierarchy's nodes, the objects, the pieces — each exactly as the walks test it — for a
    /// backend to keep on its device ([`RasterBackend::upload_occludee_boxes`]).
    pub(super) fn occludee_boxes(&self) -> Vec<DAabb> {
        let nodes = self.bvh.iter().flat_map(|b| &b.nodes).map(|node| DAabb {
            min: glam::Vec3::from(node.aabb.min).as_dvec3(),
            max: glam::Vec3::from(node.aabb.max).as_dvec3(),
        });
        let objects = self.scene.objects.iter().map(|o| o.bounds.to_f64());
        nodes
            .chain(objects)
            .chain(self.piece_boxes.iter().copied())
            .collect()
    }

    /// The boxes a walk names ([`BoxId`]).
    fn box_counts(&self) -> BoxCounts {
        BoxCounts {
            nodes: self.bvh.as_ref().map_or(0, |b| b.nodes.len()),
            objects: self.scene.objects.len(),
            pieces: self.piece_boxes.len(),
        }
    }
}

/// False when [`Prepared::test_box`] answers `Empty` for `b` on `frame` without a test: an empty
/// box, or one ending before `range.0` or starting beyond `range.1` (distances beyond the
/// face). A box inside one out of reach is out of reach too.
fn in_reach(frame: &PlaneFrame, b: &DAabb, range: (f64, f64)) -> bool {
    if b.is_empty() {
        return false;
    }
    let a = frame.axis;
    let (near, far) = if frame.positive {
        (b.min[a], b.max[a])
    } else {
        (b.max[a], b.min[a])
    };
    let sg = frame.sign();
    !(sg * (far - frame.face()) <= range.0 || sg * (near - frame.face()) > range.1)
}

/// True when sweep plane `k`, whose umbra covers every pixel of its map, ends its sweep: its
/// rectangle is its whole frame (cut to the relevant region), so what lies behind it in the
/// frame is hidden on it, and the direction needs no further plane.
fn ends_sweep(
    plan: &crate::project::planes::DirectionPlan,
    k: usize,
    job: &PlaneJob,
    relevant: Rect,
) -> bool {
    // The frame cut to the relevant region, computed as `plane_job` cuts the rectangle.
    plan.is_sweep()
        && job.frame.rect_min == plan.frame_min(k).max(relevant.0)
        && job.frame.rect_max == plan.frame_max(k).min(relevant.1)
}

/// A rectangle on a plane, world `(u, v)`: lower and upper corners.
type Rect = (glam::DVec2, glam::DVec2);

/// What one round of planes shares: its index (the `k`-th plane of every direction), the
/// cell's direction plans (each plane's frame holds the cell), the plane settings and the
/// device's share of box tests.
struct Round<'a> {
    k: usize,
    plans: &'a [DirectionPlan],
    settings: &'a PlaneSettings,
    /// Pixels per box test the device answers ([`RasterBackend::pixels_per_device_test`]).
    share: usize,
}

impl Round<'_> {
    /// The distances beyond the face of the boxes this round's plane of direction `dir` tests
    /// (see `test_box`'s `range`; `ends`: the plane ends its sweep). In a sweep, boxes far
    /// behind this plane wait for later planes (the last plane, or one whose umbra covers its
    /// whole frame and so ends the direction, tests everything): the umbra is rarely finished
    /// this far in front of them, and testing every box on every plane is most of a forest's
    /// bake time.
    fn range(&self, dir: usize, ends: bool) -> (f64, f64) {
        let plan = &self.plans[dir];
        let last = self.k + 1 == plan.distances.len() || ends;
        if plan.is_sweep() && !last {
            (
                plan.slab_start(self.k),
                SWEEP_TEST_REACH * plan.distance(self.k),
            )
        } else {
            (plan.slab_start(self.k), f64::INFINITY)
        }
    }
}

/// What a direction keeps from round to round.
#[derive(Default)]
struct DirectionState {
    /// In a sweep: the umbra covers the whole plane, so what lies behind within its frame is
    /// hidden on that plane already and the direction needs no further plane.
    finished: bool,
    /// In a sweep: the planes kept for reprojection ([`push_history`]).
    history: Vec<SweepPlane>,
    /// In a sweep: the last plane rendered (occluders it proves hidden are left out of the
    /// next plane).
    prev: Option<PrevPlane>,
}

/// A sweep's last rendered plane: its index, its frame and what its tests are answered by.
struct PrevPlane {
    index: usize,
    frame: PlaneFrame,
    tested: Tested,
}

/// A plane planned for rendering: its direction, its job and the relevant region of its plane.
struct PlannedPlane {
    dir: usize,
    job: PlaneJob,
    relevant: Rect,
}

/// A rendered plane: [`PlannedPlane`] with what its occludees are tested against and
/// whether it ends its direction's sweep ([`ends_sweep`]).
struct RenderedPlane {
    dir: usize,
    job: PlaneJob,
    relevant: Rect,
    tested: Tested,
    ends: bool,
}

/// What a rendered plane's occludees are tested against.
enum Tested {
    /// Its Depth Map and Hierarchical Depth Map, on the CPU.
    Map { map: Arc<DepthMap>, hdm: Hdm },
    /// The device's answers to its queries ([`Prepared::record_queries`]), by query.
    Answers(Answers),
    /// The device's answers, and its map kept there ([`RasterBackend::render_kept`]): the
    /// map's stand-in (a later reprojection's source), its umbra's pixel box and whether
    /// the umbra covers every pixel.
    Kept {
        answers: Answers,
        source: Arc<DepthMap>,
        umbra: Option<[u32; 4]>,
        all_umbra: bool,
    },
}

impl Tested {
    fn tests(&self) -> Tests<'_> {
        match self {
            Tested::Map { hdm, .. } => Tests::Hdm(hdm),
            Tested::Answers(a) | Tested::Kept { answers: a, .. } => Tests::Answers(a),
        }
    }

    /// A backend's result for a plane whose box tests lie as `index` says (`None`: none
    /// asked), with the pyramid of a map that came back built here.
    fn of(result: PlaneResult, index: Option<BoxIndex>) -> Tested {
        let keyed = |answers: Vec<Coverage>| -> Answers {
            Answers {
                answers,
                index: index.expect("answers come only for queries"),
            }
        };
        match result {
            PlaneResult::Map(map) => Tested::Map {
                hdm: Hdm::build(&map),
                map: Arc::new(map),
            },
            PlaneResult::Answers(a) => Tested::Answers(keyed(a)),
            PlaneResult::Kept(k) => Tested::Kept {
                answers: keyed(k.answers),
                source: k.source,
                umbra: k.umbra,
                all_umbra: k.outside_umbra == 0,
            },
        }
    }
}

/// How many boxes of each kind a walk names ([`BoxId`]): nodes, objects and pieces have a
/// slot each in a plane's [`BoxIndex`].
#[derive(Clone, Copy, Debug)]
struct BoxCounts {
    nodes: usize,
    objects: usize,
    pieces: usize,
}

/// Where each box a plane's walk recorded lies among its box tests: nodes, objects and pieces
/// through a slot per box (a plane records thousands; an array is much cheaper than hashing
/// them, and zeroed pages the walk does not touch cost nothing), occluder parts (the leave-out
/// walk's, few out of millions) through a hash map.
struct BoxIndex {
    counts: BoxCounts,
    /// Per node, then object, then piece: its test's index + 1, 0 for none, [`OPEN`] or
    /// [`EMPTY`] for a box answered without a test.
    slots: Vec<u32>,
    parts: foldhash::HashMap<u32, u32>,
}

impl BoxIndex {
    fn new(counts: BoxCounts) -> Self {
        BoxIndex {
            counts,
            slots: vec![0; counts.nodes + counts.objects + counts.pieces],
            parts: Default::default(),
        }
    }

    /// Box `id`'s slot, or `None` for a part.
    fn slot(&self, id: BoxId) -> Option<usize> {
        let c = &self.counts;
        match id {
            BoxId::Node(i) => Some(i as usize),
            BoxId::Object(i) => Some(c.nodes + i as usize),
            BoxId::Piece(i) => Some(c.nodes + c.objects + i as usize),
            BoxId::Part(_) => None,
        }
    }

    /// Box `id`'s entry: its test's index + 1, 0 if not recorded, [`OPEN`] or [`EMPTY`].
    fn get(&self, id: BoxId) -> u32 {
        match (self.slot(id), id) {
            (Some(s), _) => self.slots[s],
            (None, BoxId::Part(i)) => self.parts.get(&i).copied().unwrap_or(0),
            (None, _) => 0,
        }
    }

    /// Records box `id`'s entry (see [`Self::get`]).
    fn insert(&mut self, id: BoxId, k: u32) {
        match (self.slot(id), id) {
            (Some(s), _) => self.slots[s] = k,
            (None, BoxId::Part(i)) => {
                self.parts.insert(i, k);
            }
            (None, _) => {}
        }
    }
}

/// [`BoxIndex`] entries of boxes answered without a test ([`answer_without_test`]): `Partial`
/// and `Empty`.
const OPEN: u32 = u32::MAX;
const EMPTY: u32 = u32::MAX - 1;

/// The box tests a plane's walks may ask, each box once, in the order first asked, with
/// each box's index in [`Prepared::occludee_boxes`] (its [`BoxIndex`] slot; a part has none).
struct Queries {
    boxes: Vec<DAabb>,
    ids: Vec<u32>,
    index: BoxIndex,
}

impl Queries {
    fn new(counts: BoxCounts) -> Self {
        Queries {
            boxes: Vec::new(),
            ids: Vec::new(),
            index: BoxIndex::new(counts),
        }
    }

    /// Records box `id` (a box recorded twice, by the walk and the next plane's leave-out
    /// walk, is the same box); one whose answer is `known` without a test
    /// ([`answer_without_test`]) is only noted, not sent.
    fn record(&mut self, id: BoxId, b: &DAabb, known: Option<Coverage>) {
        if self.index.get(id) == 0 {
            let k = match known {
                Some(Coverage::Empty) => EMPTY,
                Some(_) => OPEN,
                None => {
                    self.boxes.push(*b);
                    let id = self.index.slot(id).map_or(NOT_RESIDENT, |s| s as u32);
                    self.ids.push(id);
                    self.boxes.len() as u32
                }
            };
            self.index.insert(id, k);
        }
    }
}

/// The device's answers to a plane's box tests, in order, with where each box's lies.
struct Answers {
    answers: Vec<Coverage>,
    index: BoxIndex,
}

impl Answers {
    /// Box `id`'s answer. A box that was not recorded stays open (never a cull; a debug
    /// assertion catches it).
    fn coverage(&self, id: BoxId) -> Coverage {
        match self.index.get(id) {
            OPEN => Coverage::Partial,
            EMPTY => Coverage::Empty,
            0 => {
                debug_assert!(false, "box {id:?} was not recorded");
                Coverage::Partial
            }
            k => self.answers[k as usize - 1],
        }
    }
}

/// Where [`Prepared::test_box`] tests a plane's boxes.
enum Tests<'a> {
    /// The plane's Hierarchical Depth Map.
    Hdm(&'a Hdm),
    /// The device's answers ([`RasterBackend::render_tested`]).
    Answers(&'a Answers),
    /// Recording every box tested, each answered `Partial` so that the walk goes on below
    /// it, but for the answers known without the map ([`answer_without_test`])
    /// ([`Prepared::record_queries`]).
    Record(&'a RefCell<Queries>),
}

/// Each plane's box tests for the backend ([`PlaneQueries`], naming the backend's table
/// `table` of [`Prepared::occludee_boxes`] where it keeps one), apart from where each box's
/// answer will lie.
fn split_queries(
    queries: Vec<Option<Queries>>,
    improved: bool,
    table: Option<u64>,
) -> (Vec<Option<PlaneQueries>>, Vec<Option<BoxIndex>>) {
    queries
        .into_iter()
        .map(|q| match q {
            Some(q) => (
                Some(PlaneQueries {
                    rects: Vec::new(),
                    boxes: q.boxes,
                    improved,
                    table,
                    ids: q.ids,
                }),
                Some(q.index),
            ),
            None => (None, None),
        })
        .unzip()
}

/// A rendered sweep plane kept for later reprojections.
#[derive(Clone)]
struct SweepPlane {
    /// Its index in the sweep.
    index: usize,
    frame: PlaneFrame,
    map: Arc<DepthMap>,
    /// The bounds of its umbra ([`crate::sweep::umbra_bounds`]).
    umbra: Option<Rect>,
    /// Its rectangle's open sides.
    open: OpenSides,
}

/// Renders a round's planes on the backend (one call for all), with `queries` (per plane,
/// or `None`) for the backend to answer on its device where it can and `keep` (per plane)
/// asking it to keep a sweep plane's map there, and builds the Hierarchical Depth Maps of the
/// planes whose maps came back, in parallel.
///
/// # Errors
/// The backend's failure.
fn render_round(
    round: &Round,
    backend: &dyn RasterBackend,
    planned: Vec<PlannedPlane>,
    (queries, index): (Vec<Option<PlaneQueries>>, Vec<Option<BoxIndex>>),
    keep: &[bool],
) -> Result<Vec<RenderedPlane>, BakeError> {
    let (jobs, meta): (Vec<PlaneJob>, Vec<(usize, Rect)>) = planned
        .into_iter()
        .map(|p| (p.job, (p.dir, p.relevant)))
        .unzip();
    let results = if keep.contains(&true) {
        backend.render_kept(&jobs, &queries, keep)?
    } else {
        backend.render_tested(&jobs, &queries)?
    };
    let tested: Vec<Tested> = results
        .into_par_iter()
        .zip(index)
        .map(|(r, x)| Tested::of(r, x))
        .collect();
    Ok((jobs.into_iter().zip(meta).zip(tested))
        .map(|((job, (dir, relevant)), tested)| {
            let all_umbra = match &tested {
                Tested::Map { map, .. } => map.depth.iter().all(|&x| x <= 0.0),
                Tested::Kept { all_umbra, .. } => *all_umbra,
                Tested::Answers(_) => false,
            };
            let ends = all_umbra && ends_sweep(&round.plans[dir], round.k, &job, relevant);
            RenderedPlane {
                dir,
                job,
                relevant,
                tested,
                ends,
            }
        })
        .collect())
}

/// Keeps what the next rounds need of a round's sweep planes: each direction's last plane
/// and its history for reprojection, and whether it ended its direction.
fn carry_round(round: &Round, dirs: &mut [DirectionState], rendered: Vec<RenderedPlane>) {
    for r in rendered {
        if !round.plans[r.dir].is_sweep() {
            continue;
        }
        let dir = &mut dirs[r.dir];
        dir.finished = r.ends;
        let (map, umbra) = match &r.tested {
            Tested::Map { map, .. } => (map.clone(), crate::sweep::umbra_bounds(&r.job.frame, map)),
            Tested::Kept { source, umbra, .. } => (
                source.clone(),
                umbra.map(|b| crate::sweep::umbra_rect(&r.job.frame, b)),
            ),
            Tested::Answers(_) => {
                // Only a kept plane that ended its direction is tested again for answers
                // alone (`Prepared::retest_ending`): nothing comes after it.
                debug_assert!(r.ends, "sweep planes come back as maps or kept");
                dir.finished = true;
                continue;
            }
        };
        let open = crate::sweep::open_sides(&r.job.frame, r.relevant);
        dir.prev = Some(PrevPlane {
            index: round.k,
            frame: r.job.frame.clone(),
            tested: r.tested,
        });
        push_history(
            &mut dir.history,
            SweepPlane {
                index: round.k,
                frame: r.job.frame,
                map,
                umbra,
                open,
            },
        );
    }
}

/// Adds plane `k` to a direction's history, keeping only what [`reprojections`] may use: the
/// newest plane and, for every level `m ≥ 1`, the newest plane whose index is a multiple of
/// `2^m` (a skip list, `O(log planes)` maps).
fn push_history(history: &mut Vec<SweepPlane>, plane: SweepPlane) {
    history.push(plane);
    let newest_at = |level: u32, h: &[SweepPlane]| {
        h.iter()
            .rposition(|e| e.index % (1usize << level) == 0)
            .unwrap_or(usize::MAX)
    };
    let keep: Vec<bool> = (0..history.len())
        .map(|i| i + 1 == history.len() || (1..usize::BITS).any(|m| newest_at(m, history) == i))
        .collect();
    let mut it = keep.into_iter();
    history.retain(|_| it.next().unwrap_or(false));
}

/// The reprojections onto a sweep plane (frame `to`, at `distance` beyond the face) from the
/// planes kept in its direction's history ([`push_history`]): the previous plane, and the
/// newest planes with indices multiples of 2, 4, 8… — a skip list. The previous plane alone
/// would carry everything, but each reprojection rounds its windows outward (up to a pixel per
/// side): umbra from far back that reaches this plane through a few reprojections instead of a
/// chain of them loses less. On the coarse forest (5 cells, 48 planes, resolution 256) this
/// took the culled share from 46 % to 54 %.
fn reprojections(history: &[SweepPlane], to: &PlaneFrame, distance: f64) -> Vec<Reprojection> {
    history
        .iter()
        .rev()
        .filter(|e| {
            (e.umbra).is_some_and(|b| {
                crate::sweep::carried_rect(&e.frame, b, e.open, distance).is_some()
            })
        })
        .map(|e| Reprojection::with_open_sides(&e.frame, to, e.map.clone(), e.open))
        .collect()
}

/// Marks the BVH nodes whose objects are all in `done` (bottom-up over the tree).
fn mark_done(bvh: &Bvh2, done: &[bool], node_done: &mut [bool]) {
    fn visit(bvh: &Bvh2, ni: u32, done: &[bool], node_done: &mut [bool]) -> bool {
        let n = &bvh.nodes[ni as usize];
        let all = if n.is_leaf() {
            (0..n.prim_count)
                .all(|k| done[bvh.primitive_indices[(n.first_index + k) as usize] as usize])
        } else {
            let a = visit(bvh, n.first_index, done, node_done);
            let b = visit(bvh, n.first_index + 1, done, node_done);
            a && b
        };
        node_done[ni as usize] = all;
        all
    }
    if !bvh.nodes.is_empty() {
        visit(bvh, 0, done, node_done);
    }
}

fn mark_hidden(bvh: &Bvh2, node: u32, hidden: &mut [bool], node_hidden: &mut [bool]) {
    let mut stack = vec![node];
    while let Some(ni) = stack.pop() {
        node_hidden[ni as usize] = true;
        let n = &bvh.nodes[ni as usize];
        if n.is_leaf() {
            for k in 0..n.prim_count {
                hidden[bvh.primitive_indices[(n.first_index + k) as usize] as usize] = true;
            }
        } else {
            stack.push(n.first_index);
            stack.push(n.first_index + 1);
        }
    }
}
