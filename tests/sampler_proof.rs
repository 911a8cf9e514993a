//! Brute-force check of the sampler's conservativeness claim (this file owns
//! `tests/sampler_proof.rs`: the claim's random and adversarial checks, nothing else).
//!
//! `umbrasweep::sampler` claims: after `Hemicube::begin(eye, axis, sign, eps, boxes)` and
//! `draw(occ)`, when `test_box(bx)` answers `Hidden`, then for every point `b` of the closed
//! ball of radius `eps` about the eye and every point `q` of `bx` on the outer side of the face
//! plane (`sign·(q[axis] − eye[axis]) ≥ 0`), the segment `b → q` crosses one of the polygons.
//!
//! Each family generates random configurations (a deterministic splitmix64 generator): an
//! eye, a face axis and sign, `eps`, convex exactly planar polygons (triangles, quads that are
//! extruded segments along a coordinate axis and convex polygons of up to 70 vertices in
//! planes normal to an axis, all of which stay exactly planar under every per-coordinate scale
//! and offset) and occludee boxes. The families: `foliage` (clusters of 200–2000 small leaves,
//! fusion), `grazing` (overlapping slats seen 0.5°–20° from edge-on, polygons whose planes
//! pass just beyond `eps`), `near` (plane distances `eps·(1 + 1e-7…1)`, edges just beyond
//! `eps`, huge near walls), `crossing` (leaves and walls crossing the face plane), `partly_behind`
//! (boxes across, touching or just behind the face plane, boxes at the ball), `fine_foliage`
//! (leaves of 0.3–4 pixels, fused only by the sub-pixel masks), `ground` (a
//! slanted, tiled ground drawn with per-pixel plane depths, boxes just under, on and over it,
//! boxes glued behind walls), `general` (a mix, with `eps = 0`, many-vertex and degenerate
//! polygons, flat and point boxes) and `scaled` (any of them scaled by 1e-3 and offset by 1e5).
//! `patch`, `patch_low` and `patch_scaled` check `Hemicube::begin_patch` the same way, from the
//! points of a rectangle of the face (half diagonal `eps`, some flat) instead of the ball, with
//! near polygons also nearer than `eps` and (`patch_low`) leaves and slats seen a few degrees
//! over the face's plane, whose edges across the line of sight the rectangle barely shrinks. Hemicubes are reused across configurations.
//!
//! For every box reported hidden, the check samples points `b` (the eye, the ball's axis and
//! diagonal points, random points on its sphere and inside, points of the disc in the face
//! plane, and for every `q` the points of the ball farthest outside the shadow pyramid from
//! `q` of each polygon the eye's ray to `q` crosses) and points `q` (the corners, edges, faces
//! and inside of the box's part on the outer side, and its point nearest the eye) and tests
//! each segment against the polygons in plain `f64`, strictly: a crossing counts only when the
//! segment's end points are on opposite sides of the polygon's plane and it passes inside every
//! edge, each by more than `TOL` (far above the rounding error of the test) relative to the
//! magnitudes involved. All of this is in coordinates relative to the eye, which are exact (the
//! eye is the frame's offset, and every coordinate is either unshifted or within a factor of
//! two of the offset).
//!
//! Every family asserts that it hid a share of its boxes (so it cannot pass vacuously);
//! `check_catches_a_render_with_less_shrink` renders with no shrink and with half of it and
//! asserts that the check then finds unblocked segments; `shrink_matters` asserts that a box
//! hidden from the eye alone but seen from a point of the ball is reported open (and hidden for
//! a tiny ball) in many frames. On a violation the configuration is reduced (polygons removed
//! while the box stays hidden) and printed in full. Counts are halved in debug builds and
//! multiplied by `UMBRASWEEP_SAMPLER_PROOF_SCALE` when it is set (longer campaigns reach new
//! configurations).
#![cfg(feature = "bake")]

mod common;

use glam::DVec3;
use std::f64::consts::{PI, TAU};
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube, Occludees, RectSweep, SampleOccluders};

/// Relative margin of the strict crossing test (about 450 units of rounding of `f64`).
const TOL: f64 = 1e-13;

