//! The binary `.pvs` file and the run-time library (issue 7): JSON ↔ binary round trips on a
//! real bake of `data/demo_city.obj`, refusal of damaged files (wrong magic, other version,
//! truncation at every length, flipped bytes, inconsistent content) without panics,
//! `cell_at` against brute force, `is_visible` against `visible`, cursors walking the delta
//! tree in any order, and the `bake -o OUT.pvs` / `inspect` commands.

use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;
use umbrasweep::backend::cpu::CpuBackend;
use umbrasweep::bake::{BakeSettings, bake, to_document};
use umbrasweep::pvs::binary::{
    self, FORMAT_VERSION, HEADER_LEN, LATEST_FORMAT_VERSION, MAX_DEPTH, SHARD_FORMAT_VERSION, crc32,
};
use umbrasweep::pvs::{
    CellId, EncodeError, PvsCell, PvsDatabase, PvsDocument, PvsErrorKind, PvsJsonErrorKind,
    PvsObject, PvsSummary, PvsWriteErrorKind,
};
use umbrasweep::settings::{Spacing, SweepChoice, SweepSettings};

/// The demo city baked once (CPU backend, default settings).
fn city() -> &'static PvsDocument {
    static DOC: OnceLock<PvsDocument> = OnceLock::new();
    DOC.get_or_init(|| {
        let scene = umbrasweep::scene::load(Path::new("data/demo_city.obj")).unwrap();
        let cells = umbrasweep::cells::load_json(Path::new("data/demo_city_cells.json")).unwrap();
        let settings = BakeSettings::default();
        let r = bake(&scene, &cells, &settings, &CpuBackend::new(), None).unwrap();
        to_document(&scene, &cells, &r, &settings)
    })
}

fn city_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| binary::encode(city()).unwrap())
}

fn json(doc: &PvsDocument) -> String {
    serde_json::to_string_pretty(doc).unwrap()
}

/// A small deterministic generator (SplitMix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A synthetic document: a grid of `nx × nz` cells over objects on a grid, each cell seeing
/// the objects within a radius minus a pseudo-random few (spatially coherent, like a bake).
fn synthetic(nx: usize, nz: usize, objects: usize, seed: u64) -> PvsDocument {
    let mut rng = Rng(seed);
    let side = (objects as f64).sqrt().ceil() as usize;
    let pos = |o: usize| {
        let (x, z) = (o % side, o / side);
        (
            x as f32 * nx as f32 / side as f32,
            z as f32 * nz as f32 / side as f32,
        )
    };
    let objs = (0..objects)
        .map(|o| {
            let (x, z) = pos(o);
            PvsObject {
                id: o as u32,
                name: format!("object_{o}"),
                triangles: 12,
                min: [x, 0.0, z],
                max: [x + 0.5, 2.0, z + 0.5],
            }
        })
        .collect();
    let mut cells = Vec::new();
    for z in 0..nz {
        for x in 0..nx {
            let (cx, cz) = (x as f32 + 0.5, z as f32 + 0.5);
            let visible = (0..objects as u32)
                .filter(|&o| {
                    let (ox, oz) = pos(o as usize);
                    let d = ((ox - cx).powi(2) + (oz - cz).powi(2)).sqrt();
                    d < 4.0 + 2.0 * (((o as usize * 7 + x * 3 + z) % 5) as f32 / 5.0)
                        && rng.below(50) != 0
                })
                .collect();
            cells.push(PvsCell {
                min: [x as f32, 1.0, z as f32],
                max: [x as f32 + 1.0, 2.0, z as f32 + 1.0],
                visible,
                ms: rng.unit() as f64,
                cullers: Vec::new(),
                parent: None,
            });
        }
    }
    PvsDocument {
        format: umbrasweep::pvs::FORMAT.into(),
        version: umbrasweep::pvs::VERSION,
        scene: "synthetic".into(),
        settings: Default::default(),
        objects: objs,
        cells,
        summary: Some(PvsSummary {
            cells: nx * nz,
            objects,
            adapter: Some("none".into()),
            ..Default::default()
        }),
        split: None,
    }
}

