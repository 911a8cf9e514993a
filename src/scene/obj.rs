//! Wavefront OBJ import (with MTL opacity): owns the OBJ object-numbering contract.
//!
//! # Objects
//! `o NAME` and `g NAME` both set the current name: the rest of the line, trimmed, runs of
//! white space collapsed to one space; no name means `default`. Faces before any `o`/`g`
//! belong to `default` (they count as a `default` statement at that point). An object is a
//! name that owns at least one face; faces under a name seen before join that object. Ids
//! are 0, 1, 2… in the order of the first statement naming each object; a name that never
//! owns a face gets no id.
//!
//! # Geometry
//! `v x y z [w …]` (extra values such as vertex colours are ignored; `w` is ignored) and
//! `f a b c …` with any slash form (`v`, `v/vt`, `v/vt/vn`, `v//vn`); negative indices count
//! back from the last vertex defined. Polygons are fan-triangulated (`a b c`, `a c d`, …).
//! `vt`, `vn`, `s` and other statements are ignored; `l` and `p` lines are skipped with one
//! warning per kind. Triangles are regrouped by object in id order.
//!
//! # Materials
//! `mtllib` files are read relative to the OBJ file (a missing one is a warning, its
//! materials count as opaque); `usemtl` selects the material of the following faces. A
//! material is not opaque when it has `d` < 1, `Tr` > 0 or a `map_d`; a value that cannot be
//! read makes it non-opaque too (with a warning), which is the conservative choice.

use super::{Scene, SceneError, SceneObject};
use crate::geom::Aabb;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// No material selected (`usemtl` not seen yet): opaque.
const NO_MATERIAL: u32 = u32::MAX;

/// Loads an OBJ file (and its `mtllib` files) into a [`Scene`].
///
/// The scene is not validated here; [`super::load`] does that.
///
/// # Errors
/// [`SceneError::Io`] when the file cannot be read; [`SceneError::Parse`] with the line for
/// malformed statements (bad number, index 0 or out of range, face with fewer than three
/// vertices, NaN or infinite coordinate).
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, path)
}

/// Parses OBJ text; `path` names the file in messages and anchors relative `mtllib` paths.
///
/// # Errors
/// As [`load`], except for reading the OBJ file itself.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    parse_in_chunks(bytes, path, CHUNK_BYTES)
}

/// [`parse`] in chunks of about `chunk_bytes` (whole lines; tests cut small files finely).
fn parse_in_chunks(bytes: &[u8], path: &Path, chunk_bytes: usize) -> Result<Scene, SceneError> {
    let mut p = Parser::new(path);
    p.run(bytes, chunk_bytes)?;
    Ok(p.finish())
}

/// A run of consecutive triangles (in file order) with the same name slot and material.
#[derive(Clone, Copy)]
struct Run {
    start: u32,
    slot: u32,
    material: u32,
}

struct Parser<'p> {
    path: &'p Path,
    vertices: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    runs: Vec<Run>,
    /// Name → slot; slots are created in the order of the first statement naming them.
    slots: HashMap<String, u32>,
    slot_names: Vec<String>,
    /// The current name slot; `None` before any `o`/`g`.
    current_slot: Option<u32>,
    /// `usemtl` names → material index (interned in order of first use).
    material_ids: HashMap<String, u32>,
    material_names: Vec<String>,
    current_material: u32,
    /// Opacity of materials defined by the `mtllib` files, by name.
    mtl_opaque: HashMap<String, bool>,
    warnings: Vec<String>,
    lines_skipped: usize,
    points_skipped: usize,
    /// Scratch: the name being built.
    name_buf: String,
}

/// A parse error on the current line (the line number is filled in by the caller).
type LineResult<T> = Result<T, String>;

impl<'p> Parser<'p> {
    fn new(path: &'p Path) -> Self {
        Parser {
            path,
            vertices: Vec::new(),
            triangles: Vec::new(),
            runs: Vec::new(),
            slots: HashMap::new(),
            slot_names: Vec::new(),
            current_slot: None,
            material_ids: HashMap::new(),
            material_names: Vec::new(),
            current_material: NO_MATERIAL,
            mtl_opaque: HashMap::new(),
            warnings: Vec::new(),
            lines_skipped: 0,
            points_skipped: 0,
            name_buf: String::new(),
        }
    }