/// Configurations per family: fewer in debug builds (`cargo test`), and
/// `UMBRASWEEP_SAMPLER_PROOF_SCALE` times as many (new ones: configurations are numbered)
/// when it is set, for longer campaigns.
fn count(release: usize) -> usize {
    let scale: usize = std::env::var("UMBRASWEEP_SAMPLER_PROOF_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    scale
        * if cfg!(debug_assertions) {
            release.div_ceil(2)
        } else {
            release
        }
}

// ---------------------------------------------------------------------------------------------
// Random numbers.

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn f(&mut self) -> f64 {
        (self.u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn u(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
    /// Log-uniform in [a, b].
    fn log_u(&mut self, a: f64, b: f64) -> f64 {
        self.u(a.ln(), b.ln()).exp()
    }
    fn below(&mut self, n: usize) -> usize {
        (self.u64() % n as u64) as usize
    }
    fn chance(&mut self, p: f64) -> bool {
        self.f() < p
    }
    fn sign(&mut self) -> f64 {
        if self.chance(0.5) { 1.0 } else { -1.0 }
    }
    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[self.below(xs.len())]
    }
    fn in_ball(&mut self) -> DVec3 {
        loop {
            let p = DVec3::new(self.u(-1.0, 1.0), self.u(-1.0, 1.0), self.u(-1.0, 1.0));
            if p.length_squared() <= 1.0 {
                return p;
            }
        }
    }
    fn unit(&mut self) -> DVec3 {
        loop {
            let p = self.in_ball();
            let l = p.length();
            if l > 1e-3 {
                return p / l;
            }
        }
    }
    /// A unit vector on the outer side of the face (local `z ≥ zmin`).
    fn unit_up(&mut self, zmin: f64) -> DVec3 {
        let mut d = self.unit();
        d.z = d.z.abs().max(zmin);
        d.normalize()
    }
}

// ---------------------------------------------------------------------------------------------
// Shapes, in the local frame: the eye at the origin, the face's outward normal `+z`.

/// A configuration in the local frame.
#[derive(Clone, Default)]
struct Local {
    eps: f64,
    res: u32,
    polys: Vec<Vec<DVec3>>,
    boxes: Vec<[DVec3; 2]>,
}

/// A triangle about `c` in the plane with normal `n`, circumradius about `s`.
fn tri_in_plane(rng: &mut Rng, c: DVec3, n: DVec3, s: f64) -> Vec<DVec3> {
    let (e1, e2) = n.normalize().any_orthonormal_pair();
    let t0 = rng.u(0.0, TAU);
    (0..3)
        .map(|k| {
            let t = t0 + k as f64 * TAU / 3.0 + rng.u(-0.5, 0.5);
            c + s * rng.u(0.5, 1.0) * (t.cos() * e1 + t.sin() * e2)
        })
        .collect()
}

/// A leaf: a randomly oriented triangle.
fn leaf(rng: &mut Rng, c: DVec3, s: f64) -> Vec<DVec3> {
    let n = rng.unit();
    tri_in_plane(rng, c, n, s)
}

/// The segment `a–b` (read in the two coordinates other than `ax`) extruded along axis `ax`
/// over `[lo, hi]`: a rectangle, exactly planar in floating point (its four vertices have two
/// distinct projections along `ax`), and still so after any per-coordinate map.
fn strip(ax: usize, a: DVec3, b: DVec3, lo: f64, hi: f64) -> Vec<DVec3> {
    let with = |p: DVec3, t: f64| {
        let mut p = p;
        p[ax] = t;
        p
    };
    vec![with(a, lo), with(b, lo), with(b, hi), with(a, hi)]
}

/// A random strip about `c` of size about `s`.
fn random_strip(rng: &mut Rng, c: DVec3, s: f64) -> Vec<DVec3> {
    let ax = rng.below(3);
    let (b1, b2) = ((ax + 1) % 3, (ax + 2) % 3);
    let phi = rng.u(0.0, TAU);
    let hp = s * rng.u(0.3, 1.0);
    let ha = s * rng.u(0.3, 1.0);
    let mut d = DVec3::ZERO;
    d[b1] = phi.cos() * hp;
    d[b2] = phi.sin() * hp;
    strip(ax, c - d, c + d, c[ax] - ha, c[ax] + ha)
}

fn leaf_or_strip(rng: &mut Rng, c: DVec3, s: f64, p_strip: f64) -> Vec<DVec3> {
    if rng.chance(p_strip) {
        random_strip(rng, c, s)
    } else {
        leaf(rng, c, s)
    }
}

/// A box about `c` with half sizes `h`.
fn cube(c: DVec3, h: DVec3) -> [DVec3; 2] {
    [c - h, c + h]
}

fn jitter_half(rng: &mut Rng, h: f64) -> DVec3 {
    DVec3::new(
        h * rng.u(0.5, 1.5),
        h * rng.u(0.5, 1.5),
        h * rng.u(0.5, 1.5),
    )
}

/// The number of leaves and their size for a cluster of radius `r` with optical depth `tau`.
fn leaves_for(rng: &mut Rng, r: f64, tau: f64) -> (usize, f64) {
    let n = 200 + rng.below(1801);
    // A leaf of circumradius s has an area of about 0.7 s².
    let s = (tau * PI * r * r / n as f64 / 0.7).sqrt();
    (n, s)
}

/// Leaves of circumradius `s` (area about 0.7 s²) that give a disc of radius `r` the optical
/// depth `tau`, within `[lo, hi]`.
fn leaves_to_fill(tau: f64, r: f64, s: f64, lo: usize, hi: usize) -> usize {
    ((tau * PI * r * r / (0.7 * s * s)) as usize).clamp(lo, hi)
}

/// A foliage cluster: `n` leaves in a ball (or a slab across `dir`) about `c`.
fn cluster(
    rng: &mut Rng,
    out: &mut Vec<Vec<DVec3>>,
    c: DVec3,
    dir: DVec3,
    r: f64,
    n: usize,
    s: f64,
) {
    let slab = rng.chance(0.4);
    for _ in 0..n {
        let mut p = rng.in_ball() * r;
        if slab {
            p -= dir * (p.dot(dir) * 0.7);
        }
        let poly = leaf_or_strip(rng, c + p, s, 0.15);
        out.push(poly);
    }
}

/// `count` boxes behind a cluster of radius `r` about `c` (at distance `d` along `dir`): just
/// behind it, or far behind it (large parallax across the ball), within its shadow.
fn boxes_behind(
    rng: &mut Rng,
    boxes: &mut Vec<[DVec3; 2]>,
    c: DVec3,
    dir: DVec3,
    d: f64,
    r: f64,
    count: usize,
) {
    for _ in 0..count {
        let t = if rng.chance(0.5) {
            r * rng.u(1.2, 4.0)
        } else {
            d * rng.u(0.5, 3.0)
        };
        let k = (d + t) / d;
        let lat = rng.in_ball() * r * 0.4 * k;
        let lat = lat - dir * lat.dot(dir);
        let h = r * rng.u(0.03, 0.3) * k;
        let hv = jitter_half(rng, h);
        boxes.push(cube(c + dir * t + lat, hv));
    }
}

/// A random box in the outer half-space.
fn random_box(rng: &mut Rng, dist: f64, size: f64) -> [DVec3; 2] {
    let c = rng.unit_up(0.0) * dist;
    let h = jitter_half(rng, size);
    cube(c, h)
}

// ---------------------------------------------------------------------------------------------
// Families (generators of local configurations).

/// A configuration holding one foliage cluster about `c` (at distance `|c|` along `dir`): a
/// resolution picked from `resolutions`, leaves of `leaf_px` pixels (a random share of that range),
/// clusters of 4–9 leaves across, an optical depth in `tau`, 200–2000 leaves, and a ball of
/// `eps_px` pixels at the cluster (log-uniform). Returns it and the cluster's radius.
fn dense_cluster(
    rng: &mut Rng,
    c: DVec3,
    dir: DVec3,
    resolutions: &[u32],
    leaf_px: (f64, f64),
    tau: (f64, f64),
    eps_px: (f64, f64),
) -> (Local, f64) {
    let d = c.length();
    let res = rng.pick(resolutions);
    let px = 2.0 / res as f64 * d;
    let s = rng.u(leaf_px.0, leaf_px.1) * px / 2.0;
    let r = (s * rng.u(4.0, 9.0)).min(0.4 * d);
    let tau = rng.u(tau.0, tau.1);
    let n = leaves_to_fill(tau, r, s, 200, 2000);
    let mut l = Local {
        eps: px * rng.log_u(eps_px.0, eps_px.1),
        res,
        ..Local::default()
    };
    cluster(rng, &mut l.polys, c, dir, r, n, s);
    (l, r)
}

/// Dense foliage: 200–2000 small leaves in a cluster, boxes behind it.
fn gen_foliage(rng: &mut Rng) -> Local {
    let d = rng.u(1.5, 8.0);
    let dir = rng.unit_up(0.15);
    let c = dir * d;
    // Leaves of 5–16 pixels (so that they cover whole pixels and fuse), balls from a
    // twentieth of a pixel to six pixels.
    let (mut l, r) = dense_cluster(
        rng,
        c,
        dir,
        &[64, 128, 256, 256],
        (5.0, 16.0),
        (1.0, 10.0),
        (0.05, 6.0),
    );
    boxes_behind(rng, &mut l.boxes, c, dir, d, r, 5);
    let dist = d * rng.u(0.5, 2.5);
    let size = rng.u(0.05, 0.5);
    l.boxes.push(random_box(rng, dist, size));
    l
}

/// Fine foliage: leaves of 0.3–4 pixels (far leaves, narrower than a pixel or a few), dense
/// enough that only sub-pixel masks fuse them, boxes behind.
fn gen_fine_foliage(rng: &mut Rng) -> Local {
    let d = rng.u(2.0, 10.0);
    let dir = rng.unit_up(0.15);
    let c = dir * d;
    let res = rng.pick(&[32, 64, 64, 128]);
    let px = 2.0 / res as f64 * d;
    let s = rng.log_u(0.3, 4.0) * px / 2.0;
    let r = (px * rng.u(3.0, 8.0)).min(0.4 * d);
    let tau = rng.u(5.0, 15.0);
    let n = leaves_to_fill(tau, r, s, 300, 5000);
    let mut l = Local {
        // The shrink from a hundredth of a pixel to a third of a pixel at the cluster.
        eps: px * rng.log_u(0.01, 0.3),
        res,
        ..Local::default()
    };
    cluster(rng, &mut l.polys, c, dir, r, n, s);
    boxes_behind(rng, &mut l.boxes, c, dir, d, r, 6);
    l
}

/// Depth-bounded shrinking: occludee boxes just behind or inside a cluster of leaves (some
/// leaves beyond them), all at about the same distance, so that the render shrinks each edge
/// only as much as occludees that near need; balls of a third of a pixel to 8 pixels at the
/// cluster, which without the bound would leave little of the leaves.
fn gen_depth_bounded(rng: &mut Rng) -> Local {
    let d = rng.u(1.5, 8.0);
    let dir = rng.unit_up(0.15);
    let c = dir * d;
    let (mut l, r) = dense_cluster(
        rng,
        c,
        dir,
        &[64, 128, 256],
        (3.0, 12.0),
        (4.0, 12.0),
        (0.3, 8.0),
    );
    for _ in 0..6 {
        let t = d + r * rng.u(-0.3, 1.5);
        let lat = rng.in_ball() * r * 0.4;
        let lat = lat - dir * lat.dot(dir);
        let h = r * rng.u(0.02, 0.2);
        let hv = jitter_half(rng, h);
        l.boxes.push(cube(dir * t + lat, hv));
    }
    l
}

/// Grazing angles: "blinds" (overlapping slats seen 0.5°–20° from edge-on) and leaves and
/// strips whose planes pass just beyond ε from the eye.
fn gen_grazing(rng: &mut Rng) -> Local {
    let d = rng.u(2.0, 8.0);
    let long = rng.below(2);
    let o = 1 - long;
    let beta: f64 = rng.u(-1.35, 1.35);
    // Profile coordinates (o, z).
    let f2 = (beta.sin(), beta.cos());
    let n2 = (f2.1, -f2.0);
    let gamma = rng.log_u(0.5f64.to_radians(), 20f64.to_radians()) * rng.sign();
    let w = d * rng.u(0.15, 0.6);
    let band = w * gamma.abs().sin();
    let spacing = band * rng.u(0.35, 1.05);
    let half_span = d * rng.u(0.04, 0.2);
    let k = ((2.0 * half_span / spacing).ceil() as usize).clamp(1, 250);
    let along_c = d * rng.u(-0.2, 0.2);
    let ha = d * rng.u(0.1, 0.4);
    let mut l = Local {
        eps: band * rng.log_u(0.01, 0.5),
        res: rng.pick(&[64, 128, 256, 256]),
        ..Local::default()
    };
    let to3 = |p: (f64, f64)| {
        let mut v = DVec3::ZERO;
        v[o] = p.0;
        v[2] = p.1;
        v
    };
    for i in 0..k {
        let y = -half_span + i as f64 * spacing;
        let p = (f2.0 * d + n2.0 * y, f2.1 * d + n2.1 * y);
        let pl = (p.0 * p.0 + p.1 * p.1).sqrt();
        let (ux, uz) = (p.0 / pl, p.1 / pl);
        let (sg, cg) = gamma.sin_cos();
        let t = (ux * cg - uz * sg, ux * sg + uz * cg);
        let a = to3((p.0 - t.0 * w / 2.0, p.1 - t.1 * w / 2.0));
        let b = to3((p.0 + t.0 * w / 2.0, p.1 + t.1 * w / 2.0));
        l.polys.push(strip(long, a, b, along_c - ha, along_c + ha));
    }
    // Polygons whose planes pass just beyond ε from the eye.
    let m = rng.below(60);
    for _ in 0..m {
        let c = rng.unit_up(0.0) * d * rng.u(0.2, 1.5);
        let pd = l.eps * rng.log_u(1.0 + 1e-5, 5.0);
        if rng.chance(0.5) {
            let cl = c.length();
            let t = rng.unit();
            let t = (t - c * (t.dot(c) / (cl * cl))).normalize();
            let sin = (pd / cl).min(1.0);
            let nrm = t * (1.0 - sin * sin).sqrt() + c / cl * sin;
            let s = d * rng.u(0.05, 0.4);
            l.polys.push(tri_in_plane(rng, c, nrm, s));
        } else {
            // A strip along `ax` whose line (in the other two coordinates) passes at `pd`.
            let ax = rng.below(3);
            let (b1, b2) = ((ax + 1) % 3, (ax + 2) % 3);
            let (c1, c2) = (c[b1], c[b2]);
            let cl = (c1 * c1 + c2 * c2).sqrt();
            if cl <= pd {
                continue;
            }
            let g = (pd / cl).asin() * rng.sign();
            let (ux, uy) = (c1 / cl, c2 / cl);
            let (sg, cg) = g.sin_cos();
            let t = (ux * cg - uy * sg, ux * sg + uy * cg);
            let len = d * rng.u(0.05, 0.5);
            let along = rng.u(-0.5, 0.5) * len;
            let mut a = DVec3::ZERO;
            a[b1] = c1 + t.0 * along;
            a[b2] = c2 + t.1 * along;
            let mut b = DVec3::ZERO;
            b[b1] = c1 + t.0 * (along + len);
            b[b2] = c2 + t.1 * (along + len);
            let h = d * rng.u(0.05, 0.4);
            l.polys.push(strip(ax, a, b, c[ax] - h, c[ax] + h));
        }
    }
    for _ in 0..4 {
        let y = rng.u(-0.7, 0.7) * half_span;
        let t = rng.u(1.2, 2.5);
        let p = ((f2.0 * d + n2.0 * y) * t, (f2.1 * d + n2.1 * y) * t);
        let mut c = to3(p);
        c[long] = along_c + rng.u(-0.5, 0.5) * ha * t;
        let hp = half_span * t * rng.u(0.02, 0.3);
        let mut h = DVec3::splat(hp);
        h[long] = ha * t * rng.u(0.05, 0.4);
        l.boxes.push(cube(c, h));
    }
    let dist = d * rng.u(0.5, 2.0);
    let size = rng.u(0.05, 0.5);
    l.boxes.push(random_box(rng, dist, size));
    l
}

/// Low over the face: a cluster of leaves and stacked slats a few degrees (0.06°–17°) above
/// the face's plane, some reaching below it, boxes behind them, and balls up to 20 pixels at
/// the cluster. For rectangles (`begin_patch`): edges seen across the line of sight there lie
/// in planes through the eye nearly parallel to the face, which the rectangle's support
/// barely shrinks, so these leaves fuse where a ball's shrink would open them.
fn gen_low(rng: &mut Rng) -> Local {
    let d = rng.u(1.5, 8.0);
    let phi = rng.u(0.0, TAU);
    let elev = rng.log_u(1e-3, 0.3);
    let dir = DVec3::new(phi.cos(), phi.sin(), elev.tan()).normalize();
    let across = DVec3::new(-phi.sin(), phi.cos(), 0.0);
    let c = dir * d;
    let (mut l, r) = dense_cluster(
        rng,
        c,
        dir,
        &[64, 128, 256, 256],
        (3.0, 12.0),
        (2.0, 10.0),
        (0.3, 20.0),
    );
    // Slats across the line of sight, stacked in height, each overlapping the next by a
    // share of its height, each a little farther than the one below or above it.
    let k = 2 + rng.below(6);
    let h = r * rng.u(0.1, 0.5);
    let w = r * rng.u(0.5, 2.0);
    let overlap = h * rng.log_u(0.02, 0.5);
    let mut z = c.z - 0.5 * k as f64 * (h - overlap);
    let mut t = d * rng.u(0.9, 1.1);
    let step = d * rng.u(-0.03, 0.03);
    for _ in 0..k {
        let foot = DVec3::new(dir.x, dir.y, 0.0).normalize() * t;
        let (a, b) = (foot - across * w, foot + across * w);
        // A quad in the vertical plane through `a` and `b`: exactly planar (two distinct
        // projections along z).
        l.polys.push(strip(2, a, b, z, z + h));
        z += h - overlap;
        t += step;
    }
    boxes_behind(rng, &mut l.boxes, c, dir, d, r, 6);
    l
}

/// Polygons near the sample point: plane distance just above ε (by a relative 1e-7 to 1),
/// edges just beyond ε, some huge near walls; a few leaves a little farther for fusion.
fn gen_near(rng: &mut Rng) -> Local {
    gen_near_from(rng, 1.0)
}

/// [`gen_near`] with plane distances from `eps·(base + 1e-7…1)`, `base` in [0.1, 1]: for
/// rectangles (`begin_patch`), whose edges may be shrunk by less than the half diagonal
/// `eps`, so that polygons nearer than `eps` are drawn too.
fn gen_near_patch(rng: &mut Rng) -> Local {
    let base = rng.u(0.1, 1.0);
    gen_near_from(rng, base)
}

fn gen_near_from(rng: &mut Rng, base: f64) -> Local {
    let eps = rng.u(0.01, 0.1);
    let mut l = Local {
        eps,
        res: rng.pick(&[32, 48, 64, 128, 256]),
        ..Local::default()
    };
    let kn = 1 + rng.below(5);
    for _ in 0..kn {
        let as_strip = rng.chance(0.4);
        let big = rng.chance(0.3);
        let (mut n, ax) = if as_strip {
            let ax = rng.below(3);
            let mut t = rng.unit();
            t[ax] = 0.0;
            (t.normalize(), ax)
        } else {
            (rng.unit(), 0)
        };
        if n.z < -0.3 {
            n = -n;
        }
        let (e1, e2) = if as_strip {
            let mut e2 = DVec3::ZERO;
            e2[ax] = 1.0;
            (n.cross(e2), e2)
        } else {
            n.any_orthonormal_pair()
        };
        let pd = eps * (base + rng.log_u(1e-7, 1.0));
        let foot = n * pd;
        let (h, l1, l2, l3) = if big {
            (
                eps * rng.u(5.0, 50.0),
                eps * rng.u(20.0, 200.0),
                eps * rng.u(20.0, 200.0),
                eps * rng.u(60.0, 300.0),
            )
        } else {
            (
                eps * rng.u(-0.5, 0.8),
                eps * rng.log_u(0.5, 50.0),
                eps * rng.log_u(0.5, 50.0),
                eps * rng.log_u(0.5, 50.0),
            )
        };
        if as_strip {
            let a = foot + e1 * h;
            let b = foot + e1 * (h - l3);
            l.polys.push(strip(ax, a, b, -l1, l2));
        } else {
            let y3 = rng.u(-l1, l2);
            l.polys.push(vec![
                foot + e1 * h - e2 * l1,
                foot + e1 * h + e2 * l2,
                foot + e1 * (h - l3) + e2 * y3,
            ]);
        }
    }
    let m = rng.below(30);
    for _ in 0..m {
        let c = rng.unit_up(0.0) * eps * rng.u(3.0, 30.0);
        let s = eps * rng.u(1.0, 10.0);
        let p = leaf_or_strip(rng, c, s, 0.3);
        l.polys.push(p);
    }
    for _ in 0..5 {
        let k = rng.below(l.polys.len());
        let cen = l.polys[k].iter().copied().sum::<DVec3>() / l.polys[k].len() as f64;
        let dir = cen.normalize();
        let c = dir * cen.length() * rng.log_u(1.2, 20.0) + rng.in_ball() * eps;
        let hs = eps * rng.log_u(0.05, 10.0);
        let h = jitter_half(rng, hs);
        l.boxes.push(cube(c, h));
    }
    let dist = rng.u(0.1, 2.0);
    let size = rng.u(0.01, 0.3);
    l.boxes.push(random_box(rng, dist, size));
    l
}

/// Leaves and walls crossing the face plane (some vertices behind it), boxes near the plane.
fn gen_crossing(rng: &mut Rng) -> Local {
    let mut l = Local {
        eps: rng.u(0.005, 0.08),
        res: rng.pick(&[48, 64, 128, 256]),
        ..Local::default()
    };
    let mut anchors = Vec::new();
    let walls = 1 + rng.below(4);
    for _ in 0..walls {
        let phi = rng.u(0.0, TAU);
        let rho = rng.u(0.3, 4.0);
        let p = DVec3::new(rho * phi.cos(), rho * phi.sin(), 0.0);
        let a = phi + PI / 2.0 + rng.u(-0.6, 0.6);
        let hl = rng.u(0.2, 2.0);
        let dir = DVec3::new(a.cos(), a.sin(), 0.0) * hl;
        if rng.chance(0.6) {
            // Vertical: extruded along z across the face plane.
            l.polys.push(strip(
                2,
                p - dir,
                p + dir,
                -rng.u(0.0, 2.0),
                rng.u(0.3, 3.0),
            ));
        } else {
            // Tilted, extruded along x or y, its profile crossing z = 0.
            let ax = rng.below(2);
            let ot = 1 - ax;
            let mut a3 = DVec3::ZERO;
            a3[ot] = p[ot] + rng.u(-0.5, 0.5);
            a3.z = -rng.u(0.05, 1.5);
            let mut b3 = DVec3::ZERO;
            b3[ot] = p[ot] + rng.u(-0.5, 0.5);
            b3.z = rng.u(0.1, 2.5);
            l.polys.push(strip(ax, a3, b3, p[ax] - hl, p[ax] + hl));
        }
        anchors.push(p);
    }
    let nl = 100 + rng.below(700);
    for _ in 0..nl {
        let phi = rng.u(0.0, TAU);
        let rho = rng.u(3.0 * l.eps, 4.0);
        let s = rng.u(0.05, 0.5);
        let c = DVec3::new(rho * phi.cos(), rho * phi.sin(), rng.u(-1.2, 1.2) * s);
        let p = leaf_or_strip(rng, c, s, 0.25);
        l.polys.push(p);
    }
    if rng.chance(0.5) {
        let phi = rng.u(0.0, TAU);
        let rho = rng.u(1.5, 5.0);
        let r = rng.u(0.3, 1.0);
        let c = DVec3::new(rho * phi.cos(), rho * phi.sin(), rng.u(-0.3, 0.3) * r);
        let tau = rng.u(3.0, 10.0);
        let (n, s) = leaves_for(rng, r, tau);
        let dir = c.normalize();
        cluster(rng, &mut l.polys, c, dir, r, n.min(1200), s);
        anchors.push(c);
    }
    for _ in 0..6 {
        let a = rng.pick(&anchors);
        let t = rng.u(1.2, 3.0);
        let mut c = a * t;
        c.z = 0.0;
        let z0 = -rng.u(0.0, 1.0);
        let z1 = if rng.chance(0.2) {
            0.0
        } else {
            rng.u(0.0, 1.5)
        };
        let h = rng.u(0.05, 0.6);
        l.boxes.push([
            DVec3::new(c.x - h, c.y - h * rng.u(0.5, 1.5), z0),
            DVec3::new(c.x + h, c.y + h * rng.u(0.5, 1.5), z1),
        ]);
    }
    l
}

/// Boxes partly behind the face plane (or touching it, or just behind it), some near the eye,
/// behind overlapping fences, low walls and leaves.
fn gen_partly_behind(rng: &mut Rng) -> Local {
    let mut l = Local {
        eps: rng.u(0.01, 0.1),
        res: rng.pick(&[32, 64, 128, 256]),
        ..Local::default()
    };
    // A fence of overlapping vertical walls tangent to a circle about the eye.
    let rho = rng.u(0.5, 3.0);
    let k = 5 + rng.below(8);
    let over = rng.u(1.05, 1.6);
    let half_side = rho * (PI / k as f64).tan() * over;
    let (z0, z1) = (-rng.u(0.1, 2.0), rng.u(0.2, 3.0));
    let phase = rng.u(0.0, TAU);
    for i in 0..k {
        if rng.chance(0.1) {
            continue;
        }
        let phi = phase + i as f64 * TAU / k as f64;
        let r = rho * rng.u(1.0, 1.15);
        let p = DVec3::new(r * phi.cos(), r * phi.sin(), 0.0);
        let t = DVec3::new(-phi.sin(), phi.cos(), 0.0) * half_side;
        l.polys.push(strip(2, p - t, p + t, z0, z1));
    }
    // A few leaves across the plane.
    let nl = rng.below(200);
    for _ in 0..nl {
        let phi = rng.u(0.0, TAU);
        let s = rng.u(0.05, 0.4);
        let c = DVec3::new(
            rho * 0.8 * rng.u(0.2, 1.2) * phi.cos(),
            rho * 0.8 * rng.u(0.2, 1.2) * phi.sin(),
            rng.u(-1.0, 1.0) * s,
        );
        let p = leaf_or_strip(rng, c, s, 0.3);
        l.polys.push(p);
    }
    for i in 0..7 {
        let phi = rng.u(0.0, TAU);
        let (c, h) = if i == 6 {
            // Near the eye.
            let c = DVec3::new(phi.cos(), phi.sin(), 0.0) * l.eps * rng.u(1.0, 6.0);
            (c, l.eps * rng.u(0.2, 1.5))
        } else {
            let r = rho * rng.u(1.3, 3.0);
            (
                DVec3::new(r * phi.cos(), r * phi.sin(), 0.0),
                rng.u(0.05, 0.5),
            )
        };
        let top = match rng.below(5) {
            0 => 0.0,
            1 => -rng.log_u(1e-9, 0.1),
            _ => rng.u(0.0, (z1 * 1.2).min(2.0)),
        };
        let bottom = -rng.u(0.0, 1.0) + top.min(0.0);
        l.boxes.push([
            DVec3::new(c.x - h, c.y - h, bottom),
            DVec3::new(c.x + h, c.y + h, top),
        ]);
    }
    l
}

/// A generic mix: walls, leaves, small clusters, boxes anywhere.
fn gen_general(rng: &mut Rng) -> Local {
    let eps = match rng.below(20) {
        0 => 0.0,
        1 => 1e-9,
        _ => rng.log_u(0.003, 0.2),
    };
    let mut l = Local {
        eps,
        res: rng.pick(&[16, 32, 48, 64, 128, 256]),
        ..Local::default()
    };
    let walls = rng.below(6);
    for _ in 0..walls {
        let c = rng.unit_up(0.0) * rng.u(0.3, 6.0);
        let s = rng.u(0.5, 4.0);
        let p = leaf_or_strip(rng, c, s, 0.7);
        l.polys.push(p);
    }
    // Convex polygons of many vertices (over 64 are left out by the sampler) in planes normal
    // to an axis, so exactly planar.
    let discs = rng.below(4);
    for _ in 0..discs {
        let c = rng.unit_up(0.0) * rng.u(0.3, 6.0);
        let ax = rng.below(3);
        let m = rng.pick(&[5, 8, 17, 40, 64, 65, 70]);
        let rad = rng.u(0.2, 2.0);
        let t0 = rng.u(0.0, TAU);
        let p: Vec<DVec3> = (0..m)
            .map(|i| {
                let t = t0 + i as f64 * TAU / m as f64;
                let mut v = c;
                v[(ax + 1) % 3] += rad * t.cos();
                v[(ax + 2) % 3] += rad * t.sin();
                v
            })
            .collect();
        l.polys.push(p);
    }
    // Degenerate polygons: a repeated vertex, collinear vertices.
    if rng.chance(0.2) {
        let c = rng.unit_up(0.0) * rng.u(0.5, 4.0);
        let mut p = leaf(rng, c, 1.0);
        p.insert(1, p[1]);
        l.polys.push(p);
        let e = rng.unit();
        l.polys.push(vec![c, c + e, c + e * 2.0]);
    }
    let nl = rng.below(400);
    for _ in 0..nl {
        let c = rng.unit_up(0.0) * rng.u(0.05, 6.0);
        let s = rng.log_u(0.02, 1.0);
        let p = leaf_or_strip(rng, c, s, 0.2);
        l.polys.push(p);
    }
    if rng.chance(0.5) {
        let d = rng.u(1.0, 5.0);
        let dir = rng.unit_up(0.0);
        let r = d * rng.u(0.1, 0.3);
        let tau = rng.u(3.0, 10.0);
        let (n, s) = leaves_for(rng, r, tau);
        cluster(rng, &mut l.polys, dir * d, dir, r, n.min(800), s);
    }
    for _ in 0..6 {
        let dist = rng.u(0.2, 12.0);
        let size = rng.log_u(0.01, 1.5);
        let mut b = random_box(rng, dist, size);
        // Some flat boxes and points.
        match rng.below(8) {
            0 => {
                let k = rng.below(3);
                b[1][k] = b[0][k];
            }
            1 => b[1] = b[0],
            _ => {}
        }
        l.boxes.push(b);
    }
    l
}

/// A ground (a large, possibly slanted, possibly tiled plane under the eye, drawn with the
/// per-pixel plane depth) and boxes just under it, on it, through it and just above it, at
/// gaps from 0 to 1e-1 relative (the depth margins), plus axis-aligned walls with boxes
/// glued right behind them.
fn gen_ground(rng: &mut Rng) -> Local {
    let eps = rng.u(0.005, 0.1);
    let mut l = Local {
        eps,
        res: rng.pick(&[32, 64, 128, 256]),
        ..Local::default()
    };
    // The ground y = −h + σ·z, z ∈ [−zb, zf], extruded along x over [−L, L].
    let sigma = if rng.chance(0.3) {
        0.0
    } else {
        rng.u(-0.3, 0.3)
    };
    let h = eps * (1.0 + sigma * sigma).sqrt() * rng.log_u(1.0 + 1e-6, 40.0);
    let (zb, zf, big_l) = (rng.u(0.0, 5.0), rng.u(5.0, 30.0), rng.u(5.0, 30.0));
    let at = |z: f64| DVec3::new(0.0, -h + sigma * z, z);
    let tiles = if rng.chance(0.5) { 1 } else { 2 + rng.below(6) };
    let overlap = if rng.chance(0.5) {
        0.0
    } else {
        rng.u(0.0, 0.5)
    };
    let along_z = rng.chance(0.5);
    for i in 0..tiles {
        let f0 = i as f64 / tiles as f64;
        let f1 = (i + 1) as f64 / tiles as f64;
        if along_z {
            let z0 = -zb + (zf + zb) * f0 - overlap;
            let z1 = -zb + (zf + zb) * f1;
            l.polys.push(strip(0, at(z0), at(z1), -big_l, big_l));
        } else {
            let x0 = -big_l + 2.0 * big_l * f0 - overlap;
            let x1 = -big_l + 2.0 * big_l * f1;
            l.polys.push(strip(0, at(-zb), at(zf), x0, x1));
        }
    }
    for _ in 0..6 {
        let z = rng.u(0.3, zf * 0.8);
        let x = rng.u(-0.6, 0.6) * big_l * 0.8;
        let yg = -h + sigma * z;
        let gap = if rng.chance(0.2) {
            0.0
        } else {
            z * rng.log_u(1e-12, 0.1)
        };
        let size = rng.log_u(0.01, 1.0);
        let hx = size * rng.u(0.5, 1.5);
        let hz = size * rng.u(0.5, 1.5);
        let (y0, y1) = match rng.below(4) {
            0 => (yg - gap - size, yg - gap),
            1 => (yg + gap, yg + gap + size),
            2 => (yg - size, yg + size),
            _ => (yg - gap - size, yg - gap - size * rng.f()),
        };
        // A slanted ground crosses the box's z range: keep the box under (or over) it all.
        let slope = sigma.abs() * hz;
        let (y0, y1) = if y1 <= yg {
            (y0 - slope, y1 - slope)
        } else {
            (y0 + slope, y1 + slope)
        };
        l.boxes.push([
            DVec3::new(x - hx, y0, z - hz),
            DVec3::new(x + hx, y1, z + hz),
        ]);
    }
    // Axis-aligned walls facing the eye with boxes right behind them.
    let walls = rng.below(3);
    for _ in 0..walls {
        let z = rng.u(0.5, 5.0);
        let (cx, cy) = (rng.u(-2.0, 2.0), rng.u(-0.5, 2.0));
        let (wx, wy) = (rng.u(0.5, 3.0), rng.u(0.5, 3.0));
        l.polys.push(strip(
            0,
            DVec3::new(0.0, cy - wy, z),
            DVec3::new(0.0, cy + wy, z),
            cx - wx,
            cx + wx,
        ));
        let gap = if rng.chance(0.3) {
            0.0
        } else {
            z * rng.log_u(1e-12, 0.1)
        };
        let f = rng.u(0.05, 0.5);
        let zb = z + gap;
        let zb1 = zb + rng.u(0.0, 2.0);
        let k = zb / z;
        l.boxes.push([
            DVec3::new(cx - wx * f * k, cy - wy * f * k, zb),
            DVec3::new(cx + wx * f * k, cy + wy * f * k, zb1),
        ]);
    }
    l
}

// ---------------------------------------------------------------------------------------------
// World frame.

/// The map from the local frame to the world: local `z` to `axis` (times `sign`), local `x`
/// and `y` to the two other axes (with signs), then `offset + scale × ·` per coordinate. The
/// eye is the offset (local origin).
struct Frame {
    axis: usize,
    sign: f64,
    map: [(usize, f64); 3],
    offset: DVec3,
    scale: f64,
}

impl Frame {
    /// `extent`: the largest local coordinate magnitude; `scaled`: 1e-3 scale, 1e5 offset.
    fn random(rng: &mut Rng, extent: f64, scaled: bool) -> Frame {
        let axis = rng.below(3);
        let sign = rng.sign();
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let (xa, ya) = if rng.chance(0.5) { (b, c) } else { (c, b) };
        let map = [(xa, rng.sign()), (ya, rng.sign()), (axis, sign)];
        let mut offset = DVec3::ZERO;
        let scale = if scaled { 1e-3 } else { 1.0 };
        for k in 0..3 {
            offset[k] = if scaled {
                rng.sign() * (1e5 + rng.u(0.0, 1.0))
            } else if rng.chance(0.5) {
                0.0
            } else {
                // Differences to the offset stay exact (Sterbenz).
                rng.sign() * extent * rng.u(2.5, 100.0)
            };
        }
        Frame {
            axis,
            sign,
            map,
            offset,
            scale,
        }
    }
    fn point(&self, p: DVec3) -> DVec3 {
        let mut w = self.offset;
        for k in 0..3 {
            let (ax, s) = self.map[k];
            w[ax] = self.offset[ax] + self.scale * (s * p[k]);
        }
        w
    }
    fn aabb(&self, b: &[DVec3; 2]) -> DAabb {
        let (p, q) = (self.point(b[0]), self.point(b[1]));
        DAabb {
            min: p.min(q),
            max: p.max(q),
        }
    }
}

/// A configuration in world coordinates, as given to the sampler.
#[derive(Clone)]
struct Config {
    family: &'static str,
    index: usize,
    seed: u64,
    eye: DVec3,
    axis: usize,
    sign: f64,
    eps: f64,
    /// Rendered with `begin_patch` for this rectangle of the face's plane (half sides along
    /// the axes `(axis+1) % 3` and `(axis+2) % 3`, `eps` its half diagonal) instead of the ball.
    patch: Option<[f64; 2]>,
    res: u32,
    polys: Vec<(Vec<DVec3>, u32)>,
    boxes: Vec<DAabb>,
    /// Occludee triangles, tested with `Hemicube::test_triangle` (one per box, inside it).
    tris: Vec<[DVec3; 3]>,
}

fn to_world(
    family: &'static str,
    index: usize,
    seed: u64,
    l: &Local,
    rng: &mut Rng,
    scaled: bool,
) -> Config {
    let mut extent: f64 = 0.0;
    for p in l.polys.iter().flatten().chain(l.boxes.iter().flatten()) {
        extent = extent.max(p.abs().max_element());
    }
    let f = Frame::random(rng, extent, scaled);
    Config {
        family,
        index,
        seed,
        eye: f.offset,
        axis: f.axis,
        sign: f.sign,
        eps: l.eps * f.scale,
        patch: None,
        res: l.res,
        polys: l
            .polys
            .iter()
            .enumerate()
            .map(|(i, p)| (p.iter().map(|&v| f.point(v)).collect(), i as u32))
            .collect(),
        boxes: l.boxes.iter().map(|b| f.aabb(b)).collect(),
        tris: Vec::new(),
    }
}

/// A triangle inside the box: three random points, three corners (slanted across it), a
/// sliver, or one in a face of the box.
fn tri_in_box(rng: &mut Rng, b: &DAabb) -> [DVec3; 3] {
    let at = |t: DVec3| (b.min + (b.max - b.min) * t).clamp(b.min, b.max);
    let r3 = |rng: &mut Rng| DVec3::new(rng.f(), rng.f(), rng.f());
    match rng.below(4) {
        0 => [at(r3(rng)), at(r3(rng)), at(r3(rng))],
        1 => {
            let c =
                |i: usize| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64);
            let (i, j) = (rng.below(8), rng.below(8));
            [at(c(i)), at(c(j)), at(c(7 - i))]
        }
        2 => {
            let a = r3(rng);
            let d = DVec3::new(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0)) * 1e-3;
            [at(a), at(a + d), at(r3(rng))]
        }
        _ => {
            let k = rng.below(3);
            let side = rng.below(2) as f64;
            let mut p = [r3(rng), r3(rng), r3(rng)];
            for q in &mut p {
                q[k] = side;
            }
            p.map(at)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The brute-force check, in coordinates relative to the eye.

/// A polygon relative to the eye, with its Newell normal and bounds.
struct RelPoly {
    v: Vec<DVec3>,
    n: DVec3,
    centroid: DVec3,
    lo: DVec3,
    hi: DVec3,
}

impl RelPoly {
    fn new(pts: &[DVec3], eye: DVec3) -> Option<RelPoly> {
        let v: Vec<DVec3> = pts.iter().map(|&p| p - eye).collect();
        let m = v.len();
        let mut n = DVec3::ZERO;
        for i in 0..m {
            n += v[i].cross(v[(i + 1) % m]);
        }
        if n.length().is_nan() || n.length() <= 0.0 {
            return None;
        }
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for &p in &v {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let pad = (hi - lo).max_element() * 1e-9 + lo.abs().max(hi.abs()).max_element() * 1e-12;
        Some(RelPoly {
            centroid: v.iter().copied().sum::<DVec3>() / m as f64,
            n,
            lo: lo - DVec3::splat(pad),
            hi: hi + DVec3::splat(pad),
            v,
        })
    }
}

/// Whether the segment `b → q` clearly crosses the polygon: its end points clearly on opposite
/// sides of the plane and the segment clearly inside every edge (each sign test by more than
/// `TOL` times the product of the magnitudes it is computed from).
fn crosses(b: DVec3, q: DVec3, p: &RelPoly) -> bool {
    let v0 = p.v[0];
    let nl = p.n.length();
    let sb = p.n.dot(b - v0);
    let sq = p.n.dot(q - v0);
    let tb = TOL * nl * (b.length() + v0.length());
    let tq = TOL * nl * (q.length() + v0.length());
    // sigma = sign(n · (q − b)).
    let sigma = if sb >= tb && sq <= -tq {
        -1.0
    } else if sb <= -tb && sq >= tq {
        1.0
    } else {
        return false;
    };
    let d = q - b;
    let md = q.length() + b.length();
    let bl = b.length();
    let m = p.v.len();
    for i in 0..m {
        let (va, vc) = (p.v[i], p.v[(i + 1) % m]);
        let vol = (va - b).cross(vc - b).dot(d);
        let t = TOL * (va.length() + bl) * (vc.length() + bl) * md;
        if sigma * vol < t {
            return false;
        }
    }
    true
}

/// Whether the segment `b → q` can meet the box `[lo, hi]` (slab test).
fn seg_meets_box(b: DVec3, q: DVec3, lo: DVec3, hi: DVec3) -> bool {
    let d = q - b;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        if d[k] == 0.0 {
            if b[k] < lo[k] || b[k] > hi[k] {
                return false;
            }
        } else {
            let ta = (lo[k] - b[k]) / d[k];
            let tb = (hi[k] - b[k]) / d[k];
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Points of the closed ball of radius `eps` (relative to the eye): the eye, the six axis
/// points, the eight diagonal points, random points on the sphere and inside, and points of
/// the disc in the face plane (on its rim and inside).
fn ball_points(rng: &mut Rng, eps: f64, axis: usize) -> Vec<DVec3> {
    let r = eps * (1.0 - 1e-12);
    let mut out = vec![DVec3::ZERO];
    for k in 0..3 {
        for s in [-1.0, 1.0] {
            let mut p = DVec3::ZERO;
            p[k] = s * r;
            out.push(p);
        }
    }
    for i in 0..8 {
        let s = |b: usize| if i & b != 0 { 1.0 } else { -1.0 };
        out.push(DVec3::new(s(1), s(2), s(4)) * (r / 3f64.sqrt()));
    }
    for _ in 0..12 {
        out.push(rng.unit() * r);
    }
    for _ in 0..4 {
        out.push(rng.in_ball() * r);
    }
    for i in 0..10 {
        let mut u = rng.unit();
        u[axis] = 0.0;
        if u.length() < 1e-3 {
            continue;
        }
        let f = if i < 7 { 1.0 } else { rng.f() };
        out.push(u.normalize() * r * f);
    }
    out
}

/// Points of the rectangle of the face's plane with half sides `half` about the eye: its
/// corners (for one polygon they suffice: the points whose segment to `q` crosses it form a
/// convex set), points of its edges and inside, and its centre.
fn rect_points(rng: &mut Rng, half: [f64; 2], axis: usize) -> Vec<DVec3> {
    let (ba, ca) = ((axis + 1) % 3, (axis + 2) % 3);
    let (hb, hc) = (half[0] * (1.0 - 1e-12), half[1] * (1.0 - 1e-12));
    let at = |x: f64, y: f64| {
        let mut p = DVec3::ZERO;
        p[ba] = x * hb;
        p[ca] = y * hc;
        p
    };
    let mut out = vec![DVec3::ZERO];
    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        out.push(at(x, y));
    }
    for _ in 0..3 {
        for s in [-1.0, 1.0] {
            out.push(at(s, rng.u(-1.0, 1.0)));
            out.push(at(rng.u(-1.0, 1.0), s));
        }
    }
    for _ in 0..6 {
        out.push(at(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0)));
    }
    out
}

/// Points of the box `[lo, hi]` (relative to the eye, already cut to the outer side).
fn box_points(rng: &mut Rng, lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    let at = |t: DVec3| (lo + (hi - lo) * t).clamp(lo, hi);
    let mut out = Vec::new();
    for i in 0..8 {
        out.push(DVec3::new(
            if i & 1 != 0 { hi.x } else { lo.x },
            if i & 2 != 0 { hi.y } else { lo.y },
            if i & 4 != 0 { hi.z } else { lo.z },
        ));
    }
    // The nearest point to the eye.
    out.push(DVec3::ZERO.clamp(lo, hi));
    // Edges: along axis k, the others at 0 or 1.
    for k in 0..3 {
        for c in 0..4 {
            for _ in 0..2 {
                let mut t = DVec3::ZERO;
                t[k] = rng.f();
                t[(k + 1) % 3] = (c & 1) as f64;
                t[(k + 2) % 3] = (c >> 1) as f64;
                out.push(at(t));
            }
        }
    }
    // Faces.
    for k in 0..3 {
        for s in 0..2 {
            for j in 0..3 {
                let mut t = if j == 0 {
                    DVec3::splat(0.5)
                } else {
                    DVec3::new(rng.f(), rng.f(), rng.f())
                };
                t[k] = s as f64;
                out.push(at(t));
            }
        }
    }
    for _ in 0..8 {
        out.push(at(DVec3::new(rng.f(), rng.f(), rng.f())));
    }
    out
}

/// For `q`: the points of the ball farthest outside the shadow pyramid from `q` of each of
/// (up to four of) the polygons that the eye's ray to `q` crosses: past each edge's plane
/// through `q`, past each vertex (two edges at once), and nearest the polygon's plane.
fn targeted_points(q: DVec3, eps: f64, cand: &[usize], polys: &[RelPoly], out: &mut Vec<DVec3>) {
    out.clear();
    let r = eps * (1.0 - 1e-12);
    let mut found = 0;
    for &k in cand {
        let p = &polys[k];
        if !seg_meets_box(DVec3::ZERO, q, p.lo, p.hi) || !crosses(DVec3::ZERO, q, p) {
            continue;
        }
        found += 1;
        let m = p.v.len();
        let mut outs = Vec::with_capacity(m);
        for i in 0..m {
            let ne = (p.v[i] - q).cross(p.v[(i + 1) % m] - q);
            let ne = if ne.dot(p.centroid - q) > 0.0 {
                -ne
            } else {
                ne
            };
            let o = ne.normalize_or_zero();
            outs.push(o);
            out.push(o * r);
        }
        for i in 0..m {
            let o = (outs[i] + outs[(i + 1) % m]).normalize_or_zero();
            out.push(o * r);
        }
        let nn = p.n.normalize();
        let toward = if nn.dot(p.v[0]) > 0.0 { nn } else { -nn };
        out.push(toward * r);
        if found == 4 {
            break;
        }
    }
}

/// A segment not crossing any polygon although its box was reported hidden.
#[derive(Debug)]
struct Violation {
    bx: usize,
    b: DVec3,
    q: DVec3,
}

#[derive(Default, Debug, Clone, Copy)]
struct Stats {
    configs: usize,
    polygons: usize,
    boxes: usize,
    hidden: usize,
    /// Hidden boxes with no part on the outer side of the face plane (nothing to check).
    vacuous: usize,
    segments: u64,
    /// Hidden boxes and triangles with a segment not blocked (only counted when rendering with
    /// a smaller ball than the one checked).
    violations: usize,
    /// Occludee triangles tested, found hidden (with something on the outer side), and of
    /// those, triangles whose box the same render left open.
    tris: usize,
    tris_hidden: usize,
    tris_hidden_box_open: usize,
}

/// Checks every segment for the hidden box `bi` of `cfg`.
fn check_box(
    rng: &mut Rng,
    cfg: &Config,
    polys: &[RelPoly],
    bi: usize,
    st: &mut Stats,
) -> Result<bool, Violation> {
    let bx = cfg.boxes[bi];
    let (mut lo, mut hi) = (bx.min - cfg.eye, bx.max - cfg.eye);
    let a = cfg.axis;
    if cfg.sign > 0.0 {
        lo[a] = lo[a].max(0.0);
    } else {
        hi[a] = hi[a].min(0.0);
    }
    if lo[a] > hi[a] {
        return Ok(false);
    }
    let qs = box_points(rng, lo, hi);
    check_points(rng, cfg, polys, &qs, st).map_err(|(b, q)| Violation { bx: bi, b, q })?;
    Ok(true)
}

/// Checks every segment for the hidden triangle `ti` of `cfg`: from the ball's (or
/// rectangle's) points to the triangle's vertices, points of its edges, inside it and where
/// its edges cross the face plane, those on the outer side. Ok(false) when no part of it is
/// there; Err with the segment's ends when one is not blocked.
fn check_tri(
    rng: &mut Rng,
    cfg: &Config,
    polys: &[RelPoly],
    ti: usize,
    st: &mut Stats,
) -> Result<bool, (DVec3, DVec3)> {
    let t = cfg.tris[ti].map(|p| p - cfg.eye);
    let a = cfg.axis;
    let mut qs: Vec<DVec3> = t.to_vec();
    for i in 0..3 {
        let (p, q) = (t[i], t[(i + 1) % 3]);
        for f in [0.5, rng.f(), rng.f()] {
            qs.push(p + (q - p) * f);
        }
        if (p[a] < 0.0) != (q[a] < 0.0) {
            let mut x = p + (q - p) * (p[a] / (p[a] - q[a]));
            x[a] = 0.0;
            qs.push(x);
        }
    }
    qs.push((t[0] + t[1] + t[2]) / 3.0);
    for _ in 0..10 {
        let (mut x, mut y) = (rng.f(), rng.f());
        if x + y > 1.0 {
            (x, y) = (1.0 - x, 1.0 - y);
        }
        qs.push(t[0] + (t[1] - t[0]) * x + (t[2] - t[0]) * y);
    }
    qs.retain(|q| cfg.sign * q[a] >= 0.0);
    if qs.is_empty() {
        return Ok(false);
    }
    check_points(rng, cfg, polys, &qs, st)?;
    Ok(true)
}

/// Checks the segments from the ball's (or rectangle's) points, and for balls the targeted
/// points of each `q`, to the points `qs` (relative to the eye): Err with the first segment
/// that crosses no polygon.
fn check_points(
    rng: &mut Rng,
    cfg: &Config,
    polys: &[RelPoly],
    qs: &[DVec3],
    st: &mut Stats,
) -> Result<(), (DVec3, DVec3)> {
    let a = cfg.axis;
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for &q in qs {
        lo = lo.min(q);
        hi = hi.max(q);
    }
    // Polygons that can meet a segment from the ball to the points.
    let (ulo, uhi) = (
        lo.min(DVec3::splat(-cfg.eps)),
        hi.max(DVec3::splat(cfg.eps)),
    );
    let mut cand: Vec<usize> = (0..polys.len())
        .filter(|&k| {
            let p = &polys[k];
            p.lo.cmple(uhi).all() && p.hi.cmpge(ulo).all()
        })
        .collect();
    // Nearer polygons first (they block most segments).
    cand.sort_by(|&i, &j| {
        let d = |k: usize| polys[k].centroid.length_squared();
        d(i).total_cmp(&d(j))
    });
    let bs = match cfg.patch {
        None => ball_points(rng, cfg.eps, a),
        Some(half) => rect_points(rng, half, a),
    };
    let mut targeted = Vec::new();
    let mut last = usize::MAX;
    for &q in qs {
        if cfg.patch.is_none() {
            targeted_points(q, cfg.eps, &cand, polys, &mut targeted);
        }
        for &b in bs.iter().chain(targeted.iter()) {
            st.segments += 1;
            if last != usize::MAX && crosses(b, q, &polys[last]) {
                continue;
            }
            let hit = cand.iter().copied().find(|&k| {
                seg_meets_box(b, q, polys[k].lo, polys[k].hi) && crosses(b, q, &polys[k])
            });
            match hit {
                Some(k) => last = k,
                None => return Err((b, q)),
            }
        }
    }
    Ok(())
}

/// Renders `cfg` with its ball (or rectangle) scaled by `factor` and tests its boxes.
fn render(
    hc: &mut Hemicube,
    cfg: &Config,
    polys: &[(Vec<DVec3>, u32)],
    factor: f64,
) -> Vec<BoxTest> {
    let occ = SampleOccluders::from_polygons(polys);
    match cfg.patch {
        None => hc.begin(cfg.eye, cfg.axis, cfg.sign, cfg.eps * factor, &cfg.boxes),
        Some([hb, hc_]) => hc.begin_patch(
            cfg.eye,
            cfg.axis,
            cfg.sign,
            [hb * factor, hc_ * factor],
            &cfg.boxes,
        ),
    }
    hc.draw(&occ);
    cfg.boxes.iter().map(|b| hc.test_box(b)).collect()
}

/// [`render`], then tests the configuration's triangles.
fn render_tris(
    hc: &mut Hemicube,
    cfg: &Config,
    polys: &[(Vec<DVec3>, u32)],
    factor: f64,
) -> (Vec<BoxTest>, Vec<BoxTest>) {
    let boxes = render(hc, cfg, polys, factor);
    (
        boxes,
        cfg.tris.iter().map(|t| hc.test_triangle(*t)).collect(),
    )
}

fn hidden_with(cfg: &Config, polys: &[(Vec<DVec3>, u32)], bi: usize) -> bool {
    let mut hc = Hemicube::new(cfg.res);
    render(&mut hc, cfg, polys, 1.0)[bi] == BoxTest::Hidden
}

fn fmt_v(v: DVec3) -> String {
    format!("DVec3::new({:?}, {:?}, {:?})", v.x, v.y, v.z)
}

/// The render's parameters of a configuration, for violation reports.
fn describe(cfg: &Config) -> String {
    format!(
        "eye = {}, axis = {}, sign = {:?}, eps = {:?}, patch (begin_patch half sides) = {:?}, \
         res = {}",
        fmt_v(cfg.eye),
        cfg.axis,
        cfg.sign,
        cfg.eps,
        cfg.patch,
        cfg.res
    )
}

/// Reduces the polygons of a failing configuration (the box staying hidden; removing
/// polygons cannot block the violating segment) and describes the result.
fn report(cfg: &Config, v: &Violation, reused_state: bool) -> String {
    let mut msg = format!(
        "VIOLATION in family `{}`, configuration {} (seed {:#x}): box {} reported Hidden but the \
         segment b -> q is not blocked.\n  b - eye = {}, |b - eye| / eps = {:?}\n  q - eye = {}\n",
        cfg.family,
        cfg.index,
        cfg.seed,
        v.bx,
        fmt_v(v.b),
        v.b.length() / cfg.eps,
        fmt_v(v.q)
    );
    let mut cur = cfg.polys.clone();
    if !hidden_with(cfg, &cur, v.bx) {
        msg += &format!(
            "  NOTE: a fresh Hemicube reports this box Open: the failure depends on the state left \
             by earlier renders with the reused Hemicube (reused: {reused_state}).\n"
        );
    } else {
        // ddmin over the polygons.
        let mut n = 2usize;
        while cur.len() >= 2 {
            let chunk = cur.len().div_ceil(n);
            let mut reduced = false;
            for start in (0..cur.len()).step_by(chunk) {
                let rest: Vec<_> = cur
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| *i < start || *i >= start + chunk)
                    .map(|(_, p)| p.clone())
                    .collect();
                if hidden_with(cfg, &rest, v.bx) {
                    cur = rest;
                    n = (n - 1).max(2);
                    reduced = true;
                    break;
                }
            }
            if !reduced {
                if n >= cur.len() {
                    break;
                }
                n = (2 * n).min(cur.len());
            }
        }
    }
    let b = cfg.boxes[v.bx];
    msg += &format!(
        "  {}\n  boxes given to begin: {} \
         (the failing one: min {}, max {})\n  {} of {} polygons needed:\n",
        describe(cfg),
        cfg.boxes.len(),
        fmt_v(b.min),
        fmt_v(b.max),
        cur.len(),
        cfg.polys.len()
    );
    for (pts, id) in cur.iter().take(40) {
        let vs: Vec<String> = pts.iter().map(|&p| fmt_v(p)).collect();
        msg += &format!("    ({id}) vec![{}],\n", vs.join(", "));
    }
    if cur.len() > 40 {
        msg += "    ...\n";
    }
    msg
}

/// The configuration's polygons relative to its eye, for the exact check.
fn rel_polys(cfg: &Config) -> Vec<RelPoly> {
    cfg.polys
        .iter()
        .filter_map(|(p, _)| RelPoly::new(p, cfg.eye))
        .collect()
}

/// How the hemicube renders: the default (sub-pixel masks, edges shrunk only as much as the
/// boxes given need) or without one of them, for comparisons.
#[derive(Clone, Copy)]
struct Variant {
    subpixel: bool,
    depth_bounded: bool,
    tuck: bool,
    /// Rendered by the per-rectangle sweep (`RectSweep`) instead of the hemicube, always
    /// for a rectangle.
    sweep: bool,
}

const DEFAULT: Variant = Variant {
    subpixel: true,
    depth_bounded: true,
    tuck: false,
    sweep: false,
};

/// The configuration's boxes, then its triangles, as `RectSweep` objects: a box alone; a
/// triangle as an object of its own box with one piece (the configuration's box around it)
/// holding the triangle.
struct SweepCase<'a> {
    cfg: &'a Config,
}

impl SweepCase<'_> {
    fn tri_box(&self, i: usize) -> DAabb {
        let t = self.cfg.tris[i];
        DAabb {
            min: t[0].min(t[1]).min(t[2]),
            max: t[0].max(t[1]).max(t[2]),
        }
    }
}

impl Occludees for SweepCase<'_> {
    fn len(&self) -> usize {
        self.cfg.boxes.len() + self.cfg.tris.len()
    }
    fn object_box(&self, i: usize) -> DAabb {
        let n = self.cfg.boxes.len();
        if i < n {
            self.cfg.boxes[i]
        } else {
            self.tri_box(i - n)
        }
    }
    fn pieces(&self, i: usize) -> std::ops::Range<u32> {
        let n = self.cfg.boxes.len();
        if i < n {
            0..0
        } else {
            (i - n) as u32..(i - n) as u32 + 1
        }
    }
    fn piece_box(&self, k: u32) -> DAabb {
        let (b, t) = (self.cfg.boxes[k as usize], self.tri_box(k as usize));
        DAabb {
            min: b.min.min(t.min),
            max: b.max.max(t.max),
        }
    }
    fn piece_triangles(&self, k: u32) -> &[u32] {
        &TRI_IDS[k as usize..k as usize + 1]
    }
    fn triangle(&self, t: u32) -> [DVec3; 3] {
        self.cfg.tris[t as usize]
    }
}