#[test]
fn city_round_trips_json_to_binary_and_back() {
    let doc = city();
    assert!(doc.cells.len() == 24 && doc.objects.len() == 65);
    let db = PvsDatabase::from_bytes(city_bytes()).unwrap();
    assert_eq!(db.cell_count(), 24);
    assert_eq!(db.object_count(), 65);
    assert_eq!(json(&db.to_document()), json(doc));

    // Through files: bake's writers, then the binary reader.
    let dir = tempfile::tempdir().unwrap();
    let (pvs, js) = (dir.path().join("city.pvs"), dir.path().join("city.json"));
    binary::write(&pvs, doc).unwrap();
    umbrasweep::pvs::json::write(&js, doc).unwrap();
    let back = binary::read(&pvs).unwrap();
    assert_eq!(
        serde_json::to_vec_pretty(&back).unwrap(),
        std::fs::read(&js).unwrap()
    );
    assert!(std::fs::read(&pvs).unwrap() == city_bytes());
    // And the JSON file, read back and encoded, decodes to the same document.
    let from_json = umbrasweep::pvs::json::read(&js).unwrap();
    let again = PvsDatabase::from_bytes(&binary::encode(&from_json).unwrap()).unwrap();
    assert_eq!(json(&again.to_document()), json(&from_json));
}

#[test]
fn synthetic_round_trip_uses_every_encoding_and_caps_depth() {
    let doc = synthetic(30, 20, 900, 7);
    let bytes = binary::encode(&doc).unwrap();
    let db = PvsDatabase::from_bytes(&bytes).unwrap();
    assert_eq!(json(&db.to_document()), json(&doc));
    let s = db.stats();
    assert!(s.max_depth <= MAX_DEPTH, "{s:?}");
    assert!(s.key_cells >= 1 && s.key_cells < s.cells / 4, "{s:?}");
    assert!(s.pvs_data_bytes * 3 < s.plain_bitset_bytes, "{s:?}");
    // Every encoding appears on a suitable document (dense key cells as bitsets, scattered
    // differences as lists, contiguous differences as runs).
    let mut dense = synthetic(4, 4, 200, 3);
    for (i, c) in dense.cells.iter_mut().enumerate() {
        let own = 100 + 3 * i as u32;
        c.visible = (0..200)
            .filter(|&o| o < 100 || o % 3 != 0 || o == own)
            .collect();
        if i == 5 {
            c.visible.retain(|&o| !(10..60).contains(&o));
        }
    }
    let db = PvsDatabase::from_bytes(&binary::encode(&dense).unwrap()).unwrap();
    assert_eq!(json(&db.to_document()), json(&dense));
    let by = db.stats().records_by_encoding;
    assert!(by.iter().all(|&n| n > 0), "{by:?}");
}

#[test]
fn empty_and_tiny_documents() {
    for (cells, objects) in [(0, 0), (1, 0), (0, 3), (1, 1), (2, 64), (3, 65)] {
        let mut doc = synthetic(cells, 1, objects, 1);
        doc.cells.truncate(cells);
        let db = PvsDatabase::from_bytes(&binary::encode(&doc).unwrap()).unwrap();
        assert_eq!(json(&db.to_document()), json(&doc));
        assert_eq!(db.cell_at([0.5, 1.5, 0.5]).is_some(), cells > 0);
    }
}

#[test]
fn encode_refuses_what_it_cannot_hold() {
    let mut doc = synthetic(2, 1, 10, 1);
    doc.cells[1].visible = vec![3, 2];
    let e = binary::encode(&doc).unwrap_err();
    assert_eq!(
        e,
        EncodeError::NotAscending {
            cell: 1,
            previous: 3,
            id: 2
        }
    );
    assert!(e.to_string().contains("ascending"), "{e}");
    doc.cells[1].visible = vec![10];
    let e = binary::encode(&doc).unwrap_err();
    assert!(matches!(
        e,
        EncodeError::MissingObject {
            cell: 1,
            object: 10,
            objects: 10
        }
    ));
    assert!(e.to_string().contains("only 10 objects"), "{e}");
    doc.cells[1].visible = vec![];
    doc.objects[4].id = 7;
    let e = binary::encode(&doc).unwrap_err();
    assert!(matches!(
        e,
        EncodeError::ObjectOutOfOrder { index: 4, id: 7 }
    ));
    assert!(e.to_string().contains("object 4 has id 7"), "{e}");
    // Writing names the file and leaves nothing behind.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.pvs");
    let e = binary::write(&p, &doc).unwrap_err();
    assert!(matches!(e.kind, PvsWriteErrorKind::Encode(_)), "{e}");
    assert_eq!(
        e.to_string(),
        format!(
            "{}: object 4 has id 7: the .pvs format numbers objects 0, 1, 2… in order",
            p.display()
        )
    );
    assert!(!p.exists());
}

