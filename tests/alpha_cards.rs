//! Alpha-tested cards (issue 21): glTF `MASK` materials with textures are imported with what
//! their alpha test needs, their surely opaque texels occlude (and only those), `validate`
//! traces them as a renderer at full resolution draws them, missing images are refused or
//! kept transparent as asked, and the real textured assets (Khronos' alpha test, the
//! web-optimised coconut palm) load.

mod common;

use common::{Lcg, shared_scenes};
use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{self, BakeSettings};
use umbrasweep::geom::{Aabb, box_triangles};
use umbrasweep::scene::{self, AlphaMissing, LoadOptions, Scene};
use umbrasweep::settings::{AlphaCards, SweepChoice};
use umbrasweep::validate::{CheckOptions, SceneRays, check_with};

/// One card: a quad of two triangles with its corners and texture coordinates.
struct Card {
    corners: [Vec3; 4],
    uv: [Vec2; 4],
}

/// Writes `NAME.gltf` + `NAME.bin` (+ `tex.png` from `alpha` unless `image` is false) into
/// `dir`: object 0 holds the `cards` (material MASK, cutoff 0.5, wrap `wrap`), then one
/// opaque box object per entry of `boxes`.
fn write_scene(
    dir: &Path,
    name: &str,
    cards: &[Card],
    boxes: &[Aabb],
    alpha: &image::GrayImage,
    image: bool,
    wrap: u32,
) -> PathBuf {
    /// Appends one accessor (and its view) over `bytes`; its index.
    fn push(
        bin: &mut Vec<u8>,
        views: &mut Vec<serde_json::Value>,
        accessors: &mut Vec<serde_json::Value>,
        bytes: Vec<u8>,
        count: usize,
        ty: &str,
        comp: u32,
    ) -> usize {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(
            serde_json::json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()}),
        );
        accessors.push(serde_json::json!({
            "bufferView": views.len() - 1, "componentType": comp, "count": count, "type": ty
        }));
        bin.extend(bytes);
        accessors.len() - 1
    }
    let mut bin: Vec<u8> = Vec::new();
    let mut accessors = Vec::new();
    let mut views = Vec::new();
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let u32s = |v: &[u32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    // The cards.
    let mut pos = Vec::new();
    let mut uvs = Vec::new();
    let mut idx = Vec::new();
    for (k, c) in cards.iter().enumerate() {
        for i in 0..4 {
            pos.extend(c.corners[i].to_array());
            uvs.extend(c.uv[i].to_array());
        }
        let b = 4 * k as u32;
        idx.extend([b, b + 1, b + 2, b, b + 2, b + 3]);
    }
    let mut meshes = Vec::new();
    let p = push(
        &mut bin,
        &mut views,
        &mut accessors,
        f32s(&pos),
        4 * cards.len(),
        "VEC3",
        5126,
    );
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for (i, x) in pos.iter().enumerate() {
        lo[i % 3] = lo[i % 3].min(*x);
        hi[i % 3] = hi[i % 3].max(*x);
    }
    accessors[p]["min"] = serde_json::json!(lo);
    accessors[p]["max"] = serde_json::json!(hi);
    let t = push(
        &mut bin,
        &mut views,
        &mut accessors,
        f32s(&uvs),
        4 * cards.len(),
        "VEC2",
        5126,
    );
    let i = push(
        &mut bin,
        &mut views,
        &mut accessors,
        u32s(&idx),
        idx.len(),
        "SCALAR",
        5125,
    );
    meshes.push(serde_json::json!({"primitives": [{
        "attributes": {"POSITION": p, "TEXCOORD_0": t}, "indices": i, "material": 0
    }]}));
    for b in boxes {
        let tris = box_triangles(b.min, b.max);
        let pos: Vec<f32> = tris.iter().flatten().flat_map(|v| v.to_array()).collect();
        let p = push(
            &mut bin,
            &mut views,
            &mut accessors,
            f32s(&pos),
            tris.len() * 3,
            "VEC3",
            5126,
        );
        accessors[p]["min"] = serde_json::json!(b.min.to_array());
        accessors[p]["max"] = serde_json::json!(b.max.to_array());
        meshes.push(serde_json::json!({"primitives": [{"attributes": {"POSITION": p}}]}));
    }
    let nodes: Vec<serde_json::Value> = (0..meshes.len())
        .map(|m| serde_json::json!({"mesh": m, "name": if m == 0 { "cards".to_string() } else { format!("box{}", m - 1) }}))
        .collect();
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [{
            "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": true,
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}
        }],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": wrap, "wrapT": wrap}],
        "images": [{"uri": "tex.png"}],
        "buffers": [{"uri": format!("{name}.bin"), "byteLength": bin.len()}],
        "bufferViews": views,
        "accessors": accessors,
    });
    std::fs::write(dir.join(format!("{name}.bin")), &bin).unwrap();
    if image {
        let mut rgba = image::RgbaImage::new(alpha.width(), alpha.height());
        for (x, y, p) in alpha.enumerate_pixels() {
            rgba.put_pixel(x, y, image::Rgba([40, 120, 30, p.0[0]]));
        }
        rgba.save(dir.join("tex.png")).unwrap();
    }
    let path = dir.join(format!("{name}.gltf"));
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    path
}

