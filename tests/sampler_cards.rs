//! The sampler's per-pixel texel-footprint test of alpha-tested cards (this file owns it): a
//! card hides what lies behind its opaque half and not what lies behind its transparent half,
//! and a brute force over random textured cards checks the claim — when `test_box` answers
//! `Hidden`, every segment from the sampled ball to the box crosses some card at a point the
//! renderer draws (bilinear alpha at mip 0 at least the cutoff) — also scaled by 1e-3 and
//! offset by 1e5.

use glam::{DVec2, DVec3, Vec2};
use std::sync::Arc;
use umbrasweep::geom::DAabb;
use umbrasweep::sampler::{BoxTest, Hemicube, SampleOccluders};
use umbrasweep::scene::alpha::{AlphaTexture, Coverage, Wrap};

mod common;
use common::Lcg;

const CUTOFF: f32 = 0.5;

fn texture(w: u32, h: u32, wrap: Wrap, f: impl Fn(u32, u32) -> u8) -> AlphaTexture {
    let alpha = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| f(x, y))
        .collect();
    AlphaTexture {
        label: "test".into(),
        width: w,
        height: h,
        alpha: Arc::new(alpha),
        wrap: [wrap, wrap],
    }
}

/// A quad card `[-s, s]² at z` as two triangles with texture coordinates `[0, 1]²`.
fn quad(z: f64, s: f64) -> Vec<([DVec3; 3], [DVec2; 3], u32, u32)> {
    let p = [
        DVec3::new(-s, -s, z),
        DVec3::new(s, -s, z),
        DVec3::new(s, s, z),
        DVec3::new(-s, s, z),
    ];
    let t = [
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 0.0),
        DVec2::new(1.0, 1.0),
        DVec2::new(0.0, 1.0),
    ];
    vec![
        ([p[0], p[1], p[2]], [t[0], t[1], t[2]], 0, 0),
        ([p[0], p[2], p[3]], [t[0], t[2], t[3]], 0, 0),
    ]
}

#[test]
fn a_card_hides_only_behind_its_opaque_texels() {
    // Left half opaque (u < 0.5), right half transparent.
    let tex = texture(
        32,
        32,
        Wrap::ClampToEdge,
        |x, _| if x < 16 { 255 } else { 0 },
    );
    let cov = Arc::new(Coverage::build(&tex, CUTOFF, Some(1)));
    let occ = SampleOccluders::from_polygons_and_cards(&[], &quad(2.0, 2.0), vec![cov]);
    let behind_opaque = DAabb {
        min: DVec3::new(-1.5, -0.3, 4.0),
        max: DVec3::new(-0.6, 0.3, 4.5),
    };
    let behind_clear = DAabb {
        min: DVec3::new(0.6, -0.3, 4.0),
        max: DVec3::new(1.5, 0.3, 4.5),
    };
    let across = DAabb {
        min: DVec3::new(-0.5, -0.3, 4.0),
        max: DVec3::new(0.5, 0.3, 4.5),
    };
    let mut hc = Hemicube::new(128);
    hc.begin(
        DVec3::ZERO,
        2,
        1.0,
        0.02,
        &[behind_opaque, behind_clear, across],
    );
    let st = hc.draw(&occ);
    assert!(st.polygons >= 1, "the opaque half is drawn");
    assert_eq!(hc.test_box(&behind_opaque), BoxTest::Hidden);
    assert!(matches!(hc.test_box(&behind_clear), BoxTest::Open { .. }));
    assert!(matches!(hc.test_box(&across), BoxTest::Open { .. }));

    // A fully transparent texture hides nothing.
    let clear = texture(32, 32, Wrap::ClampToEdge, |_, _| 0);
    let cov = Arc::new(Coverage::build(&clear, CUTOFF, Some(1)));
    let occ = SampleOccluders::from_polygons_and_cards(&[], &quad(2.0, 2.0), vec![cov]);
    hc.begin(DVec3::ZERO, 2, 1.0, 0.02, &[behind_opaque]);
    hc.draw(&occ);
    assert!(matches!(hc.test_box(&behind_opaque), BoxTest::Open { .. }));
}

/// The point where segment `a → b` crosses triangle `t` strictly inside (barycentric
/// coordinates above `tol`), with those coordinates.
fn crossing(a: DVec3, b: DVec3, t: &[DVec3; 3], tol: f64) -> Option<(f64, f64)> {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let (da, db) = (n.dot(a - t[0]), n.dot(b - t[0]));
    if da * db >= 0.0 {
        return None;
    }
    let x = a + (b - a) * (da / (da - db));
    let area = n.length_squared();
    let w1 = (x - t[0]).cross(t[2] - t[0]).dot(n) / area;
    let w2 = (t[1] - t[0]).cross(x - t[0]).dot(n) / area;
    let w0 = 1.0 - w1 - w2;
    (w0 > tol && w1 > tol && w2 > tol).then_some((w1, w2))
}

