//! `EXT_meshopt_compression` / `KHR_meshopt_compression` buffer-view decoding.
//!
//! Owns one thing: turning a compressed buffer view (the bufferView's extension object plus
//! the loaded buffers) into the plain bytes the view stands for, `count * byteStride` of them.
//! The bitstreams (attributes v0 and v1, triangles, indices) are decoded by meshoptimizer
//! through the `meshopt` crate; the filters (octahedral, quaternion, exponential and the
//! KHR-only colour filter) are meshoptimizer's too, applied in place after decoding.
//!
//! Limits: every constraint of the extension's specification is checked before the decoder
//! runs (meshoptimizer asserts them), so hostile input gives an `Err`, never a panic. The
//! decoded size is capped at 2 GiB and at what the compressed bytes could possibly expand to
//! (at most 1024 output bytes per input byte for attributes, 12 for triangles, 4 for indices),
//! so a tiny view cannot make us allocate gigabytes. The decoder does not check that decoded
//! indices are in range: that is the accessor reader's job. Which buffer is a fallback and
//! whether a view is compressed at all is the glTF importer's business, not this module's.

use ::gltf::json::Value;

/// Largest decoded view we accept, in bytes.
const MAX_DECODED_BYTES: u64 = 1 << 31;

/// Compression mode of a view (`mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Attributes,
    Triangles,
    Indices,
}

/// Post-decode filter of an attribute view (`filter`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Filter {
    None,
    Octahedral,
    Quaternion,
    Exponential,
    Color,
}

/// Decodes one compressed buffer view. `ext` is the bufferView's extension object
/// (`{"buffer", "byteOffset", "byteLength", "byteStride", "count", "mode", "filter"}`),
/// `buffers[i]` the bytes of buffer i (None when not loaded). Returns exactly
/// `count * byteStride` bytes.
pub fn decode_view(ext: &Value, buffers: &[Option<Vec<u8>>]) -> Result<Vec<u8>, String> {
    if !ext.is_object() {
        return Err("meshopt: the extension object is not a JSON object".into());
    }
    let obj = ext;
    let buffer = required_u64(obj, "buffer")?;
    let byte_offset = optional_u64(obj, "byteOffset")?.unwrap_or(0);
    let byte_length = required_u64(obj, "byteLength")?;
    let stride = required_u64(obj, "byteStride")?;
    let count = required_u64(obj, "count")?;
    let mode = match obj.get("mode").and_then(Value::as_str) {
        Some("ATTRIBUTES") => Mode::Attributes,
        Some("TRIANGLES") => Mode::Triangles,
        Some("INDICES") => Mode::Indices,
        Some(other) => return Err(format!("meshopt: unknown mode \"{other}\"")),
        None => return Err("meshopt: \"mode\" is missing or not a string".into()),
    };
    let filter = match obj.get("filter") {
        None => Filter::None,
        Some(v) => match v.as_str() {
            Some("NONE") => Filter::None,
            Some("OCTAHEDRAL") => Filter::Octahedral,
            Some("QUATERNION") => Filter::Quaternion,
            Some("EXPONENTIAL") => Filter::Exponential,
            Some("COLOR") => Filter::Color,
            Some(other) => return Err(format!("meshopt: unknown filter \"{other}\"")),
            None => return Err("meshopt: \"filter\" is not a string".into()),
        },
    };

    check_layout(mode, filter, stride, count)?;

    let decoded_len = count
        .checked_mul(stride)
        .filter(|&n| n <= MAX_DECODED_BYTES)
        .ok_or_else(|| {
            format!("meshopt: count {count} × byteStride {stride} exceeds the 2 GiB limit")
        })?;
    let expansion: u64 = match mode {
        Mode::Attributes => 1024,
        Mode::Triangles => 12,
        Mode::Indices => 4,
    };
    if decoded_len > byte_length.saturating_mul(expansion) {
        return Err(format!(
            "meshopt: {decoded_len} decoded bytes cannot come from {byte_length} compressed bytes \
             in {mode:?} mode"
        ));
    }

    let data = usize::try_from(buffer)
        .ok()
        .and_then(|b| buffers.get(b))
        .ok_or_else(|| format!("meshopt: buffer {buffer} does not exist"))?
        .as_deref()
        .ok_or_else(|| format!("meshopt: buffer {buffer} is not loaded"))?;
    let end = byte_offset
        .checked_add(byte_length)
        .ok_or("meshopt: byteOffset + byteLength overflows")?;
    let compressed = usize::try_from(byte_offset)
        .ok()
        .zip(usize::try_from(end).ok())
        .and_then(|(start, end)| data.get(start..end))
        .ok_or_else(|| {
            format!(
                "meshopt: bytes {byte_offset}..{end} are outside buffer {buffer} ({} bytes)",
                data.len()
            )
        })?;

    // Both fit in usize: decoded_len <= 2^31 and stride <= 256 were checked above.
    let count = count as usize;
    let stride = stride as usize;
    let mut out = match mode {
        Mode::Attributes => decode_attributes(compressed, count, stride)?,
        Mode::Triangles => decode_indices(compressed, count, stride, true)?,
        Mode::Indices => decode_indices(compressed, count, stride, false)?,
    };
    apply_filter(filter, stride, &mut out)?;
    debug_assert_eq!(out.len(), count * stride);
    Ok(out)
}