/// A 10×10 card at z = 8 facing the unit cell, texture (0,0) at its corner (-5, 5).
fn wall_card() -> Card {
    Card {
        corners: [
            Vec3::new(-5.0, 5.0, 8.0),
            Vec3::new(5.0, 5.0, 8.0),
            Vec3::new(5.0, -5.0, 8.0),
            Vec3::new(-5.0, -5.0, 8.0),
        ],
        uv: [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ],
    }
}

/// Left half of the texture opaque, right half transparent (mean alpha 0.5: the 1×1 mip is
/// not above the cutoff).
fn half_opaque() -> image::GrayImage {
    image::GrayImage::from_fn(64, 64, |x, _| image::Luma([if x < 32 { 255 } else { 0 }]))
}

/// Boxes behind the card: 0 behind the opaque left half, 1 behind the transparent right half.
fn two_boxes() -> Vec<Aabb> {
    vec![
        Aabb::new(Vec3::new(-3.5, -0.5, 14.0), Vec3::new(-2.5, 0.5, 15.0)),
        Aabb::new(Vec3::new(2.5, -0.5, 14.0), Vec3::new(3.5, 0.5, 15.0)),
    ]
}

/// The card with [`half_opaque`] (clamped) in front of [`two_boxes`], written into `dir`.
fn half_scene(dir: &Path) -> PathBuf {
    write_scene(
        dir,
        "half",
        &[wall_card()],
        &two_boxes(),
        &half_opaque(),
        true,
        33071,
    )
}

/// Runs the `umbrasweep` binary.
fn umbrasweep(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
        .args(args)
        .output()
        .unwrap()
}