/// Random textured cards before the eye, boxes behind; every box found hidden is checked
/// with segments from points of the ball to points of the box. Returns (boxes, hidden).
fn brute_force(seed: u64, scaled: bool) -> (usize, usize) {
    let mut rng = Lcg(seed);
    let (scale, offset) = if scaled {
        (1e-3, DVec3::new(1e5, -1e5, 1e5))
    } else {
        (1.0, DVec3::ZERO)
    };
    let at = |p: DVec3| p * scale + offset;
    // Textures: random opaque discs on transparent, some wrapping.
    let mut textures = Vec::new();
    for k in 0..3 {
        let discs: Vec<(f64, f64, f64)> = (0..6)
            .map(|_| {
                (
                    rng.range(0.0, 16.0),
                    rng.range(0.0, 16.0),
                    rng.range(2.0, 7.0),
                )
            })
            .collect();
        let wrap = [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat][k];
        textures.push(texture(16, 16, wrap, |x, y| {
            let inside = discs
                .iter()
                .any(|&(cx, cy, r)| (x as f64 + 0.5 - cx).hypot(y as f64 + 0.5 - cy) < r);
            if inside { 255 } else { 0 }
        }));
    }
    let covs: Vec<Arc<Coverage>> = textures
        .iter()
        .map(|t| Arc::new(Coverage::build(t, CUTOFF, Some(1))))
        .collect();
    let mut cards = Vec::new();
    let n_cards = [2, 4, 8, 40][(seed % 4) as usize];
    for _ in 0..n_cards {
        let c = DVec3::new(
            rng.range(-2.0, 2.0),
            rng.range(-2.0, 2.0),
            rng.range(0.6, 3.0),
        );
        let s = if n_cards < 40 {
            rng.range(2.0, 5.0)
        } else {
            rng.range(0.5, 2.5)
        };
        let p: [DVec3; 3] = std::array::from_fn(|_| {
            c + DVec3::new(
                rng.range(-s, s),
                rng.range(-s, s),
                rng.range(-0.3 * s, 0.3 * s),
            )
        });
        let o = DVec2::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let uv: [DVec2; 3] =
            std::array::from_fn(|_| o + DVec2::new(rng.range(-1.2, 1.2), rng.range(-1.2, 1.2)));
        let tex = (rng.unit() * 3.0) as u32 % 3;
        cards.push((p.map(at), uv, tex, 0));
    }
    let occ = SampleOccluders::from_polygons_and_cards(&[], &cards, covs);
    let boxes: Vec<DAabb> = (0..60)
        .map(|_| {
            let c = DVec3::new(
                rng.range(-2.5, 2.5),
                rng.range(-2.5, 2.5),
                rng.range(3.5, 6.0),
            );
            let hs = if seed % 4 == 3 { 0.3 } else { 0.08 };
            let h = DVec3::new(rng.range(0.0, hs), rng.range(0.0, hs), rng.range(0.0, hs));
            DAabb {
                min: at(c - h),
                max: at(c + h),
            }
        })
        .collect();
    let eps = rng.range(0.02, 0.25) * scale;
    let eye = at(DVec3::ZERO);
    let mut hc = Hemicube::new(160);
    hc.begin(eye, 2, 1.0, eps, &boxes);
    hc.draw(&occ);
    let mut hidden = 0;
    for bx in &boxes {
        if hc.test_box(bx) != BoxTest::Hidden {
            continue;
        }
        hidden += 1;
        // Points of the ball's sphere: the 26 directions of a cube's corners, edges and faces
        // (the extreme points that push a crossing furthest), then random ones.
        let dirs: Vec<DVec3> = (0..27)
            .filter(|&i| i != 13)
            .map(|i| {
                DVec3::new(
                    (i % 3) as f64 - 1.0,
                    ((i / 3) % 3) as f64 - 1.0,
                    (i / 9) as f64 - 1.0,
                )
            })
            .map(DVec3::normalize)
            .collect();
        for k in 0..1040 {
            let d = if k % 40 < 26 {
                dirs[k % 40]
            } else {
                let d = DVec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                );
                if d.length() > 1e-3 {
                    d.normalize()
                } else {
                    DVec3::X
                }
            };
            let b = eye + d * eps;
            let k = k / 40;
            let q = if k < 8 {
                DVec3::new(
                    if k & 1 == 0 { bx.min.x } else { bx.max.x },
                    if k & 2 == 0 { bx.min.y } else { bx.max.y },
                    if k & 4 == 0 { bx.min.z } else { bx.max.z },
                )
            } else {
                bx.min + (bx.max - bx.min) * DVec3::new(rng.unit(), rng.unit(), rng.unit())
            };
            let blocked = cards.iter().any(|(p, uv, tex, _)| {
                crossing(b, q, p, 1e-9).is_some_and(|(w1, w2)| {
                    let t = uv[0] * (1.0 - w1 - w2) + uv[1] * w1 + uv[2] * w2;
                    textures[*tex as usize].bilinear(Vec2::new(t.x as f32, t.y as f32))
                        >= CUTOFF + 1e-3
                })
            });
            assert!(
                blocked,
                "seed {seed} (scaled {scaled}): the segment {b:?} → {q:?} to a box found \
                 hidden crosses no drawn texel"
            );
        }
    }
    (boxes.len(), hidden)
}

#[test]
fn every_box_found_hidden_behind_random_cards_is_blocked_by_drawn_texels() {
    let (mut all, mut hidden) = (0, 0);
    for seed in 0..48 {
        for scaled in [false, true] {
            let (a, h) = brute_force(seed, scaled);
            all += a;
            hidden += h;
        }
    }
    // Not vacuous: the cards hide a real share of the boxes.
    assert!(hidden * 20 >= all, "only {hidden} of {all} boxes hidden");
}
