//! Analytic scenes for the baking core (issue 2): walls, slits, fusion of abutting walls,
//! objects in and across the cell, a closed room, and an object seen from one corner only.
//! Each expectation follows from the geometry; brute-force rays check the visible cases.

mod common;

use glam::Vec3;
use std::path::Path;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{BakeSettings, bake};
use umbrasweep::geom::Aabb;
use umbrasweep::scene::Scene;

use common::{Obj, cube, quad, unit_cell};

/// Bakes one cell with the default settings and returns the visible object names.
fn visible(objects: Vec<Obj>, cell: Aabb) -> Vec<String> {
    let scene = Scene::from_objects(Path::new("analytic"), objects);
    let r = bake(
        &scene,
        &[cell],
        &BakeSettings::default(),
        &CpuBackend::new(),
        None,
    )
    .unwrap();
    r.cells[0]
        .visible
        .iter()
        .map(|&o| scene.objects[o as usize].name.clone())
        .collect()
}

/// First object hit by the ray (brute force, see `common::first_hit`).
fn first_hit(objects: &[Obj], origin: Vec3, dir: Vec3) -> Option<String> {
    common::first_hit(
        objects.iter().map(|(n, t, _)| (n.as_str(), t.as_slice())),
        origin,
        dir,
    )
    .map(str::to_string)
}

fn has(v: &[String], name: &str) -> bool {
    v.iter().any(|n| n == name)
}

#[test]
fn an_object_behind_a_large_wall_is_hidden() {
    let objects = vec![
        cube("wall", [-20.0, -20.0, 5.0], [20.0, 20.0, 5.5]),
        cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]),
        cube("in_view", [-1.0, -1.0, -11.0], [1.0, 1.0, -10.0]),
    ];
    let v = visible(objects, unit_cell());
    assert!(has(&v, "wall"));
    assert!(!has(&v, "target"), "{v:?}");
    assert!(has(&v, "in_view"));
}

#[test]
fn an_object_seen_through_a_slit_is_visible() {
    let objects = vec![
        cube("left", [-20.0, -20.0, 5.0], [-0.15, 20.0, 5.5]),
        cube("right", [0.15, -20.0, 5.0], [20.0, 20.0, 5.5]),
        cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]),
    ];
    // Ground truth: the ray from the cell centre through the slit reaches the target.
    assert_eq!(
        first_hit(&objects, Vec3::ZERO, Vec3::Z).as_deref(),
        Some("target")
    );
    let v = visible(objects, unit_cell());
    assert!(has(&v, "target"), "{v:?}");
}

#[test]
fn two_abutting_walls_hide_together_what_neither_hides_alone() {
    let z = 5.0;
    let wall_a = quad(
        "wall_a",
        Vec3::new(-20.0, -20.0, z),
        Vec3::new(0.0, -20.0, z),
        Vec3::new(0.0, 20.0, z),
        Vec3::new(-20.0, 20.0, z),
    );
    let wall_b = quad(
        "wall_b",
        Vec3::new(0.0, -20.0, z),
        Vec3::new(20.0, -20.0, z),
        Vec3::new(20.0, 20.0, z),
        Vec3::new(0.0, 20.0, z),
    );
    let target = cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]);
    let both = visible(
        vec![wall_a.clone(), wall_b.clone(), target.clone()],
        unit_cell(),
    );
    assert!(!has(&both, "target"), "fusion hides the target: {both:?}");
    let a_only = visible(vec![wall_a, target.clone()], unit_cell());
    assert!(has(&a_only, "target"));
    let b_only = visible(vec![wall_b, target], unit_cell());
    assert!(has(&b_only, "target"));
}

#[test]
fn objects_inside_or_straddling_the_cell_are_visible() {
    // A closed room around the cell would hide anything outside; these are not outside.
    let mut objects = room();
    objects.push(cube("inside", [-0.1, -0.1, -0.1], [0.1, 0.1, 0.1]));
    objects.push(cube("straddling", [0.3, -0.2, -0.2], [2.0, 0.2, 0.2]));
    objects.push(cube("touching", [0.5, 0.3, 0.3], [1.0, 0.4, 0.4]));
    let v = visible(objects, unit_cell());
    for name in ["inside", "straddling", "touching"] {
        assert!(has(&v, name), "{name} must be visible: {v:?}");
    }
}

/// Six thick walls enclosing [-3, 3]³, overlapping at the edges.
fn room() -> Vec<Obj> {
    let (a, b) = (3.0, 3.5);
    vec![
        cube("room+x", [a, -b, -b], [b, b, b]),
        cube("room-x", [-b, -b, -b], [-a, b, b]),
        cube("room+y", [-b, a, -b], [b, b, b]),
        cube("room-y", [-b, -b, -b], [b, -a, b]),
        cube("room+z", [-b, -b, a], [b, b, b]),
        cube("room-z", [-b, -b, -b], [b, b, -a]),
    ]
}