/// Asserts that a run exited 0, showing its stderr otherwise.
fn succeeded(run: &std::process::Output) {
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

fn settings(cards: AlphaCards, mips: u32) -> BakeSettings {
    BakeSettings {
        alpha_cards: cards,
        alpha_mips: mips,
        rsf: SweepChoice::Off,
        ..BakeSettings::default()
    }
}

fn unit_cell() -> Aabb {
    Aabb::new(Vec3::splat(-0.5), Vec3::splat(0.5))
}

/// Object ids: 0 the cards, 1.. the boxes. Returns whether each box is in the PVS.
fn boxes_visible(scene: &Scene, s: &BakeSettings) -> Vec<bool> {
    let r = bake::bake(scene, &[unit_cell()], s, &CpuBackend::new(), None).unwrap();
    (1..scene.objects.len() as u32)
        .map(|o| r.cells[0].visible.contains(&o))
        .collect()
}

#[test]
fn opaque_texels_hide_transparent_ones_do_not_and_all_mips_are_conservative() {
    let dir = tempfile::tempdir().unwrap();
    let path = half_scene(dir.path());
    let scene = scene::load(&path).unwrap();
    let a = scene.alpha.as_ref().expect("the card is alpha-tested");
    assert_eq!(a.cards.len(), 2);
    assert_eq!(a.materials[0].cutoff, 0.5);
    // Trusting mip 0 (and 0..4): the box behind the opaque half is hidden, the other seen.
    for mips in [1, 4] {
        assert_eq!(
            boxes_visible(&scene, &settings(AlphaCards::Coverage, mips)),
            [false, true],
            "--alpha-mips {mips}"
        );
    }
    // All levels: the 1×1 level is the mean, 0.5, not above the cutoff: nothing is surely
    // opaque, so nothing is hidden. Ignored cards hide nothing either.
    assert_eq!(
        boxes_visible(&scene, &settings(AlphaCards::Coverage, 0)),
        [true, true]
    );
    assert_eq!(
        boxes_visible(&scene, &settings(AlphaCards::Ignore, 1)),
        [true, true]
    );
    // The unsafe whole-card rule hides both, the one seen through the transparent half too.
    let unsafe_settings = BakeSettings {
        alpha_occluders: true,
        ..settings(AlphaCards::Ignore, 0)
    };
    assert_eq!(boxes_visible(&scene, &unsafe_settings), [false, false]);
}

/// An opaque card with a soft-edged slit (alpha 128, 40, 40, 128 across four columns, none
/// fully transparent):
/// the box behind the slit is seen by rays (bilinear alpha at mip 0 stays below the cutoff
/// in the slit), so the bake must keep it; a coverage that let half-transparent texels
/// occlude would close the slit.
#[test]
fn a_soft_edged_slit_keeps_the_box_behind_it() {
    let dir = tempfile::tempdir().unwrap();
    let slit = image::GrayImage::from_fn(64, 64, |x, _| {
        image::Luma([match x {
            30 | 33 => 128,
            31 | 32 => 40,
            _ => 255,
        }])
    });
    let boxes = vec![Aabb::new(
        Vec3::new(-0.05, -0.5, 14.0),
        Vec3::new(0.05, 0.5, 14.2),
    )];
    let path = write_scene(
        dir.path(),
        "slit",
        &[wall_card()],
        &boxes,
        &slit,
        true,
        10497,
    );
    let scene = scene::load(&path).unwrap();
    let rays = SceneRays::new(&scene);
    let seen = rays.trace(Vec3::ZERO, Vec3::new(0.05, 0.0, 14.1), false);
    assert_eq!(
        seen.first().map(|h| h.object),
        Some(1),
        "the slit is open: {seen:?}"
    );
    for mips in [1, 2, 0] {
        assert_eq!(
            boxes_visible(&scene, &settings(AlphaCards::Coverage, mips)),
            [true],
            "--alpha-mips {mips}"
        );
    }
    // Without the slit the same box is hidden (the test can fail).
    let solid = image::GrayImage::from_pixel(64, 64, image::Luma([255]));
    let path = write_scene(
        dir.path(),
        "solid",
        &[wall_card()],
        &boxes,
        &solid,
        true,
        10497,
    );
    let scene = scene::load(&path).unwrap();
    assert_eq!(
        boxes_visible(&scene, &settings(AlphaCards::Coverage, 1)),
        [false]
    );
}

#[test]
fn an_opaque_texture_hides_at_every_mip_level() {
    let dir = tempfile::tempdir().unwrap();
    let full = image::GrayImage::from_pixel(16, 16, image::Luma([255]));
    let path = write_scene(
        dir.path(),
        "full",
        &[wall_card()],
        &two_boxes(),
        &full,
        true,
        10497,
    );
    let scene = scene::load(&path).unwrap();
    let r = bake::bake(
        &scene,
        &[unit_cell()],
        &settings(AlphaCards::Coverage, 0),
        &CpuBackend::new(),
        None,
    )
    .unwrap();
    assert_eq!(r.cells[0].visible, vec![0], "both boxes hidden");
    let cards = r.cards.expect("card statistics");
    assert_eq!(cards.triangles, 2);
    assert!(
        cards.opaque_area > 0.95 * cards.card_area,
        "{} of {}",
        cards.opaque_area,
        cards.card_area
    );
}

#[test]
fn validate_sees_through_transparent_texels_only() {
    let dir = tempfile::tempdir().unwrap();
    let path = half_scene(dir.path());
    let scene = scene::load(&path).unwrap();
    let rays = SceneRays::new(&scene);
    // Through the transparent right half: the box behind is the first thing hit.
    let hits = rays.trace(Vec3::ZERO, Vec3::new(3.0, 0.0, 14.5), false);
    assert_eq!(hits.first().map(|h| h.object), Some(2), "{hits:?}");
    // Through the opaque left half: the card blocks.
    let hits = rays.trace(Vec3::ZERO, Vec3::new(-3.0, 0.0, 14.5), false);
    assert_eq!(hits.iter().map(|h| h.object).collect::<Vec<_>>(), [0]);
    // The whole bake, validated with rays aimed at the culled box: no false cull.
    let s = settings(AlphaCards::Coverage, 1);
    let r = bake::bake(&scene, &[unit_cell()], &s, &CpuBackend::new(), None).unwrap();
    let doc = bake::to_document(&scene, &[unit_cell()], &r, &s);
    for hunt in [false, true] {
        let report = check_with(
            &rays,
            &scene,
            &doc,
            &CheckOptions {
                rays: 20_000,
                seed: 3,
                hunt,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(report.false_culls, 0, "hunt {hunt}");
    }
}

#[test]
fn a_missing_image_is_an_error_naming_it_unless_kept_transparent() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_scene(
        dir.path(),
        "missing",
        &[wall_card()],
        &two_boxes(),
        &half_opaque(),
        false,
        10497,
    );
    let e = scene::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("tex.png")
            && e.contains("--alpha-missing transparent")
            && e.contains("missing.gltf"),
        "{e}"
    );
    let scene = scene::load_with(
        &path,
        &LoadOptions {
            alpha_missing: AlphaMissing::Transparent,
        },
    )
    .unwrap();
    assert!(
        scene.warnings.iter().any(|w| w.contains("tex.png")),
        "{:?}",
        scene.warnings
    );
    assert_eq!(scene.alpha.as_ref().map(|a| a.missing_transparent), Some(2));
    assert!(scene.alpha.as_ref().is_none_or(|a| a.cards.is_empty()));
    assert_eq!(
        boxes_visible(&scene, &settings(AlphaCards::Coverage, 1)),
        [true, true]
    );
    // The command line: exit 2, the message, no output file.
    let out = dir.path().join("out.json");
    let cells = dir.path().join("cells.json");
    std::fs::write(
        &cells,
        r#"{"cells": [{"min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5]}]}"#,
    )
    .unwrap();
    let (p, c, o) = (
        path.to_str().unwrap(),
        cells.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let run = umbrasweep(&["bake", p, "--cells", c, "--backend", "cpu", "-o", o]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("tex.png"));
    assert!(!out.exists());
    succeeded(&umbrasweep(&[
        "bake",
        p,
        "--cells",
        c,
        "--backend",
        "cpu",
        "--alpha-missing",
        "transparent",
        "-o",
        o,
    ]));
    // The setting is recorded, so that validate reloads the scene the same way.
    succeeded(&umbrasweep(&["validate", p, o, "--rays", "2000"]));
}

#[test]
fn alpha_settings_are_checked_and_survive_the_pvs_file() {
    let bad = BakeSettings {
        alpha_mips: 40,
        ..BakeSettings::default()
    };
    assert!(bad.check().unwrap_err().to_string().contains("alpha-mips"));
    let bad = BakeSettings {
        alpha_card_polygons: 0,
        ..BakeSettings::default()
    };
    assert!(
        bad.check()
            .unwrap_err()
            .to_string()
            .contains("alpha-card-polygons")
    );
    let dir = tempfile::tempdir().unwrap();
    let path = half_scene(dir.path());
    let scene = scene::load(&path).unwrap();
    let s = BakeSettings {
        alpha_missing: AlphaMissing::Transparent,
        alpha_card_polygons: 7,
        ..settings(AlphaCards::Coverage, 3)
    };
    let r = bake::bake(&scene, &[unit_cell()], &s, &CpuBackend::new(), None).unwrap();
    let doc = bake::to_document(&scene, &[unit_cell()], &r, &s);
    let bytes = umbrasweep::pvs::binary::encode(&doc).unwrap();
    let back = umbrasweep::pvs::PvsDatabase::from_bytes(&bytes)
        .unwrap()
        .to_document();
    assert_eq!(back.settings.bake.alpha_mips, 3);
    assert_eq!(back.settings.bake.alpha_card_polygons, 7);
    assert_eq!(back.settings.bake.alpha_missing, AlphaMissing::Transparent);
    assert_eq!(back.settings.bake.alpha_cards, AlphaCards::Coverage);
    // JSON documents from before the cards read as "ignore".
    let mut v = serde_json::to_value(&doc.settings.bake).unwrap();
    v.as_object_mut().unwrap().remove("alpha_cards");
    let old: BakeSettings = serde_json::from_value(v).unwrap();
    assert_eq!(old.alpha_cards, AlphaCards::Ignore);
}

#[test]
fn the_memory_estimate_counts_the_card_polygons() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene::load(&half_scene(dir.path())).unwrap();
    let est = |s: &BakeSettings| bake::estimate_memory(&scene, s, 1);
    let ignore = est(&settings(AlphaCards::Ignore, 0));
    let four = est(&settings(AlphaCards::Coverage, 0));
    let many = est(&BakeSettings {
        alpha_card_polygons: 64,
        ..settings(AlphaCards::Coverage, 0)
    });
    // Two card triangles: 4 and 64 polygons each at 600 bytes.
    assert_eq!(four - ignore, 2 * 4 * bake::CARD_POLYGON_BYTES);
    assert_eq!(many - ignore, 2 * 64 * bake::CARD_POLYGON_BYTES);
    // With the sampler each also holds a polygon of the sampler's occluders (its share was
    // missing: the dense beech forest peaked at 13.5 GB where the estimate said 10.1).
    let sampled = |s: BakeSettings| BakeSettings {
        sampling: SweepChoice::On,
        ..s
    };
    let ignore_sampled = est(&sampled(settings(AlphaCards::Ignore, 0)));
    let four_sampled = est(&sampled(settings(AlphaCards::Coverage, 0)));
    assert_eq!(
        four_sampled - ignore_sampled,
        2 * 4 * (bake::CARD_POLYGON_BYTES + bake::SAMPLER_BYTES_PER_CARD_POLYGON)
    );
}

/// Random cards (blob textures, random poses, wrap modes and texture transforms of their
/// coordinates) in front of random boxes: every box a bake hides stays hidden under rays
/// aimed at it (`validate --hunt`), for mip 0 only and for levels 0..3.
#[test]
fn random_cards_never_cull_a_box_seen_through_them() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Lcg(21);
    let mut hidden_total = 0;
    for case in 0..12 {
        // Blobs of opaque texels on a transparent ground.
        let n = [16, 32, 64][case % 3];
        let blobs: Vec<(f64, f64, f64)> = (0..6)
            .map(|_| {
                (
                    rng.range(0.0, n as f64),
                    rng.range(0.0, n as f64),
                    rng.range(2.0, n as f64 / 2.5),
                )
            })
            .collect();
        // Soft edges: alpha falls from 255 to 0 over 3 texels around each blob's rim.
        let tex = image::GrayImage::from_fn(n, n, |x, y| {
            let a = blobs
                .iter()
                .map(|&(cx, cy, r)| {
                    let d = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
                    ((r - d) / 3.0 + 0.5).clamp(0.0, 1.0)
                })
                .fold(0.0, f64::max);
            image::Luma([(255.0 * a).round() as u8])
        });
        let mut cards = Vec::new();
        for _ in 0..8 {
            let c = Vec3::new(
                rng.range(-3.0, 3.0) as f32,
                rng.range(-3.0, 3.0) as f32,
                rng.range(2.0, 6.0) as f32,
            );
            let u = Vec3::new(
                rng.range(-1.0, 1.0) as f32,
                rng.range(-1.0, 1.0) as f32,
                rng.range(-0.3, 0.3) as f32,
            )
            .normalize()
                * rng.range(1.0, 3.0) as f32;
            let v = u.cross(Vec3::Z).normalize() * rng.range(1.0, 3.0) as f32;
            let o = Vec2::new(rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32);
            let s = rng.range(0.5, 2.0) as f32;
            cards.push(Card {
                corners: [c - u - v, c + u - v, c + u + v, c - u + v],
                uv: [
                    o,
                    o + Vec2::new(s, 0.0),
                    o + Vec2::new(s, s),
                    o + Vec2::new(0.0, s),
                ],
            });
        }
        let boxes: Vec<Aabb> = (0..10)
            .map(|_| {
                let c = Vec3::new(
                    rng.range(-3.0, 3.0) as f32,
                    rng.range(-3.0, 3.0) as f32,
                    rng.range(7.0, 10.0) as f32,
                );
                Aabb::new(c - 0.3, c + 0.3)
            })
            .collect();
        let wrap = [10497, 33648, 33071][case % 3];
        let name = format!("case{case}");
        let path = write_scene(dir.path(), &name, &cards, &boxes, &tex, true, wrap);
        let scene = scene::load(&path).unwrap();
        let rays = SceneRays::new(&scene);
        let cell = Aabb::new(Vec3::splat(-0.3), Vec3::splat(0.3));
        for mips in [1, 3] {
            let s = BakeSettings {
                alpha_card_polygons: 16,
                ..settings(AlphaCards::Coverage, mips)
            };
            let r = bake::bake(&scene, &[cell], &s, &CpuBackend::new(), None).unwrap();
            hidden_total += scene.objects.len() - r.cells[0].visible.len();
            let doc = bake::to_document(&scene, &[cell], &r, &s);
            let report = check_with(
                &rays,
                &scene,
                &doc,
                &CheckOptions {
                    rays: 40_000,
                    seed: case as u64,
                    hunt: true,
                    ..Default::default()
                },
            )
            .unwrap();
            assert_eq!(report.false_culls, 0, "case {case}, --alpha-mips {mips}");
        }
    }
    // The test means something only if cards hide boxes.
    assert!(
        hidden_total >= 10,
        "only {hidden_total} boxes hidden in all cases"
    );
}

