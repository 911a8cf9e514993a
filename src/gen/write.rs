//! OBJ (and MTL) output of the generators: fixed-point coordinates (exact for vertices on the
//! 1e-4 grid of [`quantize`](super::quantize)), objects formatted in parallel and written in
//! order, through an atomic write so no partial file is left.

use super::{GenError, GenObject, Generated, NO_VERTEX};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Material of opaque faces (only written when some face is translucent).
const OPAQUE: &str = "opaque";
/// Material of non-opaque faces (`d 0.5`).
const TRANSLUCENT: &str = "translucent";

/// The MTL file written beside `obj` when the scene has translucent faces (same stem, `.mtl`).
pub fn mtl_path(obj: &Path) -> PathBuf {
    obj.with_extension("mtl")
}

/// Writes `g` as OBJ to `path` (one `o NAME` per object, positive 1-based indices; quads as
/// 4-vertex faces). When some face is not opaque, also writes [`mtl_path`] with the
/// materials `opaque` (`d 1`) and `translucent` (`d 0.5`) and refers to it with `mtllib`.
///
/// # Errors
/// [`GenError::Write`]: I/O errors with the path; on error neither file is left (an existing file stays as it was).
pub fn write_obj(path: &Path, g: &Generated) -> Result<(), GenError> {
    let materials = g.has_translucent();
    let mtl = mtl_path(path);
    crate::util::write_atomic_with(path, |w| {
        writeln!(w, "# {}", g.comment.replace('\n', " "))?;
        writeln!(
            w,
            "# {} objects, {} triangles",
            g.objects.len(),
            g.triangle_count()
        )?;
        if materials {
            let name = mtl
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            writeln!(w, "mtllib {name}")?;
        }
        // First vertex index (1-based) of each object.
        let mut bases = Vec::with_capacity(g.objects.len());
        let mut next = 1u64;
        for o in &g.objects {
            bases.push(next);
            next += o.vertices.len() as u64;
        }
        // Format a window of chunks in parallel, write it in order, go on: memory stays bounded.
        const CHUNK: usize = 32;
        const WINDOW: usize = CHUNK * 64;
        for start in (0..g.objects.len()).step_by(WINDOW) {
            let end = (start + WINDOW).min(g.objects.len());
            let texts: Vec<Vec<u8>> = g.objects[start..end]
                .par_chunks(CHUNK)
                .zip(bases[start..end].par_chunks(CHUNK))
                .map(|(objs, bases)| {
                    let mut out = Vec::with_capacity(
                        objs.iter()
                            .map(|o| o.vertices.len() * 28 + o.faces.len() * 24)
                            .sum(),
                    );
                    for (o, &b) in objs.iter().zip(bases) {
                        format_object(&mut out, o, b, materials);
                    }
                    out
                })
                .collect();
            for t in texts {
                w.write_all(&t)?;
            }
        }
        Ok(())
    })
    .map_err(|e| GenError::Write(e.to_string()))?;
    if materials {
        let text = format!(
            "# umbrasweep gen materials: translucent faces were not opaque in the source model\n\
             newmtl {OPAQUE}\nKd 0.6 0.5 0.4\nd 1\n\nnewmtl {TRANSLUCENT}\nKd 0.3 0.6 0.2\nd 0.5\n"
        );
        if let Err(e) = crate::util::write_atomic(&mtl, text.as_bytes()) {
            let _ = std::fs::remove_file(path);
            return Err(GenError::Write(e.to_string()));
        }
    }
    Ok(())
}

/// Appends one object: `o`, its vertices, its faces (with `usemtl` where opacity changes).
fn format_object(out: &mut Vec<u8>, o: &GenObject, base: u64, materials: bool) {
    out.extend_from_slice(b"o ");
    out.extend_from_slice(o.name.as_bytes());
    out.push(b'\n');
    for v in &o.vertices {
        out.extend_from_slice(b"v ");
        fixed4(out, v.x);
        out.push(b' ');
        fixed4(out, v.y);
        out.push(b' ');
        fixed4(out, v.z);
        out.push(b'\n');
    }
    let mut current: Option<bool> = None;
    for (f, &opaque) in o.faces.iter().zip(&o.opaque) {
        if materials && current != Some(opaque) {
            out.extend_from_slice(b"usemtl ");
            out.extend_from_slice(if opaque { OPAQUE } else { TRANSLUCENT }.as_bytes());
            out.push(b'\n');
            current = Some(opaque);
        }
        out.push(b'f');
        for &i in f.iter().take_while(|&&i| i != NO_VERTEX) {
            out.push(b' ');
            uint(out, base + i as u64);
        }
        out.push(b'\n');
    }
}

/// Appends `n` in decimal.
fn uint(out: &mut Vec<u8>, mut n: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.extend_from_slice(&buf[i..]);
}

/// Appends `x` rounded to 4 decimals, trailing zeros dropped (`-3.25`, `0`, `12.0001`).
/// For `x` on the 1e-4 grid (see [`quantize`](super::quantize)) the text parses back to the
/// same `f32`.
fn fixed4(out: &mut Vec<u8>, x: f32) {
    let k = (x as f64 * 1e4).round() as i64;
    if k < 0 {
        out.push(b'-');
    }
    let k = k.unsigned_abs();
    uint(out, k / 10_000);
    let mut frac = k % 10_000;
    if frac != 0 {
        let mut digits = 4;
        while frac.is_multiple_of(10) {
            frac /= 10;
            digits -= 1;
        }
        out.push(b'.');
        let mut buf = [b'0'; 4];
        for d in (0..digits).rev() {
            buf[d] = b'0' + (frac % 10) as u8;
            frac /= 10;
        }
        out.extend_from_slice(&buf[..digits]);
    }
}

#[cfg(test)]
mod tests {
    use super::super::quantize;
    use super::*;
    use glam::Vec3;

    fn text(x: f32) -> String {
        let mut v = Vec::new();
        fixed4(&mut v, x);
        String::from_utf8(v).unwrap()
    }

    #[test]
    fn fixed_point_text() {
        assert_eq!(text(0.0), "0");
        assert_eq!(text(-0.0), "0");
        assert_eq!(text(-3.25), "-3.25");
        assert_eq!(text(12.0001), "12.0001");
        assert_eq!(text(-0.05), "-0.05");
        assert_eq!(text(100.0), "100");
        assert_eq!(text(0.1234), "0.1234");
    }

    #[test]
    fn quantized_values_round_trip_exactly() {
        let mut x = -2100.0f32;
        let mut seen = 0;
        while x < 2100.0 {
            let q = quantize(Vec3::splat(x)).x;
            let back: f32 = text(q).parse().unwrap();
            assert_eq!(back.to_bits(), q.to_bits(), "{x} -> {q} -> {}", text(q));
            x += 0.013_37;
            seen += 1;
        }
        assert!(seen > 100_000);
    }

    #[test]
    fn faces_use_global_one_based_indices() {
        let mut a = GenObject::new("a");
        let (p, q, r) = (a.vertex(Vec3::ZERO), a.vertex(Vec3::X), a.vertex(Vec3::Y));
        a.triangle(p, q, r, true);
        let mut out = Vec::new();
        format_object(&mut out, &a, 4, false);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 4 5 6\n"
        );
    }
}
