//! Scene import tests: OBJ and glTF numbering contract, geometry, opacity, errors, closed
//! detection, and the real scenes under `../shared/scenes` when present.
#![cfg(feature = "bake")]

mod common;

use common::shared_scenes;
use glam::Vec3;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::time::Instant;
use umbrasweep::geom::Aabb;
use umbrasweep::scene::{self, Scene, SceneError, closed};

// ---------------------------------------------------------------------------------------
// Helpers

fn write(dir: &Path, name: &str, content: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

fn load_obj_text(text: &str) -> (tempfile::TempDir, Result<Scene, SceneError>) {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "scene.obj", text);
    let r = scene::load(&p);
    (dir, r)
}

fn obj(text: &str) -> Scene {
    let (_d, r) = load_obj_text(text);
    r.unwrap_or_else(|e| panic!("load failed: {e}"))
}

fn obj_err(text: &str) -> String {
    let (_d, r) = load_obj_text(text);
    match r {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e.to_string(),
    }
}

fn names(s: &Scene) -> Vec<&str> {
    s.objects.iter().map(|o| o.name.as_str()).collect()
}

fn object_triangles(s: &Scene, id: usize) -> Vec<[u32; 3]> {
    let r = &s.objects[id].triangles;
    s.triangles[r.start as usize..r.end as usize].to_vec()
}

fn object_corners(s: &Scene, id: usize) -> Vec<[Vec3; 3]> {
    let r = s.objects[id].triangles.clone();
    (r.start..r.end).map(|t| s.triangle(t as usize)).collect()
}

fn assert_near(a: Vec3, b: Vec3) {
    assert!((a - b).abs().max_element() < 1e-5, "{a} != {b}");
}

fn assert_tri_near(a: [Vec3; 3], b: [Vec3; 3]) {
    for k in 0..3 {
        assert_near(a[k], b[k]);
    }
}

