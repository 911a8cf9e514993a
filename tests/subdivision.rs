//! Adaptive subdivision (`--max-pvs-triangles`): a cell whose PVS is over budget is split in
//! halves baked against its PVS; halves' PVS are subsets of their parent's, the halves tile
//! it, the document and the `.pvs` file keep the hierarchy, the run-time lookup descends to
//! the smallest cell, and neighbouring cells agree on what is seen from their shared face.

mod common;

use common::cube;
use glam::Vec3;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{self, BakeSettings, CellResult};
use umbrasweep::geom::Aabb;
use umbrasweep::pvs::{PvsDatabase, binary};
use umbrasweep::scene::Scene;
use umbrasweep::validate::{CheckOptions, SceneRays, check};

/// A cell 8 long in x; a wall at z = 3 ending at x = 4; a target behind it at x ≤ 0, seen
/// past the wall's end only from the part of the cell with x > 4; a box beside the cell
/// that every point sees.
fn scene() -> (Scene, Aabb) {
    let s = Scene::from_objects(
        std::path::Path::new("subdivision"),
        vec![
            cube("wall", [-60.0, -20.0, 3.0], [4.0, 20.0, 3.2]),
            cube("target", [-3.0, -1.0, 10.0], [0.0, 1.0, 11.0]),
            cube("beside", [12.0, -1.0, -2.0], [13.0, 1.0, 2.0]),
        ],
    );
    (
        s,
        Aabb::new(Vec3::new(0.0, -1.0, -1.0), Vec3::new(8.0, 1.0, 1.0)),
    )
}

fn settings(budget: u64) -> BakeSettings {
    BakeSettings {
        max_pvs_triangles: Some(budget),
        min_cell_size: Some(1.0),
        ..BakeSettings::default()
    }
}

/// Every (cell box, result) of a subtree, parents before halves.
fn nodes(r: &CellResult, b: Aabb) -> Vec<(Aabb, &CellResult)> {
    r.flatten(b).into_iter().map(|(b, _, r)| (b, r)).collect()
}

#[test]
fn halves_tile_their_parent_and_see_a_subset_of_it() {
    let (s, cell) = scene();
    let r = bake::bake(&s, &[cell], &settings(20), &CpuBackend::new(), None).unwrap();
    let top = &r.cells[0];
    // The whole cell sees the target past the wall's end: 36 triangles > 20, so it is split.
    assert!(top.visible.contains(&1), "{:?}", top.visible);
    assert_eq!(top.children.len(), 2, "over budget: split");
    for (b, n) in nodes(top, cell) {
        if n.children.is_empty() {
            continue;
        }
        let [lo, hi] = [&n.children[0], &n.children[1]];
        let axis = (b.max - b.min).max_position();
        assert_eq!(lo.max[axis], hi.min[axis], "halves share the split plane");
        assert_eq!(Vec3::from(lo.min), b.min);
        assert_eq!(Vec3::from(hi.max), b.max);
        for h in [lo, hi] {
            for o in &h.result.visible {
                assert!(
                    n.visible.contains(o),
                    "a half sees {o}, its parent does not"
                );
            }
        }
    }
    // The first split is along x at 4: the left half cannot see the target.
    assert_eq!(top.children[0].max[0], 4.0);
    assert!(!top.children[0].result.visible.contains(&1));
    assert!(top.children[1].result.visible.contains(&1));
}

#[test]
fn no_budget_or_under_budget_means_no_split() {
    let (s, cell) = scene();
    let plain = bake::bake(
        &s,
        &[cell],
        &BakeSettings::default(),
        &CpuBackend::new(),
        None,
    );
    let plain = plain.unwrap();
    assert!(plain.cells[0].children.is_empty());
    let roomy = bake::bake(&s, &[cell], &settings(1000), &CpuBackend::new(), None).unwrap();
    assert!(roomy.cells[0].children.is_empty());
    assert_eq!(roomy.cells[0].visible, plain.cells[0].visible);
}

#[test]
fn the_pvs_file_keeps_the_hierarchy_and_the_lookup_descends() {
    let (s, cell) = scene();
    let set = settings(20);
    let r = bake::bake(&s, &[cell], &set, &CpuBackend::new(), None).unwrap();
    let doc = bake::to_document(&s, &[cell], &r, &set);
    assert!(doc.cells.len() > 3);
    assert_eq!(doc.cells[0].parent, None);
    for (i, c) in doc.cells.iter().enumerate().skip(1) {
        let p = c.parent.expect("every later cell is a half") as usize;
        assert!(p < i);
        let q = &doc.cells[p];
        assert!((0..3).all(|k| q.min[k] <= c.min[k] && c.max[k] <= q.max[k]));
    }
    let bytes = binary::encode(&doc).unwrap();
    assert_eq!(
        &bytes[8..12],
        &6u32.to_le_bytes(),
        "a hierarchy makes a version 6 file"
    );
    let db = PvsDatabase::from_bytes(&bytes).unwrap();
    let back = db.to_document();
    assert_eq!(
        serde_json::to_value(&back.cells).unwrap(),
        serde_json::to_value(&doc.cells).unwrap()
    );
    assert_eq!(back.settings.bake.max_pvs_triangles, Some(20));
    // The lookup ends in a cell that was not split, inside the top cell.
    for (p, sees_target) in [([1.0, 0.0, 0.0], false), ([7.5, 0.5, 0.5], true)] {
        let id = db.cell_at(p).expect("inside the cell");
        assert_eq!(db.cell_halves(id).count(), 0, "a leaf");
        assert_ne!(id.index(), 0);
        let (lo, hi) = db.cell_bounds(id);
        assert!((0..3).all(|k| lo[k] <= p[k] && p[k] <= hi[k]));
        assert_eq!(db.is_visible(id, 1), sees_target, "at {p:?}");
        let mut up = db.cell_parent(id);
        let mut depth = 1;
        while let Some(c) = up {
            up = db.cell_parent(c);
            depth += 1;
        }
        assert!(depth >= 2);
    }
    assert_eq!(db.cell_at([100.0, 0.0, 0.0]), None);
}

