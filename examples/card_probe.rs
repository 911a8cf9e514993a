//! Measures the conservative coverage of a scene's alpha-tested cards: per texture the share
//! of half-texel cells surely opaque at mip 0, 0..2, 0..4 and over the full chain, and per
//! setting the share of the cards' world-space area the card polygons cover.
//!
//! `cargo run --release --example card_probe -- SCENE.gltf [MAX_POLYGONS [MIN_SHARE]]`

use umbrasweep::project::occluders::prepare_with;
use umbrasweep::scene::alpha::{CardOptions, Coverage};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: card_probe SCENE.gltf [MAX_POLYGONS]");
        std::process::exit(2);
    };
    let max_polygons: usize = args.get(2).map_or(4, |s| s.parse().expect("a number"));
    let min_share: f64 = args
        .get(3)
        .map_or(umbrasweep::scene::alpha::MIN_POLYGON_SHARE, |s| {
            s.parse().expect("a number")
        });
    let scene = match umbrasweep::scene::load(std::path::Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let Some(cards) = &scene.alpha else {
        println!("{path}: no alpha-tested cards");
        return;
    };
    println!(
        "{path}: {} card triangles, {} materials, {} textures",
        cards.cards.len(),
        cards.materials.len(),
        cards.textures.len()
    );
    for m in &cards.materials {
        let Some(t) = m.texture else {
            println!("  material {}: no texture, factor {}", m.name, m.factor);
            continue;
        };
        let tex = &cards.textures[t as usize];
        let thr = m.cutoff / m.factor;
        let share = |levels| 100.0 * Coverage::build(tex, thr, levels).opaque_share;
        let texels = tex
            .alpha
            .iter()
            .filter(|&&a| a as f32 / 255.0 >= thr)
            .count() as f64
            / tex.alpha.len() as f64;
        println!(
            "  material {} (cutoff {}, {}×{} {}): texels ≥ cutoff {:.1} %; surely opaque cells: \
             mip 0 {:.1} %, 0..2 {:.1} %, 0..4 {:.1} %, all {:.1} %",
            m.name,
            m.cutoff,
            tex.width,
            tex.height,
            tex.label,
            100.0 * texels,
            share(Some(1)),
            share(Some(2)),
            share(Some(4)),
            share(None)
        );
    }
    if std::env::var("CARD_DEBUG").is_ok() {
        debug(&scene);
    }
    let all = vec![true; scene.objects.len()];
    for mips in [Some(1), Some(2), Some(4), None] {
        let t = std::time::Instant::now();
        let occ = prepare_with(
            &scene,
            &all,
            false,
            Some(CardOptions {
                mips,
                max_polygons,
                min_share,
            }),
        );
        let c = occ.cards;
        println!(
            "  mips {:>4}: {} polygons, {:.1} % of the card area surely opaque ({:.2} s)",
            mips.map_or("all".to_string(), |m| format!("0..{m}")),
            c.polygons,
            100.0 * c.opaque_area / c.card_area.max(1e-300),
            t.elapsed().as_secs_f64()
        );
    }
}

/// With `CARD_DEBUG` set: the texture coordinates of the first cards.
fn debug(scene: &umbrasweep::scene::Scene) {
    let Some(cards) = scene.alpha.as_ref() else {
        return;
    };
    for c in cards.cards.iter().take(8) {
        println!("{:?}", c.uv);
    }
}