/// The six faces of the axis-aligned box [lo, hi], outward counter-clockwise, as 12 triangles
/// over 8 shared corners (OBJ text starting at vertex `base` + 1).
fn cube_obj(lo: Vec3, hi: Vec3, base: usize) -> String {
    let mut s = String::new();
    for k in 0..8 {
        let p = Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        s += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for q in CUBE_QUADS {
        let [a, b, c, d] = q.map(|i| i + 1 + base);
        s += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
    }
    s
}

/// Cube faces as corner-index quads (bit 0 = x, bit 1 = y, bit 2 = z), outward CCW.
const CUBE_QUADS: [[usize; 4]; 6] = [
    [0, 2, 3, 1], // z = lo
    [4, 5, 7, 6], // z = hi
    [0, 1, 5, 4], // y = lo
    [2, 6, 7, 3], // y = hi
    [0, 4, 6, 2], // x = lo
    [1, 3, 7, 5], // x = hi
];

fn cube_tris(lo: Vec3, hi: Vec3) -> Vec<[Vec3; 3]> {
    let corner = |k: usize| {
        Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let mut out = Vec::new();
    for [a, b, c, d] in CUBE_QUADS {
        out.push([corner(a), corner(b), corner(c)]);
        out.push([corner(a), corner(c), corner(d)]);
    }
    out
}

// ---------------------------------------------------------------------------------------
// OBJ

#[test]
fn obj_numbering_fixture_ids_grouping_and_opacity() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scene/numbering.obj");
    let s = scene::load(&p).unwrap();
    assert_eq!(names(&s), ["default", "Big House", "wall", "late"]);
    // Triangles grouped by id, re-opened names joined, in file order within an object.
    assert_eq!(object_triangles(&s, 0), [[0, 1, 2], [2, 1, 0]]);
    assert_eq!(object_triangles(&s, 1), [[0, 2, 3]]);
    assert_eq!(object_triangles(&s, 2), [[0, 1, 3], [1, 2, 3]]);
    assert_eq!(object_triangles(&s, 3), [[0, 1, 2]]);
    let ranges: Vec<_> = s.objects.iter().map(|o| o.triangles.clone()).collect();
    assert_eq!(ranges, [0..2, 2..3, 3..5, 5..6]);
    // Opacity follows the material of each face through the regrouping.
    assert_eq!(s.opaque, [true, true, true, false, true, false]);
    assert_eq!(
        s.objects[1].bounds,
        Aabb::new(Vec3::ZERO, Vec3::new(0.0, 1.0, 1.0))
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    for t in 0..s.triangles.len() as u32 {
        let o = s.triangle_object(t) as usize;
        assert!(s.objects[o].triangles.contains(&t));
    }
}

#[test]
fn obj_faces_before_any_statement_are_default_and_first() {
    let s = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\no a\nf 1 2 3\ng b\nf 1 2 3\ng\nf 1 2 3\n");
    assert_eq!(names(&s), ["a", "b", "default"]);

    let s = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\no a\nf 1 2 3\no default\nf 3 2 1\n");
    assert_eq!(names(&s), ["default", "a"]);
    assert_eq!(object_triangles(&s, 0), [[0, 1, 2], [2, 1, 0]]);

    // No loose faces: no `default` object.
    let s = obj("o x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    assert_eq!(names(&s), ["x"]);
}

#[test]
fn obj_g_and_o_mix_whitespace_and_first_statement_order() {
    // "first" is named before "second" but owns faces only later: it still comes first.
    let s = obj(concat!(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
        "g first\n",
        "o \t second   obj \t\r\n",
        "f 1 2 3\n",
        "g first\n",
        "f 1 2 3\n",
        "o nothing here\n",
        "g second obj\n",
        "f 2 3 1\n",
        "o\n",
        "f 1 2 3\n",
    ));
    assert_eq!(names(&s), ["first", "second obj", "default"]);
    assert_eq!(object_triangles(&s, 1), [[0, 1, 2], [1, 2, 0]]);
    assert_eq!(s.objects.len(), 3, "a name with no faces gets no id");
}

#[test]
fn obj_fan_triangulation_negative_indices_and_slash_forms() {
    let s = obj(concat!(
        "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0 1.0\n",
        "vt 0 0\nvn 0 0 1\n",
        "s off\nusemtl none\n",
        "f 1/1/1 2/1/1 3/1/1 4/1/1 5/1/1\n",
        "f -3//1 -2//1 -1//1\n",
        "f 1/1 2/1 3/1\n",
        "v 5 5 5 0.5 0.2 0.1\n",
        "f -1 -2 -3\n",
        "f\t1  2\t 3   # trailing comment\r\n",
    ));
    assert_eq!(
        s.triangles,
        [
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 4],
            [2, 3, 4],
            [0, 1, 2],
            [5, 4, 3],
            [0, 1, 2]
        ]
    );
    assert_eq!(s.vertices[5], Vec3::splat(5.0));
    assert_eq!(names(&s), ["default"]);
}

#[test]
fn obj_lines_and_points_are_skipped_with_one_warning_per_kind() {
    let s = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\np 1\np 2\np 3\nf 1 2 3\n");
    assert_eq!(s.triangles.len(), 1);
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(s.warnings.iter().any(|w| w.contains("`l`")));
    assert!(s.warnings.iter().any(|w| w.contains("`p`")));
}

#[test]
fn obj_degenerate_triangles_are_kept() {
    let s = obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\nf 1 1 2\n");
    assert_eq!(s.triangles.len(), 3);
    assert_eq!(s.degenerate_triangles(), 2);
}

#[test]
fn obj_mtl_opacity_d_tr_map_d() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "mats.mtl",
        concat!(
            "newmtl solid\nKd 1 1 1\nd 1\nTr 0\n",
            "newmtl glass\nd 0.5\n",
            "newmtl tinted\nTr 0.25\n",
            "newmtl cutout\nmap_d -clamp on cut.png\n",
            "newmtl halo\nd -halo 0.9\n",
            "newmtl plain\nKd 0.5 0.5 0.5\n",
        ),
    );
    let p = write(
        dir.path(),
        "m.obj",
        concat!(
            "mtllib mats.mtl\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
            "f 1 2 3\n",
            "usemtl solid\nf 1 2 3\n",
            "usemtl glass\nf 1 2 3\n",
            "usemtl tinted\nf 1 2 3\n",
            "usemtl cutout\nf 1 2 3\n",
            "usemtl halo\nf 1 2 3\n",
            "usemtl plain\nf 1 2 3\n",
        ),
    );
    let s = scene::load(&p).unwrap();
    assert_eq!(s.opaque, [true, true, false, false, false, false, true]);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn obj_missing_mtl_is_a_warning() {
    let s = obj("mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glass\nf 1 2 3\n");
    assert_eq!(s.opaque, [true]);
    assert!(
        s.warnings.iter().any(|w| w.contains("nowhere.mtl")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn obj_errors_name_the_file_and_line() {
    let e = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    assert!(
        e.contains("scene.obj:4:") && e.contains("out of range"),
        "{e}"
    );
    let e = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf -4 1 2\n");
    assert!(
        e.contains("scene.obj:5:") && e.contains("out of range"),
        "{e}"
    );
    let e = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    assert!(e.contains("scene.obj:4:"), "{e}");
    let e = obj_err("v 0 0 0\nv 1 x 0\n");
    assert!(
        e.contains("scene.obj:2:") && e.contains("malformed number"),
        "{e}"
    );
    let e = obj_err("v 0 0 0\nv 1 0\n");
    assert!(e.contains("scene.obj:2:"), "{e}");
    let e = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2/a 3\n");
    assert!(e.contains("scene.obj:4:") && e.contains("2/a"), "{e}");
    let e = obj_err("v 0 0 0\nv 1 0 0\nf 1 2\n");
    assert!(e.contains("scene.obj:3:"), "{e}");
}

#[test]
fn obj_nan_infinite_and_empty_scenes_are_errors() {
    for bad in [
        "nan",
        "NaN",
        "inf",
        "-infinity",
        "1.#QNAN",
        "-1.#IND",
        "1e39",
    ] {
        let e = obj_err(&format!("v 0 0 0\nv 1 {bad} 0\nv 0 1 0\nf 1 2 3\n"));
        assert!(
            e.contains("scene.obj") && e.contains("NaN or infinite"),
            "{bad}: {e}"
        );
    }
    let e = obj_err("v 0 0 0\nv 1 0 0\nv 0 1 0\ng lonely\n");
    assert!(e.contains("scene.obj") && e.contains("no triangles"), "{e}");
    let e = obj_err("");
    assert!(e.contains("no triangles"), "{e}");
}

#[test]
fn missing_file_and_unknown_extension() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["gone.obj", "gone.gltf", "gone.glb"] {
        let e = scene::load(&dir.path().join(name)).unwrap_err();
        assert!(matches!(e, SceneError::Io { .. }), "{e:?}");
        assert!(e.to_string().contains(name), "{e}");
    }
    let p = write(dir.path(), "mesh.ply", "ply\n");
    let e = scene::load(&p).unwrap_err();
    assert!(matches!(e, SceneError::UnknownFormat { .. }));
    assert!(e.to_string().contains("mesh.ply"), "{e}");
    let e = scene::load(&dir.path().join("noext")).unwrap_err();
    assert!(matches!(e, SceneError::UnknownFormat { .. }));
}

#[test]
fn obj_extension_case_crlf_and_bom() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "UP.OBJ",
        "o a\r\nv 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",
    );
    let s = scene::load(&p).unwrap();
    assert_eq!(names(&s), ["a"]);
    // A byte-order mark does not hide the first statement.
    let p = write(
        dir.path(),
        "bom.obj",
        "\u{FEFF}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    assert_eq!(scene::load(&p).unwrap().vertices.len(), 3);
}

// ---------------------------------------------------------------------------------------
// Closed detection

#[test]
fn closed_cube_and_broken_variants() {
    let cube = cube_tris(Vec3::ZERO, Vec3::ONE);
    assert!(closed::is_closed(&cube));
    assert!(
        !closed::is_closed(&cube[1..]),
        "a missing triangle opens it"
    );
    assert!(!closed::is_closed(&cube[2..]), "a missing face opens it");
    let mut flipped = cube.clone();
    flipped[5].swap(0, 1);
    assert!(
        !closed::is_closed(&flipped),
        "a flipped triangle breaks orientation"
    );
    // Two cubes sharing an edge: that edge is used by four triangles.
    let mut two = cube.clone();
    two.extend(cube_tris(
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(2.0, 2.0, 1.0),
    ));
    assert!(!closed::is_closed(&two));
    // Two disjoint cubes are closed surfaces.
    let mut apart = cube.clone();
    apart.extend(cube_tris(Vec3::splat(3.0), Vec3::splat(4.0)));
    assert!(closed::is_closed(&apart));
    // Degenerate triangles are ignored; unshared vertices with equal positions are welded.
    let mut with_degenerate = cube.clone();
    with_degenerate.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
    assert!(closed::is_closed(&with_degenerate));
    // A double-covered triangle is not a 2-manifold.
    let mut doubled = cube.clone();
    doubled.push(cube[0]);
    doubled.push([cube[0][0], cube[0][2], cube[0][1]]);
    assert!(!closed::is_closed(&doubled));
}

#[test]
fn closed_flags_per_object_after_load() {
    let mut text = String::new();
    text += "o cube\n";
    text += &cube_obj(Vec3::ZERO, Vec3::ONE, 0);
    text += "o open\n";
    let open = cube_obj(Vec3::splat(2.0), Vec3::splat(3.0), 8);
    // Drop the last face (two triangles).
    let lines: Vec<&str> = open.lines().collect();
    text += &lines[..lines.len() - 2].join("\n");
    text += "\no pair\n";
    text += &cube_obj(Vec3::ZERO, Vec3::ONE, 16);
    text += &cube_obj(Vec3::new(1.0, 1.0, 0.0), Vec3::new(2.0, 2.0, 1.0), 24);
    text += "o flipped\n";
    let flipped = cube_obj(Vec3::splat(5.0), Vec3::splat(6.0), 32);
    text += &flipped.replacen("f 33 35 36", "f 33 36 35", 1);
    // Unshared vertices (every triangle its own corners) weld into a closed cube.
    text += "o soup\n";
    let mut n = 40;
    for t in cube_tris(Vec3::splat(-2.0), Vec3::splat(-1.0)) {
        for p in t {
            text += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
        text += &format!("f {} {} {}\n", n + 1, n + 2, n + 3);
        n += 3;
    }
    let s = obj(&text);
    assert_eq!(names(&s), ["cube", "open", "pair", "flipped", "soup"]);
    let closed: Vec<bool> = s.objects.iter().map(|o| o.closed).collect();
    assert_eq!(closed, [true, false, false, false, true]);
}

// ---------------------------------------------------------------------------------------
// glTF

/// Builds glTF buffers, views and accessors in one binary blob.
#[derive(Default)]
struct Gl {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Gl {
    fn view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    fn accessor(&mut self, a: Value) -> usize {
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn positions(&mut self, ps: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = ps.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in ps {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        self.accessor(
            json!({"bufferView": view, "componentType": 5126, "count": ps.len(),
            "type": "VEC3", "min": lo, "max": hi}),
        )
    }

    fn indices(&mut self, ix: &[u16]) -> usize {
        let bytes: Vec<u8> = ix.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.view(&bytes, None);
        self.accessor(
            json!({"bufferView": view, "componentType": 5123, "count": ix.len(),
            "type": "SCALAR"}),
        )
    }

    /// The document: `rest` holds nodes, meshes, scenes, materials…
    fn document(&self, mut rest: Value, buffer: Value) -> Value {
        rest["asset"] = json!({"version": "2.0"});
        rest["buffers"] = json!([buffer]);
        rest["bufferViews"] = json!(self.views);
        rest["accessors"] = json!(self.accessors);
        rest
    }

    fn embedded(&self, rest: Value) -> String {
        let uri = format!("data:application/octet-stream;base64,{}", base64(&self.bin));
        self.document(rest, json!({"byteLength": self.bin.len(), "uri": uri}))
            .to_string()
    }

    fn glb(&self, rest: Value) -> Vec<u8> {
        let mut js = self
            .document(rest, json!({"byteLength": self.bin.len()}))
            .to_string()
            .into_bytes();
        while !js.len().is_multiple_of(4) {
            js.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + js.len() + 8 + bin.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(js.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
        out.extend_from_slice(&js);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x004E_4942u32.to_le_bytes());
        out.extend_from_slice(&bin);
        out
    }
}

fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

const STRIP: [[f32; 3]; 5] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 2.0, 0.0],
];

/// The hierarchy scene: returns the builder and the JSON without buffers.
fn hierarchy() -> (Gl, Value) {
    let mut g = Gl::default();
    let tri = g.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let tri_ix = g.indices(&[0, 1, 2]);
    let strip = g.positions(&STRIP);
    let pts = g.positions(&[[9.0, 9.0, 9.0]]);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let rest = json!({
        "scene": 1,
        "scenes": [{"nodes": [5]}, {"nodes": [4, 0]}],
        "nodes": [
            {"name": "root", "translation": [10.0, 0.0, 0.0], "children": [1, 2]},
            {"name": "A", "mesh": 0, "rotation": [0.0, 0.0, s, s], "scale": [2.0, 2.0, 2.0],
             "children": [3]},
            {"mesh": 0, "translation": [0.0, 5.0, 0.0]},
            {"name": "C", "mesh": 1},
            {"name": "strips", "mesh": 2},
            {"name": "not in the scene", "mesh": 0}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": tri}, "indices": tri_ix}]},
            {"primitives": [{"attributes": {"POSITION": pts}, "mode": 0}]},
            {"primitives": [
                {"attributes": {"POSITION": strip}, "mode": 5, "material": 0},
                {"attributes": {"POSITION": strip}, "mode": 6, "material": 1},
                {"attributes": {"POSITION": tri}, "indices": tri_ix, "material": 2}
            ]}
        ],
        "materials": [{"alphaMode": "MASK"}, {"alphaMode": "BLEND"}, {"alphaMode": "OPAQUE"}]
    });
    (g, rest)
}

fn check_hierarchy(s: &Scene) {
    // Scene 1 (the `scene` property): node 4, then 0 (no mesh) → 1 → 3, then 2.
    assert_eq!(names(s), ["strips", "A", "C", "node2"]);
    let v = |a: [f32; 3]| Vec3::from_array(a);
    // strips: strip p_i = {v_i, v_{i+1+i%2}, v_{i+2-i%2}}; fan p_i = {v_{i+1}, v_{i+2}, v_0}.
    let strip = object_corners(s, 0);
    assert_eq!(strip.len(), 7);
    let expect_ix = [
        [0, 1, 2],
        [1, 3, 2],
        [2, 3, 4],
        [1, 2, 0],
        [2, 3, 0],
        [3, 4, 0],
    ];
    for (t, ix) in strip.iter().zip(expect_ix) {
        assert_tri_near(*t, ix.map(|i| v(STRIP[i])));
    }
    assert_eq!(
        s.opaque[0..7],
        [false, false, false, false, false, false, true]
    );
    // A: root translation (10,0,0) ∘ rotation 90° about z ∘ scale 2.
    assert_tri_near(
        object_corners(s, 1)[0],
        [
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(10.0, 2.0, 0.0),
            Vec3::new(8.0, 0.0, 0.0),
        ],
    );
    let b = s.objects[1].bounds;
    assert_near(b.min, Vec3::new(8.0, 0.0, 0.0));
    assert_near(b.max, Vec3::new(10.0, 2.0, 0.0));
    // C: a mesh without triangles still gets an id.
    assert_eq!(s.objects[2].triangles.len(), 0);
    assert_eq!(s.objects[2].bounds, Aabb::EMPTY);
    assert!(!s.objects[2].closed);
    // node2: the same mesh as A, another instance.
    assert_tri_near(
        object_corners(s, 3)[0],
        [
            Vec3::new(10.0, 5.0, 0.0),
            Vec3::new(11.0, 5.0, 0.0),
            Vec3::new(10.0, 6.0, 0.0),
        ],
    );
    assert!(s.opaque[7] && s.opaque[8]);
    assert_eq!(s.triangles.len(), 9);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("point"), "{:?}", s.warnings);
}

#[test]
fn gltf_embedded_hierarchy_instancing_modes_materials() {
    let (g, rest) = hierarchy();
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "h.gltf", g.embedded(rest));
    let s = scene::load(&p).unwrap();
    check_hierarchy(&s);
}

#[test]
fn glb_hierarchy_matches_gltf() {
    let (g, rest) = hierarchy();
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "h.glb", g.glb(rest));
    let s = scene::load(&p).unwrap();
    check_hierarchy(&s);
}

#[test]
fn gltf_scene_selection_fallbacks() {
    let (g, mut rest) = hierarchy();
    // No `scene`: scene 0 (node 5 only).
    rest.as_object_mut().unwrap().remove("scene");
    let dir = tempfile::tempdir().unwrap();
    let s = scene::load(&write(dir.path(), "s0.gltf", g.embedded(rest.clone()))).unwrap();
    assert_eq!(names(&s), ["not in the scene"]);
    // No scenes at all: the root nodes (0, 4, 5) in index order.
    rest.as_object_mut().unwrap().remove("scenes");
    let s = scene::load(&write(dir.path(), "roots.gltf", g.embedded(rest))).unwrap();
    assert_eq!(names(&s), ["A", "C", "node2", "strips", "not in the scene"]);
}

#[test]
fn gltf_external_buffer_relative_to_file() {
    let (g, rest) = hierarchy();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    write(&dir.path().join("sub"), "my data.bin", &g.bin);
    let doc = g.document(
        rest.clone(),
        json!({"byteLength": g.bin.len(), "uri": "my%20data.bin"}),
    );
    let p = write(&dir.path().join("sub"), "ext.gltf", doc.to_string());
    check_hierarchy(&scene::load(&p).unwrap());

    let doc = g.document(
        rest,
        json!({"byteLength": g.bin.len(), "uri": "missing.bin"}),
    );
    let p = write(dir.path(), "broken.gltf", doc.to_string());
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("broken.gltf") && e.contains("missing.bin"),
        "{e}"
    );
}

#[test]
fn gltf_draco_is_refused_and_meshopt_is_read() {
    let (g, rest) = hierarchy();
    let dir = tempfile::tempdir().unwrap();
    let ext = "KHR_draco_mesh_compression";
    let mut r = rest.clone();
    r["extensionsUsed"] = json!([ext]);
    r["extensionsRequired"] = json!([ext]);
    let p = write(dir.path(), "c.gltf", g.embedded(r.clone()));
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("c.gltf") && e.contains(ext), "{e}");
    let p = write(dir.path(), "c.glb", g.glb(r));
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("c.glb") && e.contains(ext), "{e}");
    // Meshopt is decoded (`scene::meshopt`; the real palm in tests/alpha_cards.rs): a file
    // requiring it loads, with the same objects as without it.
    let plain = scene::load(&write(dir.path(), "p.gltf", g.embedded(rest.clone()))).unwrap();
    for ext in ["EXT_meshopt_compression", "KHR_meshopt_compression"] {
        let mut r = rest.clone();
        r["extensionsUsed"] = json!([ext]);
        r["extensionsRequired"] = json!([ext]);
        let s =
            scene::load(&write(dir.path(), "m.glb", g.glb(r))).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.triangles.len(), plain.triangles.len());
        assert_eq!(s.objects.len(), plain.objects.len());
    }
}