#[test]
fn khronos_alpha_test_orders_its_cutoffs() {
    let Some(dir) = shared_scenes() else { return };
    let scene = scene::load(
        &dir.join("foliage-textured/alpha_blend_mode_test/glTF-Binary/AlphaBlendModeTest.glb"),
    )
    .unwrap();
    let a = scene.alpha.as_ref().unwrap();
    let mut shares: Vec<(f32, f64)> = a
        .materials
        .iter()
        .map(|m| {
            let t = &a.textures[m.texture.unwrap() as usize];
            let c = umbrasweep::scene::alpha::Coverage::build(t, m.cutoff / m.factor, Some(1));
            (m.cutoff, c.opaque_share)
        })
        .collect();
    shares.sort_by(|x, y| x.0.total_cmp(&y.0));
    let cutoffs: Vec<f32> = shares.iter().map(|s| s.0).collect();
    assert_eq!(cutoffs, [0.25, 0.5, 0.75]);
    // A lower cutoff leaves more texels surely opaque; each share is a little below the
    // texel share SOURCES.md gives (0.441, 0.368, 0.295): the bilinear cells erode edges.
    assert!(
        shares[0].1 > shares[1].1 && shares[1].1 > shares[2].1,
        "{shares:?}"
    );
    for ((_, share), texels) in shares.iter().zip([0.441, 0.368, 0.295]) {
        assert!(
            *share <= texels && *share > texels - 0.03,
            "{share} against {texels}"
        );
    }
}

