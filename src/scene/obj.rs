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
    let mut p = Parser::new(path);
    p.run(bytes)?;
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
    /// Scratch: the corners of the current face and the name being built.
    corners: Vec<u32>,
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
            corners: Vec::with_capacity(16),
            name_buf: String::new(),
        }
    }

    fn run(&mut self, bytes: &[u8]) -> Result<(), SceneError> {
        // A rough guess of the sizes saves a few reallocations of the big arrays.
        let guess = bytes.len() / 64;
        self.vertices.reserve(guess / 2);
        self.triangles.reserve(guess);
        let mut line_no = 0usize;
        // Skip a UTF-8 byte-order mark, which would otherwise hide the first statement.
        let mut pos = if bytes.starts_with(b"\xEF\xBB\xBF") {
            3
        } else {
            0
        };
        let n = bytes.len();
        while pos < n {
            line_no += 1;
            let end = find_newline(bytes, pos);
            let line = &bytes[pos..end];
            pos = end + 1;
            if let Err(message) = self.line(line) {
                return Err(SceneError::Parse {
                    path: self.path.to_path_buf(),
                    line: line_no,
                    message,
                });
            }
        }
        Ok(())
    }

    fn line(&mut self, line: &[u8]) -> LineResult<()> {
        let mut t = Tokens { s: line, i: 0 };
        let Some(key) = t.next() else {
            return Ok(());
        };
        match key {
            b"v" => self.vertex(&mut t),
            b"f" => self.face(&mut t),
            b"o" | b"g" => {
                collapse_name(t.rest(), &mut self.name_buf);
                let slot = self.slot_of_name_buf();
                self.current_slot = Some(slot);
                Ok(())
            }
            b"usemtl" => {
                collapse_name(t.rest(), &mut self.name_buf);
                self.current_material = match self.material_ids.get(self.name_buf.as_str()) {
                    Some(&m) => m,
                    None => {
                        let m = self.material_names.len() as u32;
                        self.material_names.push(self.name_buf.clone());
                        self.material_ids.insert(self.name_buf.clone(), m);
                        m
                    }
                };
                Ok(())
            }
            b"mtllib" => {
                self.mtllib(t.rest());
                Ok(())
            }
            b"l" => {
                self.lines_skipped += 1;
                Ok(())
            }
            b"p" => {
                self.points_skipped += 1;
                Ok(())
            }
            // vt, vn, vp, s, comments, curves and anything else: bookkeeping we do not need.
            _ => Ok(()),
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

    fn vertex(&mut self, t: &mut Tokens) -> LineResult<()> {
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
                self.vertices.len() + 1
            ));
        }
        self.vertices.push(v);
        Ok(())
    }

    fn face(&mut self, t: &mut Tokens) -> LineResult<()> {
        let nv = self.vertices.len() as i64;
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
        let start = self.triangles.len();
        if start + self.corners.len() - 2 > u32::MAX as usize {
            return Err("more than 2^32 triangles".into());
        }
        match self.runs.last() {
            Some(r) if r.slot == slot && r.material == self.current_material => {}
            _ => self.runs.push(Run {
                start: start as u32,
                slot,
                material: self.current_material,
            }),
        }
        let c0 = self.corners[0];
        for w in self.corners[1..].windows(2) {
            self.triangles.push([c0, w[0], w[1]]);
        }
        Ok(())
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
    let mut pos = 0;
    let mut line_no = 0;
    while pos < bytes.len() {
        line_no += 1;
        let end = find_newline(bytes, pos);
        let line = &bytes[pos..end];
        pos = end + 1;
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