fn kind(bytes: &[u8]) -> PvsErrorKind {
    match PvsDatabase::from_bytes(bytes) {
        Ok(_) => panic!("damaged file accepted"),
        Err(e) => {
            assert!(!e.to_string().is_empty());
            e.kind
        }
    }
}

#[test]
fn wrong_magic_is_refused() {
    let mut b = city_bytes().to_vec();
    b[0] = b'X';
    assert_eq!(
        kind(&b),
        PvsErrorKind::BadMagic {
            looks_like_json: false
        }
    );
    let js = serde_json::to_vec_pretty(city()).unwrap();
    let e = PvsDatabase::from_bytes(&js).unwrap_err();
    assert_eq!(
        e.kind,
        PvsErrorKind::BadMagic {
            looks_like_json: true
        }
    );
    assert!(e.to_string().contains("JSON"), "{e}");
}

#[test]
fn other_versions_are_refused_before_anything_else() {
    for v in [0, LATEST_FORMAT_VERSION + 1, u32::MAX] {
        let mut b = city_bytes().to_vec();
        b[8..12].copy_from_slice(&v.to_le_bytes());
        assert_eq!(kind(&b), PvsErrorKind::UnsupportedVersion { found: v });
        // A future version may have another header: only the first 12 bytes are read.
        assert_eq!(
            kind(&b[..12]),
            PvsErrorKind::UnsupportedVersion { found: v }
        );
        let e = PvsDatabase::from_bytes(&b).unwrap_err().to_string();
        assert!(e.contains(&format!("version {v}")), "{e}");
    }
}

#[test]
fn truncated_at_every_length_is_refused() {
    let b = city_bytes();
    for k in 0..b.len() {
        match kind(&b[..k]) {
            PvsErrorKind::Truncated { actual, .. } => assert_eq!(actual, k as u64),
            other => panic!("length {k}: {other:?}"),
        }
    }
    let mut longer = b.to_vec();
    longer.push(0);
    assert!(matches!(kind(&longer), PvsErrorKind::TrailingBytes { .. }));
}

#[test]
fn flipped_bytes_are_refused() {
    let b = city_bytes();
    for i in 0..b.len() {
        for bit in [0x01u8, 0x80] {
            let mut d = b.to_vec();
            d[i] ^= bit;
            let k = kind(&d);
            let expected_ok = match i {
                0..8 => matches!(k, PvsErrorKind::BadMagic { .. }),
                // Another version: unknown, or an older one that misreads the payload.
                8..12 => matches!(
                    k,
                    PvsErrorKind::UnsupportedVersion { .. } | PvsErrorKind::Corrupt(_)
                ),
                16..24 => matches!(
                    k,
                    PvsErrorKind::Truncated { .. } | PvsErrorKind::TrailingBytes { .. }
                ),
                _ => matches!(k, PvsErrorKind::Checksum { .. }),
            };
            assert!(expected_ok, "byte {i} ^ {bit:#x}: {k:?}");
        }
    }
}

