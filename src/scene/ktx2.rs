//! KTX2 images (`KHR_texture_basisu`, `image/ktx2`) decoded to RGBA8.
//!
//! Owns one thing: level 0 of a KTX2 file as `(width, height, RGBA8 pixels row-major)`, so
//! the glTF importer can read a base-colour texture's alpha like any PNG's. Basis Universal
//! payloads (ETC1S with BasisLZ supercompression, UASTC raw or Zstandard supercompressed) are
//! transcoded to uncompressed RGBA32 by the pure-Rust `basisu` transcoder, so alpha is exactly
//! what the Basis transcoder gives (ETC1S without an alpha slice decodes as opaque). Plain
//! 8-bit formats (`R8G8B8A8`, `B8G8R8A8`, `R8G8B8`, UNORM or SRGB; uncompressed or Zstandard)
//! are copied out directly. The container is parsed and checked by the `ktx2` crate first.
//!
//! Limits: only the first layer / face of level 0 is returned; 3D textures, other
//! Vulkan formats (BCn, ASTC, ETC2, 16-bit, float) and ZLIB supercompression are refused with
//! an `Err`. Colour values are returned as stored (no sRGB conversion). Width and height are
//! capped at 16384, array layers at 2048, and every declared size is checked against the
//! dimensions before anything is allocated, so hostile input gives an `Err`, never a panic or
//! a huge allocation.

use ::ktx2::{Format, SupercompressionScheme};

/// Largest width or height accepted (a 16384² RGBA8 image is 1 GiB).
const MAX_DIMENSION: u32 = 16384;

/// Most array layers accepted (Vulkan guarantees at least 256; desktop GPUs offer 2048).
const MAX_LAYERS: u32 = 2048;

/// Decodes level 0 of a KTX2 file (Basis Universal ETC1S or UASTC, possibly Zstandard
/// supercompressed; also uncompressed RGBA8/R8G8B8A8 formats) into (width, height, RGBA8 pixels row-major).
pub fn decode_rgba(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), String> {
    let reader =
        ::ktx2::Reader::new(bytes).map_err(|e| format!("ktx2: not a valid KTX2 file ({e:?})"))?;
    let header = reader.header();
    let width = header.pixel_width;
    // A 1D texture has height 0; it is one row.
    let height = header.pixel_height.max(1);
    if width == 0 || width > MAX_DIMENSION || height > MAX_DIMENSION {
        return Err(format!(
            "ktx2: {width}×{height} is outside the supported size (1..={MAX_DIMENSION} per side)"
        ));
    }
    if header.pixel_depth > 1 {
        return Err(format!(
            "ktx2: 3D textures (depth {}) are not supported",
            header.pixel_depth
        ));
    }
    if header.face_count != 1 && header.face_count != 6 {
        return Err(format!(
            "ktx2: {} faces (1 or 6 expected)",
            header.face_count
        ));
    }
    if header.layer_count > MAX_LAYERS {
        return Err(format!(
            "ktx2: {} array layers (at most {MAX_LAYERS} supported)",
            header.layer_count
        ));
    }
    // Images in level 0: layers × faces (depth is 1 here).
    let images = u64::from(header.layer_count.max(1)) * u64::from(header.face_count);
    let level0 = reader
        .levels()
        .next()
        .ok_or("ktx2: the file has no mip level")?;

    match header.format {
        None => decode_basis(bytes, &header, &level0, images, width, height),
        Some(format) => decode_plain(format, &header, &level0, images, width, height),
    }
}