    /// Parses the file in chunks of whole lines, side by side ([`Chunk::parse`]: vertices,
    /// faces, and the statements that change the name or material), then replays the
    /// chunks' statements in file order: the same scene, warnings and first error as a
    /// parse line by line. (Loading the paper-size forest's 836 MB took 3.6 s with the parse
    /// on one thread, 2.6 s with chunks on two cores.)
    fn run(&mut self, bytes: &[u8], chunk_bytes: usize) -> Result<(), SceneError> {
        // Skip a UTF-8 byte-order mark, which would otherwise hide the first statement.
        let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        let chunks = split_lines(body, chunk_bytes.max(1));
        // Where each chunk starts: its first line's number and the vertices defined before.
        let counts: Vec<(usize, u64)> = chunks.par_iter().map(|c| count_lines(c)).collect();
        let mut starts = Vec::with_capacity(chunks.len());
        let (mut line, mut verts) = (0usize, 0u64);
        for &(l, v) in &counts {
            starts.push((line, verts));
            line += l;
            verts += v;
        }
        let parsed: Vec<Chunk> = chunks
            .par_iter()
            .zip(&starts)
            .map(|(c, &(_, v))| Chunk::parse(c, v, 0))
            .collect();
        let error = |line0: usize, (line, message): (usize, String)| SceneError::Parse {
            path: self.path.to_path_buf(),
            line: line0 + line,
            message,
        };
        if let Some((k, e)) = parsed
            .iter()
            .enumerate()
            .find_map(|(k, c)| c.error.clone().map(|e| (k, e)))
        {
            return Err(error(starts[k].0, e));
        }
        self.vertices.reserve_exact(verts as usize);
        let tris: usize = parsed.iter().map(|c| c.triangles.len()).sum();
        self.triangles.reserve_exact(tris);
        for (k, chunk) in parsed.into_iter().enumerate() {
            let base = self.triangles.len();
            if base + chunk.triangles.len() > u32::MAX as usize {
                // Parsed again knowing where its triangles start, for the face's line.
                let again = Chunk::parse(chunks[k], starts[k].1, base as u64);
                let e = again.error.expect("the chunk's triangles pass 2^32");
                return Err(error(starts[k].0, e));
            }
            let mut at = 0;
            for (next, statement) in chunk.statements {
                self.faces(base + at, next as usize - at);
                at = next as usize;
                match statement {
                    Statement::Name(name) => {
                        self.name_buf = name;
                        let slot = self.slot_of_name_buf();
                        self.current_slot = Some(slot);
                    }
                    Statement::Material(name) => {
                        self.current_material = match self.material_ids.get(name.as_str()) {
                            Some(&m) => m,
                            None => {
                                let m = self.material_names.len() as u32;
                                self.material_names.push(name.clone());
                                self.material_ids.insert(name, m);
                                m
                            }
                        };
                    }
                    Statement::MtlLib(rest) => self.mtllib(&rest),
                }
            }
            self.faces(base + at, chunk.triangles.len() - at);
            self.vertices.extend_from_slice(&chunk.vertices);
            self.triangles.extend_from_slice(&chunk.triangles);
            self.lines_skipped += chunk.lines_skipped;
            self.points_skipped += chunk.points_skipped;
        }
        Ok(())
    }

    /// The triangles `start..start + count` (in file order) come from faces under the
    /// current name and material: a new run where those changed.
    fn faces(&mut self, start: usize, count: usize) {
        if count == 0 {
            return;
        }
        let slot = match self.current_slot {
            Some(s) => s,
            None => {
                // Faces before any o/g: an implicit `default` statement here.
                self.name_buf.clear();
                self.name_buf.push_str("default");
                let s = self.slot_of_name_buf();
                self.current_slot = Some(s);
                s
            }
        };
        match self.runs.last() {
            Some(r) if r.slot == slot && r.material == self.current_material => {}
            _ => self.runs.push(Run {
                start: start as u32,
                slot,
                material: self.current_material,
            }),
        }
    }

