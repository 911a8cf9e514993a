//! The culler pipeline's accounting (issue 15): per cell and culler, the objects it hid, those
//! only it hid, its time and planes; the bake summary's means in the PVS document; the names of
//! the cullers that ran for each choice of the sweep.

mod common;

use glam::Vec3;
use std::path::Path;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{BakeSettings, SweepChoice, bake, to_document};
use umbrasweep::geom::Aabb;
use umbrasweep::scene::Scene;

use common::{cube, unit_cell};

/// A wall at z = 5 hiding three boxes behind it; two boxes in view; an object without
/// triangles (never listed, never counted).
fn scene() -> Scene {
    Scene::from_objects(
        Path::new("pipeline"),
        vec![
            cube("wall", [-30.0, -30.0, 5.0], [30.0, 30.0, 5.5]),
            cube("hidden_a", [-2.0, -1.0, 10.0], [-1.0, 1.0, 11.0]),
            cube("hidden_b", [1.0, -1.0, 10.0], [2.0, 1.0, 11.0]),
            cube("hidden_c", [-1.0, 3.0, 12.0], [1.0, 4.0, 13.0]),
            cube("seen_a", [-1.0, -1.0, -11.0], [1.0, 1.0, -10.0]),
            cube("seen_b", [10.0, -1.0, -1.0], [11.0, 1.0, 1.0]),
            ("empty".to_string(), Vec::new(), true),
        ],
    )
}

/// The planes alone (ray space factorization, which the automatic rule runs on these boxes,
/// has its own test below).
fn settings(sweep: SweepChoice) -> BakeSettings {
    BakeSettings {
        sweep,
        rsf: SweepChoice::Off,
        ..BakeSettings::default()
    }
}

/// With ray space factorization first, each culler accounts for what it hid; the planes skip
/// what it hid, so what it hid counts as hidden only by it.
#[test]
fn ray_space_factorization_runs_first_and_the_planes_skip_what_it_hid() {
    let scene = scene();
    let cells = [unit_cell()];
    let s = BakeSettings {
        sweep: SweepChoice::Off,
        ..BakeSettings::default()
    };
    let r = bake(&scene, &cells, &s, &CpuBackend::new(), None).unwrap();
    assert!(r.rsf, "boxes are upright: {}", r.rsf_reason);
    assert_eq!(
        r.cullers,
        vec!["ray_space_factorization", "extended_projections"]
    );
    let c = &r.cells[0];
    let culled = (scene.objects.iter().enumerate())
        .filter(|(o, ob)| !ob.bounds.is_empty() && !c.visible.contains(&(*o as u32)))
        .count() as u32;
    assert!(culled >= 3, "{:?}", c.visible);
    let (rsf, planes) = (&c.cullers[0], &c.cullers[1]);
    assert_eq!(rsf.hidden + planes.hidden, culled);
    assert_eq!(rsf.only, rsf.hidden);
    assert_eq!(planes.only, planes.hidden);
    // The wall reaches below the cell's bottom (it spans y −30..30), so it casts half
    // umbrae: the boxes behind it are ray space factorization's.
    assert!(rsf.hidden >= 3, "{rsf:?}");
}

#[test]
fn each_choice_of_the_sweep_runs_its_culler_and_accounts_for_what_it_hid() {
    let scene = scene();
    let cells = [
        unit_cell(),
        Aabb::new(Vec3::new(-0.5, -0.5, -3.5), Vec3::new(0.5, 0.5, -2.5)),
    ];
    for (choice, name) in [
        (SweepChoice::Off, "extended_projections"),
        (SweepChoice::On, "occlusion_sweep"),
    ] {
        let r = bake(&scene, &cells, &settings(choice), &CpuBackend::new(), None).unwrap();
        assert_eq!(r.cullers, vec![name]);
        for (ci, c) in r.cells.iter().enumerate() {
            let names: Vec<&str> = c
                .visible
                .iter()
                .map(|&o| scene.objects[o as usize].name.as_str())
                .collect();
            for h in ["hidden_a", "hidden_b", "hidden_c"] {
                assert!(!names.contains(&h), "{name}, cell {ci}: {h} in {names:?}");
            }
            assert_eq!(c.cullers.len(), 1);
            let s = &c.cullers[0];
            // Every culled object with triangles was hidden by the one culler, and only it.
            let culled = (scene.objects.iter().enumerate())
                .filter(|(o, ob)| !ob.bounds.is_empty() && !c.visible.contains(&(*o as u32)))
                .count() as u32;
            assert_eq!(s.hidden, culled, "{name}, cell {ci}");
            assert_eq!(s.only, culled, "{name}, cell {ci}");
            assert!(
                s.ms > 0.0 && s.ms <= c.ms,
                "{name}, cell {ci}: {} of {}",
                s.ms,
                c.ms
            );
            assert_eq!(s.work.planes, c.planes);
            assert_eq!(s.work.occluders_projected, c.occluders_projected);
            assert!(c.planes > 0);
        }
        // The document's summary holds the means per cell.
        let doc = to_document(&scene, &cells, &r, &settings(choice));
        let sum = doc.summary.unwrap();
        assert_eq!(sum.cullers.len(), 1);
        let mean = |f: &dyn Fn(&umbrasweep::bake::CullerStats) -> f64| {
            r.cells.iter().map(|c| f(&c.cullers[0])).sum::<f64>() / cells.len() as f64
        };
        assert_eq!(sum.cullers[0].name, name);
        assert_eq!(sum.cullers[0].hidden, mean(&|s| s.hidden as f64));
        assert_eq!(sum.cullers[0].only, mean(&|s| s.only as f64));
        assert_eq!(sum.cullers[0].planes, mean(&|s| s.work.planes as f64));
        assert!(sum.cullers[0].hidden >= 3.0);
    }
}

/// With sub-cells an object counts as hidden from the cell only when every sub-cell hides it:
/// `seen_c` is hidden from the left half of the cell and seen from the right half.
#[test]
fn sub_cells_count_only_what_the_whole_cell_hides() {
    let mut objects = vec![
        // A wall covering x < 0.3 of the view along +z, close to the cell.
        cube("wall", [-30.0, -30.0, 2.0], [0.3, 30.0, 2.5]),
        cube("seen_c", [0.6, -0.2, 6.0], [1.0, 0.2, 6.5]),
        cube("hidden_d", [-8.0, -1.0, 6.0], [-6.0, 1.0, 7.0]),
    ];
    objects.push(cube("seen_a", [-1.0, -1.0, -11.0], [1.0, 1.0, -10.0]));
    let scene = Scene::from_objects(Path::new("subcells"), objects);
    let cell = Aabb::new(Vec3::new(-1.0, -0.5, -0.5), Vec3::new(1.0, 0.5, 0.5));
    let s = BakeSettings {
        subcell: Some(1.0),
        sweep: SweepChoice::Off,
        rsf: SweepChoice::Off,
        ..BakeSettings::default()
    };
    let r = bake(&scene, &[cell], &s, &CpuBackend::new(), None).unwrap();
    let c = &r.cells[0];
    let culled = (0..scene.objects.len() as u32)
        .filter(|o| !c.visible.contains(o))
        .count() as u32;
    assert!(c.visible.contains(&1), "seen_c is seen from the right half");
    assert!(
        !c.visible.contains(&2),
        "hidden_d is hidden from both halves"
    );
    assert_eq!(c.cullers[0].hidden, culled);
    assert_eq!(c.cullers[0].only, culled);
}