/// Basis Universal payloads (`VK_FORMAT_UNDEFINED`): ETC1S/BasisLZ or UASTC.
fn decode_basis(
    bytes: &[u8],
    header: &::ktx2::Header,
    level0: &::ktx2::Level<'_>,
    images: u64,
    width: u32,
    height: u32,
) -> Result<(u32, u32, Vec<u8>), String> {
    // UASTC stores 16 bytes per 4×4 block; check the declared sizes against that before the
    // transcoder allocates what they say.
    let blocks = u64::from(width.div_ceil(4)) * u64::from(height.div_ceil(4));
    // At most 4096² blocks × 16 bytes × 2048 layers × 6 faces: no overflow in u64.
    let uastc_bytes = blocks * 16 * images;
    match header.supercompression_scheme {
        Some(SupercompressionScheme::BasisLZ) => {
            if header.index.sgd_byte_length == 0 {
                return Err("ktx2: BasisLZ file without supercompression global data".into());
            }
        }
        Some(SupercompressionScheme::Zstandard) => {
            if level0.uncompressed_byte_length != uastc_bytes {
                return Err(format!(
                    "ktx2: level 0 declares {} uncompressed bytes, {width}×{height} UASTC needs \
                     {uastc_bytes}",
                    level0.uncompressed_byte_length
                ));
            }
        }
        None => {
            if level0.data.len() as u64 != uastc_bytes {
                return Err(format!(
                    "ktx2: level 0 holds {} bytes, {width}×{height} UASTC needs {uastc_bytes}",
                    level0.data.len()
                ));
            }
        }
        Some(other) => {
            return Err(format!(
                "ktx2: supercompression {other:?} is not supported for Basis data"
            ));
        }
    }
    let transcoder = ::basisu::Transcoder::new(bytes)
        .map_err(|e| format!("ktx2: not a Basis Universal texture ({e:?})"))?;
    if transcoder.base_dimensions() != (width, height) {
        return Err(format!(
            "ktx2: the transcoder sees {:?}, the header says {width}×{height}",
            transcoder.base_dimensions()
        ));
    }
    let pixels = transcoder
        .transcode_image(
            0,
            0,
            0,
            ::basisu::TargetFormat::Rgba32,
            ::basisu::DecodeFlags::NONE,
        )
        .map_err(|e| {
            format!(
                "ktx2: cannot transcode {:?} level 0 to RGBA32 ({e:?})",
                transcoder.source_format()
            )
        })?;
    let want = width as usize * height as usize * 4;
    if pixels.len() != want {
        return Err(format!(
            "ktx2: the transcoder returned {} bytes for {width}×{height} RGBA32 (expected {want})",
            pixels.len()
        ));
    }
    Ok((width, height, pixels))
}

/// Uncompressed 8-bit formats, possibly Zstandard supercompressed.
fn decode_plain(
    format: Format,
    header: &::ktx2::Header,
    level0: &::ktx2::Level<'_>,
    images: u64,
    width: u32,
    height: u32,
) -> Result<(u32, u32, Vec<u8>), String> {
    // (bytes per texel, BGR order)
    let (texel, bgr) = match format {
        Format::R8G8B8A8_UNORM | Format::R8G8B8A8_SRGB => (4, false),
        Format::B8G8R8A8_UNORM | Format::B8G8R8A8_SRGB => (4, true),
        Format::R8G8B8_UNORM | Format::R8G8B8_SRGB => (3, false),
        Format::B8G8R8_UNORM | Format::B8G8R8_SRGB => (3, true),
        other => return Err(format!("ktx2: Vulkan format {other:?} is not supported")),
    };
    let image_bytes = u64::from(width) * u64::from(height) * texel;
    // At most 16384² × 4 bytes × 2048 layers × 6 faces: no overflow in u64.
    let level_bytes = image_bytes * images;
    let decompressed;
    let data: &[u8] = match header.supercompression_scheme {
        None => level0.data,
        Some(SupercompressionScheme::Zstandard) => {
            if level0.uncompressed_byte_length != level_bytes {
                return Err(format!(
                    "ktx2: level 0 declares {} uncompressed bytes, {width}×{height} needs \
                     {level_bytes}",
                    level0.uncompressed_byte_length
                ));
            }
            decompressed = zstd_first_bytes(level0.data, image_bytes)?;
            &decompressed
        }
        Some(other) => {
            return Err(format!("ktx2: supercompression {other:?} is not supported"));
        }
    };
    if (data.len() as u64) < image_bytes {
        return Err(format!(
            "ktx2: level 0 holds {} bytes, {width}×{height} at {texel} bytes per texel needs \
             {image_bytes}",
            data.len()
        ));
    }
    // image_bytes <= 16384² × 4 fits in usize on the 64-bit targets we build for.
    let image = data
        .get(..image_bytes as usize)
        .ok_or("ktx2: level 0 is too short")?;
    let mut rgba = Vec::with_capacity(width as usize * height as usize * 4);
    for t in image.chunks_exact(texel as usize) {
        let (r, b) = if bgr { (t[2], t[0]) } else { (t[0], t[2]) };
        let a = if texel == 4 { t[3] } else { 255 };
        rgba.extend_from_slice(&[r, t[1], b, a]);
    }
    Ok((width, height, rgba))
}