/// Triangle indices `0, 1, 2, …` for [`SweepCase::piece_triangles`].
static TRI_IDS: [u32; 4096] = {
    let mut a = [0u32; 4096];
    let mut i = 0;
    while i < 4096 {
        a[i] = i as u32;
        i += 1;
    }
    a
};

/// Renders `cfg` (with a rectangle) by the sweep, its rectangle scaled by `factor`: the
/// boxes' and the triangles' results.
fn render_sweep(cfg: &Config, factor: f64) -> (Vec<BoxTest>, Vec<BoxTest>) {
    let occ = SampleOccluders::from_polygons(&cfg.polys);
    let [hb, hc] = cfg.patch.expect("the sweep renders rectangles");
    let mut sw = RectSweep::new(cfg.res.max(16));
    let case = SweepCase { cfg };
    let (hidden, _) = sw.render(
        &occ,
        cfg.eye,
        cfg.axis,
        cfg.sign,
        [hb * factor, hc * factor],
        &case,
    );
    let to = |h: bool| {
        if h {
            BoxTest::Hidden
        } else {
            BoxTest::Open {
                direction: DVec3::X,
            }
        }
    };
    let n = cfg.boxes.len();
    (
        hidden[..n].iter().map(|&h| to(h)).collect(),
        hidden[n..].iter().map(|&h| to(h)).collect(),
    )
}