#[test]
fn the_web_optimised_palm_loads_with_its_ktx2_leaves() {
    let Some(dir) = shared_scenes() else { return };
    let folder = dir.join("foliage-textured/palm_coconut_evolveduk_ktx2");
    let file = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "glb"))
        .expect("the palm's .glb");
    let scene = scene::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let a = scene.alpha.as_ref().expect("alpha-tested fronds");
    // SOURCES.md: 2,592 MASK triangles (Tree_2Mat, cutoff 0.2581), 4,038 opaque.
    assert_eq!(a.cards.len(), 2592);
    assert_eq!(scene.triangles.len(), 2592 + 4038);
    let m = &a.materials[0];
    assert!((m.cutoff - 0.2581).abs() < 1e-4, "{}", m.cutoff);
    let t = &a.textures[m.texture.unwrap() as usize];
    assert_eq!((t.width, t.height), (1024, 1024));
    let opaque = t.alpha.iter().filter(|&&x| x == 255).count();
    let clear = t.alpha.iter().filter(|&&x| x == 0).count();
    assert!(
        opaque > 100_000 && clear > 100_000,
        "{opaque} opaque, {clear} clear"
    );
    // Positions decoded from meshopt and dequantized: a palm some metres tall.
    let size = scene.bounds().size();
    assert!(size.max_element() > 1.0 && size.is_finite(), "{size}");
}