#[test]
fn every_cell_of_the_hierarchy_is_conservative() {
    let (s, cell) = scene();
    let set = settings(20);
    let r = bake::bake(&s, &[cell], &set, &CpuBackend::new(), None).unwrap();
    let doc = bake::to_document(&s, &[cell], &r, &set);
    let report = check(
        &s,
        &doc,
        &CheckOptions {
            rays: 50_000,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(report.false_culls, 0, "{}", report.table());
}

/// An object seen from a point on the face two cells share is in both cells' PVS: rays from
/// points of every shared face of the leaves, in many directions.
#[test]
fn neighbouring_cells_agree_on_their_shared_faces() {
    let (s, cell) = scene();
    let set = settings(20);
    let r = bake::bake(&s, &[cell], &set, &CpuBackend::new(), None).unwrap();
    let leaves: Vec<(Aabb, &CellResult)> = nodes(&r.cells[0], cell)
        .into_iter()
        .filter(|(_, n)| n.children.is_empty())
        .collect();
    assert!(leaves.len() >= 3);
    let rays = SceneRays::new(&s);
    let mut checked = 0;
    for (i, (a, ra)) in leaves.iter().enumerate() {
        for (b, rb) in leaves.iter().skip(i + 1) {
            // The shared face: where the closed boxes touch.
            let lo = a.min.max(b.min);
            let hi = a.max.min(b.max);
            if (0..3).any(|k| lo[k] > hi[k]) || (0..3).filter(|&k| lo[k] == hi[k]).count() != 1 {
                continue;
            }
            for u in 0..5 {
                for v in 0..5 {
                    let t = Vec3::new(u as f32 / 4.0, v as f32 / 4.0, (u + v) as f32 / 8.0);
                    let p = lo + (hi - lo) * t;
                    for d in 0..200 {
                        let (th, ph) = (d as f32 * 2.399_963, (d as f32 + 0.5) / 200.0);
                        let z = 1.0 - 2.0 * ph;
                        let r2 = (1.0 - z * z).max(0.0).sqrt();
                        let dir = Vec3::new(r2 * th.cos(), r2 * th.sin(), z);
                        for h in rays.trace(p, dir, false) {
                            assert!(
                                ra.visible.contains(&h.object) && rb.visible.contains(&h.object),
                                "object {} seen from {p} on the face of {a:?} and {b:?}",
                                h.object
                            );
                            checked += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 1000, "{checked} hits checked");
}

/// A version 6 file (split table and hierarchy) damaged behind a recomputed checksum: every
/// payload byte changed in turn never panics, and damage to the extensions is refused with
/// a message saying what is wrong.
#[test]
fn damaged_extensions_are_refused_without_panics() {
    use umbrasweep::pvs::{PvsErrorKind, PvsSource, PvsSplit};
    let (s, cell) = scene();
    let set = settings(20);
    let r = bake::bake(&s, &[cell], &set, &CpuBackend::new(), None).unwrap();
    let mut doc = bake::to_document(&s, &[cell], &r, &set);
    let source = |id: u32, name: &str, triangles: u32, first: u32, count: u32| PvsSource {
        id,
        name: name.into(),
        triangles,
        min: [0.0; 3],
        max: [1.0; 3],
        first,
        count,
    };
    doc.split = Some(PvsSplit {
        size: 2.0,
        sources: vec![
            source(0, "wall and target", 24, 0, 2),
            source(1, "beside", 12, 2, 1),
        ],
    });
    let b = binary::encode(&doc).unwrap();
    let back = PvsDatabase::from_bytes(&b).unwrap();
    assert_eq!(back.split(), doc.split.as_ref());
    assert_eq!(back.split().unwrap().source_of(1), 0);
    let mut messages = Vec::new();
    for i in binary::HEADER_LEN..b.len() {
        for v in [0x00u8, 0xFF, b[i] ^ 0x01] {
            let mut d = b.clone();
            if d[i] == v {
                continue;
            }
            d[i] = v;
            let crc = binary::crc32(&d[binary::HEADER_LEN..]);
            d[12..16].copy_from_slice(&crc.to_le_bytes());
            if let Err(e) = PvsDatabase::from_bytes(&d) {
                assert!(matches!(e.kind, PvsErrorKind::Corrupt(_)), "{e}");
                messages.push(e.to_string());
            }
        }
    }
    for want in [
        "does not come before",
        "split source",
        "does not lie inside",
        "one entry per cell",
    ] {
        assert!(messages.iter().any(|m| m.contains(want)), "{want}");
    }
    // A split table that does not cover the objects cannot be written.
    doc.split.as_mut().unwrap().sources[1].count = 2;
    assert!(binary::encode(&doc).is_err());
}
