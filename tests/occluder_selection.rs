//! Occluder selection by solid angle (`--occluder-min-solid-angle`): the bound it uses is never
//! below a box's real solid angle from any point of the cell (Monte Carlo), an occluder whose
//! solid angle is above the threshold still hides what it hides, one below it is left out
//! (its target comes back, never the reverse), and the setting survives the `.pvs` file.

mod common;

use common::{Lcg, cube};
use glam::{DVec3, Vec3};
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{self, BakeSettings};
use umbrasweep::geom::{Aabb, DAabb};
use umbrasweep::pvs::{PvsDatabase, binary};
use umbrasweep::scene::Scene;
use umbrasweep::settings::SweepChoice;

/// The fraction of `n` uniform directions from `p` whose ray meets `b`, times 4π.
fn monte_carlo_solid_angle(p: DVec3, b: &DAabb, n: usize, rng: &mut Lcg) -> f64 {
    let mut hits = 0;
    for _ in 0..n {
        let z = 2.0 * rng.unit() - 1.0;
        let phi = std::f64::consts::TAU * rng.unit();
        let r = (1.0 - z * z).sqrt();
        let d = DVec3::new(r * phi.cos(), r * phi.sin(), z);
        // Slab test.
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            let inv = 1.0 / d[k];
            let (a, c) = ((b.min[k] - p[k]) * inv, (b.max[k] - p[k]) * inv);
            t0 = t0.max(a.min(c));
            t1 = t1.min(a.max(c));
        }
        if t0 <= t1 {
            hits += 1;
        }
    }
    4.0 * std::f64::consts::PI * hits as f64 / n as f64
}

#[test]
fn the_bound_is_never_below_the_solid_angle_from_any_point_of_the_cell() {
    let mut rng = Lcg(7);
    let n = 20_000;
    for case in 0..60 {
        let mut rand_box = |scale: f64, spread: f64| {
            let c = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * spread - spread / 2.0;
            let h = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * scale + 1e-3;
            DAabb {
                min: c - h,
                max: c + h,
            }
        };
        let cell = rand_box(2.0, 4.0);
        // Flat, long and cubic boxes, near and far.
        let b = rand_box(3.0, 30.0);
        let bound = b.max_solid_angle_from(&cell);
        for corner in 0..9 {
            let p = if corner == 8 {
                cell.center()
            } else {
                cell.corners()[corner]
            };
            let est = monte_carlo_solid_angle(p, &b, n, &mut rng);
            // Four standard deviations of the estimate.
            let q = est / (4.0 * std::f64::consts::PI);
            let sigma = 4.0 * std::f64::consts::PI * (q * (1.0 - q) / n as f64).sqrt();
            assert!(
                bound >= est - 4.0 * sigma - 1e-9,
                "case {case}: bound {bound} below the solid angle {est} (σ {sigma}) from {p} of \
                 {cell:?}, box {b:?}"
            );
        }
    }
}

/// A unit cell at the origin; a wall 8 × 8 at z = 20 (about 0.13 sr from the cell's far
/// face, at least 0.11 from its near one); a target behind it.
fn scene() -> (Scene, Aabb) {
    let s = Scene::from_objects(
        std::path::Path::new("selection"),
        vec![
            cube("wall", [-4.0, -4.0, 20.0], [4.0, 4.0, 20.5]),
            cube("target", [-0.5, -0.5, 30.0], [0.5, 0.5, 31.0]),
        ],
    );
    (s, Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5)))
}

fn settings(min_solid_angle: f64, sweep: SweepChoice) -> BakeSettings {
    BakeSettings {
        occluder_min_solid_angle: min_solid_angle,
        sweep,
        // The selection is the planes' (ray space factorization would hide the target alone).
        rsf: SweepChoice::Off,
        ..BakeSettings::default()
    }
}

#[test]
fn an_occluder_above_the_threshold_still_hides_and_one_below_is_left_out() {
    let (s, cell) = scene();
    let wall = DAabb {
        min: DVec3::new(-4.0, -4.0, 20.0),
        max: DVec3::new(4.0, 4.0, 20.5),
    };
    let bound = wall.max_solid_angle_from(&DAabb {
        min: DVec3::splat(-0.5),
        max: DVec3::splat(0.5),
    });
    assert!(bound > 0.1 && bound < 0.3, "{bound}");
    for sweep in [SweepChoice::Off, SweepChoice::On] {
        for (angle, hidden) in [
            (0.0, true),
            (0.05, true),
            (bound * 1.01, false),
            (1.0, false),
        ] {
            let r = bake::bake(
                &s,
                &[cell],
                &settings(angle, sweep),
                &CpuBackend::new(),
                None,
            )
            .unwrap();
            assert_eq!(
                !r.cells[0].visible.contains(&1),
                hidden,
                "threshold {angle} sr, sweep {sweep:?}: target hidden should be {hidden}"
            );
            assert!(r.cells[0].visible.contains(&0), "the wall is always seen");
        }
    }
}

#[test]
fn the_threshold_survives_the_pvs_file_and_a_default_bake_stays_version_4() {
    let (s, cell) = scene();
    for angle in [0.0, 0.001] {
        let st = settings(angle, SweepChoice::Off);
        let r = bake::bake(&s, &[cell], &st, &CpuBackend::new(), None).unwrap();
        let doc = bake::to_document(&s, &[cell], &r, &st);
        let bytes = binary::encode(&doc).unwrap();
        let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
        assert_eq!(version, if angle == 0.0 { 4 } else { 6 });
        let back = PvsDatabase::from_bytes(&bytes).unwrap().to_document();
        assert_eq!(back.settings.bake.occluder_min_solid_angle, angle);
        let json = serde_json::to_string(&doc).unwrap();
        assert!(json.contains("\"occluder_min_solid_angle\""), "{json}");
    }
}

#[test]
fn a_solid_angle_out_of_range_is_refused_naming_the_option() {
    for bad in [-1e-3, f64::NAN, 13.0] {
        let e = settings(bad, SweepChoice::Off).check().unwrap_err();
        assert_eq!(e.option, "occluder-min-solid-angle", "{bad}");
    }
}
