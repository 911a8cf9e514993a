//! `umbrasweep bench --foliage` on tiny forests (the hidden `--foliage-trees` override): the
//! studies come out with their labels, their tables, and no false cull. (The fine study's
//! sub-cell rows take minutes even on tiny forests — a 4×2×4 cell in sub-cells of 0.5 is 256
//! bakes — so its labels are checked by the unit tests in `bench::foliage` instead.)

use umbrasweep::bench::foliage::{COLUMNS, FoliageBench, collect};
use umbrasweep::bench::{BenchBackend, BenchOptions};

/// `bench --foliage --foliage-studies STUDIES --foliage-trees 3 --foliage-model-trees 1
/// --foliage-paper-cells 2 --foliage-subcell-cells 1 --cells 1 --rays 2000 --backend cpu`.
fn run(studies: &str) -> FoliageBench {
    collect(&BenchOptions {
        foliage_studies: Some(studies.split(',').map(String::from).collect()),
        foliage_trees: Some(3),
        foliage_model_trees: 1,
        foliage_paper_cells: 2,
        foliage_subcell_cells: 1,
        cells: Some(1),
        rays: Some(2000),
        backend: BenchBackend::Cpu,
        ..BenchOptions::default()
    })
    .unwrap()
}

fn labels(bench: &FoliageBench, study: &str) -> Vec<String> {
    bench
        .rows
        .iter()
        .filter(|r| r.study == study)
        .map(|r| r.variant.clone())
        .collect()
}