#[test]
fn gltf_mirrored_node_keeps_winding_and_instancing_extension() {
    let mut g = Gl::default();
    let tri = g.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let t = g.positions(&[[0.0, 0.0, 0.0], [0.0, 0.0, 10.0], [0.0, 0.0, 20.0]]);
    let rest = json!({
        "extensionsUsed": ["EXT_mesh_gpu_instancing"],
        "nodes": [
            {"name": "mirror", "mesh": 0, "scale": [-1.0, 1.0, 1.0]},
            {"name": "many", "mesh": 0, "translation": [0.0, 5.0, 0.0],
             "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": t}}}}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": tri}}]}]
    });
    let dir = tempfile::tempdir().unwrap();
    let s = scene::load(&write(dir.path(), "m.gltf", g.embedded(rest))).unwrap();
    assert_eq!(names(&s), ["mirror", "many"]);
    let [a, b, c] = object_corners(&s, 0)[0];
    assert!((b - a).cross(c - a).z > 0.0, "front face still faces +z");
    let many = object_corners(&s, 1);
    assert_eq!(many.len(), 3);
    for (k, t) in many.iter().enumerate() {
        assert_near(t[0], Vec3::new(0.0, 5.0, 10.0 * k as f32));
    }
}

#[test]
fn gltf_sparse_and_quantized_positions() {
    let mut g = Gl::default();
    // Float positions with a sparse override of vertex 2.
    let base = g.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let iv = g.view(&[2u8], None);
    let vv = g.view(&[0.0f32, 0.0, 7.0].map(f32::to_le_bytes).concat(), None);
    g.accessors[base]["sparse"] = json!({"count": 1,
        "indices": {"bufferView": iv, "componentType": 5121},
        "values": {"bufferView": vv}});
    // Signed bytes, padded to a 4-byte stride (KHR_mesh_quantization).
    let bytes: Vec<u8> = [[0i8, 0, 0, 0], [3, 0, 0, 0], [0, 3, 0, 0]]
        .iter()
        .flatten()
        .map(|&b| b as u8)
        .collect();
    let qv = g.view(&bytes, Some(4));
    let q = g.accessor(
        json!({"bufferView": qv, "componentType": 5120, "count": 3, "type": "VEC3",
        "min": [0, 0, 0], "max": [3, 3, 0]}),
    );
    // Normalized unsigned shorts.
    let bytes: Vec<u8> = [[0u16, 0, 0, 0], [65535, 0, 0, 0], [0, 65535, 0, 0]]
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let nv = g.view(&bytes, Some(8));
    let n = g.accessor(
        json!({"bufferView": nv, "componentType": 5123, "normalized": true,
        "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [65535, 65535, 0]}),
    );
    let rest = json!({
        "extensionsUsed": ["KHR_mesh_quantization"],
        "extensionsRequired": ["KHR_mesh_quantization"],
        "nodes": [{"name": "sparse", "mesh": 0}, {"name": "bytes", "mesh": 1},
                  {"name": "norm", "mesh": 2}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": base}}]},
                   {"primitives": [{"attributes": {"POSITION": q}}]},
                   {"primitives": [{"attributes": {"POSITION": n}}]}]
    });
    let dir = tempfile::tempdir().unwrap();
    let s = scene::load(&write(dir.path(), "q.glb", g.glb(rest))).unwrap();
    assert_tri_near(
        object_corners(&s, 0)[0],
        [Vec3::ZERO, Vec3::X, Vec3::new(0.0, 0.0, 7.0)],
    );
    assert_tri_near(
        object_corners(&s, 1)[0],
        [Vec3::ZERO, Vec3::X * 3.0, Vec3::Y * 3.0],
    );
    assert_tri_near(object_corners(&s, 2)[0], [Vec3::ZERO, Vec3::X, Vec3::Y]);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn gltf_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "junk.gltf", "{ not json");
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("junk.gltf"), "{e}");
    let p = write(dir.path(), "junk.glb", b"glTF\x02\x00\x00\x00");
    let e = scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("junk.glb"), "{e}");

    // Index out of range.
    let mut g = Gl::default();
    let tri = g.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let ix = g.indices(&[0, 1, 3]);
    let rest = json!({"nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": tri}, "indices": ix}]}]});
    let e = scene::load(&write(dir.path(), "ix.gltf", g.embedded(rest))).unwrap_err();
    assert!(
        e.to_string().contains("ix.gltf") && e.to_string().contains("out of range"),
        "{e}"
    );

    // A cycle in the hierarchy.
    let rest = json!({"scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "children": [1]}, {"children": [0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": tri}}]}]});
    let e = scene::load(&write(dir.path(), "cyc.gltf", g.embedded(rest))).unwrap_err();
    assert!(
        e.to_string().contains("cyc.gltf") && e.to_string().contains("cycle"),
        "{e}"
    );

    // NaN positions, and a scene with no triangles at all.
    let mut g = Gl::default();
    let bad = g.positions(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let pts = g.positions(&[[0.0, 0.0, 0.0]]);
    let rest = json!({"nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": bad}}]}]});
    let e = scene::load(&write(dir.path(), "nan.glb", g.glb(rest))).unwrap_err();
    assert!(
        e.to_string().contains("nan.glb") && e.to_string().contains("NaN"),
        "{e}"
    );
    let rest = json!({"nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": pts}, "mode": 0}]}]});
    let e = scene::load(&write(dir.path(), "empty.glb", g.glb(rest))).unwrap_err();
    assert!(
        e.to_string().contains("empty.glb") && e.to_string().contains("no triangles"),
        "{e}"
    );
}