/// Damage behind a recomputed checksum (a buggy writer): every byte of the payload changed in
/// turn, checksum fixed up. Never a panic; structural damage and sets that do not decode to
/// their stored size are refused.
#[test]
fn inconsistent_content_with_a_valid_checksum_never_panics() {
    let doc = synthetic(6, 4, 150, 11);
    let b = binary::encode(&doc).unwrap();
    let mut messages = Vec::new();
    for i in HEADER_LEN..b.len() {
        for v in [0x00u8, 0xFF, b[i] ^ 0x01] {
            let mut d = b.clone();
            if d[i] == v {
                continue;
            }
            d[i] = v;
            let crc = crc32(&d[HEADER_LEN..]);
            d[12..16].copy_from_slice(&crc.to_le_bytes());
            if let Err(e) = PvsDatabase::from_bytes(&d) {
                assert!(matches!(e.kind, PvsErrorKind::Corrupt(_)), "{e}");
                messages.push(e.to_string());
            }
        }
    }
    for want in [
        "decodes to",
        "runs past the end",
        "missing cell",
        "not UTF-8",
    ] {
        assert!(messages.iter().any(|m| m.contains(want)), "{want}");
    }
}

#[test]
fn cell_at_matches_brute_force() {
    for doc in [city().clone(), synthetic(17, 9, 100, 5)] {
        let db = PvsDatabase::from_bytes(&binary::encode(&doc).unwrap()).unwrap();
        let brute = |p: [f32; 3]| {
            doc.cells
                .iter()
                .position(|c| (0..3).all(|k| c.min[k] <= p[k] && p[k] <= c.max[k]))
                .map(|i| CellId(i as u32))
        };
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for c in &doc.cells {
            for k in 0..3 {
                lo[k] = lo[k].min(c.min[k]);
                hi[k] = hi[k].max(c.max[k]);
            }
        }
        let mut rng = Rng(42);
        let mut hits = 0;
        for _ in 0..20_000 {
            // Half uniform over the cells' bounds and beyond, half near a random cell.
            let (a, b) = if rng.below(2) == 0 {
                (lo, hi)
            } else {
                let c = &doc.cells[rng.below(doc.cells.len())];
                (c.min, c.max)
            };
            let p = [0, 1, 2].map(|k| {
                let span = b[k] - a[k];
                a[k] - 0.1 * span + 1.2 * span * rng.unit()
            });
            let got = db.cell_at(p);
            assert_eq!(got, brute(p), "{p:?}");
            hits += got.is_some() as usize;
        }
        assert!(hits > 5000, "{hits}");
        // Corners, faces and centres of every cell, exactly.
        for c in &doc.cells {
            for m in 0..27 {
                let p = [0, 1, 2].map(|k| match (m / 3usize.pow(k as u32)) % 3 {
                    0 => c.min[k],
                    1 => 0.5 * (c.min[k] + c.max[k]),
                    _ => c.max[k],
                });
                assert_eq!(db.cell_at(p), brute(p), "{p:?}");
            }
        }
        assert_eq!(db.cell_at([f32::NAN, 0.0, 0.0]), None);
        assert_eq!(db.cell_at([f32::INFINITY, 0.0, 0.0]), None);
    }
}

#[test]
fn is_visible_agrees_with_visible() {
    for doc in [city().clone(), synthetic(8, 8, 300, 9)] {
        let db = PvsDatabase::from_bytes(&binary::encode(&doc).unwrap()).unwrap();
        for c in 0..db.cell_count() {
            let cell = CellId(c as u32);
            let set: Vec<u32> = db.visible(cell).collect();
            assert_eq!(set, doc.cells[c].visible);
            assert_eq!(db.visible_count(cell), set.len());
            for o in 0..db.object_count() as u32 + 3 {
                assert_eq!(db.is_visible(cell, o), set.binary_search(&o).is_ok());
            }
        }
    }
}