fn required_u64(obj: &Value, key: &str) -> Result<u64, String> {
    optional_u64(obj, key)?.ok_or_else(|| format!("meshopt: \"{key}\" is missing"))
}

fn optional_u64(obj: &Value, key: &str) -> Result<Option<u64>, String> {
    match obj.get(key) {
        None => Ok(None),
        Some(v) => v
            .as_u64()
            .map(Some)
            .ok_or_else(|| format!("meshopt: \"{key}\" is not a non-negative integer: {v}")),
    }
}

/// The specification's validity rules for `mode`, `filter`, `byteStride` and `count`.
fn check_layout(mode: Mode, filter: Filter, stride: u64, count: u64) -> Result<(), String> {
    match mode {
        Mode::Attributes => {
            if stride == 0 || !stride.is_multiple_of(4) || stride > 256 {
                return Err(format!(
                    "meshopt: ATTRIBUTES needs a byteStride that is a multiple of 4 in 4..=256, \
                     not {stride}"
                ));
            }
        }
        Mode::Triangles | Mode::Indices => {
            if stride != 2 && stride != 4 {
                return Err(format!(
                    "meshopt: {mode:?} needs a byteStride of 2 or 4, not {stride}"
                ));
            }
            if mode == Mode::Triangles && !count.is_multiple_of(3) {
                return Err(format!(
                    "meshopt: TRIANGLES needs a count divisible by 3, not {count}"
                ));
            }
            if filter != Filter::None {
                return Err(format!(
                    "meshopt: filter {filter:?} is only allowed with ATTRIBUTES"
                ));
            }
        }
    }
    let ok = match filter {
        Filter::None | Filter::Exponential => true, // stride % 4 == 0 already holds
        Filter::Octahedral | Filter::Color => stride == 4 || stride == 8,
        Filter::Quaternion => stride == 8,
    };
    if !ok {
        return Err(format!(
            "meshopt: filter {filter:?} does not allow a byteStride of {stride}"
        ));
    }
    Ok(())
}

/// One vertex of `N` bytes, so the typed decoder can write any stride without `unsafe`.
#[derive(Clone, Copy)]
#[repr(transparent)]
struct Element<const N: usize>([u8; N]);

impl<const N: usize> Default for Element<N> {
    fn default() -> Self {
        Self([0; N])
    }
}

fn decode_attributes_n<const N: usize>(data: &[u8], count: usize) -> Result<Vec<u8>, String> {
    let elements: Vec<Element<N>> = ::meshopt::decode_vertex_buffer(data, count)
        .map_err(|e| format!("meshopt: malformed ATTRIBUTES data ({e})"))?;
    let mut out = Vec::with_capacity(count * N);
    for e in &elements {
        out.extend_from_slice(&e.0);
    }
    Ok(out)
}

macro_rules! dispatch_stride {
    ($data:expr, $count:expr, $stride:expr; $($n:literal)*) => {
        match $stride {
            $($n => decode_attributes_n::<$n>($data, $count),)*
            other => Err(format!("meshopt: unsupported ATTRIBUTES byteStride {other}")),
        }
    };
}