/// Runs `n` configurations of a family and checks every hidden box.
#[expect(
    clippy::too_many_arguments,
    reason = "the family's fields and the two render variants, all plain"
)]
fn run_family(
    name: &'static str,
    seed: u64,
    n: usize,
    scaled: bool,
    patch: bool,
    generate: &dyn Fn(&mut Rng) -> Local,
    render_eps: f64,
    variant: Variant,
) -> Stats {
    let start = std::time::Instant::now();
    let mut st = Stats::default();
    let mut cubes: Vec<Hemicube> = Vec::new();
    for index in 0..n {
        let cseed = seed.wrapping_mul(1_000_003).wrapping_add(index as u64);
        let mut rng = Rng(cseed);
        let local = generate(&mut rng);
        let mut cfg = to_world(name, index, cseed, &local, &mut rng, scaled);
        if patch || variant.sweep {
            // Half sides with the ball's radius as half diagonal; some flat (a segment).
            let t = match rng.below(10) {
                0 => 0.0,
                1 => PI / 2.0,
                _ => rng.u(0.0, PI / 2.0),
            };
            cfg.patch = Some([cfg.eps * t.cos(), cfg.eps * t.sin()]);
        }
        // Hemicubes are reused across configurations (as the baker does).
        let res = (cfg.res.max(16) as usize).div_ceil(16) * 16;
        let k = match cubes.iter().position(|h| h.resolution() == res) {
            Some(k) => k,
            None => {
                cubes.push(Hemicube::new(cfg.res));
                cubes.len() - 1
            }
        };
        cubes[k].set_subpixel(variant.subpixel);
        cubes[k].set_depth_bounded(variant.depth_bounded);
        cubes[k].set_tuck(variant.tuck);
        cfg.tris = cfg.boxes.iter().map(|b| tri_in_box(&mut rng, b)).collect();
        let (results, tri_results) = if variant.sweep {
            render_sweep(&cfg, render_eps)
        } else {
            render_tris(&mut cubes[k], &cfg, &cfg.polys, render_eps)
        };
        let rel = rel_polys(&cfg);
        st.configs += 1;
        st.polygons += cfg.polys.len();
        for (bi, r) in results.iter().enumerate() {
            st.boxes += 1;
            if *r != BoxTest::Hidden {
                continue;
            }
            match check_box(&mut rng, &cfg, &rel, bi, &mut st) {
                Ok(true) => st.hidden += 1,
                Ok(false) => st.vacuous += 1,
                Err(_) if render_eps < 1.0 => st.violations += 1,
                Err(v) => panic!("{}", report(&cfg, &v, true)),
            }
        }
        for (ti, r) in tri_results.iter().enumerate() {
            st.tris += 1;
            if *r != BoxTest::Hidden {
                continue;
            }
            match check_tri(&mut rng, &cfg, &rel, ti, &mut st) {
                Ok(true) => {
                    st.tris_hidden += 1;
                    if results[ti] != BoxTest::Hidden {
                        st.tris_hidden_box_open += 1;
                    }
                }
                Ok(false) => {}
                Err(_) if render_eps < 1.0 => st.violations += 1,
                Err((b, q)) => panic!(
                    "VIOLATION in family `{}`, configuration {} (seed {:#x}): triangle {ti} {:?} \
                     reported Hidden but the segment b -> q is not blocked.\n  b - eye = {}, \
                     q - eye = {}\n  {}, {} polygons",
                    cfg.family,
                    cfg.index,
                    cfg.seed,
                    cfg.tris[ti],
                    fmt_v(b),
                    fmt_v(q),
                    describe(&cfg),
                    cfg.polys.len()
                ),
            }
        }
    }
    eprintln!(
        "sampler_proof family {name} (rendered with eps x {render_eps}): {} configurations, {} \
         polygons, {} boxes, {} hidden (+{} with nothing on the outer side), {} triangles, {} \
         hidden ({} of them in open boxes), {} segments checked, {} violations, {:.2} s",
        st.configs,
        st.polygons,
        st.boxes,
        st.hidden,
        st.vacuous,
        st.tris,
        st.tris_hidden,
        st.tris_hidden_box_open,
        st.segments,
        st.violations,
        start.elapsed().as_secs_f64()
    );
    st
}