#[test]
fn walking_the_deltas_in_any_order_gives_the_json_sets() {
    for doc in [city().clone(), synthetic(20, 15, 500, 13)] {
        let db = PvsDatabase::from_bytes(&binary::encode(&doc).unwrap()).unwrap();
        let n = db.cell_count() as u32;
        let mut rng = Rng(3);
        let mut orders: Vec<Vec<u32>> = vec![(0..n).collect(), (0..n).rev().collect()];
        orders.push((0..3 * n).map(|_| rng.below(n as usize) as u32).collect());
        // A camera path: always to a spatial neighbour (the closest other cell centre).
        let mut walk = vec![0u32];
        for _ in 0..2 * n {
            let c = &doc.cells[*walk.last().unwrap() as usize];
            let near = (0..n)
                .filter(|&j| {
                    let d = &doc.cells[j as usize];
                    (0..3).all(|k| d.min[k] <= c.max[k] + 1.0 && c.min[k] <= d.max[k] + 1.0)
                })
                .collect::<Vec<_>>();
            walk.push(near[rng.below(near.len())]);
        }
        orders.push(walk);
        let mut cursor = db.cursor();
        assert_eq!(cursor.iter().count(), 0);
        for order in &orders {
            for &c in order {
                let got: Vec<u32> = cursor.visible(&db, CellId(c)).collect();
                assert_eq!(got, doc.cells[c as usize].visible, "cell {c}");
                assert_eq!(cursor.visible_count(), got.len());
                assert_eq!(cursor.cell(), Some(CellId(c)));
                for &o in got.iter().take(5) {
                    assert!(cursor.contains(o));
                }
            }
        }
        // A cursor of another database starts over instead of answering wrongly.
        let other = PvsDatabase::from_bytes(&binary::encode(&doc).unwrap()).unwrap();
        let got: Vec<u32> = cursor.visible(&other, CellId(n - 1)).collect();
        assert_eq!(got, doc.cells[n as usize - 1].visible);
    }
}

#[test]
fn open_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.pvs");
    std::fs::write(&p, &city_bytes()[..100]).unwrap();
    let e = PvsDatabase::open(&p).unwrap_err();
    assert!(e.to_string().starts_with(&p.display().to_string()), "{e}");
    assert!(e.to_string().contains("truncated"), "{e}");
    let e = PvsDatabase::open(dir.path().join("missing.pvs")).unwrap_err();
    assert!(matches!(e.kind, PvsErrorKind::Io(_)), "{e}");
}

#[test]
fn writers_and_the_json_reader_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // No such directory: an I/O error naming the file, once.
    let p = dir.path().join("missing").join("city.pvs");
    for e in [
        binary::write(&p, city()).unwrap_err(),
        umbrasweep::pvs::json::write(&p, city()).unwrap_err(),
    ] {
        assert!(matches!(e.kind, PvsWriteErrorKind::Io(_)), "{e}");
        let text = e.to_string();
        let name = p.display().to_string();
        assert!(text.starts_with(&format!("{name}: ")), "{e}");
        assert_eq!(text.matches(&name).count(), 1, "{e}");
    }
    // The JSON reader: missing, binary, other format, missing object.
    let read = |p: &Path| umbrasweep::pvs::json::read(p).unwrap_err();
    let e = read(&dir.path().join("none.json"));
    assert!(matches!(e.kind, PvsJsonErrorKind::Io(_)), "{e}");
    assert!(e.to_string().contains("none.json: cannot read: "), "{e}");
    let bin = dir.path().join("city.pvs");
    std::fs::write(&bin, city_bytes()).unwrap();
    let e = read(&bin);
    assert!(
        matches!(e.kind, PvsJsonErrorKind::Io(_) | PvsJsonErrorKind::Parse(_)),
        "{e}"
    );
    let mut doc = synthetic(2, 1, 3, 1);
    doc.format = "other".into();
    let js = dir.path().join("doc.json");
    std::fs::write(&js, json(&doc)).unwrap();
    assert_eq!(
        read(&js).to_string(),
        format!(
            "{}: format is \"other\", expected \"umbrasweep-pvs\"",
            js.display()
        )
    );
    doc.format = umbrasweep::pvs::FORMAT.into();
    doc.cells[0].visible = vec![5];
    std::fs::write(&js, json(&doc)).unwrap();
    let e = read(&js);
    assert!(
        matches!(
            e.kind,
            PvsJsonErrorKind::MissingObject {
                cell: 0,
                object: 5,
                objects: 3
            }
        ),
        "{e}"
    );
}