    /// The slot of the name in `name_buf`, created on first use.
    fn slot_of_name_buf(&mut self) -> u32 {
        if let Some(&s) = self.slots.get(self.name_buf.as_str()) {
            return s;
        }
        let s = self.slot_names.len() as u32;
        self.slot_names.push(self.name_buf.clone());
        self.slots.insert(self.name_buf.clone(), s);
        s
    }

    fn mtllib(&mut self, rest: &[u8]) {
        let rest = String::from_utf8_lossy(rest);
        let rest = rest.trim();
        if rest.is_empty() {
            return;
        }
        let dir = self.path.parent().unwrap_or(Path::new(""));
        // A file name may contain spaces: try the whole rest first, then each word.
        let whole = dir.join(rest);
        let files: Vec<PathBuf> = if whole.is_file() {
            vec![whole]
        } else {
            rest.split_whitespace().map(|f| dir.join(f)).collect()
        };
        for f in files {
            match std::fs::read(&f) {
                Ok(bytes) => parse_mtl(&bytes, &f, &mut self.mtl_opaque, &mut self.warnings),
                Err(e) => self.warnings.push(format!(
                    "{}: mtllib {}: cannot read ({e}); its materials count as opaque",
                    self.path.display(),
                    f.display()
                )),
            }
        }
    }

    fn finish(mut self) -> Scene {
        let path = self.path;
        if self.lines_skipped > 0 {
            self.warnings.push(format!(
                "{}: skipped {} line statement(s) (`l`)",
                path.display(),
                self.lines_skipped
            ));
        }
        if self.points_skipped > 0 {
            self.warnings.push(format!(
                "{}: skipped {} point statement(s) (`p`)",
                path.display(),
                self.points_skipped
            ));
        }

        // Material opacity by material index.
        let mut undefined = Vec::new();
        let material_opaque: Vec<bool> = self
            .material_names
            .iter()
            .map(|m| match self.mtl_opaque.get(m) {
                Some(&o) => o,
                None => {
                    undefined.push(m.as_str());
                    true
                }
            })
            .collect();
        if !undefined.is_empty() {
            let shown: Vec<&str> = undefined.iter().take(5).copied().collect();
            self.warnings.push(format!(
                "{}: {} material(s) used but not defined, treated as opaque: {}{}",
                path.display(),
                undefined.len(),
                shown.join(", "),
                if undefined.len() > 5 { ", …" } else { "" }
            ));
        }
        let opaque_of = |m: u32| m == NO_MATERIAL || material_opaque[m as usize];

        // Triangle counts per slot, then ids for the slots owning faces, in slot order.
        let ntri = self.triangles.len() as u32;
        let run_end = |i: usize, runs: &[Run]| runs.get(i + 1).map_or(ntri, |r| r.start);
        let mut slot_count = vec![0u32; self.slot_names.len()];
        for (i, r) in self.runs.iter().enumerate() {
            slot_count[r.slot as usize] += run_end(i, &self.runs) - r.start;
        }
        let mut slot_id = vec![u32::MAX; self.slot_names.len()];
        let mut id_slot = Vec::new();
        for (s, &c) in slot_count.iter().enumerate() {
            if c > 0 {
                slot_id[s] = id_slot.len() as u32;
                id_slot.push(s);
            }
        }

        // Regroup triangles by id unless the file already has them in that order.
        let in_order = self
            .runs
            .windows(2)
            .all(|w| slot_id[w[0].slot as usize] <= slot_id[w[1].slot as usize]);
        let mut opaque = Vec::with_capacity(self.triangles.len());
        let triangles = if in_order {
            for (i, r) in self.runs.iter().enumerate() {
                let len = (run_end(i, &self.runs) - r.start) as usize;
                opaque.extend(std::iter::repeat_n(opaque_of(r.material), len));
            }
            std::mem::take(&mut self.triangles)
        } else {
            let mut by_id: Vec<Vec<usize>> = vec![Vec::new(); id_slot.len()];
            for (i, r) in self.runs.iter().enumerate() {
                by_id[slot_id[r.slot as usize] as usize].push(i);
            }
            let mut out = Vec::with_capacity(self.triangles.len());
            for runs in &by_id {
                for &i in runs {
                    let r = self.runs[i];
                    let end = run_end(i, &self.runs);
                    out.extend_from_slice(&self.triangles[r.start as usize..end as usize]);
                    opaque.extend(std::iter::repeat_n(
                        opaque_of(r.material),
                        (end - r.start) as usize,
                    ));
                }
            }
            out
        };

        let mut start = 0u32;
        let mut objects: Vec<SceneObject> = id_slot
            .iter()
            .map(|&s| {
                let end = start + slot_count[s];
                let o = SceneObject {
                    name: std::mem::take(&mut self.slot_names[s]),
                    triangles: start..end,
                    bounds: Aabb::EMPTY,
                    closed: false,
                };
                start = end;
                o
            })
            .collect();
        let vertices = self.vertices;
        objects.par_iter_mut().for_each(|o| {
            let mut b = Aabb::EMPTY;
            for t in &triangles[o.triangles.start as usize..o.triangles.end as usize] {
                for &i in t {
                    b.grow(vertices[i as usize]);
                }
            }
            o.bounds = b;
        });

        Scene {
            source: path.to_path_buf(),
            vertices,
            triangles,
            opaque,
            objects,
            warnings: self.warnings,
            alpha: None,
            split: None,
        }
    }
}