/// Asserts that a family hid at least `min_share` of its boxes and of its triangles (with
/// something to check), and some triangles whose box it left open (the triangle test is not
/// the box test).
fn assert_meaningful(name: &str, st: &Stats, min_share: f64) {
    let tri_share = st.tris_hidden as f64 / st.tris.max(1) as f64;
    assert!(
        st.tris_hidden >= 3 && tri_share >= min_share && st.tris_hidden_box_open > 0,
        "family {name} hid only {} of {} triangles ({} in open boxes): the check is too weak",
        st.tris_hidden,
        st.tris,
        st.tris_hidden_box_open
    );
    let share = st.hidden as f64 / st.boxes.max(1) as f64;
    assert!(
        st.hidden >= 3 && share >= min_share,
        "family {name} hid only {} of {} boxes (share {share:.3} < {min_share}): the check is too weak",
        st.hidden,
        st.boxes
    );
}

// ---------------------------------------------------------------------------------------------
// Tests.

/// A family: its generator, seed, configurations (release), whether scaled by 1e-3 and offset
/// by 1e5, and the least share of its boxes it must hide.
struct Family {
    name: &'static str,
    seed: u64,
    configs: usize,
    scaled: bool,
    /// Rendered with `begin_patch` (a rectangle of the face) and checked from its points.
    patch: bool,
    generate: fn(&mut Rng) -> Local,
    min_hidden: f64,
}

