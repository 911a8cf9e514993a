//! The page of `umbrasweep report SCENE PVS.json -o DIR`: a self-contained static HTML page
//! ([`render`], written as `DIR/index.html` by [`write_page`]), with every image inlined as a
//! `data:` URI (no network resources):
//!
//! - a top-down picture of the scene (x to the right, z downward, seen from +y) drawn with
//!   tiny-skia: each object's footprint (its bounds in x–z) green when in the chosen cell's
//!   PVS, grey when culled, larger footprints below smaller ones; every cell outlined in blue,
//!   the chosen one filled orange with a thick outline (footprints covering more than a
//!   quarter of the picture are outlined only);
//! - beside it, a per-cell table: index, bounds, PVS size, % of objects culled, bake time;
//! - the chosen cell's planes, re-baked in-process on the CPU backend with the settings the
//!   PVS document records: Depth preview and mask of each plane, with its frame, and the
//!   colour legend (see [`super::preview`]);
//! - when the bake ran ray space factorization for the chosen cell, its four charts as the
//!   traversal leaves them ([`preview::rsf_chart_image`]), each with the side it leaves and the
//!   share of its pixels holding an umbra.

use super::preview;
use crate::backend::cpu::CpuBackend;
use crate::bake::{self, BakeSettings};
use crate::geom::Aabb;
use crate::plane::{DepthMap, PlaneFrame};
use crate::pvs::PvsDocument;
use crate::scene::Scene;
use glam::Vec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// What the page shows, and the files it names (`umbrasweep report`'s options without the
/// output folder).
#[derive(Clone, Debug, Default)]
pub struct ReportOptions {
    /// The scene's file: named in errors (the scene itself is given to [`render`]).
    pub scene_file: PathBuf,
    /// The PVS document's file: named in errors and in the page's title.
    pub pvs_file: PathBuf,
    /// The cell whose PVS colours the picture and whose planes are previewed.
    pub cell: usize,
    /// Do not re-bake the chosen cell for the plane previews.
    pub no_previews: bool,
}