#[test]
fn a_tiny_foliage_bench_has_every_row_and_no_false_cull() {
    let bench = run("paper,coarse,jacaranda");
    // Canonical order, whatever the order asked.
    assert_eq!(bench.studies, ["coarse", "paper", "jacaranda"]);
    assert_eq!(
        labels(&bench, "coarse"),
        [
            "--sweep",
            "--no-sweep",
            "--sweep --resolution 1024 --sweep-planes 32",
            "--sweep --sampling --sampling-budget 2000"
        ]
    );
    assert_eq!(
        labels(&bench, "paper"),
        ["--sweep", "--sweep --sampling --sampling-budget 2000"]
    );
    let jacaranda = labels(&bench, "jacaranda");
    if jacaranda.is_empty() {
        assert!(
            bench
                .skipped
                .iter()
                .any(|s| s.starts_with("jacaranda: skipped")),
            "{:?}",
            bench.skipped
        );
    } else {
        assert_eq!(jacaranda, ["--sweep", "--no-sweep"]);
    }
    for r in &bench.rows {
        assert_eq!(r.row.false_culls, 0, "{} {}", r.study, r.variant);
        assert_eq!(r.row.backend, "cpu");
        assert_eq!(
            r.settings.sweep == umbrasweep::bake::SweepChoice::On,
            r.variant.starts_with("--sweep")
        );
    }
    let paper = bench.rows.iter().find(|r| r.study == "paper").unwrap();
    assert_eq!(paper.row.scene, "paper_forest");
    assert_eq!(paper.row.cells, 2);
    if std::path::Path::new("/proc/self/status").is_file() {
        assert!(paper.peak_mib.is_some_and(|p| p > 1.0));
    }
    let coarse = bench.rows.iter().find(|r| r.study == "coarse").unwrap();
    assert_eq!(coarse.row.cells, 1);
    assert_eq!(coarse.row.objects, 1 + 3 * 5);
    let goal = bench
        .rows
        .iter()
        .filter(|r| r.study == "coarse")
        .nth(2)
        .unwrap();
    assert_eq!(
        (
            goal.settings.resolution,
            goal.settings.sweep_settings.planes
        ),
        (1024, 32)
    );

    let tables = bench.tables();
    assert!(tables.contains("### coarse") && tables.contains("### paper"));
    let header = tables.lines().find(|l| l.starts_with("| scene")).unwrap();
    let cols: Vec<&str> = header
        .split('|')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    assert_eq!(cols, COLUMNS);
    assert_eq!(
        tables
            .lines()
            .filter(|l| l.starts_with("| coarse_forest | --no-sweep"))
            .count(),
        1
    );
    // The sampler rows' cost curves: points, seconds and objects hidden grow level by level,
    // the last level gives the row's own % culled, and each curve is printed and in the JSON.
    let sampled: Vec<_> = bench
        .rows
        .iter()
        .filter(|r| r.variant.contains("--sampling"))
        .collect();
    assert!(sampled.iter().any(|r| !r.sampling_curve.is_empty()));
    for r in &bench.rows {
        let c = &r.sampling_curve;
        if !r.variant.contains("--sampling") {
            assert!(c.is_empty(), "{} {}", r.study, r.variant);
            continue;
        }
        if c.is_empty() {
            continue;
        }
        for w in c.windows(2) {
            assert!(w[1].eps < w[0].eps, "{} {}: {w:?}", r.study, r.variant);
            assert!(w[1].points >= w[0].points && w[1].seconds >= w[0].seconds);
            assert!(w[1].sampler_hidden >= w[0].sampler_hidden);
            assert!(w[1].objects_culled_percent >= w[0].objects_culled_percent);
        }
        let last = c.last().unwrap();
        assert!((last.objects_culled_percent - r.row.objects_culled_percent).abs() < 1e-9);
        assert!(tables.contains(&format!("cost curve of [{}]", r.variant)));
    }
    let json = serde_json::to_value(&bench).unwrap();
    let curved = json["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r.get("sampling_curve").is_some())
        .expect("a row with a cost curve");
    assert!(curved["sampling_curve"][0]["objects_culled_percent"].is_number());
    let row = &json["rows"][0];
    assert_eq!(row["variant"], "--sweep");
    assert_eq!(row["scene"], "coarse_forest");
    assert!(row.get("peak_mib").is_some() && row.get("false_culls").is_some());
    // No harder checks unless asked for.
    assert!(row.get("hunt").is_none() && row.get("confirm").is_none());
    assert!(json.get("hunt_rays").is_none() && !tables.contains("harder checks"));
}

#[test]
fn harder_checks_hunt_and_confirm_every_row() {
    let bench = collect(&BenchOptions {
        foliage_studies: Some(vec!["coarse".into()]),
        foliage_trees: Some(60),
        cells: Some(1),
        rays: Some(2000),
        hunt_rays: Some(30_000),
        confirm_rays: Some(40_000),
        backend: BenchBackend::Cpu,
        ..BenchOptions::default()
    })
    .unwrap();
    assert_eq!(bench.rows.len(), 4);
    let mut culled_any = false;
    for r in &bench.rows {
        let h = r.row.hunt.as_ref().expect("hunted");
        let c = r.row.confirm.as_ref().expect("confirmed");
        // The hunt's culled objects are the row's: those with area outside its PVS (every
        // object of the forest has area), each with the whole budget split between them.
        let culled = (r.row.objects_culled_percent / 100.0 * r.row.objects as f64).round();
        assert_eq!(h.hunted_objects as f64, culled, "{}", r.variant);
        culled_any |= h.hunted_objects > 0;
        if let Some(each) = 30_000u64.checked_div(h.hunted_objects) {
            assert_eq!(h.rays_per_culled_object, each);
        }
        assert_eq!(
            (h.rays_per_cell, h.false_culls),
            (30_000, 0),
            "{}",
            r.variant
        );
        // With no false cull, the confirmed visible set lies inside the PVS.
        assert_eq!(c.confirm_rays, 40_000);
        assert_eq!(c.false_culls, 0, "{c:?}");
        let pvs = r.row.objects as f64 - culled;
        assert!(c.vs_plus >= 1.0 && c.vs_plus <= pvs, "{}: {c:?}", r.variant);
        let ratio = c.pvs_over_confirmed_vs.expect("something is seen");
        assert!(
            (ratio - pvs / c.vs_plus).abs() < 1e-9,
            "{}: {c:?}",
            r.variant
        );
    }
    assert!(culled_any, "some row of the tiny coarse forest culls");
    let tables = bench.tables();
    assert!(
        tables.contains("harder checks, hunt 30000 rays per cell, confirm 40000 rays per cell"),
        "{tables}"
    );
    assert!(tables.contains("| hunt false culls |"), "{tables}");
    let json = serde_json::to_value(&bench).unwrap();
    assert_eq!(json["hunt_rays"], 30_000);
    assert_eq!(json["rows"][0]["hunt"]["false_culls"], 0);
    assert!(json["rows"][0]["confirm"]["pvs_over_confirmed_vs"].is_number());
}

/// The progress lines of the checkpoint test's bench runs.
static LINES: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// `bench --foliage --checkpoint-dir DIR`: the sampler row keeps its cell's checkpoint, and
/// the same bench run again replays it (no rectangle rendered again, the progress says how
/// many were replayed) and reports the same row, its time including the first run's.
#[test]
fn a_bench_run_again_with_its_checkpoint_dir_replays_the_sampler_row() {
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("ckpt");
    let opts = BenchOptions {
        foliage_studies: Some(vec!["coarse".into()]),
        foliage_trees: Some(3),
        cells: Some(1),
        rays: Some(2000),
        backend: BenchBackend::Cpu,
        checkpoint_dir: Some(ckpt.clone()),
        progress: Some(|l: &str| LINES.lock().unwrap().push(l.to_string())),
        ..BenchOptions::default()
    };
    let first = collect(&opts).unwrap();
    let files: Vec<String> = std::fs::read_dir(&ckpt)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    // Only the sampler row (the fourth) has a sampler cell.
    assert_eq!(files.len(), 1, "{files:?}");
    assert!(files[0].starts_with("coarse-03.sampler-"), "{files:?}");
    let row = |b: &FoliageBench| {
        let r = b.rows.last().unwrap();
        assert!(r.variant.contains("--sampling"), "{}", r.variant);
        let curve: Vec<_> = r
            .sampling_curve
            .iter()
            .map(|c| (c.eps, c.points, c.sampler_hidden))
            .collect();
        (
            r.row.objects_culled_percent,
            curve,
            r.row.median_ms_per_cell,
        )
    };
    let (culled, curve, ms) = row(&first);
    assert!(
        !curve.is_empty() && curve.last().unwrap().1 > 0.0,
        "{curve:?}"
    );
    assert!(
        !LINES.lock().unwrap().iter().any(|l| l.contains("replayed")),
        "nothing to replay the first time"
    );
    let again = collect(&opts).unwrap();
    let (culled2, curve2, ms2) = row(&again);
    assert_eq!((culled2, &curve2), (culled, &curve));
    let sampled = first
        .rows
        .last()
        .unwrap()
        .sampling_curve
        .last()
        .unwrap()
        .seconds
        * 1e3;
    assert!(
        ms2 >= sampled,
        "{ms2} ms, the first run sampled {sampled} ms (of {ms} ms)"
    );
    let lines = LINES.lock().unwrap();
    let replayed: Vec<_> = lines.iter().filter(|l| l.contains("replayed")).collect();
    assert_eq!(replayed.len(), 1, "{lines:?}");
    assert!(
        replayed[0].contains("foliage coarse [--sweep --sampling")
            && replayed[0].contains("sampler rectangles from"),
        "{}",
        replayed[0]
    );
}