/// For rectangles: near polygons (nearer than the half diagonal too), leaves low over the
/// face, or any family.
fn gen_patch(rng: &mut Rng) -> Local {
    if rng.chance(0.4) {
        gen_near_patch(rng)
    } else if rng.chance(0.2) {
        gen_low(rng)
    } else {
        gen_any(rng)
    }
}

/// Any family's generator, chosen at random (for the scaled family).
fn gen_any(rng: &mut Rng) -> Local {
    let gens: [fn(&mut Rng) -> Local; 9] = [
        gen_foliage,
        gen_depth_bounded,
        gen_fine_foliage,
        gen_grazing,
        gen_near,
        gen_crossing,
        gen_partly_behind,
        gen_general,
        gen_ground,
    ];
    let g = rng.pick(&gens);
    g(rng)
}

const FAMILIES: [Family; 13] = [
    Family {
        name: "depth_bounded",
        seed: 0xDE_B0DED,
        configs: 800,
        scaled: false,
        patch: false,
        generate: gen_depth_bounded,
        min_hidden: 0.05,
    },
    Family {
        name: "fine_foliage",
        seed: 0xF1_0E1A6E,
        configs: 600,
        scaled: false,
        patch: false,
        generate: gen_fine_foliage,
        min_hidden: 0.05,
    },
    Family {
        name: "ground",
        seed: 0x62_0ED,
        configs: 1000,
        scaled: false,
        patch: false,
        generate: gen_ground,
        min_hidden: 0.05,
    },
    Family {
        name: "foliage",
        seed: 0x0F01_1A6E,
        configs: 2000,
        scaled: false,
        patch: false,
        generate: gen_foliage,
        min_hidden: 0.05,
    },
    Family {
        name: "grazing",
        seed: 0x006A_21A6,
        configs: 600,
        scaled: false,
        patch: false,
        generate: gen_grazing,
        min_hidden: 0.05,
    },
    Family {
        name: "near",
        seed: 0x4EA2,
        configs: 1500,
        scaled: false,
        patch: false,
        generate: gen_near,
        min_hidden: 0.05,
    },
    Family {
        name: "crossing",
        seed: 0xC2055,
        configs: 400,
        scaled: false,
        patch: false,
        generate: gen_crossing,
        min_hidden: 0.05,
    },
    Family {
        name: "partly_behind",
        seed: 0xBE41D,
        configs: 1000,
        scaled: false,
        patch: false,
        generate: gen_partly_behind,
        min_hidden: 0.05,
    },
    Family {
        name: "general",
        seed: 0x6E4E2A1,
        configs: 750,
        scaled: false,
        patch: false,
        generate: gen_general,
        min_hidden: 0.02,
    },
    Family {
        name: "scaled",
        seed: 0x5CA1ED,
        configs: 750,
        scaled: true,
        patch: false,
        generate: gen_any,
        min_hidden: 0.05,
    },
    Family {
        name: "patch",
        seed: 0x9A7C,
        configs: 1000,
        scaled: false,
        patch: true,
        generate: gen_patch,
        min_hidden: 0.05,
    },
    Family {
        name: "patch_low",
        seed: 0x009A_7C10,
        configs: 800,
        scaled: false,
        patch: true,
        generate: gen_low,
        min_hidden: 0.05,
    },
    Family {
        name: "patch_scaled",
        seed: 0x9A7C_5CA1,
        configs: 400,
        scaled: true,
        patch: true,
        generate: gen_patch,
        min_hidden: 0.05,
    },
];