#[test]
fn a_partial_asset_warns_about_its_missing_bark_and_loads() {
    let Some(dir) = shared_scenes() else { return };
    let scene =
        scene::load(&dir.join("foliage-textured/euro_beech_fadiyasotodeh_partial/scene.gltf"))
            .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("Euro_Beech_Bark_baseColor.png")),
        "{:?}",
        scene.warnings
    );
    assert_eq!(scene.alpha.as_ref().unwrap().cards.len(), 7456);
}

/// `gen forest --tree-model TREE.gltf -o forest.glb` keeps the model's cards: materials,
/// texture coordinates, wrap modes and the textures' alpha, so the forest bakes with them.
#[test]
fn gen_writes_textured_forests_as_glb_with_their_cards() {
    let dir = tempfile::tempdir().unwrap();
    // A "tree": a trunk and two crossed cards above it.
    let crown = |a: Vec3, b: Vec3| Card {
        corners: [
            Vec3::new(0.0, 2.0, 0.0) - a,
            Vec3::new(0.0, 2.0, 0.0) + a,
            Vec3::new(0.0, 2.0, 0.0) + a + b,
            Vec3::new(0.0, 2.0, 0.0) - a + b,
        ],
        uv: [
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 0.0),
        ],
    };
    let cards = [crown(Vec3::X, Vec3::Y * 2.0), crown(Vec3::Z, Vec3::Y * 2.0)];
    let trunk = [Aabb::new(
        Vec3::new(-0.1, 0.0, -0.1),
        Vec3::new(0.1, 2.0, 0.1),
    )];
    let model = write_scene(
        dir.path(),
        "tree",
        &cards,
        &trunk,
        &half_opaque(),
        true,
        33648,
    );
    let out = dir.path().join("forest.glb");
    let cells = dir.path().join("cells.json");
    succeeded(&umbrasweep(&[
        "gen",
        "forest",
        "--tree-model",
        model.to_str().unwrap(),
        "--trees",
        "12",
        "--seed",
        "4",
        "--cells",
        "2",
        "-o",
        out.to_str().unwrap(),
        "--cells-out",
        cells.to_str().unwrap(),
    ]));
    let source = scene::load(&model).unwrap();
    let forest = scene::load(&out).unwrap_or_else(|e| panic!("{e}"));
    let (a, b) = (
        source.alpha.unwrap(),
        forest.alpha.clone().expect("cards kept"),
    );
    assert_eq!(b.cards.len(), 12 * a.cards.len());
    assert_eq!(b.materials.len(), 1);
    assert_eq!(b.materials[0].cutoff, a.materials[0].cutoff);
    assert_eq!(b.textures[0].alpha, a.textures[0].alpha);
    assert_eq!(
        b.textures[0].wrap,
        [umbrasweep::scene::alpha::Wrap::MirroredRepeat; 2]
    );
    // The same texture coordinates on every tree, in the same corner order.
    let uv_set = |cards: &umbrasweep::scene::alpha::AlphaCards| {
        let mut v: Vec<[u32; 6]> = cards
            .cards
            .iter()
            .map(|c| {
                let f = c.uv.map(|u| u.to_array());
                [f[0][0], f[0][1], f[1][0], f[1][1], f[2][0], f[2][1]].map(f32::to_bits)
            })
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    assert_eq!(uv_set(&a), uv_set(&b));
    // Opaque trunks stay opaque; the cards alone are not.
    let opaque = forest.opaque.iter().filter(|&&o| o).count();
    assert_eq!(opaque, forest.triangles.len() - b.cards.len());
    let cells = umbrasweep::cells::load_json(&cells).unwrap();
    let r = bake::bake(
        &forest,
        &cells,
        &settings(AlphaCards::Coverage, 1),
        &CpuBackend::new(),
        None,
    )
    .unwrap();
    assert!(r.cards.is_some_and(|c| c.polygons > 0));
}