/// Bytes per chunk of a parse (a chunk ends at the end of a line): small files are one chunk.
const CHUNK_BYTES: usize = 4 << 20;

/// `bytes` cut into chunks of whole lines, each about `size` bytes or more (the last less).
fn split_lines(bytes: &[u8], size: usize) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < bytes.len() {
        let end = if bytes.len() - pos <= size {
            bytes.len()
        } else {
            (find_newline(bytes, pos + size) + 1).min(bytes.len())
        };
        out.push(&bytes[pos..end]);
        pos = end;
    }
    out
}

/// The lines of a chunk and its vertex statements (`v`, well formed or not).
fn count_lines(chunk: &[u8]) -> (usize, u64) {
    let (mut lines, mut verts) = (0usize, 0u64);
    for line in lines_of(chunk) {
        lines += 1;
        if (Tokens { s: line, i: 0 }).next() == Some(b"v".as_slice()) {
            verts += 1;
        }
    }
    (lines, verts)
}

/// The lines of `bytes` without their `\n` (a last line without one included, no empty line
/// after a final `\n`).
fn lines_of(bytes: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut pos = 0;
    std::iter::from_fn(move || {
        (pos < bytes.len()).then(|| {
            let end = find_newline(bytes, pos);
            let line = &bytes[pos..end];
            pos = end + 1;
            line
        })
    })
}

/// A statement of a chunk that the replay applies in order ([`Parser::run`]).
enum Statement {
    /// `o`/`g`: the collapsed name.
    Name(String),
    /// `usemtl`: the collapsed material name.
    Material(String),
    /// `mtllib`: the rest of the line.
    MtlLib(Vec<u8>),
}

/// One chunk of lines, parsed on its own.
#[derive(Default)]
struct Chunk {
    vertices: Vec<Vec3>,
    /// Fan-triangulated faces, with the file's vertex numbering.
    triangles: Vec<[u32; 3]>,
    /// Name and material statements, each after the chunk's triangles before it.
    statements: Vec<(u32, Statement)>,
    lines_skipped: usize,
    points_skipped: usize,
    /// The first malformed statement: its line within the chunk (from 1) and the message.
    /// The chunk stops there.
    error: Option<(usize, String)>,
    /// Scratch: a face's corners.
    corners: Vec<u32>,
}

impl Chunk {
    /// Parses `chunk`, whose first vertex is the file's `first_vertex`-th and whose first
    /// triangle is `first_triangle`-th (known only on the rare second parse that looks for
    /// the face passing 2^32 triangles; 0 first).
    fn parse(chunk: &[u8], first_vertex: u64, first_triangle: u64) -> Chunk {
        let mut c = Chunk::default();
        for (k, line) in lines_of(chunk).enumerate() {
            if let Err(message) = c.line(line, first_vertex, first_triangle) {
                c.error = Some((k + 1, message));
                break;
            }
        }
        c
    }