/// Runs family `name` with the true ball and asserts it hid enough boxes.
fn family(name: &str) {
    let f = FAMILIES.iter().find(|f| f.name == name).expect("family");
    let st = run_family(
        f.name,
        f.seed,
        count(f.configs),
        f.scaled,
        f.patch,
        &f.generate,
        1.0,
        DEFAULT,
    );
    assert_meaningful(f.name, &st, f.min_hidden);
}

#[test]
fn foliage_hidden_boxes_are_hidden_from_the_whole_ball() {
    family("foliage");
}

/// Leaves of a fraction of a pixel to a few pixels: sub-pixel masks fuse them.
#[test]
fn fine_foliage_fused_in_sub_pixels_is_hidden_from_the_whole_ball() {
    family("fine_foliage");
}

/// Sub-pixel masks are what hides the fine foliage's boxes: without them (one polygon over a
/// whole pixel) far fewer are hidden, from the same configurations.
#[test]
fn sub_pixel_masks_fuse_what_whole_pixels_cannot() {
    let f = FAMILIES
        .iter()
        .find(|f| f.name == "fine_foliage")
        .expect("family");
    let n = count(f.configs / 3);
    let run = |sub: bool| {
        run_family(
            f.name,
            f.seed ^ 0x5B,
            n,
            false,
            false,
            &f.generate,
            1.0,
            Variant {
                subpixel: sub,
                ..DEFAULT
            },
        )
    };
    let (with, without) = (run(true), run(false));
    assert!(
        with.hidden >= 2 * without.hidden + 10,
        "sub-pixel masks hid {} boxes, whole pixels {}: masks must hide far more",
        with.hidden,
        without.hidden
    );
}

/// Occludees just behind or among leaves: hidden from the whole ball with edges shrunk only
/// for their distance.
#[test]
fn occludees_near_the_leaves_with_depth_bounded_shrinks() {
    family("depth_bounded");
}

/// Depth-bounded shrinks are what hides those occludees: shrunk for occludees at any distance,
/// far fewer are hidden, from the same configurations.
#[test]
fn depth_bounded_shrinks_fuse_what_unbounded_ones_cannot() {
    let f = FAMILIES
        .iter()
        .find(|f| f.name == "depth_bounded")
        .expect("family");
    let n = count(f.configs / 3);
    let run = |depth_bounded: bool| {
        run_family(
            f.name,
            f.seed ^ 0xB0,
            n,
            false,
            false,
            &f.generate,
            1.0,
            Variant {
                depth_bounded,
                ..DEFAULT
            },
        )
    };
    let (with, without) = (run(true), run(false));
    assert!(
        2 * with.hidden >= 3 * without.hidden + 20,
        "depth-bounded shrinks hid {} boxes, unbounded ones {}: the bound must hide far more",
        with.hidden,
        without.hidden
    );
}

/// Every family again with the tuck pass (`Hemicube::set_tuck`): edges covered nearer than
/// themselves drawn unshrunk. Each hidden box and triangle gets the same segment checks.
#[test]
fn tucked_edges_keep_every_family_hidden_from_the_whole_ball() {
    let tuck = Variant {
        tuck: true,
        ..DEFAULT
    };
    for (f, st) in FAMILIES.iter().zip(run_every_family(0x7C, 2, 1.0, tuck)) {
        assert_meaningful(f.name, &st, f.min_hidden);
    }
}

/// Every family again rendered by the per-rectangle sweep (`RectSweep`, module docs of
/// `sampler::sweep`), each from a rectangle of the face (some flat): every hidden box and
/// triangle gets the same segment checks from the rectangle's points. The sweep fuses
/// differently from the hemicube, so the share each family hides differs; together they must
/// hide a share of their boxes and triangles.
#[test]
fn the_sweep_keeps_every_family_hidden_from_the_whole_rectangle() {
    let sweep = Variant {
        sweep: true,
        ..DEFAULT
    };
    let (mut hidden, mut boxes, mut tris_hidden, mut tris) = (0, 0, 0, 0);
    for st in run_every_family(0x5EE9, 2, 1.0, sweep) {
        hidden += st.hidden;
        boxes += st.boxes;
        tris_hidden += st.tris_hidden;
        tris += st.tris;
    }
    assert!(
        hidden * 20 >= boxes && tris_hidden * 20 >= tris,
        "the sweep hid {hidden} of {boxes} boxes and {tris_hidden} of {tris} triangles: the \
         check is too weak"
    );
}

/// The segment check catches a sweep rendered for a smaller rectangle than the one checked
/// (half of it, or a point): some box or triangle it reports hidden is seen from a point of
/// the whole rectangle.
#[test]
fn check_catches_a_sweep_for_a_smaller_rectangle() {
    for factor in [0.0, 0.5] {
        let found = violations_per_family(
            factor,
            0x5EEA,
            Variant {
                sweep: true,
                ..DEFAULT
            },
        );
        assert!(
            found.iter().map(|f| f.1).sum::<usize>() > 0,
            "no violation found with the sweep's rectangle x {factor}"
        );
    }
}