/// Errors of the report. Each names the file at fault or what could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The scene has another number of objects than the PVS: give the scene the PVS was
    /// baked from.
    #[error(
        "{} has {scene_objects} objects but {} lists {pvs_objects}: not the scene this PVS \
         was baked from",
        scene_file.display(),
        pvs_file.display()
    )]
    ObjectCount {
        /// The scene's file.
        scene_file: PathBuf,
        /// Objects in the scene.
        scene_objects: usize,
        /// The PVS document's file.
        pvs_file: PathBuf,
        /// Objects the PVS lists.
        pvs_objects: usize,
    },
    /// Object `index` has another name in the scene than in the PVS: give the scene the PVS
    /// was baked from.
    #[error(
        "object {index} is {scene_name:?} in {} but {pvs_name:?} in {}: not the scene this \
         PVS was baked from",
        scene_file.display(),
        pvs_file.display()
    )]
    ObjectName {
        /// The object's index.
        index: usize,
        /// Its name in the scene.
        scene_name: String,
        /// The scene's file.
        scene_file: PathBuf,
        /// Its name in the PVS.
        pvs_name: String,
        /// The PVS document's file.
        pvs_file: PathBuf,
    },
    /// The chosen cell is not in the PVS: choose one of `0 … cells - 1`.
    #[error(
        "--cell {cell}: {} has {cells} cells (0 … {})",
        pvs_file.display(),
        cells.saturating_sub(1)
    )]
    NoSuchCell {
        /// The chosen cell.
        cell: usize,
        /// The PVS document's file.
        pvs_file: PathBuf,
        /// Cells in the PVS.
        cells: usize,
    },
    /// The bake settings the PVS document records are refused by the baker.
    #[error("the PVS document's settings: {0}")]
    Settings(#[source] crate::settings::SettingsError),
    /// Re-baking the chosen cell for the previews failed.
    #[error(transparent)]
    Bake(#[from] crate::bake::BakeError),
    /// A picture could not be made or encoded (`what: why`).
    #[error("{0}")]
    Image(String),
    /// Formatting the page failed.
    #[error("cannot format the page")]
    Format(#[from] std::fmt::Error),
    /// The output folder cannot be created.
    #[error("{}: cannot create", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The page cannot be written (`PATH: why`).
    #[error("{0}")]
    Write(String),
}

/// One ray-space chart of the report.
struct ChartPreview {
    info: crate::rsf::ChartInfo,
    /// Pixels holding an umbra, and all pixels.
    filled: (usize, usize),
    png: Vec<u8>,
}

/// One plane preview of the report.
struct PlanePreview {
    index: usize,
    frame: PlaneFrame,
    occluders: usize,
    covered: usize,
    depth_png: Vec<u8>,
    mask_png: Vec<u8>,
}

/// The whole page for `scene` and its PVS document `doc` (see the module docs): checks that
/// they match and that the cell exists, draws the top-down picture and, unless
/// `opts.no_previews`, re-bakes the chosen cell on the CPU for its plane previews.
///
/// # Errors
/// A scene that is not the one the PVS was baked from, a cell index out of range, invalid
/// recorded settings, a failed re-bake or picture.
pub fn render(
    scene: &Scene,
    doc: &PvsDocument,
    opts: &ReportOptions,
) -> Result<String, ReportError> {
    check_match(scene, doc, opts)?;
    if opts.cell >= doc.cells.len() {
        return Err(ReportError::NoSuchCell {
            cell: opts.cell,
            pvs_file: opts.pvs_file.clone(),
            cells: doc.cells.len(),
        });
    }
    let topdown = draw_topdown(scene, doc, opts.cell)?;
    let (previews, rebaked, charts) = if opts.no_previews {
        (Vec::new(), None, None)
    } else {
        let (p, v) = rebake_cell(scene, doc, opts.cell)?;
        (p, Some(v), chart_previews(scene, doc, opts.cell)?)
    };
    page(
        opts,
        doc,
        &topdown,
        &previews,
        rebaked.as_deref(),
        charts.as_deref(),
    )
}

/// The chosen cell's ray-space charts, or `None` when the recorded settings do not run ray
/// space factorization on this scene.
fn chart_previews(
    scene: &Scene,
    doc: &PvsDocument,
    cell: usize,
) -> Result<Option<Vec<ChartPreview>>, ReportError> {
    let settings = recorded_settings(doc)?;
    let Some(charts) = bake::rsf_charts(scene, &[cell_box(&doc.cells[cell])], &[0], &settings)?
    else {
        return Ok(None);
    };
    let (_, charts) = &charts[0];
    let n = charts.resolution();
    (0..4)
        .map(|c| {
            let filled = (0..n * n)
                .filter(|k| {
                    charts
                        .umbrae(c, k / n, k % n)
                        .iter()
                        .any(|u| u.guard.is_finite())
                })
                .count();
            Ok(ChartPreview {
                info: charts.chart_info(c),
                filled: (filled, n * n),
                png: preview::encode_png(&preview::rsf_chart_image(charts, c))
                    .map_err(ReportError::Image)?,
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// Writes the page `html` as `dir/index.html` (atomically: temporary file, then rename),
/// creating `dir` when missing.
///
/// # Errors
/// The folder cannot be created or the file cannot be written.
pub fn write_page(dir: &Path, html: &str) -> Result<(), ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })?;
    crate::util::write_atomic(&dir.join("index.html"), html.as_bytes())
        .map_err(|e| ReportError::Write(e.to_string()))
}

/// Refuses a PVS baked from another scene: the same number of objects, with the same names.
fn check_match(scene: &Scene, doc: &PvsDocument, opts: &ReportOptions) -> Result<(), ReportError> {
    if scene.objects.len() != doc.objects.len() {
        return Err(ReportError::ObjectCount {
            scene_file: opts.scene_file.clone(),
            scene_objects: scene.objects.len(),
            pvs_file: opts.pvs_file.clone(),
            pvs_objects: doc.objects.len(),
        });
    }
    if let Some((i, (a, b))) = scene
        .objects
        .iter()
        .zip(&doc.objects)
        .enumerate()
        .find(|(_, (a, b))| a.name != b.name)
    {
        return Err(ReportError::ObjectName {
            index: i,
            scene_name: a.name.clone(),
            scene_file: opts.scene_file.clone(),
            pvs_name: b.name.clone(),
            pvs_file: opts.pvs_file.clone(),
        });
    }
    Ok(())
}

fn cell_box(c: &crate::pvs::PvsCell) -> Aabb {
    Aabb::new(Vec3::from(c.min), Vec3::from(c.max))
}

/// The bake settings recorded in the document (defaults for fields it lacks).
///
/// # Errors
/// An unknown placement or settings the baker refuses.
pub fn recorded_settings(doc: &PvsDocument) -> Result<BakeSettings, ReportError> {
    let settings = doc.settings.bake.clone();
    settings.check().map_err(ReportError::Settings)?;
    Ok(settings)
}

/// Re-bakes one cell on the CPU, keeping each plane's previews; returns them in rendering
/// order and the re-baked visible set.
fn rebake_cell(
    scene: &Scene,
    doc: &PvsDocument,
    cell: usize,
) -> Result<(Vec<PlanePreview>, Vec<u32>), ReportError> {
    let settings = recorded_settings(doc)?;
    let cells = [cell_box(&doc.cells[cell])];
    let out: Mutex<Vec<Result<PlanePreview, String>>> = Mutex::new(Vec::new());
    let observe = |_ci: usize, k: usize, job: &crate::plane::PlaneJob, map: &DepthMap, _: &_| {
        let d = preview::plane_distance(&job.frame);
        let p = preview::encode_png(&preview::depth_image(map, d)).and_then(|depth_png| {
            Ok(PlanePreview {
                index: k,
                frame: job.frame.clone(),
                occluders: job.occluders.len(),
                covered: map.covered(),
                depth_png,
                mask_png: preview::encode_png(&preview::mask_image(map))?,
            })
        });
        out.lock().expect("not poisoned").push(p);
    };
    let result = bake::bake_observed(
        scene,
        &cells,
        &settings,
        &CpuBackend::new(),
        None,
        Some(&observe),
    )?;
    let mut previews = out
        .into_inner()
        .expect("not poisoned")
        .into_iter()
        .collect::<Result<Vec<_>, _>>()
        .map_err(ReportError::Image)?;
    previews.sort_by_key(|p| p.index);
    let visible = result
        .cells
        .into_iter()
        .next()
        .map(|c| c.visible)
        .unwrap_or_default();
    Ok((previews, visible))
}

/// The top-down picture as PNG bytes (see the module docs).
fn draw_topdown(scene: &Scene, doc: &PvsDocument, cell: usize) -> Result<Vec<u8>, ReportError> {
    use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};
    let mut bounds = scene.bounds();
    for c in &doc.cells {
        let b = cell_box(c);
        bounds = if bounds.is_empty() {
            b
        } else {
            bounds.union(&b)
        };
    }
    if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
        bounds = Aabb::new(Vec3::ZERO, Vec3::ONE);
    }
    let (w_world, h_world) = (
        (bounds.max.x - bounds.min.x).max(1e-6),
        (bounds.max.z - bounds.min.z).max(1e-6),
    );
    const SIDE: f32 = 900.0;
    const MARGIN: f32 = 10.0;
    let scale = (SIDE - 2.0 * MARGIN) / w_world.max(h_world);
    let (w, h) = (
        (w_world * scale + 2.0 * MARGIN).ceil() as u32,
        (h_world * scale + 2.0 * MARGIN).ceil() as u32,
    );
    let mut pm = Pixmap::new(w.max(1), h.max(1))
        .ok_or_else(|| ReportError::Image("top-down picture: bad size".into()))?;
    pm.fill(Color::from_rgba8(250, 250, 247, 255));
    // World box → pixel rectangle, at least one pixel wide and tall.
    let rect = |b: &Aabb| {
        let x0 = MARGIN + (b.min.x - bounds.min.x) * scale;
        let x1 = (MARGIN + (b.max.x - bounds.min.x) * scale).max(x0 + 1.0);
        let y0 = MARGIN + (b.min.z - bounds.min.z) * scale;
        let y1 = (MARGIN + (b.max.z - bounds.min.z) * scale).max(y0 + 1.0);
        Rect::from_ltrb(x0, y0, x1, y1)
    };
    let paint = |r: u8, g: u8, b: u8, a: u8| {
        let mut p = Paint::default();
        p.set_color_rgba8(r, g, b, a);
        p.anti_alias = true;
        p
    };
    let stroke_rect = |pm: &mut Pixmap, r: Rect, p: &Paint, width: f32| {
        let path = PathBuilder::from_rect(r);
        let s = Stroke {
            width,
            ..Stroke::default()
        };
        pm.stroke_path(&path, p, &s, Transform::identity(), None);
    };
    let visible: std::collections::HashSet<u32> = doc.cells[cell].visible.iter().copied().collect();
    let mut order: Vec<usize> = (0..scene.objects.len())
        .filter(|&o| !scene.objects[o].bounds.is_empty())
        .collect();
    let area = |o: usize| {
        let s = scene.objects[o].bounds.size();
        s.x * s.z
    };
    order.sort_by(|&a, &b| area(b).total_cmp(&area(a)));
    let (vis_fill, vis_line) = (paint(46, 160, 67, 150), paint(20, 100, 40, 255));
    let (cul_fill, cul_line) = (paint(160, 160, 160, 110), paint(110, 110, 110, 200));
    for o in order {
        let Some(r) = rect(&scene.objects[o].bounds) else {
            continue;
        };
        let (fill, line) = if visible.contains(&(o as u32)) {
            (&vis_fill, &vis_line)
        } else {
            (&cul_fill, &cul_line)
        };
        // Grounds and other footprints covering much of the picture are outlined only, so
        // that they do not tint everything under them.
        if r.width() * r.height() <= 0.25 * (w * h) as f32 {
            pm.fill_rect(r, fill, Transform::identity(), None);
        }
        stroke_rect(&mut pm, r, line, 1.0);
    }
    let cell_line = paint(40, 90, 210, 230);
    for (i, c) in doc.cells.iter().enumerate() {
        if i == cell {
            continue;
        }
        if let Some(r) = rect(&cell_box(c)) {
            stroke_rect(&mut pm, r, &cell_line, 1.5);
        }
    }
    if let Some(r) = rect(&cell_box(&doc.cells[cell])) {
        pm.fill_rect(r, &paint(255, 140, 0, 170), Transform::identity(), None);
        stroke_rect(&mut pm, r, &paint(200, 40, 0, 255), 3.0);
        // A ring around small cells so that they stay findable.
        let (cx, cy) = ((r.left() + r.right()) / 2.0, (r.top() + r.bottom()) / 2.0);
        let rad = (r.width().max(r.height()) / 2.0 + 8.0).max(12.0);
        if let Some(circle) = PathBuilder::from_circle(cx, cy, rad) {
            let s = Stroke {
                width: 2.0,
                ..Stroke::default()
            };
            pm.stroke_path(
                &circle,
                &paint(200, 40, 0, 200),
                &s,
                Transform::identity(),
                None,
            );
        }
    }
    pm.encode_png()
        .map_err(|e| ReportError::Image(format!("top-down picture: cannot encode PNG: {e}")))
}

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn data_uri(png: &[u8]) -> String {
    format!("data:image/png;base64,{}", preview::base64(png))
}

fn fmt_v3(v: [f32; 3]) -> String {
    format!("({:.2}, {:.2}, {:.2})", v[0], v[1], v[2])
}

/// The whole page.
fn page(
    args: &ReportOptions,
    doc: &PvsDocument,
    topdown: &[u8],
    previews: &[PlanePreview],
    rebaked: Option<&[u32]>,
    charts: Option<&[ChartPreview]>,
) -> Result<String, ReportError> {
    let n_obj = doc.objects.len().max(1);
    let chosen = &doc.cells[args.cell];
    let mut h = String::new();
    let title = format!(
        "umbrasweep report: {}",
        args.pvs_file
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
    );
    write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>{}</title>\n<style>{CSS}</style></head><body>\n<h1>{}</h1>\n",
        esc(&title),
        esc(&title)
    )?;
    let s = &doc.settings;
    write!(
        h,
        "<p class=\"meta\">scene <code>{}</code> · {} objects · {} cells · backend {} · \
         resolution {} · {} planes + {} slice planes per direction · placement {} · extend {}",
        esc(&doc.scene),
        doc.objects.len(),
        doc.cells.len(),
        esc(&s.backend),
        s.bake.resolution,
        s.bake.planes,
        s.bake.slice_planes,
        esc(&format!("{:?}", s.bake.placement).to_lowercase()),
        s.bake.extend
    )?;
    if let Some(sum) = &doc.summary {
        write!(
            h,
            " · {:.1} % of objects culled on average · median {:.1} ms per cell",
            sum.objects_culled_percent, sum.median_ms_per_cell
        )?;
    }
    h.push_str("</p>\n");
    if let Some(sum) = doc.summary.as_ref().filter(|s| !s.cullers.is_empty()) {
        h.push_str(
            "<h2>Cullers</h2>\n<table class=\"cullers\"><thead><tr><th>culler</th>\
             <th>objects hidden per cell</th><th>only by it</th><th>ms per cell</th>\
             <th>planes per cell</th></tr></thead><tbody>\n",
        );
        for c in &sum.cullers {
            writeln!(
                h,
                "<tr><td>{}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>",
                esc(&c.name),
                c.hidden,
                c.only,
                c.ms,
                c.planes
            )?;
        }
        h.push_str("</tbody></table>\n");
    }

    let mut t = String::new();
    t.push_str(
        "<h2>Cells</h2>\n<div class=\"scroll\"><table><thead><tr><th>cell</th><th>min</th><th>max</th>\
         <th>PVS size</th><th>% culled</th><th>ms</th></tr></thead><tbody>\n",
    );
    for (i, c) in doc.cells.iter().enumerate() {
        let culled = 100.0 * (1.0 - c.visible.len() as f64 / n_obj as f64);
        writeln!(
            t,
            "<tr{}><td>{i}</td><td>{}</td><td>{}</td><td>{}</td><td>{culled:.1}</td>\
             <td>{:.1}</td></tr>",
            if i == args.cell {
                " class=\"chosen\""
            } else {
                ""
            },
            fmt_v3(c.min),
            fmt_v3(c.max),
            c.visible.len(),
            c.ms
        )?;
    }
    t.push_str("</tbody></table></div>\n");
    write!(
        h,
        "<div class=\"row\"><div class=\"pic\"><h2>Cell {} from above</h2>\n<p class=\"meta\">x to the right, z downward, seen from +y. \
         <span class=\"sw\" style=\"background:#2ea043\"></span> in the PVS of cell {} \
         ({} objects) · <span class=\"sw\" style=\"background:#a0a0a0\"></span> culled · \
         <span class=\"sw\" style=\"border:2px solid #285ad2\"></span> cells · \
         <span class=\"sw\" style=\"background:#ff8c00;border:2px solid #c82800\"></span> \
         cell {} {} – {}. Footprints are the objects' bounds; those covering more than a \
         quarter of the picture (grounds) are outlined only.</p>\n\
         <img class=\"top\" alt=\"top-down view of the scene\" src=\"{}\"></div>\n\
         <div class=\"cells\">{t}</div></div>\n",
        args.cell,
        args.cell,
        chosen.visible.len(),
        args.cell,
        fmt_v3(chosen.min),
        fmt_v3(chosen.max),
        data_uri(topdown)
    )?;

    h.push_str("<h2>Planes of the chosen cell</h2>\n");
    if args.no_previews {
        h.push_str("<p class=\"meta\">Previews skipped (--no-previews).</p>\n");
    } else {
        if let Some(v) = rebaked {
            let same = v == chosen.visible.as_slice();
            writeln!(
                h,
                "<p class=\"meta\">Re-baked on the CPU with the recorded settings: {} planes, \
                 PVS of {} objects ({}).</p>",
                previews.len(),
                v.len(),
                if same {
                    "the same as in the document".to_string()
                } else {
                    format!(
                        "the document lists {}: baked with another backend or version",
                        chosen.visible.len()
                    )
                }
            )?;
        }
        write!(
            h,
            "<p class=\"meta\">Each plane: Depth (left) and mask (right); pixel (i, j) at \
             x = i, y = j (v grows downward). Colour of Depth d: ramp(d / (d + D)), D the \
             plane's distance from the cell's face.</p>\n\
             <img class=\"legend\" alt=\"colour legend\" src=\"{}\">\n<div class=\"planes\">\n",
            data_uri(&preview::encode_png(&preview::legend_image()).map_err(ReportError::Image)?)
        )?;
        let names = ["x", "y", "z"];
        for p in previews {
            let f = &p.frame;
            let (u, v) = f.uv_axes();
            let px = f.pixel_size();
            writeln!(
                h,
                "<figure><img alt=\"Depth\" src=\"{}\"><img alt=\"mask\" src=\"{}\">\
                 <figcaption>plane {} · {}{} at {:.3} (D = {:.3}) · {} × {} px of {:.3} × {:.3} · \
                 {} [{:.2}, {:.2}] × {} [{:.2}, {:.2}] · {} occluders · {:.1} % covered\
                 </figcaption></figure>",
                data_uri(&p.depth_png),
                data_uri(&p.mask_png),
                p.index,
                names[f.axis.min(2)],
                if f.positive { "+" } else { "−" },
                f.position,
                (f.position - f.face()).abs(),
                f.width,
                f.height,
                px.x,
                px.y,
                names[u],
                f.rect_min.x,
                f.rect_max.x,
                names[v],
                f.rect_min.y,
                f.rect_max.y,
                p.occluders,
                100.0 * p.covered as f64 / (f.pixels() as f64).max(1.0)
            )?;
        }
        h.push_str("</div>\n");
        chart_section(&mut h, charts)?;
    }

    h.push_str("</body></html>\n");
    Ok(h)
}

/// The ray-space charts' section of the page.
fn chart_section(h: &mut String, charts: Option<&[ChartPreview]>) -> Result<(), ReportError> {
    h.push_str("<h2>Ray space factorization of the chosen cell</h2>\n");
    let Some(charts) = charts else {
        h.push_str(
            "<p class=\"meta\">Not run for this bake (the automatic rule or --no-rsf; \
             --rsf forces it).</p>\n",
        );
        return Ok(());
    };
    h.push_str(
        "<p class=\"meta\">One chart per side of the cell's footprint, as the traversal leaves \
         it: column = slope m of the horizontal line (−1 at the left, +1 at the right), row = \
         its crossing s of the side (growing downward). Colour: elevation of the pixel's \
         highest umbra line (the legend's ramp from climbing steeply, yellow, to falling \
         steeply, violet); checkerboard: no umbra.</p>\n<div class=\"planes\">\n",
    );
    let names = ["x", "y", "z"];
    for c in charts {
        let i = &c.info;
        writeln!(
            h,
            "<figure><img class=\"chart\" alt=\"ray-space chart\" src=\"{}\"><figcaption>\
             chart {}{} · s along {} in [{:.2}, {:.2}] · {:.1} % of {} pixels hold an umbra\
             </figcaption></figure>",
            data_uri(&c.png),
            if i.positive { "+" } else { "−" },
            names[i.axis.min(2)],
            names[i.tangent.min(2)],
            i.s_min,
            i.s_max,
            100.0 * c.filled.0 as f64 / (c.filled.1 as f64).max(1.0),
            c.filled.1
        )?;
    }
    h.push_str("</div>\n");
    Ok(())
}

const CSS: &str = "body{font:14px/1.4 sans-serif;margin:16px;color:#222;background:#fff}\
h1{font-size:20px}h2{font-size:16px;margin-top:24px}.meta{color:#555}\
code{background:#f2f2f2;padding:0 3px}\
.sw{display:inline-block;width:12px;height:12px;vertical-align:middle;box-sizing:border-box}\
img.top{width:100%;border:1px solid #ccc}\
.row{display:flex;gap:24px;align-items:flex-start}.pic{flex:0 1 600px}\
.scroll{max-height:620px;overflow-y:auto}img.legend{display:block;margin:8px 0}\
.planes{display:flex;flex-wrap:wrap;gap:12px}\
figure{margin:0;width:340px}figure img{width:160px;height:160px;image-rendering:pixelated;\
border:1px solid #ccc;margin-right:4px}figure img.chart{width:256px;height:256px}figcaption{font-size:12px;color:#444}\
table{border-collapse:collapse}td,th{border:1px solid #ddd;padding:2px 8px;text-align:right}\
tr.chosen{background:#ffe3c0;font-weight:bold}";