/// The first `want` bytes of a Zstandard stream (an `Err` when it holds fewer).
fn zstd_first_bytes(compressed: &[u8], want: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let decoder = ::ruzstd::StreamingDecoder::new(compressed)
        .map_err(|e| format!("ktx2: bad Zstandard level data ({e})"))?;
    let mut out = Vec::new();
    decoder
        .take(want)
        .read_to_end(&mut out)
        .map_err(|e| format!("ktx2: bad Zstandard level data ({e})"))?;
    if (out.len() as u64) < want {
        return Err(format!(
            "ktx2: the Zstandard level data gave {} bytes, {want} expected",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal KTX2 file: one level, no DFD blocks, no key/value or global data.
    fn plain_ktx2(
        vk: u32,
        w: u32,
        h: u32,
        scheme: u32,
        level: &[u8],
        uncompressed: u64,
    ) -> Vec<u8> {
        let level_index_end = 80 + 24;
        let dfd_offset = level_index_end as u32;
        let level_offset = (level_index_end + 4) as u64;
        let mut f = Vec::new();
        f.extend_from_slice(&[
            0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
        ]);
        for v in [vk, 1, w, h, 0, 0, 1, 1, scheme] {
            f.extend_from_slice(&v.to_le_bytes());
        }
        for v in [dfd_offset, 4, 0, 0] {
            f.extend_from_slice(&v.to_le_bytes());
        }
        f.extend_from_slice(&0u64.to_le_bytes());
        f.extend_from_slice(&0u64.to_le_bytes());
        for v in [level_offset, level.len() as u64, uncompressed] {
            f.extend_from_slice(&v.to_le_bytes());
        }
        f.extend_from_slice(&4u32.to_le_bytes()); // DFD: only its total size
        f.extend_from_slice(level);
        f.push(0); // the ktx2 crate wants the DFD to end before the file does
        f
    }

    /// A Zstandard frame holding `data` in one raw block (`data.len()` < 256).
    fn zstd_raw(data: &[u8]) -> Vec<u8> {
        let mut z = vec![0x28, 0xB5, 0x2F, 0xFD, 0x20, data.len() as u8];
        let bh = ((data.len() as u32) << 3) | 1;
        z.extend_from_slice(&bh.to_le_bytes()[..3]);
        z.extend_from_slice(data);
        z
    }

    #[test]
    fn plain_formats_decode() {
        let px: Vec<u8> = (0..4 * 3 * 2).map(|i| i as u8 * 7).collect(); // 3×2 RGBA
        let (w, h, rgba) = decode_rgba(&plain_ktx2(37, 3, 2, 0, &px, px.len() as u64)).unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(rgba, px);
        // BGRA swaps red and blue.
        let (_, _, bgra) = decode_rgba(&plain_ktx2(50, 3, 2, 0, &px, px.len() as u64)).unwrap();
        assert_eq!(&bgra[..4], &[px[2], px[1], px[0], px[3]]);
        // RGB gets opaque alpha.
        let rgb: Vec<u8> = (0..3 * 3 * 2).map(|i| i as u8).collect();
        let (_, _, out) = decode_rgba(&plain_ktx2(23, 3, 2, 0, &rgb, rgb.len() as u64)).unwrap();
        assert_eq!(&out[..8], &[0, 1, 2, 255, 3, 4, 5, 255]);
        // Zstandard supercompressed RGBA.
        let z = zstd_raw(&px);
        let (_, _, out) = decode_rgba(&plain_ktx2(43, 3, 2, 2, &z, px.len() as u64)).unwrap();
        assert_eq!(out, px);
    }

    #[test]
    fn plain_format_errors() {
        let px = vec![9u8; 4 * 3 * 2];
        // Too short, unknown format, ZLIB, lying uncompressed size, truncated zstd, huge size.
        assert!(decode_rgba(&plain_ktx2(37, 3, 3, 0, &px, px.len() as u64)).is_err());
        assert!(decode_rgba(&plain_ktx2(131, 3, 2, 0, &px, px.len() as u64)).is_err());
        assert!(decode_rgba(&plain_ktx2(37, 3, 2, 3, &px, px.len() as u64)).is_err());
        let z = zstd_raw(&px);
        assert!(decode_rgba(&plain_ktx2(37, 3, 2, 2, &z, 1 << 40)).is_err());
        assert!(decode_rgba(&plain_ktx2(37, 3, 2, 2, &z[..z.len() - 3], 24)).is_err());
        assert!(decode_rgba(&plain_ktx2(37, 70000, 2, 0, &px, 24)).is_err());
        assert!(decode_rgba(&plain_ktx2(0, 16384, 16384, 2, &z, 1 << 40)).is_err());
        assert!(decode_rgba(&plain_ktx2(0, 16384, 16384, 0, &px, 24)).is_err());
        assert!(decode_rgba(b"").is_err());
        assert!(decode_rgba(b"\xABKTX 20\xBB\r\n\x1A\n").is_err());
    }

    /// The palm's KTX2 images, through the gltf crate's document: image → bufferView → bytes
    /// of the GLB BIN chunk. Also returns the base-colour image of the MASK (leaf) material.
    fn palm_images() -> Option<(Vec<Vec<u8>>, usize)> {
        let path = crate::scene::meshopt::tests::palm_glb()?;
        let bytes = std::fs::read(&path).unwrap();
        let gltf = ::gltf::Gltf::from_slice_without_validation(&bytes).unwrap();
        let bin = gltf.blob.as_deref().expect("GLB BIN chunk");
        let mut images = Vec::new();
        for image in gltf.document.images() {
            let ::gltf::image::Source::View { view, mime_type } = image.source() else {
                panic!("image {} is not in a buffer view", image.index());
            };
            assert_eq!(mime_type, "image/ktx2");
            images.push(bin[view.offset()..view.offset() + view.length()].to_vec());
        }
        // KHR_texture_basisu keeps the image index in the texture's extension object.
        let leaf = gltf
            .document
            .materials()
            .find(|m| m.alpha_mode() == ::gltf::material::AlphaMode::Mask)
            .expect("a MASK material");
        let tex = leaf
            .pbr_metallic_roughness()
            .base_color_texture()
            .unwrap()
            .texture();
        let source = tex.extension_value("KHR_texture_basisu").unwrap()["source"]
            .as_u64()
            .unwrap();
        Some((images, source as usize))
    }

    #[test]
    fn palm_images_decode() {
        let Some((images, leaf)) = palm_images() else {
            return;
        };
        assert_eq!(images.len(), 15);
        for (i, ktx) in images.iter().enumerate() {
            let (w, h, px) = decode_rgba(ktx).unwrap_or_else(|e| panic!("image {i}: {e}"));
            assert_eq!(px.len(), w as usize * h as usize * 4);
            let a0 = px.chunks_exact(4).filter(|p| p[3] == 0).count();
            let a255 = px.chunks_exact(4).filter(|p| p[3] == 255).count();
            let n = px.len() / 4;
            let is_uastc = ::basisu::Transcoder::new(ktx).unwrap().source_format()
                == ::basisu::SourceFormat::UastcLdr;
            eprintln!(
                "palm image {i}: {w}×{h} {} alpha 0: {a0}, 255: {a255}, other: {}",
                if is_uastc { "UASTC" } else { "ETC1S" },
                n - a0 - a255
            );
            // Not a blank image: the colour channels vary.
            let first = &px[..3];
            assert!(
                px.chunks_exact(4).any(|p| &p[..3] != first),
                "image {i} is flat"
            );
            if i == leaf {
                assert_eq!((w, h), (1024, 1024));
                assert!(is_uastc, "the leaf texture is UASTC");
                assert!(
                    a0 > n / 20 && a255 > n / 20,
                    "leaf alpha: {a0} zero, {a255} full"
                );
            }
        }
    }

    #[test]
    fn hostile_ktx2_is_an_error_not_a_panic() {
        let Some((images, _)) = palm_images() else {
            return;
        };
        // The smallest UASTC (zstd) and ETC1S (BasisLZ) images keep this quick.
        let mut small: Vec<&Vec<u8>> = images.iter().collect();
        small.sort_by_key(|k| k.len());
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for ktx in small.iter().take(3) {
            for _ in 0..40 {
                let cut = (rnd() as usize) % ktx.len();
                assert!(decode_rgba(&ktx[..cut]).is_err());
            }
            for round in 0..60 {
                let mut m = (*ktx).clone();
                // Half the rounds hit the header, level index, DFD and global data.
                let span = if round % 2 == 0 {
                    400.min(m.len())
                } else {
                    m.len()
                };
                for _ in 0..1 + rnd() % 6 {
                    let at = (rnd() as usize) % span;
                    m[at] = rnd() as u8;
                }
                if let Ok((w, h, px)) = decode_rgba(&m) {
                    assert_eq!(px.len(), w as usize * h as usize * 4);
                }
            }
        }
        let mut garbage = vec![0u8; 4096];
        garbage.iter_mut().for_each(|b| *b = rnd() as u8);
        assert!(decode_rgba(&garbage).is_err());
        garbage[..12].copy_from_slice(&images[0][..12]);
        assert!(decode_rgba(&garbage).is_err());
    }
}