#[test]
fn gltf_closed_cube_from_unindexed_triangles() {
    let mut g = Gl::default();
    let ps: Vec<[f32; 3]> = cube_tris(Vec3::ZERO, Vec3::ONE)
        .iter()
        .flatten()
        .map(|p| p.to_array())
        .collect();
    let cube = g.positions(&ps);
    let open = g.positions(&ps[6..]);
    let rest = json!({"nodes": [{"name": "cube", "mesh": 0}, {"name": "open", "mesh": 1},
            {"name": "mirrored", "mesh": 0, "scale": [1.0, -1.0, 1.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": cube}}]},
                   {"primitives": [{"attributes": {"POSITION": open}}]}]});
    let dir = tempfile::tempdir().unwrap();
    let s = scene::load(&write(dir.path(), "cube.glb", g.glb(rest))).unwrap();
    let closed: Vec<bool> = s.objects.iter().map(|o| o.closed).collect();
    assert_eq!(closed, [true, false, true]);
}

// ---------------------------------------------------------------------------------------
// Real scenes

fn load_timed(path: &Path) -> Scene {
    let t = Instant::now();
    let s = scene::load(path).unwrap_or_else(|e| panic!("{e}"));
    eprintln!(
        "{}: {} objects, {} triangles, {} closed, {} non-opaque, loaded in {:.1?}",
        path.display(),
        s.objects.len(),
        s.triangles.len(),
        s.objects.iter().filter(|o| o.closed).count(),
        s.opaque.iter().filter(|&&o| !o).count(),
        t.elapsed()
    );
    s
}

#[test]
fn real_scene_munich() {
    let Some(dir) = shared_scenes() else { return };
    let s = load_timed(&dir.join("urban/sionna_munich.glb"));
    assert_eq!(s.objects.len(), 1189);
    assert_eq!(s.triangles.len(), 38_936);
    // A flat scene: ids follow the scene's node list, the ground comes last.
    assert_eq!(s.objects[0].name, "Heilig_Geist");
    assert_eq!(s.objects[1188].name, "ground");
    let b = s.bounds();
    assert!(
        (b.min - Vec3::new(-805.584, 0.0, -517.035))
            .abs()
            .max_element()
            < 0.01,
        "{b:?}"
    );
    assert!(
        (b.max - Vec3::new(669.883, 98.570, 688.601))
            .abs()
            .max_element()
            < 0.01,
        "{b:?}"
    );
}

#[test]
fn real_scene_pandora() {
    let Some(dir) = shared_scenes() else { return };
    let s = load_timed(&dir.join("levels/pandora.obj"));
    assert_eq!(s.objects.len(), 206);
    assert_eq!(s.triangles.len(), 60_810);
    assert_eq!(s.objects[0].name, "slot2");
    let b = s.bounds();
    assert_eq!(
        b,
        Aabb::new(
            Vec3::new(-736.0, 0.0, -416.0),
            Vec3::new(736.0, 448.0, 416.0)
        )
    );
}

#[test]
fn real_scene_jacaranda() {
    let Some(dir) = shared_scenes() else { return };
    let s = load_timed(&dir.join("foliage/jacaranda_tree.glb"));
    assert_eq!(s.objects.len(), 1);
    assert_eq!(s.triangles.len(), 54_953);
    // The file's leaf material has no `alphaMode` (SOURCES.md: MASK kept only "where the
    // source had it"), so by the glTF default every triangle is opaque.
    assert!(s.opaque.iter().all(|&o| o));
}

#[test]
fn real_scene_poinciana_leaves_are_not_opaque() {
    let Some(dir) = shared_scenes() else { return };
    let s = load_timed(&dir.join("foliage/tree_poinciana.glb"));
    assert_eq!(s.objects.len(), 6);
    assert_eq!(s.triangles.len(), 54_512);
    let non_opaque = s.opaque.iter().filter(|&&o| !o).count();
    assert!(
        non_opaque > 0 && non_opaque < s.triangles.len(),
        "{non_opaque}"
    );
    // Opacity is per primitive: a whole object (the foliage node) is non-opaque.
    assert!(s.objects.iter().any(|o| {
        let r = o.triangles.start as usize..o.triangles.end as usize;
        !r.is_empty() && s.opaque[r].iter().all(|&x| !x)
    }));
}

/// File, triangles, objects, bounds min, bounds max.
type Row = (&'static str, usize, usize, [f32; 3], [f32; 3]);

/// Every shared scene against the counts and bounds of `SOURCES.md`.
#[test]
fn real_scenes_match_sources_table() {
    let Some(dir) = shared_scenes() else { return };
    #[rustfmt::skip]
    let table: [Row; 12] = [
        ("foliage/tree_poinciana.glb", 54_512, 6, [-4.548, 0.000, -3.964], [4.496, 4.262, 4.154]),
        ("foliage/tree_orchid.glb", 31_004, 4, [-3.603, 0.000, -3.653], [3.615, 5.159, 3.650]),
        ("foliage/jacaranda_tree.glb", 54_953, 1, [-12.721, -0.146, -9.943], [11.222, 19.179, 8.909]),
        ("foliage/island_tree_02.glb", 38_364, 1, [-2.052, 0.032, -1.114], [2.155, 3.389, 2.957]),
        ("foliage/pachira_aquatica_01.glb", 11_322, 8, [-2.309, -0.018, -0.591], [4.557, 1.886, 0.406]),
        ("foliage/palm_coconut.glb", 6_630, 5, [-3.572, 0.000, -2.047], [2.725, 6.284, 1.976]),
        ("foliage/fern_02.glb", 6_232, 4, [-0.528, -0.031, -0.422], [1.444, 0.397, 1.302]),
        ("urban/sionna_munich.glb", 38_936, 1189, [-805.584, 0.000, -517.035], [669.883, 98.570, 688.601]),
        ("urban/sionna_san_francisco.glb", 268_041, 2368, [-508.155, 0.000, -459.661], [713.548, 170.628, 468.032]),
        ("urban/sionna_etoile.glb", 13_098, 281, [-426.831, 0.000, -338.060], [426.831, 50.000, 338.060]),
        ("levels/pandora.obj", 60_810, 206, [-736.0, 0.0, -416.0], [736.0, 448.0, 416.0]),
        ("levels/zdm2.obj", 70_754, 84, [-434.0, 0.0, -304.0], [434.0, 324.0, 304.0]),
    ];
    for (file, tris, objects, lo, hi) in table {
        let s = load_timed(&dir.join(file));
        assert_eq!(s.triangles.len(), tris, "{file}");
        assert_eq!(s.objects.len(), objects, "{file}");
        let b = s.bounds();
        let tol = 1e-3 * (1.0 + b.size().max_element());
        assert!(
            (b.min - Vec3::from(lo)).abs().max_element() < tol,
            "{file}: {b:?}"
        );
        assert!(
            (b.max - Vec3::from(hi)).abs().max_element() < tol,
            "{file}: {b:?}"
        );
    }
}