    fn line(&mut self, line: &[u8], first_vertex: u64, first_triangle: u64) -> LineResult<()> {
        let mut t = Tokens { s: line, i: 0 };
        let Some(key) = t.next() else {
            return Ok(());
        };
        let at = self.triangles.len() as u32;
        let name = || {
            let mut n = String::new();
            collapse_name(t.rest(), &mut n);
            n
        };
        match key {
            b"v" => return self.vertex(&mut t, first_vertex),
            b"f" => return self.face(&mut t, first_vertex, first_triangle),
            b"o" | b"g" => self.statements.push((at, Statement::Name(name()))),
            b"usemtl" => self.statements.push((at, Statement::Material(name()))),
            b"mtllib" => self
                .statements
                .push((at, Statement::MtlLib(t.rest().to_vec()))),
            b"l" => self.lines_skipped += 1,
            b"p" => self.points_skipped += 1,
            // vt, vn, vp, s, comments, curves and anything else: bookkeeping we do not need.
            _ => {}
        }
        Ok(())
    }

    fn vertex(&mut self, t: &mut Tokens, first_vertex: u64) -> LineResult<()> {
        let mut c = [0f32; 3];
        for (k, v) in c.iter_mut().enumerate() {
            let tok = t
                .next()
                .ok_or_else(|| format!("vertex has {k} coordinates, expected 3"))?;
            *v = parse_f32(tok)?;
        }
        let v = Vec3::from_array(c);
        if !v.is_finite() {
            return Err(format!(
                "vertex {} has a NaN or infinite coordinate ({v:?})",
                first_vertex + self.vertices.len() as u64 + 1
            ));
        }
        self.vertices.push(v);
        Ok(())
    }

    fn face(&mut self, t: &mut Tokens, first_vertex: u64, first_triangle: u64) -> LineResult<()> {
        let nv = (first_vertex + self.vertices.len() as u64) as i64;
        self.corners.clear();
        while let Some(tok) = t.next() {
            let raw = parse_index(tok)?;
            let resolved = if raw > 0 {
                raw - 1
            } else if raw < 0 {
                nv + raw
            } else {
                return Err("vertex index 0 (OBJ indices start at 1)".into());
            };
            if resolved < 0 || resolved >= nv {
                return Err(format!(
                    "vertex index {raw} out of range ({nv} vertices defined so far)"
                ));
            }
            self.corners.push(resolved as u32);
        }
        if self.corners.len() < 3 {
            return Err(format!(
                "face with {} vertices (at least 3 expected)",
                self.corners.len()
            ));
        }
        let start = first_triangle + self.triangles.len() as u64;
        if start + self.corners.len() as u64 - 2 > u32::MAX as u64 {
            return Err("more than 2^32 triangles".into());
        }
        let c0 = self.corners[0];
        for w in self.corners[1..].windows(2) {
            self.triangles.push([c0, w[0], w[1]]);
        }
        Ok(())
    }
}

/// Parses an MTL file, recording each material's opacity in `out` (later definitions of a
/// name win). Problems become warnings: materials matter less than geometry.
fn parse_mtl(
    bytes: &[u8],
    path: &Path,
    out: &mut HashMap<String, bool>,
    warnings: &mut Vec<String>,
) {
    let mut current: Option<String> = None;
    let mut name = String::new();
    for (k, line) in lines_of(bytes).enumerate() {
        let line_no = k + 1;
        let mut t = Tokens { s: line, i: 0 };
        let Some(key) = t.next() else { continue };
        if key == b"newmtl" {
            collapse_name(t.rest(), &mut name);
            out.insert(name.clone(), true);
            current = Some(name.clone());
            continue;
        }
        let Some(cur) = current.as_ref() else {
            continue;
        };
        let mut not_opaque = |why: String| {
            if let Some(o) = out.get_mut(cur) {
                *o = false;
            }
            if !why.is_empty() {
                warnings.push(format!("{}:{line_no}: {why}", path.display()));
            }
        };
        if key.eq_ignore_ascii_case(b"d") || key.eq_ignore_ascii_case(b"Tr") {
            // `d -halo 0.5` has an option before the value.
            let mut tok = t.next();
            if tok.is_some_and(|x| x.starts_with(b"-")) && parse_f32(tok.unwrap_or(b"")).is_err() {
                tok = t.next();
            }
            let is_d = key.eq_ignore_ascii_case(b"d");
            match tok.map(parse_f32) {
                Some(Ok(v)) => {
                    let transparent = v.is_nan() || if is_d { v < 1.0 } else { v > 0.0 };
                    if transparent {
                        not_opaque(String::new());
                    }
                }
                _ => not_opaque(format!(
                    "material {cur}: cannot read the `{}` value; treated as not opaque",
                    String::from_utf8_lossy(key)
                )),
            }
        } else if key.eq_ignore_ascii_case(b"map_d") {
            not_opaque(String::new());
        }
    }
}

