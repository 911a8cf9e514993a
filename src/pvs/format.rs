//! The byte-level definitions of the binary `.pvs` file laid out in `docs/pvs-format.md`: its
//! magic number, version, fixed lengths, record encodings and sentinel values, its checksum
//! ([`crc32`]) and the LEB128 varints of its records.
//!
//! This module owns those definitions; the writer ([`binary`](super::binary)) and the reader
//! ([`database`](super::database)) both take them from here, and it imports nothing from the
//! rest of [`pvs`](super). Changing anything here changes the file format: bump
//! [`FORMAT_VERSION`] and the document together.

/// The first 8 bytes of every `.pvs` file.
pub const MAGIC: [u8; 8] = *b"UMBRAPVS";
/// The binary format version this crate writes for a PVS.
pub const FORMAT_VERSION: u32 = 4;
/// The version of a shard's `.pvs` file (`bake --shard I/N -o SHARD.pvs`): version 4 with a
/// trailing section holding the shard's description for `umbrasweep merge`.
pub const SHARD_FORMAT_VERSION: u32 = 5;
/// The version of a file with extension sections (split objects, a cell hierarchy, or a
/// shard's description beside either): version 4's payload followed by tagged sections.
pub const EXTENDED_FORMAT_VERSION: u32 = 6;
/// Extension tag: a shard's description (UTF-8 JSON), as version 5's last section.
pub const TAG_SHARD: u32 = 1;
/// Extension tag: objects split into clusters (`--split-objects`), mapped to the file's.
pub const TAG_SPLIT: u32 = 2;
/// Extension tag: the cell hierarchy of adaptive subdivision (`--max-pvs-triangles`).
pub const TAG_HIERARCHY: u32 = 3;
/// Extension tag: culling settings version 4 has no field for (occluder selection by solid
/// angle); written only when one differs from its default.
pub const TAG_CULLING: u32 = 4;
/// Length of the fixed header: magic, version, checksum, payload length.
pub const HEADER_LEN: usize = 24;
/// The newest version this crate reads (it reads versions 1 to this one).
pub const LATEST_FORMAT_VERSION: u32 = EXTENDED_FORMAT_VERSION;
/// The `parent` value of a key cell (a record holding the full set).
pub const NO_PARENT: u32 = u32::MAX;
/// The `length` value of an absent optional string.
pub const NO_STRING: u32 = u32::MAX;
/// Record encoding: a bitset of `ceil(objects / 8)` bytes, least significant bit first.
pub const ENC_BITSET: u8 = 0;
/// Record encoding: LEB128 run lengths, alternately clear and set, starting with clear.
pub const ENC_RUNS: u8 = 1;
/// Record encoding: LEB128 gaps between ascending set ids.
pub const ENC_LIST: u8 = 2;
/// Bytes per object record (triangles, min, max).
pub const OBJECT_RECORD_LEN: usize = 28;
/// Bytes per cell record (min, max, parent, visible count, data length, encoding, reserved).
pub const CELL_RECORD_LEN: usize = 40;
/// The writer's cap on the number of records decoded to rebuild one cell from scratch
/// (readers must not assume it: any forest of parents is valid).
pub const MAX_DEPTH: u32 = 16;

/// The CRC-32 of `bytes` (IEEE 802.3, reflected polynomial `0xEDB88320`, initial value and
/// final XOR `0xFFFFFFFF`): the checksum of zlib's `crc32`, PNG and gzip.
pub fn crc32(bytes: &[u8]) -> u32 {
    const TABLE: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = i as u32;
            let mut k = 0;
            while k < 8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
                k += 1;
            }
            t[i] = c;
            i += 1;
        }
        t
    };
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c = TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c ^ 0xFFFF_FFFF
}

/// Bytes of `v` as an unsigned LEB128 varint.
pub(crate) fn varint_len(v: u32) -> usize {
    match v {
        0..0x80 => 1,
        0x80..0x4000 => 2,
        0x4000..0x20_0000 => 3,
        0x20_0000..0x1000_0000 => 4,
        _ => 5,
    }
}

/// Appends `v` as an unsigned LEB128 varint ([`varint_len`] bytes).
pub(crate) fn put_varint(out: &mut Vec<u8>, mut v: u32) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Reads an unsigned LEB128 varint of at most 5 bytes at `*pos`, advancing it; `None` when
/// it is cut short or overflows 32 bits.
pub(crate) fn get_varint(bytes: &[u8], pos: &mut usize) -> Option<u32> {
    let mut v = 0u32;
    for k in 0..5 {
        let b = *bytes.get(*pos)?;
        *pos += 1;
        if k == 4 && b > 0x0F {
            return None;
        }
        v |= ((b & 0x7F) as u32) << (7 * k);
        if b & 0x80 == 0 {
            return Some(v);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn varints_round_trip() {
        for v in [
            0,
            1,
            127,
            128,
            16383,
            16384,
            1 << 21,
            (1 << 28) - 1,
            1 << 28,
            u32::MAX,
        ] {
            let mut b = Vec::new();
            put_varint(&mut b, v);
            assert_eq!(b.len(), varint_len(v));
            let mut pos = 0;
            assert_eq!(get_varint(&b, &mut pos), Some(v));
            assert_eq!(pos, b.len());
        }
        assert_eq!(get_varint(&[0x80], &mut 0), None);
        assert_eq!(get_varint(&[0xFF, 0xFF, 0xFF, 0xFF, 0x1F], &mut 0), None);
    }
}
