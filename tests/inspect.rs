//! Inspection (issue 6): EXR dumps read back with the exr crate, PNG previews, the HTML
//! report, and a headless-Chromium screenshot of the report (skipped without Chromium unless
//! `CI` is set).

mod common;

use common::{Obj, bake_unit_cell_observed, cube, unit_cell};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{BakeSettings, bake, to_document};
use umbrasweep::geom::Aabb;
use umbrasweep::hdm::Hdm;
use umbrasweep::inspect::report::{self, ReportError, ReportOptions};
use umbrasweep::inspect::{DumpOptions, dump_plane, file_stem};
use umbrasweep::plane::{DepthMap, PlaneJob, depth_up};
use umbrasweep::scene::Scene;

/// A wall in front of the cell's +z face, an object hidden behind it, one beside the cell.
fn wall_scene() -> Vec<Obj> {
    vec![
        cube("wall", [-1.5, -1.5, 2.0], [1.5, 1.5, 2.2]),
        cube("hidden", [-0.2, -0.2, 4.0], [0.2, 0.2, 4.4]),
        cube("beside", [3.0, -0.5, -0.5], [3.5, 0.5, 0.5]),
    ]
}

const RES: u32 = 64;

/// Separate planes (the wall and slice planes these tests look for), not the sweep.
fn settings() -> BakeSettings {
    BakeSettings {
        resolution: RES,
        sweep: umbrasweep::bake::SweepChoice::Off,
        ..BakeSettings::default()
    }
}

/// A fresh temporary folder (removed on drop).
fn tmp() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("umbrasweep-inspect-")
        .tempdir()
        .unwrap()
}

type Seen = Mutex<Vec<(usize, PlaneJob, DepthMap, Hdm)>>;

/// Bakes the wall scene's cell with dumps into `opts`, returning the planes seen.
fn bake_with_dumps(opts: &DumpOptions) -> Vec<(usize, PlaneJob, DepthMap, Hdm)> {
    let scene = Scene::from_objects(Path::new("analytic"), wall_scene());
    let seen: Seen = Mutex::new(Vec::new());
    let errors = Mutex::new(Vec::new());
    let observe = |ci: usize, k: usize, job: &PlaneJob, map: &DepthMap, hdm: &Hdm| {
        if let Err(e) = dump_plane(opts, ci, k, job, map, hdm) {
            errors.lock().unwrap().push(e);
        }
        seen.lock()
            .unwrap()
            .push((k, job.clone(), map.clone(), hdm.clone()));
    };
    let r = bake_unit_cell_observed(&scene, &settings(), &observe);
    assert_eq!(errors.into_inner().unwrap(), Vec::<String>::new());
    let names: Vec<&str> = r.cells[0]
        .visible
        .iter()
        .map(|&o| scene.objects[o as usize].name.as_str())
        .collect();
    assert_eq!(names, ["wall", "beside"], "the analytic bake itself");
    let mut seen = seen.into_inner().unwrap();
    seen.sort_by_key(|s| s.0);
    seen
}