/// Index of the next `\n` at or after `from`, or `bytes.len()`.
#[inline]
fn find_newline(bytes: &[u8], from: usize) -> usize {
    // Word-at-a-time search; OBJ lines are short but files are huge.
    let mut i = from;
    let n = bytes.len();
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    const NL: u64 = LO * b'\n' as u64;
    while i + 8 <= n {
        let w = u64::from_le_bytes(bytes[i..i + 8].try_into().unwrap()) ^ NL;
        let z = w.wrapping_sub(LO) & !w & HI;
        if z != 0 {
            return i + (z.trailing_zeros() / 8) as usize;
        }
        i += 8;
    }
    while i < n && bytes[i] != b'\n' {
        i += 1;
    }
    i
}

/// White-space separated tokens of one line; a token starting with `#` ends the line.
struct Tokens<'a> {
    s: &'a [u8],
    i: usize,
}

#[inline]
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c')
}

impl<'a> Tokens<'a> {
    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let s = self.s;
        let mut i = self.i;
        while i < s.len() && is_space(s[i]) {
            i += 1;
        }
        if i >= s.len() || s[i] == b'#' {
            self.i = s.len();
            return None;
        }
        let start = i;
        while i < s.len() && !is_space(s[i]) {
            i += 1;
        }
        self.i = i;
        Some(&s[start..i])
    }

    /// The rest of the line after the current token (untrimmed).
    fn rest(&self) -> &'a [u8] {
        &self.s[self.i..]
    }
}

/// The name rule: trimmed, runs of white space collapsed to one space, `default` if empty.
fn collapse_name(rest: &[u8], out: &mut String) {
    out.clear();
    let text = String::from_utf8_lossy(rest);
    for (k, word) in text.split_whitespace().enumerate() {
        if k > 0 {
            out.push(' ');
        }
        out.push_str(word);
    }
    if out.is_empty() {
        out.push_str("default");
    }
}

/// Parses a coordinate. Accepts what `f32::from_str` accepts (including `nan`, `inf`) and
/// the MSVC spellings `1.#QNAN`, `-1.#IND`, `1.#INF`, so that such values reach the NaN check.
fn parse_f32(tok: &[u8]) -> LineResult<f32> {
    if let Ok(s) = std::str::from_utf8(tok) {
        if let Ok(v) = s.parse::<f32>() {
            return Ok(v);
        }
        let upper = s.to_ascii_uppercase();
        if upper.contains("#QNAN") || upper.contains("#SNAN") || upper.contains("#IND") {
            return Ok(f32::NAN);
        }
        if upper.contains("#INF") {
            return Ok(if s.starts_with('-') {
                f32::NEG_INFINITY
            } else {
                f32::INFINITY
            });
        }
    }
    Err(format!(
        "malformed number `{}`",
        String::from_utf8_lossy(tok)
    ))
}