fn decode_attributes(data: &[u8], count: usize, stride: usize) -> Result<Vec<u8>, String> {
    dispatch_stride!(data, count, stride;
        4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64
        68 72 76 80 84 88 92 96 100 104 108 112 116 120 124 128
        132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192
        196 200 204 208 212 216 220 224 228 232 236 240 244 248 252 256)
}

fn decode_indices(
    data: &[u8],
    count: usize,
    stride: usize,
    triangles: bool,
) -> Result<Vec<u8>, String> {
    let what = if triangles { "TRIANGLES" } else { "INDICES" };
    let err = |e: ::meshopt::Error| format!("meshopt: malformed {what} data ({e})");
    if stride == 2 {
        let v: Vec<u16> = if triangles {
            ::meshopt::decode_index_buffer(data, count).map_err(err)?
        } else {
            ::meshopt::decode_index_sequence(data, count).map_err(err)?
        };
        Ok(v.iter().flat_map(|i| i.to_le_bytes()).collect())
    } else {
        let v: Vec<u32> = if triangles {
            ::meshopt::decode_index_buffer(data, count).map_err(err)?
        } else {
            ::meshopt::decode_index_sequence(data, count).map_err(err)?
        };
        Ok(v.iter().flat_map(|i| i.to_le_bytes()).collect())
    }
}

/// Applies `filter` in place to little-endian attribute bytes (`check_layout` has run).
fn apply_filter(filter: Filter, stride: usize, bytes: &mut [u8]) -> Result<(), String> {
    match (filter, stride) {
        (Filter::None, _) => {}
        (Filter::Octahedral, 4) => {
            let mut v = to_quads(bytes, |b: [u8; 1]| i8::from_le_bytes(b));
            ::meshopt::decode_filter_oct(&mut v);
            from_quads(&v, bytes, i8::to_le_bytes);
        }
        (Filter::Octahedral, 8) => {
            let mut v = to_quads(bytes, i16::from_le_bytes);
            ::meshopt::decode_filter_oct(&mut v);
            from_quads(&v, bytes, i16::to_le_bytes);
        }
        (Filter::Quaternion, 8) => {
            let mut v = to_quads(bytes, i16::from_le_bytes);
            ::meshopt::decode_filter_quat(&mut v);
            from_quads(&v, bytes, i16::to_le_bytes);
        }
        (Filter::Color, 4) => {
            let mut v = to_quads(bytes, u8::from_le_bytes);
            ::meshopt::decode_filter_color(&mut v);
            from_quads(&v, bytes, u8::to_le_bytes);
        }
        (Filter::Color, 8) => {
            let mut v = to_quads(bytes, u16::from_le_bytes);
            ::meshopt::decode_filter_color(&mut v);
            from_quads(&v, bytes, u16::to_le_bytes);
        }
        (Filter::Exponential, _) => {
            // Every 32-bit component is decoded on its own, so the stride does not matter.
            let mut v: Vec<[u32; 1]> = bytes
                .chunks_exact(4)
                .map(|c| [u32::from_le_bytes([c[0], c[1], c[2], c[3]])])
                .collect();
            ::meshopt::decode_filter_exp(&mut v);
            for (dst, src) in bytes.chunks_exact_mut(4).zip(&v) {
                dst.copy_from_slice(&src[0].to_le_bytes());
            }
        }
        (f, s) => {
            return Err(format!(
                "meshopt: filter {f:?} does not allow a byteStride of {s}"
            ));
        }
    }
    Ok(())
}

/// Splits `bytes` into elements of four `C`s, each `C` read from `S` little-endian bytes.
fn to_quads<C: Copy + Default, const S: usize>(
    bytes: &[u8],
    read: impl Fn([u8; S]) -> C,
) -> Vec<[C; 4]> {
    bytes
        .chunks_exact(4 * S)
        .map(|e| {
            let mut q = [C::default(); 4];
            for (c, b) in q.iter_mut().zip(e.chunks_exact(S)) {
                let mut a = [0u8; S];
                a.copy_from_slice(b);
                *c = read(a);
            }
            q
        })
        .collect()
}