fn umbrasweep(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_umbrasweep"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn bake_writes_pvs_and_inspect_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let pvs = dir.path().join("city.pvs");
    let js = dir.path().join("city.json");
    let pvs_s = pvs.to_str().unwrap();
    for out in [pvs_s, js.to_str().unwrap()] {
        let o = umbrasweep(&[
            "bake",
            "data/demo_city.obj",
            "--cells",
            "data/demo_city_cells.json",
            "--backend",
            "cpu",
            "-q",
            "-o",
            out,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // `inspect --json` gives the document `bake -o OUT.json` writes (the timings differ
    // between the two bakes).
    let o = umbrasweep(&["inspect", pvs_s, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let strip = |text: &[u8]| {
        let mut v: serde_json::Value = serde_json::from_slice(text).unwrap();
        for c in v["cells"].as_array_mut().unwrap() {
            c["ms"] = 0.into();
        }
        v["summary"]["median_ms_per_cell"] = 0.into();
        v["summary"]["total_seconds"] = 0.into();
        for c in v["summary"]["cullers"].as_array_mut().unwrap() {
            c["ms"] = 0.into();
        }
        v
    };
    assert_eq!(strip(&o.stdout), strip(&std::fs::read(&js).unwrap()));
    // And byte for byte what the JSON writer makes of the same document.
    let doc = binary::read(&pvs).unwrap();
    assert_eq!(o.stdout, serde_json::to_vec_pretty(&doc).unwrap());

    let o = umbrasweep(&["inspect", pvs_s]);
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(o.status.success());
    for want in [
        "cells           24",
        "objects         65",
        "average PVS",
        "file size",
        "plain bitsets",
    ] {
        assert!(text.contains(want), "{want}: {text}");
    }
    let o = umbrasweep(&["inspect", pvs_s, "--cell", "3"]);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    let listed: Vec<u32> = text
        .lines()
        .filter_map(|l| l.split('\t').next()?.parse().ok())
        .collect();
    assert_eq!(listed, doc.cells[3].visible, "{text}");
    assert!(text.contains("ground") || !doc.cells[3].visible.contains(&0));

    // Errors: exit 2 with the file named, no panic.
    let o = umbrasweep(&["inspect", pvs_s, "--cell", "24"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no cell 24"));
    let o = umbrasweep(&["inspect", js.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(err.contains("city.json") && err.contains("JSON"), "{err}");
    let cut = dir.path().join("cut.pvs");
    std::fs::write(&cut, &std::fs::read(&pvs).unwrap()[..50]).unwrap();
    let o = umbrasweep(&["inspect", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("truncated"));
}

#[test]
fn version_4_keeps_the_cullers_and_sweep_settings_and_versions_1_to_3_still_read() {
    let mut doc = city().clone();
    let s = &mut doc.settings.bake;
    s.sweep = SweepChoice::On;
    s.sweep_settings.planes = 20;
    s.sweep_settings.kernel = 7;
    s.sweep_settings.spacing = Spacing::Kernel;
    s.subcell = Some(2.0);
    s.max_stretch = 4;
    // A bake records the sampler and ray space factorization as they ran (true or false);
    // the cullers' accounts below name neither.
    s.sampling = SweepChoice::Off;
    s.rsf = SweepChoice::Off;
    let culler = umbrasweep::pvs::PvsCullerSummary {
        name: "occlusion_sweep".into(),
        hidden: 12.5,
        only: 11.5,
        ms: 3.25,
        planes: 7.0,
        ..Default::default()
    };
    doc.summary.as_mut().unwrap().cullers = vec![culler.clone()];
    let v4 = binary::encode(&doc).unwrap();
    assert_eq!(&v4[8..12], &4u32.to_le_bytes());
    let back = PvsDatabase::from_bytes(&v4).unwrap().to_document();
    assert_eq!(json(&back), json(&doc));
    // The sampler's switch is read back from the cullers' accounts.
    let mut sampled = doc.clone();
    sampled.settings.bake.sampling = SweepChoice::On;
    sampled
        .summary
        .as_mut()
        .unwrap()
        .cullers
        .push(umbrasweep::pvs::PvsCullerSummary {
            name: "shrunk_sampling".into(),
            hidden: 1.0,
            ..Default::default()
        });
    let back_sampled = PvsDatabase::from_bytes(&binary::encode(&sampled).unwrap())
        .unwrap()
        .to_document();
    assert_eq!(json(&back_sampled), json(&sampled));
    assert_eq!(back.summary.unwrap().cullers, vec![culler]);

    // Rewrites `file`'s payload without `cut` (found in it), as version `version`.
    let older = |file: &[u8], cut: &[u8], keep: usize, version: u32| {
        let payload = &file[HEADER_LEN..];
        let at = payload
            .windows(cut.len())
            .position(|w| w == cut)
            .expect("the newer settings in the payload");
        let mut p = payload[..at + keep].to_vec();
        p.extend_from_slice(&payload[at + cut.len()..]);
        let mut out = file[..8].to_vec();
        out.extend(version.to_le_bytes());
        out.extend(crc32(&p).to_le_bytes());
        out.extend((p.len() as u64).to_le_bytes());
        out.extend(p);
        out
    };
    // Version 3 wrote no cullers after the summary's total_seconds.
    let mut cullers = 1u32.to_le_bytes().to_vec();
    cullers.extend(15u32.to_le_bytes());
    cullers.extend(b"occlusion_sweep");
    for v in [12.5f64, 11.5, 3.25, 7.0] {
        cullers.extend(v.to_le_bytes());
    }
    let v3 = older(&v4, &cullers, 0, 3);
    let old = PvsDatabase::from_bytes(&v3).unwrap().to_document();
    let mut expected = doc.clone();
    expected.summary.as_mut().unwrap().cullers.clear();
    assert_eq!(json(&old), json(&expected));

    // Version 2 wrote no max_stretch after the subcell size: maps were square.
    let mut v3_tail = 2.0f64.to_le_bytes().to_vec();
    v3_tail.extend(4u32.to_le_bytes());
    let v2 = older(&v3, &v3_tail, 8, 2);
    let old = PvsDatabase::from_bytes(&v2).unwrap().to_document();
    expected.settings.bake.max_stretch = 1;
    assert_eq!(json(&old), json(&expected));

    // The same file as version 1 wrote it: without the sweep fields.
    let mut ext = vec![1u8];
    ext.extend(20u32.to_le_bytes());
    ext.extend(7u32.to_le_bytes());
    ext.extend(6u32.to_le_bytes());
    ext.extend(b"kernel");
    ext.push(1);
    ext.extend(2.0f64.to_le_bytes());
    let v1 = older(&v2, &ext, 0, 1);
    let old = PvsDatabase::from_bytes(&v1).unwrap().to_document();
    assert!(old.settings.bake.sweep == SweepChoice::Off && old.settings.bake.subcell.is_none());
    expected.settings.bake.sweep = SweepChoice::Off;
    expected.settings.bake.sweep_settings = SweepSettings::default();
    expected.settings.bake.subcell = None;
    assert_eq!(json(&old), json(&expected));
}

/// A shard's file (version 5) reads as its version 4 payload plus the shard's description;
/// a whole bake's file (version 4) has none.
#[test]
fn shard_files_carry_their_description() {
    let plain = PvsDatabase::from_bytes(city_bytes()).unwrap();
    assert_eq!(plain.shard(), None);
    assert_eq!(
        u32::from_le_bytes(city_bytes()[8..12].try_into().unwrap()),
        FORMAT_VERSION
    );
    let doc = plain.to_document();
    let bytes = binary::encode_shard(&doc, "{\"format\": \"umbrasweep-shard\"}").unwrap();
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
        SHARD_FORMAT_VERSION
    );
    let shard = PvsDatabase::from_bytes(&bytes).unwrap();
    assert_eq!(shard.shard(), Some("{\"format\": \"umbrasweep-shard\"}"));
    assert_eq!(shard.cell_count(), plain.cell_count());
    assert_eq!(
        serde_json::to_string(&shard.to_document()).unwrap(),
        serde_json::to_string(&doc).unwrap()
    );
    // Cut short inside the description: refused, as any truncation is.
    let mut cut = bytes.clone();
    cut.truncate(cut.len() - 3);
    assert!(PvsDatabase::from_bytes(&cut).is_err());
}