/// Parses the vertex part of a face corner (`v`, `v/vt`, `v/vt/vn`, `v//vn`).
#[inline]
fn parse_index(tok: &[u8]) -> LineResult<i64> {
    let bad = || format!("malformed face vertex `{}`", String::from_utf8_lossy(tok));
    let mut i = 0;
    let neg = tok.first() == Some(&b'-');
    if neg || tok.first() == Some(&b'+') {
        i = 1;
    }
    let digits_start = i;
    let mut v: i64 = 0;
    while i < tok.len() && tok[i].is_ascii_digit() {
        v = v
            .checked_mul(10)
            .and_then(|v| v.checked_add((tok[i] - b'0') as i64))
            .ok_or_else(bad)?;
        i += 1;
    }
    if i == digits_start {
        return Err(bad());
    }
    if i < tok.len() {
        // The texture/normal parts: digits, signs and slashes only.
        if tok[i] != b'/'
            || !tok[i..]
                .iter()
                .all(|&b| b == b'/' || b == b'-' || b.is_ascii_digit())
        {
            return Err(bad());
        }
    }
    Ok(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newline_search_matches_naive() {
        let s = b"abc\ndefghijklmnop\n\nqrstuvwxyz0123456789";
        let mut pos = 0;
        while pos < s.len() {
            let naive = s[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(s.len(), |k| pos + k);
            assert_eq!(find_newline(s, pos), naive);
            pos = naive + 1;
        }
    }

    /// What a parse gives, to compare parses (the scene has no `PartialEq`).
    fn summary(r: Result<Scene, SceneError>) -> String {
        match r {
            Ok(s) => format!(
                "{:?} {:?} {:?} {:?} {:?}",
                s.vertices,
                s.triangles,
                s.opaque,
                s.objects
                    .iter()
                    .map(|o| (&o.name, o.triangles.clone(), o.bounds))
                    .collect::<Vec<_>>(),
                s.warnings
            ),
            Err(e) => format!("error: {e}"),
        }
    }

    #[test]
    fn any_chunking_parses_like_one_chunk() {
        // Faces before any name, names and materials that return, negative indices reaching
        // vertices of earlier lines, skipped statements, comments, CRLF, a byte-order mark.
        let text = "\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\r\nusemtl glass\n\
                    o a\nv 0 0 1\n# c\nf -1 -2 -3\nl 1 2\ng  b  c \nusemtl stone\n\
                    v 2 2 2\nf 1 2 3 4 5\no a\nf -3/1 -2//4 -1/2/3\np 1\nusemtl glass\n\
                    f 4 5 1\ng\nf 5 4 3\nvt 0 1\no d\n";
        let path = Path::new("chunks.obj");
        let whole = summary(parse_in_chunks(text.as_bytes(), path, usize::MAX));
        assert!(whole.contains("\"b c\""), "{whole}");
        for size in [1, 2, 5, 9, 17, 40, 100] {
            let cut = summary(parse_in_chunks(text.as_bytes(), path, size));
            assert_eq!(cut, whole, "chunks of {size} bytes");
        }
        // The first error in the file, with its line, whatever chunk it falls in; a later
        // chunk's error does not hide an earlier one.
        for (text, line) in [
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\no a\nf 1 2 3\nf 1 2 4\nv nan 0 0\n",
                6,
            ),
            ("v 0 0 0\nv 1 0 0\nf 1 2 -3\nv 0 1 0\nf 1 2 3\nf 1 2\n", 3),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\n\nv 1 1 x\nf 0 1 2\n",
                7,
            ),
        ] {
            let whole = summary(parse_in_chunks(text.as_bytes(), path, usize::MAX));
            assert!(whole.contains(&format!("chunks.obj:{line}")), "{whole}");
            for size in [1, 3, 8, 20] {
                let cut = summary(parse_in_chunks(text.as_bytes(), path, size));
                assert_eq!(cut, whole, "chunks of {size} bytes");
            }
        }
    }

    #[test]
    fn index_forms() {
        assert_eq!(parse_index(b"12").unwrap(), 12);
        assert_eq!(parse_index(b"-3/4").unwrap(), -3);
        assert_eq!(parse_index(b"5//6").unwrap(), 5);
        assert_eq!(parse_index(b"5/6/7").unwrap(), 5);
        assert!(parse_index(b"x").is_err());
        assert!(parse_index(b"5a").is_err());
        assert!(parse_index(b"/5").is_err());
    }

    #[test]
    fn names_collapse() {
        let mut s = String::new();
        collapse_name(b"  a \t b   c ", &mut s);
        assert_eq!(s, "a b c");
        collapse_name(b"   ", &mut s);
        assert_eq!(s, "default");
    }
}