#[test]
fn a_cell_inside_a_closed_room_hides_everything_outside() {
    let mut objects = room();
    let mut outside = Vec::new();
    for (i, c) in [
        [10.0, 0.0, 0.0],
        [-10.0, 0.0, 0.0],
        [0.0, 10.0, 0.0],
        [0.0, -10.0, 0.0],
        [0.0, 0.0, 10.0],
        [0.0, 0.0, -10.0],
        [8.0, 8.0, 8.0],
        [-8.0, 6.0, -7.0],
        [9.0, -9.0, 0.0],
    ]
    .iter()
    .enumerate()
    {
        let name = format!("outside{i}");
        let c = Vec3::from(*c);
        objects.push(cube(&name, (c - 0.5).into(), (c + 0.5).into()));
        outside.push(name);
    }
    let v = visible(objects, unit_cell());
    for w in ["room+x", "room-x", "room+y", "room-y", "room+z", "room-z"] {
        assert!(has(&v, w), "the walls are visible");
    }
    for name in &outside {
        assert!(!has(&v, name), "{name} is outside the closed room: {v:?}");
    }
}

#[test]
fn an_object_seen_from_one_corner_only_stays_visible() {
    // A wall with a small square hole; the target sits on the line from the cell's corner
    // (0.5, 0.5, 0.5) through the hole, far behind.
    let (h0, h1) = (2.0f32, 2.3f32);
    let mut objects = vec![
        cube("wall_low", [-20.0, -20.0, 5.0], [20.0, h0, 5.5]),
        cube("wall_high", [-20.0, h1, 5.0], [20.0, 20.0, 5.5]),
        cube("wall_left", [-20.0, h0, 5.0], [h0, h1, 5.5]),
        cube("wall_right", [h1, h0, 5.0], [20.0, h1, 5.5]),
    ];
    let corner = Vec3::splat(0.5);
    let hole = Vec3::new(0.5 * (h0 + h1), 0.5 * (h0 + h1), 5.25);
    let dir = (hole - corner).normalize();
    let t = (15.0 - corner.z) / dir.z;
    let c = corner + dir * t;
    objects.push(cube("target", (c - 0.1).into(), (c + 0.1).into()));
    // Ground truth: visible from (just inside) the corner, hidden from the centre.
    let eye = corner - Vec3::splat(1e-4);
    assert_eq!(
        first_hit(&objects, eye, (c - eye).normalize()).as_deref(),
        Some("target")
    );
    assert_ne!(
        first_hit(&objects, Vec3::ZERO, c.normalize()).as_deref(),
        Some("target")
    );
    let v = visible(objects, unit_cell());
    assert!(has(&v, "target"), "{v:?}");
}

#[test]
fn settings_are_checked() {
    let scene = Scene::from_objects(
        Path::new("t"),
        vec![cube("a", [1.0, 1.0, 1.0], [2.0, 2.0, 2.0])],
    );
    let bad = BakeSettings {
        resolution: 300,
        ..BakeSettings::default()
    };
    let err = bake(&scene, &[unit_cell()], &bad, &CpuBackend::new(), None).unwrap_err();
    assert!(err.to_string().contains("power of two"), "{err}");
}

#[test]
fn alpha_tested_walls_hide_nothing_unless_asked_and_occluder_patterns_select() {
    let wall = |opaque: bool| {
        let (name, tris, _) = cube("wall", [-20.0, -20.0, 5.0], [20.0, 20.0, 5.5]);
        (name, tris, opaque)
    };
    let target = cube("target", [-1.0, -1.0, 10.0], [1.0, 1.0, 11.0]);
    let bake_with = |objects: Vec<Obj>, settings: BakeSettings| {
        let scene = Scene::from_objects(Path::new("analytic"), objects);
        let r = bake(&scene, &[unit_cell()], &settings, &CpuBackend::new(), None).unwrap();
        r.cells[0].visible.contains(&1)
    };
    // A leaf-card material (not opaque) is an occludee only.
    assert!(bake_with(
        vec![wall(false), target.clone()],
        BakeSettings::default()
    ));
    // --alpha-occluders treats it as opaque.
    let alpha = BakeSettings {
        alpha_occluders: true,
        ..BakeSettings::default()
    };
    assert!(!bake_with(vec![wall(false), target.clone()], alpha));
    // --occluders 'wa*' keeps the wall; 'tar*' leaves no occluder; the target stays an occludee.
    let only = |p: &str| BakeSettings {
        occluders: Some(p.into()),
        ..BakeSettings::default()
    };
    assert!(!bake_with(vec![wall(true), target.clone()], only("wa*")));
    assert!(bake_with(vec![wall(true), target.clone()], only("tar*")));
    // A bad pattern is an error, not a panic.
    let scene = Scene::from_objects(Path::new("t"), vec![wall(true)]);
    let err = bake(
        &scene,
        &[unit_cell()],
        &only("[x"),
        &CpuBackend::new(),
        None,
    )
    .unwrap_err();
    assert!(err.to_string().contains("--occluders"), "{err}");
}