/// An EXR file with all its layers, channels and attributes (largest level).
fn read_exr(
    path: &Path,
) -> exr::prelude::Image<exr::prelude::Layers<exr::prelude::AnyChannels<exr::prelude::FlatSamples>>>
{
    use exr::prelude::*;
    read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn f32_samples(ch: &exr::prelude::AnyChannel<exr::prelude::FlatSamples>) -> Vec<f32> {
    match &ch.sample_data {
        exr::prelude::FlatSamples::F32(v) => v.clone(),
        other => panic!("channel {} is not f32: {other:?}", ch.name),
    }
}

#[test]
fn exr_dump_reads_back_with_channels_levels_values_and_metadata() {
    use exr::prelude::*;
    let dir = tmp();
    let exr_dir = dir.path().join("exr/nested"); // created on demand
    let opts = DumpOptions {
        exr: Some(exr_dir.clone()),
        png: None,
        cells: None,
    };
    let seen = bake_with_dumps(&opts);
    assert!(!seen.is_empty());
    let mut checked_wall = 0;
    let mut stretched = 0;
    for (k, job, map, hdm) in &seen {
        // Maps are stretched to their rectangles with RES² pixels (the wall scene's planes are
        // not all square).
        let (w, h) = (map.width as usize, map.height as usize);
        assert_eq!(w * h, (RES * RES) as usize);
        stretched += usize::from(w != h);
        let levels = w.max(h).trailing_zeros() as usize;
        assert_eq!(hdm.max.len(), levels + 1);
        let stem = file_stem(0, *k, job);
        assert!(
            stem.starts_with(&format!("cell0000_plane{k:02}_")),
            "{stem}"
        );
        let path = exr_dir.join(format!("{stem}.exr"));
        let image = read_exr(&path);
        let layer_names: Vec<String> = image
            .layer_data
            .iter()
            .map(|l| l.attributes.layer_name.as_ref().unwrap().to_string())
            .collect();
        let mut expected = vec!["plane".to_string()];
        expected.extend((1..=levels).map(|l| format!("hdm_max_{l}")));
        expected.extend((1..=levels).map(|l| format!("hdm_min_{l}")));
        assert_eq!(layer_names, expected);
        // The plane layer: depth and mask.
        let base = &image.layer_data[0];
        assert_eq!(base.size, Vec2(w, h));
        let chans: Vec<String> = base
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(chans, ["depth", "mask"]);
        let depth = f32_samples(&base.channel_data.list[0]);
        let mask = f32_samples(&base.channel_data.list[1]);
        assert_eq!(depth.len(), w * h);
        for (i, (a, b)) in depth.iter().zip(&map.depth).enumerate() {
            assert_eq!(a.to_bits(), b.to_bits(), "{stem}: pixel {i}");
            assert_eq!(mask[i], if b.is_finite() { 1.0 } else { 0.0 });
        }
        // The pyramid levels halve and hold the HDM.
        for (li, layer) in image.layer_data.iter().enumerate().skip(1) {
            let (kind, l) = if li <= levels {
                (&hdm.max, li)
            } else {
                (&hdm.min, li - levels)
            };
            let (lw, lh) = ((w >> l).max(1), (h >> l).max(1));
            assert_eq!(layer.size, Vec2(lw, lh), "{stem} layer {li}");
            assert_eq!(layer.channel_data.list.len(), 1);
            assert_eq!(layer.channel_data.list[0].name.to_string(), "depth");
            let v = f32_samples(&layer.channel_data.list[0]);
            assert_eq!(v.len(), lw * lh);
            assert!(
                v.iter()
                    .zip(&kind[l])
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        // Metadata.
        let other = &base.attributes.other;
        assert!(
            image
                .layer_data
                .iter()
                .all(|l| l.attributes.other == *other)
        );
        let text = |k: &str| match other.get(&Text::from(k)) {
            Some(AttributeValue::Text(t)) => t.to_string(),
            v => panic!("{k}: {v:?}"),
        };
        let f = &job.frame;
        assert_eq!(text("planeAxis"), ["x", "y", "z"][f.axis]);
        assert_eq!(text("planeSide"), if f.positive { "+" } else { "-" });
        match other.get(&Text::from("planePosition")) {
            Some(AttributeValue::F64(p)) => assert_eq!(*p, f.position),
            v => panic!("planePosition: {v:?}"),
        }
        match other.get(&Text::from("resolution")) {
            Some(AttributeValue::I32(r)) => assert_eq!(*r as usize, w.max(h)),
            v => panic!("resolution: {v:?}"),
        }
        for (key, n) in [("width", w), ("height", h)] {
            match other.get(&Text::from(key)) {
                Some(AttributeValue::I32(r)) => assert_eq!(*r as usize, n),
                v => panic!("{key}: {v:?}"),
            }
        }
        match other.get(&Text::from("cellMin")) {
            Some(AttributeValue::FloatVec3(v)) => assert_eq!(*v, (-0.5, -0.5, -0.5)),
            v => panic!("cellMin: {v:?}"),
        }
        match other.get(&Text::from("pixelSize")) {
            Some(AttributeValue::FloatVec2(v)) => {
                let ps = f.pixel_size();
                assert_eq!(*v, Vec2(ps.x as f32, ps.y as f32));
            }
            v => panic!("pixelSize: {v:?}"),
        }
        for key in ["cellMax", "rectMin", "rectMax", "planeDistance", "uvAxes"] {
            assert!(other.contains_key(&Text::from(key)), "{key}");
        }
        // Known values on the +z planes: the plane just behind the wall holds the wall's
        // Depth (its far face, `2.2`, seen from the plane) where covered; the slice plane
        // through the wall holds Depth 0 in the wall's cross-section; the corners (beyond
        // the wall's outline) are uncovered.
        if f.axis == 2 && f.positive && f.position < 3.0 {
            let wall = if job.slices.is_empty() {
                depth_up(2.2f32 as f64 - f.position)
            } else {
                0.0
            };
            let p = f.to_pixel(glam::DVec2::ZERO);
            let (i, j) = (p.x.floor() as usize, p.y.floor() as usize);
            assert!((depth[j * w + i] - wall).abs() <= 1e-5, "{stem}: centre");
            assert_eq!(mask[j * w + i], 1.0);
            assert_eq!(
                depth.iter().filter(|d| d.is_finite()).count(),
                map.covered()
            );
            assert!(
                depth
                    .iter()
                    .all(|&d| !d.is_finite() || (d - wall).abs() <= 1e-5),
                "{stem}: every covered pixel holds the wall's Depth"
            );
            let (lo, hi) = (f.rect_min, f.rect_max);
            assert!(lo.x < -1.5 && lo.y < -1.5 && hi.x > 1.5 && hi.y > 1.5);
            for c in [0, w - 1, w * (h - 1), w * h - 1] {
                assert_eq!(depth[c], f32::INFINITY, "{stem}: corner {c}");
                assert_eq!(mask[c], 0.0);
            }
            let nonempty = map.covered() > w * h / 2;
            assert!(nonempty, "{stem}: the wall covers most of the plane");
            checked_wall += 1;
        }
    }
    assert_eq!(
        checked_wall, 2,
        "the slice plane and the plane behind the wall"
    );
    assert_eq!(stretched, 0, "separate planes keep square maps");
}

/// Sweep planes are stretched to their rectangles: beside a flat layer of boxes their dumps
/// (EXR layers and pyramid levels, PNG previews) have the maps' own sizes.
#[test]
fn stretched_sweep_planes_dump_at_their_size() {
    use exr::prelude::*;
    let dir = tmp();
    let opts = DumpOptions {
        exr: Some(dir.path().join("exr")),
        png: Some(dir.path().join("png")),
        cells: None,
    };
    // A low, wide row of boxes on each side of the cell: flat rectangles on the x planes.
    let mut objects = Vec::new();
    for k in 0..40 {
        let z = -20.0 + k as f32;
        for x in [3.0f32, -4.0] {
            objects.push(cube(
                &format!("box{k}_{x}"),
                [x, -0.3, z],
                [x + 1.0, 0.3, z + 0.6],
            ));
        }
    }
    let scene = Scene::from_objects(Path::new("row"), objects);
    let seen: Seen = Mutex::new(Vec::new());
    let observe = |ci: usize, k: usize, job: &PlaneJob, map: &DepthMap, hdm: &Hdm| {
        dump_plane(&opts, ci, k, job, map, hdm).unwrap();
        seen.lock()
            .unwrap()
            .push((k, job.clone(), map.clone(), hdm.clone()));
    };
    let settings = BakeSettings {
        resolution: RES,
        max_stretch: 8,
        sweep: umbrasweep::bake::SweepChoice::On,
        ..BakeSettings::default()
    };
    bake_unit_cell_observed(&scene, &settings, &observe);
    let mut stretched = 0;
    for (k, job, map, hdm) in seen.into_inner().unwrap() {
        let (w, h) = (map.width as usize, map.height as usize);
        assert_eq!(w * h, (RES * RES) as usize);
        stretched += usize::from(w != h);
        let stem = file_stem(0, k, &job);
        let path = dir.path().join("exr").join(format!("{stem}.exr"));
        let image = read_exr(&path);
        let levels = hdm.max.len() - 1;
        assert_eq!(image.layer_data.len(), 1 + 2 * levels);
        assert_eq!(image.layer_data[0].size, Vec2(w, h));
        for (li, layer) in image.layer_data.iter().enumerate().skip(1) {
            let l = if li <= levels { li } else { li - levels };
            assert_eq!(layer.size, Vec2((w >> l).max(1), (h >> l).max(1)));
        }
        for what in ["depth", "mask"] {
            let p = dir.path().join("png").join(format!("{stem}_{what}.png"));
            let img = image::open(&p).unwrap().to_rgb8();
            assert_eq!(img.dimensions(), (w as u32, h as u32), "{}", p.display());
        }
    }
    assert!(stretched > 0, "some sweep plane's map is stretched");
}

#[test]
fn png_previews_have_the_map_sizes_and_a_legend() {
    let dir = tmp();
    let png_dir = dir.path().join("png");
    let opts = DumpOptions {
        exr: None,
        png: Some(png_dir.clone()),
        cells: None,
    };
    let seen = bake_with_dumps(&opts);
    for (k, job, map, _) in &seen {
        let stem = file_stem(0, *k, job);
        for what in ["depth", "mask", "hdm"] {
            let p = png_dir.join(format!("{stem}_{what}.png"));
            let img = image::open(&p)
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
                .to_rgb8();
            let size = if what == "hdm" {
                (map.width, map.height.max(2))
            } else {
                (map.width, map.height)
            };
            assert_eq!(img.dimensions(), size, "{}", p.display());
            if what == "mask" {
                let white = img.pixels().filter(|p| p.0 == [255, 255, 255]).count();
                assert_eq!(white, map.covered());
            }
        }
    }
    let legend = image::open(png_dir.join("legend.png")).unwrap().to_rgb8();
    assert!(legend.width() >= 200 && legend.height() >= 100);
}

/// Writes `objects` as an OBJ file (one `o` per object).
fn write_obj(path: &Path, objects: &[Obj]) {
    let mut s = String::new();
    let mut n = 0;
    for (name, tris, _) in objects {
        s += &format!("o {name}\n");
        for t in tris {
            for p in t {
                s += &format!("v {} {} {}\n", p.x, p.y, p.z);
            }
            s += &format!("f {} {} {}\n", n + 1, n + 2, n + 3);
            n += 3;
        }
    }
    std::fs::write(path, s).unwrap();
}

/// Writes a small scene, bakes two cells and writes the PVS: returns (scene, pvs) paths.
fn scene_and_pvs(dir: &Path) -> (PathBuf, PathBuf) {
    let scene_path = dir.join("walls.obj");
    write_obj(&scene_path, &wall_scene());
    let scene = umbrasweep::scene::load(&scene_path).unwrap();
    let cells = [
        unit_cell(),
        Aabb::new(Vec3::new(1.0, -0.5, -0.5), Vec3::new(2.0, 0.5, 0.5)),
    ];
    let r = bake(&scene, &cells, &settings(), &CpuBackend::new(), None).unwrap();
    let doc = to_document(&scene, &cells, &r, &settings());
    let pvs = dir.join("walls.json");
    umbrasweep::pvs::json::write(&pvs, &doc).unwrap();
    (scene_path, pvs)
}

/// What `umbrasweep report SCENE PVS -o OUT --cell N [--no-previews]` does: reads both files,
/// renders the page and writes `OUT/index.html`.
fn run_report(
    scene: &Path,
    pvs: &Path,
    out: &Path,
    cell: usize,
    no_previews: bool,
) -> Result<(), ReportError> {
    let s = umbrasweep::scene::load(scene).unwrap();
    let doc = umbrasweep::pvs::json::read(pvs).unwrap();
    let opts = ReportOptions {
        scene_file: scene.to_path_buf(),
        pvs_file: pvs.to_path_buf(),
        cell,
        no_previews,
    };
    let html = report::render(&s, &doc, &opts)?;
    report::write_page(out, &html)
}

fn report(dir: &Path) -> PathBuf {
    let (scene, pvs) = scene_and_pvs(dir);
    let out = dir.join("report");
    run_report(&scene, &pvs, &out, 0, false).unwrap();
    out.join("index.html")
}

#[test]
fn report_is_a_self_contained_page() {
    let dir = tmp();
    let index = report(dir.path());
    let html = std::fs::read_to_string(&index).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(!html.contains("http://") && !html.contains("https://"));
    assert!(!html.contains("url("), "no CSS resources");
    let srcs: Vec<&str> = html.split("src=\"").skip(1).collect();
    // Top-down picture, legend, and two images per plane.
    assert!(srcs.len() >= 4, "{} images", srcs.len());
    assert!(srcs.iter().all(|s| s.starts_with("data:image/png;base64,")));
    assert!(html.contains("<table>") && html.contains("class=\"chosen\""));
    assert!(
        html.contains("the same as in the document"),
        "re-bake agrees"
    );
}

/// The report of cell 0 of the wall scene baked with ray space factorization `rsf`.
fn report_with_rsf(dir: &Path, rsf: umbrasweep::bake::SweepChoice) -> String {
    let scene_path = dir.join("walls.obj");
    write_obj(&scene_path, &wall_scene());
    let scene = umbrasweep::scene::load(&scene_path).unwrap();
    let cells = [unit_cell()];
    let s = BakeSettings {
        rsf,
        rsf_resolution: 32,
        ..settings()
    };
    let r = bake(&scene, &cells, &s, &CpuBackend::new(), None).unwrap();
    let pvs = dir.join("walls.json");
    umbrasweep::pvs::json::write(&pvs, &to_document(&scene, &cells, &r, &s)).unwrap();
    let out = dir.join("report");
    run_report(&scene_path, &pvs, &out, 0, false).unwrap();
    std::fs::read_to_string(out.join("index.html")).unwrap()
}

#[test]
fn report_pictures_the_ray_space_charts_when_the_bake_ran_them() {
    let dir = tmp();
    let html = report_with_rsf(dir.path(), umbrasweep::bake::SweepChoice::On);
    let charts: Vec<&str> = html.split("<img class=\"chart\"").skip(1).collect();
    assert_eq!(charts.len(), 4, "four charts");
    for side in ["chart +x", "chart −x", "chart +z", "chart −z"] {
        assert!(html.contains(side), "{side}");
    }
    // The wall across +z (in front of the cell) fills part of the +z chart, nothing fills the
    // −z one (nothing stands behind the cell there).
    let share = |side: &str| -> f64 {
        let at = html.find(side).unwrap();
        let rest = &html[at..];
        let pct = rest.split(" · ").nth(2).unwrap();
        pct.split(' ').next().unwrap().parse().unwrap()
    };
    assert!(share("chart +z") > 5.0, "{}", share("chart +z"));
    assert_eq!(share("chart −z"), 0.0);
    // The picture of a chart: its size, the checkerboard exactly where no pixel holds an
    // umbra.
    let scene = Scene::from_objects(Path::new("walls"), wall_scene());
    let s = BakeSettings {
        rsf: umbrasweep::bake::SweepChoice::On,
        rsf_resolution: 32,
        ..settings()
    };
    let charts = umbrasweep::bake::rsf_charts(&scene, &[unit_cell()], &[0], &s)
        .unwrap()
        .unwrap();
    let charts = &charts[0].1;
    let plus_z = (0..4).find(|&c| charts.chart_info(c).axis == 2 && charts.chart_info(c).positive);
    let plus_z = plus_z.unwrap();
    let img = umbrasweep::inspect::preview::rsf_chart_image(charts, plus_z);
    assert_eq!(img.dimensions(), (32, 32));
    let greys = umbrasweep::inspect::preview::UNCOVERED;
    let mut coloured = 0;
    for (x, y, p) in img.enumerate_pixels() {
        let has = charts
            .umbrae(plus_z, y as usize, x as usize)
            .iter()
            .any(|u| u.guard.is_finite());
        assert_eq!(!greys.contains(&p.0), has, "pixel ({x}, {y})");
        coloured += usize::from(has);
    }
    assert!(coloured > 50, "{coloured}");

    let dir = tmp();
    let html = report_with_rsf(dir.path(), umbrasweep::bake::SweepChoice::Off);
    assert!(!html.contains("<img class=\"chart\""));
    assert!(html.contains("Not run for this bake"));
}

#[test]
fn report_refuses_a_pvs_of_another_scene_and_a_missing_cell() {
    let dir = tmp();
    let (scene, pvs) = scene_and_pvs(dir.path());
    let other = dir.path().join("other.obj");
    write_obj(&other, &wall_scene()[..2]);
    let out = dir.path().join("r");
    let e = run_report(&other, &pvs, &out, 0, true).unwrap_err();
    assert!(matches!(e, ReportError::ObjectCount { .. }), "{e:?}");
    let e = e.to_string();
    assert!(e.contains("2 objects") && e.contains("lists 3"), "{e}");
    let e = run_report(&scene, &pvs, &out, 7, true).unwrap_err();
    assert!(matches!(e, ReportError::NoSuchCell { .. }), "{e:?}");
    let e = e.to_string();
    assert!(e.contains("--cell 7"), "{e}");
    assert!(!dir.path().join("r/index.html").exists());
    run_report(&scene, &pvs, &out, 1, true).unwrap();
    assert!(dir.path().join("r/index.html").is_file());
}

/// Runs `cmd`, killing it after `secs` seconds.
fn run_with_timeout(cmd: &mut std::process::Command, secs: u64) -> std::process::ExitStatus {
    let mut child = cmd.spawn().expect("chromium starts");
    let start = std::time::Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if start.elapsed().as_secs() > secs {
            let _ = child.kill();
            panic!("chromium did not finish within {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

#[test]
fn report_renders_in_headless_chromium() {
    let chromium = ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .map(Path::new)
        .find(|p| p.exists());
    let Some(chromium) = chromium else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but Chromium is missing (apt-get install chromium)"
        );
        eprintln!("skipped: no /usr/bin/chromium (apt-get install chromium to run this test)");
        return;
    };
    let dir = tmp();
    let index = report(dir.path());
    let profile = dir.path().join("profile");
    let shot = dir.path().join("shot.png");
    let t = std::time::Instant::now();
    let status = run_with_timeout(
        std::process::Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(format!("--screenshot={}", shot.display()))
            .arg("--window-size=1200,900")
            .arg(format!(
                "file://{}",
                index.canonicalize().unwrap().display()
            ))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null()),
        120,
    );
    eprintln!("chromium took {:.1} s", t.elapsed().as_secs_f64());
    assert!(status.success(), "chromium failed: {status}");
    let img = image::open(&shot).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1200, 900));
    let mut counts = std::collections::HashMap::new();
    for p in img.pixels() {
        *counts.entry(p.0).or_insert(0usize) += 1;
    }
    let most = counts.values().copied().max().unwrap();
    let total = (img.width() * img.height()) as usize;
    assert!(counts.len() >= 20, "only {} colours", counts.len());
    assert!(
        most < total * 95 / 100,
        "one colour covers {most} of {total} pixels"
    );
    // The visible objects' green reached the screen.
    assert!(
        img.pixels()
            .any(|p| p.0[1] > 120 && p.0[0] < 140 && p.0[2] < 140 && p.0[1] > p.0[0] + 30),
        "no green footprint in the screenshot"
    );
}

/// `--dump-exr` with ray space factorization: its four charts of a cell as one EXR file, a
/// part per side of the footprint; a wall across +x fills the +x chart and nothing else.
#[test]
fn ray_space_charts_dump_as_four_exr_parts() {
    let dir = tmp();
    let scene = Scene::from_objects(
        Path::new("charts"),
        vec![cube("wall", [6.0, -1.0, -40.0], [7.0, 10.0, 40.0])],
    );
    let cells = [Aabb::new(
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::new(2.0, 2.0, 2.0),
    )];
    let s = BakeSettings {
        rsf: umbrasweep::bake::SweepChoice::On,
        rsf_resolution: 32,
        ..BakeSettings::default()
    };
    let charts = umbrasweep::bake::rsf_charts(&scene, &cells, &[0], &s)
        .unwrap()
        .expect("ray space factorization is on");
    let opts = DumpOptions {
        exr: Some(dir.path().to_path_buf()),
        png: None,
        cells: None,
    };
    umbrasweep::inspect::dump_charts(&opts, 0, &cells[0], &charts[0].1).unwrap();
    let img = read_exr(&dir.path().join("cell0000_rsf.exr"));
    let mut filled = std::collections::BTreeMap::new();
    for layer in &img.layer_data {
        let name = layer.attributes.layer_name.as_ref().unwrap().to_string();
        assert_eq!((layer.size.0, layer.size.1), (32, 32), "{name}");
        let channels: Vec<String> = layer
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        for want in [
            "near_slope",
            "near_guard",
            "near_base",
            "far_slope",
            "far_guard",
            "far_base",
        ] {
            assert!(channels.iter().any(|c| c == want), "{name}: {channels:?}");
        }
        let guard = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == "near_guard")
            .unwrap();
        let finite = f32_samples(guard).iter().filter(|g| g.is_finite()).count();
        filled.insert(name, finite);
    }
    let names: Vec<&str> = filled.keys().map(String::as_str).collect();
    assert_eq!(names, ["chart_+x", "chart_+z", "chart_-x", "chart_-z"]);
    assert!(filled["chart_+x"] > 100, "{filled:?}");
    assert_eq!(filled["chart_-x"], 0, "{filled:?}");
    // Without ray space factorization there is nothing to dump.
    let off = BakeSettings {
        rsf: umbrasweep::bake::SweepChoice::Off,
        ..s
    };
    assert!(
        umbrasweep::bake::rsf_charts(&scene, &cells, &[0], &off)
            .unwrap()
            .is_none()
    );
}