/// Writes quads back over `bytes` (the inverse of [`to_quads`]).
fn from_quads<C: Copy, const S: usize>(
    quads: &[[C; 4]],
    bytes: &mut [u8],
    write: fn(C) -> [u8; S],
) {
    for (e, q) in bytes.chunks_exact_mut(4 * S).zip(quads) {
        for (b, &c) in e.chunks_exact_mut(S).zip(q) {
            b.copy_from_slice(&write(c));
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use serde_json::json;

    fn view(mode: &str, filter: &str, stride: usize, count: usize, len: usize) -> Value {
        json!({
            "buffer": 0, "byteOffset": 0, "byteLength": len, "byteStride": stride,
            "count": count, "mode": mode, "filter": filter,
        })
    }

    /// Deterministic pseudo-random bytes (xorshift).
    fn noise(seed: u64, n: usize) -> Vec<u8> {
        let mut s = seed | 1;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                s as u8
            })
            .collect()
    }

    #[test]
    fn attributes_round_trip_every_stride() {
        for stride in (4..=256).step_by(4) {
            for count in [1usize, 15, 16, 17, 300] {
                // Smooth data with some noise, like real vertex streams.
                let mut raw = noise((stride * 1000 + count) as u64, stride * count);
                for (i, b) in raw.iter_mut().enumerate() {
                    *b = if i % 3 == 0 {
                        (i / stride) as u8
                    } else {
                        *b & 0x0f
                    };
                }
                let encoded = match stride {
                    12 => ::meshopt::encode_vertex_buffer(&as_elements::<12>(&raw)),
                    _ => encode_any(&raw, stride),
                }
                .expect("encode");
                let ext = view("ATTRIBUTES", "NONE", stride, count, encoded.len());
                let out = decode_view(&ext, &[Some(encoded)]).expect("decode");
                assert_eq!(out, raw, "stride {stride} count {count}");
            }
        }
    }

    fn as_elements<const N: usize>(raw: &[u8]) -> Vec<Element<N>> {
        raw.chunks_exact(N)
            .map(|c| {
                let mut e = Element::<N>::default();
                e.0.copy_from_slice(c);
                e
            })
            .collect()
    }

    /// Encodes with the stride taken from `Element<N>` for the strides the test uses.
    fn encode_any(raw: &[u8], stride: usize) -> ::meshopt::Result<Vec<u8>> {
        macro_rules! enc {
            ($($n:literal)*) => {
                match stride {
                    $($n => ::meshopt::encode_vertex_buffer(&as_elements::<$n>(raw)),)*
                    _ => unreachable!(),
                }
            };
        }
        enc!(4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64
            68 72 76 80 84 88 92 96 100 104 108 112 116 120 124 128
            132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192
            196 200 204 208 212 216 220 224 228 232 236 240 244 248 252 256)
    }

    #[test]
    fn attributes_v0_encoding_decodes() {
        // EXT_meshopt_compression files carry the v0 bitstream.
        let raw = noise(7, 12 * 40);
        let encoded =
            ::meshopt::encode_vertex_buffer_level(&as_elements::<12>(&raw), 2, Some(0)).unwrap();
        assert_eq!(::meshopt::decode_vertex_version(&encoded), Some(0));
        let ext = view("ATTRIBUTES", "NONE", 12, 40, encoded.len());
        assert_eq!(decode_view(&ext, &[Some(encoded)]).unwrap(), raw);
    }

    #[test]
    fn triangles_and_indices_round_trip() {
        let indices: Vec<u32> = (0..300u32).map(|i| (i * 7 + i / 3) % 101).collect();
        let tri = ::meshopt::encode_index_buffer(&indices, 101).unwrap();
        let seq = ::meshopt::encode_index_sequence(&indices, 101).unwrap();
        // The triangle codec keeps triangles and their order but may rotate a triangle's
        // corners (the winding is kept), so compare triangles by their smallest-first rotation.
        let canonical = |ix: &[u32], triangles: bool| -> Vec<u32> {
            if !triangles {
                return ix.to_vec();
            }
            ix.chunks_exact(3)
                .flat_map(|t| {
                    let r = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
                    [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
                })
                .collect()
        };
        for (mode, enc) in [("TRIANGLES", &tri), ("INDICES", &seq)] {
            let triangles = mode == "TRIANGLES";
            let want = canonical(&indices, triangles);
            for stride in [4usize, 2] {
                let ext = view(mode, "NONE", stride, 300, enc.len());
                let out = decode_view(&ext, &[Some(enc.clone())]).unwrap();
                assert_eq!(out.len(), 300 * stride);
                let got: Vec<u32> = if stride == 4 {
                    out.chunks_exact(4)
                        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                        .collect()
                } else {
                    out.chunks_exact(2)
                        .map(|b| u32::from(u16::from_le_bytes([b[0], b[1]])))
                        .collect()
                };
                assert_eq!(canonical(&got, triangles), want, "{mode} stride {stride}");
            }
        }
    }

    #[test]
    fn offsets_and_buffer_selection() {
        let raw = noise(3, 8 * 20);
        let enc = ::meshopt::encode_vertex_buffer(&as_elements::<8>(&raw)).unwrap();
        let mut buf = vec![0xAAu8; 13];
        buf.extend_from_slice(&enc);
        buf.extend_from_slice(&[0x55; 7]);
        let ext = json!({"buffer": 1, "byteOffset": 13, "byteLength": enc.len(),
            "byteStride": 8, "count": 20, "mode": "ATTRIBUTES"});
        assert_eq!(decode_view(&ext, &[None, Some(buf)]).unwrap(), raw);
        // Buffer 0 is not loaded; buffer 2 does not exist.
        let e = decode_view(
            &json!({"buffer": 0, "byteLength": 1, "byteStride": 4, "count": 1,
            "mode": "ATTRIBUTES"}),
            &[None],
        )
        .unwrap_err();
        assert!(e.contains("not loaded"), "{e}");
        let e = decode_view(
            &json!({"buffer": 2, "byteLength": 1, "byteStride": 4, "count": 1,
            "mode": "ATTRIBUTES"}),
            &[None],
        )
        .unwrap_err();
        assert!(e.contains("does not exist"), "{e}");
    }

    /// The octahedral filter by the specification's formula.
    fn spec_oct(input: [f32; 4], max: f32) -> [f32; 4] {
        let one = input[2];
        let mut x = input[0] / one;
        let mut y = input[1] / one;
        let z = 1.0 - x.abs() - y.abs();
        let t = z.min(0.0);
        x -= t.copysign(x);
        y -= t.copysign(y);
        let len = (x * x + y * y + z * z).sqrt();
        [
            (x / len * max).round(),
            (y / len * max).round(),
            (z / len * max).round(),
            input[3],
        ]
    }

    fn filtered(filter: &str, stride: usize, raw: &[u8]) -> Vec<u8> {
        let count = raw.len() / stride;
        let enc = encode_any(raw, stride).unwrap();
        decode_view(
            &view("ATTRIBUTES", filter, stride, count, enc.len()),
            &[Some(enc)],
        )
        .unwrap()
    }

    #[test]
    fn octahedral_filter_matches_spec() {
        // 8-bit, K = 8 (one = 127) and K = 6 (one = 31); 16-bit, K = 16 and K = 12.
        let cases8: [[i8; 4]; 5] = [
            [0, 0, 127, 5],
            [127, 0, 127, -3],
            [-60, 40, 127, 0],
            [90, -90, 127, 1],
            [-20, -11, 31, 9],
        ];
        let raw: Vec<u8> = cases8.iter().flatten().map(|&c| c as u8).collect();
        let out = filtered("OCTAHEDRAL", 4, &raw);
        for (case, got) in cases8.iter().zip(out.chunks_exact(4)) {
            let want = spec_oct(case.map(f32::from), 127.0);
            for k in 0..4 {
                let g = f32::from(got[k] as i8);
                assert!(
                    (g - want[k]).abs() <= 1.0,
                    "{case:?}: got {got:?} want {want:?}"
                );
            }
            assert_eq!(got[3] as i8, case[3], "w passes through");
        }
        let cases16: [[i16; 4]; 4] = [
            [0, 0, 32767, 77],
            [20000, -12767, 32767, -1],
            [-30000, -2767, 32767, 0],
            [1000, -2000, 2047, 3],
        ];
        let raw: Vec<u8> = cases16
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let out = filtered("OCTAHEDRAL", 8, &raw);
        for (case, got) in cases16.iter().zip(out.chunks_exact(8)) {
            let got: Vec<i16> = got
                .chunks_exact(2)
                .map(|b| i16::from_le_bytes([b[0], b[1]]))
                .collect();
            let want = spec_oct(case.map(f32::from), 32767.0);
            for k in 0..4 {
                assert!(
                    (f32::from(got[k]) - want[k]).abs() <= 1.0,
                    "{case:?}: {got:?} vs {want:?}"
                );
            }
            assert_eq!(got[3], case[3]);
        }
    }

    #[test]
    fn quaternion_filter_matches_spec() {
        // input[3] = K-bit 1.0 with the max-component index in the low two bits.
        let cases: [[i16; 4]; 4] = [
            [0, 0, 0, 32767 & !3],
            [10000, -5000, 3000, (32767 & !3) | 1],
            [-20000, 100, 9000, (32767 & !3) | 2],
            [300, -400, 500, (1023 & !3) | 3],
        ];
        let raw: Vec<u8> = cases
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let out = filtered("QUATERNION", 8, &raw);
        for (case, got) in cases.iter().zip(out.chunks_exact(8)) {
            let got: Vec<i16> = got
                .chunks_exact(2)
                .map(|b| i16::from_le_bytes([b[0], b[1]]))
                .collect();
            let range = 1.0 / 2f32.sqrt();
            let one = f32::from(case[3] | 3);
            let x = f32::from(case[0]) / one * range;
            let y = f32::from(case[1]) / one * range;
            let z = f32::from(case[2]) / one * range;
            let w = (1.0 - x * x - y * y - z * z).max(0.0).sqrt();
            let m = (case[3] & 3) as usize;
            let mut want = [0f32; 4];
            want[(m + 1) % 4] = (x * 32767.0).round();
            want[(m + 2) % 4] = (y * 32767.0).round();
            want[(m + 3) % 4] = (z * 32767.0).round();
            want[m] = (w * 32767.0).round();
            for k in 0..4 {
                assert!(
                    (f32::from(got[k]) - want[k]).abs() <= 1.0,
                    "{case:?}: {got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn exponential_filter_is_exact() {
        let spec = |v: u32| -> f32 {
            let e = (v as i32) >> 24;
            let m = ((v << 8) as i32) >> 8;
            2f64.powi(e) as f32 * m as f32
        };
        let mk = |e: i32, m: i32| ((e as u32) << 24) | (m as u32 & 0x00ff_ffff);
        let values = [
            mk(0, 0),
            mk(0, 1),
            mk(-1, 3),
            mk(-10, -1234),
            mk(5, 8_388_607),
            mk(-23, -8_388_608),
            mk(100, 1),
            mk(-100, 77),
            mk(17, -5),
            mk(-126 + 26, 123_456),
            mk(3, 0),
            mk(-7, 99),
        ];
        // Stride 12: three values per element.
        let raw: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let out = filtered("EXPONENTIAL", 12, &raw);
        for (v, got) in values.iter().zip(out.chunks_exact(4)) {
            let got = f32::from_le_bytes([got[0], got[1], got[2], got[3]]);
            assert_eq!(got.to_bits(), spec(*v).to_bits(), "input {v:#010x}");
        }
    }

    #[test]
    fn color_filter_matches_spec() {
        // 8-bit, K = 8: Y unsigned, Co/Cg signed, alpha 7 bits with bit 7 set.
        let cases: [[u8; 4]; 3] = [
            [100, 10, 250, 0x80 | 0x7f],
            [200, 0xf0, 5, 0x80 | 0x10],
            [0, 0, 0, 0x80],
        ];
        let raw: Vec<u8> = cases.iter().flatten().copied().collect();
        let out = filtered("COLOR", 4, &raw);
        for (c, got) in cases.iter().zip(out.chunks_exact(4)) {
            let msb = 31 - u32::from(c[3]).leading_zeros();
            let a_s = (1i32 << (msb + 1)) - 1;
            let (y, co, cg) = (
                i32::from(c[0]),
                i32::from(c[1] as i8),
                i32::from(c[2] as i8),
            );
            let (r, g, b) = (y + co - cg, y + cg, y - co - cg);
            let mut a = i32::from(c[3]) & (a_s >> 1);
            a = (a << 1) | (a & 1);
            let ss = 255.0 / a_s as f32;
            let want = [r, g, b, a].map(|v| (v as f32 * ss).round() as i32 as u8);
            for k in 0..4 {
                assert!(
                    (i32::from(got[k]) - i32::from(want[k])).abs() <= 1,
                    "{c:?}: {got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn hostile_views_are_errors() {
        let raw = noise(11, 16 * 64);
        let enc = encode_any(&raw, 16).unwrap();
        let ok = view("ATTRIBUTES", "NONE", 16, 64, enc.len());
        assert!(decode_view(&ok, &[Some(enc.clone())]).is_ok());
        let bad = [
            json!([1, 2]),
            json!({"buffer": 0, "byteLength": enc.len(), "byteStride": 16, "count": 64}),
            view("ATTRIBUTES", "NONE", 6, 64, enc.len()),
            view("ATTRIBUTES", "NONE", 260, 64, enc.len()),
            view("ATTRIBUTES", "NONE", 0, 64, enc.len()),
            view("TRIANGLES", "NONE", 4, 64, enc.len()),
            view("INDICES", "NONE", 8, 64, enc.len()),
            view("TRIANGLES", "OCTAHEDRAL", 4, 63, enc.len()),
            view("ATTRIBUTES", "OCTAHEDRAL", 16, 64, enc.len()),
            view("ATTRIBUTES", "QUATERNION", 4, 64, enc.len()),
            view("ATTRIBUTES", "MAGIC", 16, 64, enc.len()),
            view("SPLINES", "NONE", 16, 64, enc.len()),
            view("ATTRIBUTES", "NONE", 16, 64, enc.len() + 1),
            view("ATTRIBUTES", "NONE", 16, 1 << 40, enc.len()),
            view("ATTRIBUTES", "NONE", 256, 1 << 24, enc.len()),
            json!({"buffer": 0, "byteOffset": u64::MAX, "byteLength": 2, "byteStride": 4,
                "count": 1, "mode": "ATTRIBUTES"}),
            json!({"buffer": -1, "byteLength": 2, "byteStride": 4, "count": 1, "mode": "INDICES"}),
            json!({"buffer": 0, "byteLength": 2.5, "byteStride": 4, "count": 1, "mode": "INDICES"}),
        ];
        for b in &bad {
            assert!(decode_view(b, &[Some(enc.clone())]).is_err(), "{b}");
        }
        // Truncated or garbled streams, in every mode.
        let tri = ::meshopt::encode_index_buffer(&(0..96u32).collect::<Vec<_>>(), 96).unwrap();
        let seq = ::meshopt::encode_index_sequence(&(0..96u32).collect::<Vec<_>>(), 96).unwrap();
        for (mode, stride, count, stream) in [
            ("ATTRIBUTES", 16, 64, &enc),
            ("TRIANGLES", 4, 96, &tri),
            ("INDICES", 2, 96, &seq),
        ] {
            for cut in 0..stream.len() {
                let ext = view(mode, "NONE", stride, count, cut);
                assert!(
                    decode_view(&ext, &[Some(stream[..cut].to_vec())]).is_err(),
                    "{mode} cut {cut}"
                );
            }
            for seed in 0..200u64 {
                let mut s = stream.clone();
                let flips = noise(seed + 99, 8);
                for pair in flips.chunks_exact(2) {
                    let at = usize::from(pair[0]) * s.len() / 256;
                    s[at] ^= pair[1] | 1;
                }
                // Garbage may decode to garbage, but must not panic and must keep the size.
                if let Ok(out) =
                    decode_view(&view(mode, "NONE", stride, count, s.len()), &[Some(s)])
                {
                    assert_eq!(out.len(), stride * count);
                }
            }
            let garbage = noise(5, 300);
            let ext = view(mode, "NONE", stride, count, garbage.len());
            if let Ok(out) = decode_view(&ext, &[Some(garbage)]) {
                assert_eq!(out.len(), stride * count);
            }
        }
    }

    /// Path of the shared web-optimised palm; `None` (with a printed reason) when absent
    /// outside CI.
    pub(crate) fn palm_glb() -> Option<std::path::PathBuf> {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/scenes/foliage-textured/palm_coconut_evolveduk_ktx2/palm_coconut.glb");
        if p.exists() {
            return Some(p);
        }
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("{} is missing on CI", p.display());
        }
        eprintln!("skipped: {} is absent", p.display());
        None
    }

    #[test]
    fn palm_compressed_views_decode() {
        let Some(path) = palm_glb() else { return };
        let file = std::fs::read(&path).unwrap();
        let glb = ::gltf::Glb::from_slice(&file).unwrap();
        let root: Value = serde_json::from_slice(&glb.json).unwrap();
        let bin = glb.bin.expect("GLB has a BIN chunk").into_owned();
        // Buffer 0 is the BIN chunk; buffer 1 is the uncompressed fallback (not stored).
        let buffers = vec![Some(bin), None];
        let views = root["bufferViews"].as_array().unwrap();
        let mut decoded = 0;
        for (i, v) in views.iter().enumerate() {
            let Some(ext) = v["extensions"].get("EXT_meshopt_compression") else {
                continue;
            };
            let out = decode_view(ext, &buffers).unwrap_or_else(|e| panic!("view {i}: {e}"));
            assert_eq!(
                out.len() as u64,
                v["byteLength"].as_u64().unwrap(),
                "view {i}"
            );
            decoded += 1;
        }
        eprintln!("palm: {decoded} compressed views decoded");
        assert_eq!(decoded, 21);

        // Without filters the decoded bytes are exact, so every accessor's min/max (written
        // from the uncompressed data) must bound its values and be reached.
        let view_bytes = |i: usize| -> Vec<u8> {
            decode_view(&views[i]["extensions"]["EXT_meshopt_compression"], &buffers).unwrap()
        };
        let accessors = root["accessors"].as_array().unwrap();
        let mut bounded = 0;
        let mut primitives = 0;
        for (a, acc) in accessors.iter().enumerate() {
            let (Some(min), Some(max)) = (acc["min"].as_array(), acc["max"].as_array()) else {
                continue;
            };
            let bv = acc["bufferView"].as_u64().unwrap() as usize;
            let bytes = view_bytes(bv);
            let size = match acc["componentType"].as_u64().unwrap() {
                5120 | 5121 => 1,
                5122 | 5123 => 2,
                _ => 4,
            };
            let stride = views[bv]["byteStride"]
                .as_u64()
                .map_or(size * min.len(), |s| s as usize);
            let offset = acc["byteOffset"].as_u64().unwrap_or(0) as usize;
            let read = |at: usize| -> f64 {
                let b = &bytes[at..at + size];
                match acc["componentType"].as_u64().unwrap() {
                    5120 => f64::from(b[0] as i8),
                    5121 => f64::from(b[0]),
                    5122 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                    5123 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                    5125 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    _ => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                }
            };
            for c in 0..min.len() {
                let vals: Vec<f64> = (0..acc["count"].as_u64().unwrap() as usize)
                    .map(|i| read(offset + i * stride + c * size))
                    .collect();
                let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(
                    lo,
                    min[c].as_f64().unwrap(),
                    "accessor {a} component {c} min"
                );
                assert_eq!(
                    hi,
                    max[c].as_f64().unwrap(),
                    "accessor {a} component {c} max"
                );
            }
            bounded += 1;
        }
        // Indices address the vertices of their own primitive.
        for mesh in root["meshes"].as_array().unwrap() {
            for prim in mesh["primitives"].as_array().unwrap() {
                let ia = &accessors[prim["indices"].as_u64().unwrap() as usize];
                let pa = &accessors[prim["attributes"]["POSITION"].as_u64().unwrap() as usize];
                let bytes = view_bytes(ia["bufferView"].as_u64().unwrap() as usize);
                let start = ia["byteOffset"].as_u64().unwrap_or(0) as usize;
                let n = ia["count"].as_u64().unwrap() as usize;
                assert_eq!(ia["componentType"], 5123);
                let idx = &bytes[start..start + 2 * n];
                let verts = pa["count"].as_u64().unwrap();
                assert!(
                    idx.chunks_exact(2)
                        .all(|b| u64::from(u16::from_le_bytes([b[0], b[1]])) < verts)
                );
                primitives += 1;
            }
        }
        eprintln!(
            "palm: {bounded} accessors' min/max match the decoded data; {primitives} primitives' \
             indices address their vertices"
        );
        assert!(bounded >= primitives && primitives == 5);
    }
}
