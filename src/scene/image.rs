//! Image decoding for alpha-tested cards: the alpha plane of a PNG (palette with `tRNS`
//! too), JPEG (no alpha: opaque), WebP or KTX2 (Basis Universal) image, told apart by their
//! first bytes.

/// Decodes an image's alpha: `(width, height, alpha row-major)`.
///
/// # Errors
/// A message saying what the bytes are not or why they did not decode.
pub fn decode_alpha(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), String> {
    const KTX2: &[u8] = b"\xABKTX 20\xBB\r\n\x1A\n";
    let (w, h, rgba) = if bytes.starts_with(KTX2) {
        decode_ktx2(bytes)?
    } else {
        let format = image::guess_format(bytes)
            .map_err(|_| "not a PNG, JPEG, WebP or KTX2 image".to_string())?;
        let img = image::load_from_memory_with_format(bytes, format)
            .map_err(|e| format!("cannot decode the {format:?} image: {e}"))?;
        let rgba = img.to_rgba8();
        (rgba.width(), rgba.height(), rgba.into_raw())
    };
    if w == 0 || h == 0 || rgba.len() != w as usize * h as usize * 4 {
        return Err(format!("the image decoded to a bad size ({w}×{h})"));
    }
    Ok((w, h, rgba.chunks_exact(4).map(|p| p[3]).collect()))
}

/// KTX2 through the Basis Universal transcoder ([`super::ktx2`]).
fn decode_ktx2(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>), String> {
    super::ktx2::decode_rgba(bytes).map_err(|e| format!("KTX2: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_alpha_and_garbage() {
        let mut img = image::RgbaImage::new(3, 2);
        img.put_pixel(1, 0, image::Rgba([1, 2, 3, 200]));
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let (w, h, a) = decode_alpha(&png).unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(a, vec![0, 200, 0, 0, 0, 0]);
        assert!(decode_alpha(b"hello").is_err());
        assert!(decode_alpha(&png[..20]).is_err());
    }
}