/// Every family's violations (its name, how many) rendered `variant`, with the ball or
/// rectangle scaled by `factor`, a quarter of its configurations, seeds salted by `salt`.
fn violations_per_family(factor: f64, salt: u64, variant: Variant) -> Vec<(&'static str, usize)> {
    FAMILIES
        .iter()
        .zip(run_every_family(salt, 4, factor, variant))
        .map(|(f, st)| (f.name, st.violations))
        .collect()
}

/// Runs every family ([`run_family`]) with `1/share` of its configurations, seeds salted by
/// `salt`, the ball or rectangle scaled by `factor`, rendered `variant`: their stats in
/// [`FAMILIES`]' order.
fn run_every_family(salt: u64, share: usize, factor: f64, variant: Variant) -> Vec<Stats> {
    FAMILIES
        .iter()
        .map(|f| {
            run_family(
                f.name,
                f.seed ^ salt,
                count(f.configs / share),
                f.scaled,
                f.patch,
                &f.generate,
                factor,
                variant,
            )
        })
        .collect()
}

/// Degenerate polygons hide nothing: three collinear points (up to rounding) give one plane
/// through the eye for all their edges, and each edge's inner side, taken from the centroid
/// that lies on that plane, is a rounding error; when all took the same side the polygon
/// covered a half-space. Both configurations were found by `general_mix` and the tuck pass's
/// run at `UMBRASWEEP_SAMPLER_PROOF_SCALE=15` (configurations 2013 and 2382), reduced to the
/// one polygon: a box behind it was reported hidden.
#[test]
fn collinear_polygons_hide_nothing() {
    let cases = common::collinear_cases();
    for (k, (eye, axis, eps, res, poly, [min, max])) in cases.into_iter().enumerate() {
        let occ = SampleOccluders::from_polygons(&[(poly.to_vec(), 0)]);
        let bx = DAabb { min, max };
        for tuck in [false, true] {
            let mut hc = Hemicube::new(res);
            hc.set_subpixel(true);
            hc.set_depth_bounded(true);
            hc.set_tuck(tuck);
            hc.begin(eye, axis, 1.0, eps, &[bx]);
            hc.draw(&occ);
            assert_ne!(
                hc.test_box(&bx),
                BoxTest::Hidden,
                "case {k} (tuck {tuck}): a box hidden by a degenerate polygon"
            );
        }
    }
}

/// The tuck pass hides more of the foliage family's boxes and triangles: with it, from the
/// same configurations, more are hidden (these sparse clusters gain a few per cent, the fine
/// forest's renders about a sixth, `docs/sampling.md`; the fine-foliage family's leaves of a few pixels,
/// fused by sub-pixel masks, gain almost nothing).
#[test]
fn tucked_edges_fuse_what_shrunk_ones_cannot() {
    let name = "foliage";
    let f = FAMILIES.iter().find(|f| f.name == name).expect("family");
    let n = count(f.configs / 3);
    let run = |tuck: bool| {
        run_family(
            f.name,
            f.seed ^ 0x7D,
            n,
            false,
            false,
            &f.generate,
            1.0,
            Variant { tuck, ..DEFAULT },
        )
    };
    let (with, without) = (run(true), run(false));
    let (w, wo) = (
        with.hidden + with.tris_hidden,
        without.hidden + without.tris_hidden,
    );
    assert!(
        w >= wo + 10,
        "{name}: the tuck pass hid {w} boxes and triangles, shrunk edges alone {wo}: it \
         must hide more"
    );
}

#[test]
fn grazing_angles() {
    family("grazing");
}

#[test]
fn leaves_near_the_sample_point() {
    family("near");
}

#[test]
fn leaves_crossing_the_face_plane() {
    family("crossing");
}

#[test]
fn boxes_partly_behind_the_face_plane() {
    family("partly_behind");
}

#[test]
fn ground_and_glued_boxes() {
    family("ground");
}

/// `Hemicube::begin_patch`: hidden from every point of a rectangle of the face (half
/// diagonal `eps`; some flat), any family, unscaled and scaled.
#[test]
fn patches_instead_of_balls() {
    family("patch");
    family("patch_low");
    family("patch_scaled");
}

#[test]
fn general_mix() {
    family("general");
}

#[test]
fn scaled_by_1e_3_and_offset_by_1e5() {
    family("scaled");
}

/// The check is sharp: rendering with a smaller ball than the one checked (no shrink at all,
/// or half of it) must produce boxes that the check finds visible from some point of the ball.
#[test]
fn check_catches_a_render_with_less_shrink() {
    for factor in [0.0, 0.5] {
        let found = violations_per_family(factor, 0x5A5A, DEFAULT);
        for (name, v) in &found {
            if ["near", "general", "patch"].contains(name) {
                assert!(
                    *v > 0,
                    "family {name}: no violation found with the render's eps x {factor}"
                );
            }
        }
        assert!(
            found.iter().map(|f| f.1).sum::<usize>() > 0,
            "no violation found with the render's eps x {factor}"
        );
    }
}

/// The checker itself: strict on edges and planes, and finds a crossing through the inside.
#[test]
fn checker_is_strict() {
    let sq = [
        DVec3::new(-1.0, -1.0, 2.0),
        DVec3::new(1.0, -1.0, 2.0),
        DVec3::new(1.0, 1.0, 2.0),
        DVec3::new(-1.0, 1.0, 2.0),
    ];
    let p = RelPoly::new(&sq, DVec3::ZERO).unwrap();
    let mut rev = sq;
    rev.reverse();
    let pr = RelPoly::new(&rev, DVec3::ZERO).unwrap();
    for p in [&p, &pr] {
        assert!(crosses(DVec3::ZERO, DVec3::new(0.5, -0.3, 5.0), p));
        assert!(crosses(DVec3::new(0.5, -0.3, 5.0), DVec3::ZERO, p));
        // Through an edge, through a vertex, ending on the plane, short of the plane: no.
        assert!(!crosses(DVec3::ZERO, DVec3::new(2.0, 0.0, 4.0), p));
        assert!(!crosses(DVec3::ZERO, DVec3::new(2.0, 2.0, 4.0), p));
        assert!(!crosses(DVec3::ZERO, DVec3::new(0.0, 0.0, 2.0), p));
        assert!(!crosses(DVec3::ZERO, DVec3::new(0.0, 0.0, 1.9), p));
        assert!(!crosses(DVec3::ZERO, DVec3::new(2.2, 0.0, 4.0), p));
        // Just inside an edge, by far more than the tolerance: yes.
        assert!(crosses(DVec3::ZERO, DVec3::new(2.0 - 1e-9, 0.0, 4.0), p));
    }
}

/// A box hidden from the eye point alone but seen from a point of the ball must be reported
/// open (the test fails if the shrink is removed), and hidden for a tiny ball; the check must
/// find the segment that is not blocked, in every frame (axes, signs, offsets, 1e-3 scale).
#[test]
fn shrink_matters() {
    let wall = vec![
        DVec3::new(-1.0, -1.0, 2.0),
        DVec3::new(1.0, -1.0, 2.0),
        DVec3::new(1.0, 1.0, 2.0),
        DVec3::new(-1.0, 1.0, 2.0),
    ];
    let bx = [DVec3::new(-2.42, -2.42, 5.0), DVec3::new(2.42, 2.42, 6.0)];
    let rel = RelPoly::new(&wall, DVec3::ZERO).unwrap();
    // From the eye every point of the box is behind the wall ...
    let mut rng = Rng(7);
    for q in box_points(&mut rng, bx[0], bx[1]) {
        assert!(crosses(DVec3::ZERO, q, &rel), "eye to {q} must be blocked");
    }
    // ... but not from a point of the ball of radius 0.1 (x = +0.1 sees past the wall's edge
    // at x = 1 to the box's corner at x = 2.42, z = 5), which the targeted points find.
    let corner = DVec3::new(2.42, 0.0, 5.0);
    assert!(!crosses(
        DVec3::new(0.1 * (1.0 - 1e-12), 0.0, 0.0),
        corner,
        &rel
    ));
    let mut targeted = Vec::new();
    targeted_points(corner, 0.1, &[0], std::slice::from_ref(&rel), &mut targeted);
    assert!(targeted.iter().any(|&b| !crosses(b, corner, &rel)));
    for case in 0..12 {
        let scaled = case >= 8;
        let mut rng = Rng(0x5412 + case);
        let local = |eps: f64| Local {
            eps,
            res: 256,
            polys: vec![wall.clone()],
            boxes: vec![bx],
        };
        let tiny = to_world(
            "shrink_matters",
            case as usize,
            0,
            &local(1e-6),
            &mut Rng(case),
            scaled,
        );
        let cfg = to_world(
            "shrink_matters",
            case as usize,
            0,
            &local(0.1),
            &mut Rng(case),
            scaled,
        );
        let what = format!(
            "case {case}: eye {}, axis {}, sign {}",
            cfg.eye, cfg.axis, cfg.sign
        );
        for res in [128, 256] {
            let mut hc = Hemicube::new(res);
            let mut t = tiny.clone();
            t.res = res;
            assert_eq!(
                render(&mut hc, &t, &t.polys, 1.0)[0],
                BoxTest::Hidden,
                "tiny ball, res {res}, {what}"
            );
            // The same Hemicube, reused.
            let r = render(&mut hc, &cfg, &cfg.polys, 1.0)[0];
            assert!(
                matches!(r, BoxTest::Open { .. }),
                "ball of radius 0.1, res {res}: {r:?}, {what}"
            );
        }
        // The check run on it as if it had been reported hidden finds a violation.
        let rel = rel_polys(&cfg);
        let mut st = Stats::default();
        assert!(
            check_box(&mut rng, &cfg, &rel, 0, &mut st).is_err(),
            "the check misses the gap, {what}"
        );
        let rel = rel_polys(&tiny);
        assert!(
            check_box(&mut rng, &tiny, &rel, 0, &mut st).is_ok(),
            "tiny ball: the check must pass, {what}"
        );
    }
}

/// A polygon nearer than ε (plane distance) is left out even where it would hide everything.
#[test]
fn polygon_within_eps_is_left_out() {
    let eps = 0.1;
    for d in [0.05, 0.1, 0.1 * (1.0 + 1e-9)] {
        let wall = vec![
            DVec3::new(-100.0, -100.0, d),
            DVec3::new(100.0, -100.0, d),
            DVec3::new(100.0, 100.0, d),
            DVec3::new(-100.0, 100.0, d),
        ];
        let cfg = Config {
            family: "within_eps",
            index: 0,
            seed: 0,
            eye: DVec3::ZERO,
            axis: 2,
            sign: 1.0,
            eps,
            patch: None,
            res: 64,
            polys: vec![(wall, 0)],
            boxes: vec![DAabb {
                min: DVec3::new(-0.5, -0.5, 3.0),
                max: DVec3::new(0.5, 0.5, 4.0),
            }],
            tris: Vec::new(),
        };
        let mut hc = Hemicube::new(64);
        assert!(
            matches!(
                render(&mut hc, &cfg, &cfg.polys, 1.0)[0],
                BoxTest::Open { .. }
            ),
            "d = {d}"
        );
    }
}
