//! Measures run-time lookups: `cell_at` alone, `cell_at` plus iterating the visible set
//! through a cursor (random jumps, and a camera moving through neighbouring cells), and
//! `is_visible`, in ns per lookup.
//!
//! ```sh
//! cargo run --release --example lookup_bench              # a synthetic 10,000-cell file
//! cargo run --release --example lookup_bench -- city.pvs  # a baked file
//! ```
//!
//! The synthetic file is a 100 × 100 grid of cells over 4,096 objects, each cell seeing the
//! objects within a radius (a few hundred), encoded with the delta-PVS writer.

use std::hint::black_box;
use std::time::Instant;
use umbrasweep::pvs::{CellId, PvsCell, PvsDatabase, PvsDocument, PvsObject, binary};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn synthetic(n: usize, objects: usize) -> PvsDocument {
    let side = (objects as f64).sqrt() as usize;
    let pos = |o: usize| {
        let s = n as f32 / side as f32;
        ((o % side) as f32 * s, (o / side) as f32 * s)
    };
    let objs = (0..objects)
        .map(|o| {
            let (x, z) = pos(o);
            PvsObject {
                id: o as u32,
                name: format!("o{o}"),
                triangles: 12,
                min: [x, 0.0, z],
                max: [x + 0.5, 3.0, z + 0.5],
            }
        })
        .collect();
    let mut cells = Vec::with_capacity(n * n);
    for z in 0..n {
        for x in 0..n {
            let (cx, cz) = (x as f32 + 0.5, z as f32 + 0.5);
            let visible = (0..objects as u32)
                .filter(|&o| {
                    let (ox, oz) = pos(o as usize);
                    let r = 8.0 + 3.0 * ((o % 7) as f32 / 7.0);
                    (ox - cx).powi(2) + (oz - cz).powi(2) < r * r
                })
                .collect();
            cells.push(PvsCell {
                min: [x as f32, 0.0, z as f32],
                max: [x as f32 + 1.0, 2.0, z as f32 + 1.0],
                visible,
                ms: 0.0,
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
        summary: None,
        split: None,
    }
}

fn time<F: FnMut() -> usize>(label: &str, n: usize, mut f: F) {
    let t = Instant::now();
    let mut sink = 0usize;
    for _ in 0..n {
        sink = sink.wrapping_add(f());
    }
    let ns = t.elapsed().as_nanos() as f64 / n as f64;
    black_box(sink);
    println!("{label:44} {ns:9.1} ns per lookup");
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let db = match std::env::args().nth(1) {
        Some(p) => PvsDatabase::open(p)?,
        None => {
            let t = Instant::now();
            let bytes = binary::encode(&synthetic(100, 4096))?;
            println!(
                "encoded a synthetic file in {:.2} s",
                t.elapsed().as_secs_f64()
            );
            PvsDatabase::from_bytes(&bytes)?
        }
    };
    let s = db.stats();
    println!(
        "{} cells, {} objects, mean PVS {:.1}, file {} bytes (records {} vs plain bitsets {}), \
         delta depth mean {:.2} max {}",
        s.cells,
        s.objects,
        s.mean_visible,
        s.file_bytes,
        s.pvs_data_bytes,
        s.plain_bitset_bytes,
        s.mean_depth,
        s.max_depth
    );
    if s.cells == 0 {
        return Ok(());
    }
    // Points inside random cells.
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let points: Vec<[f32; 3]> = (0..65_536)
        .map(|_| {
            let c = (rng.next() % s.cells as u64) as u32;
            let (lo, hi) = db.cell_bounds(CellId(c));
            [0, 1, 2].map(|k| lo[k] + (hi[k] - lo[k]) * rng.unit())
        })
        .collect();
    // A camera path: from each cell to a cell whose box touches it.
    let mut walk = Vec::with_capacity(65_536);
    let mut p = points[0];
    for _ in 0..65_536 {
        let step = [0, 1, 2].map(|_| rng.unit() - 0.5);
        let q = [0, 1, 2].map(|k| p[k] + step[k] * 0.5);
        if db.cell_at(q).is_some() {
            p = q;
        }
        walk.push(p);
    }
    let n = points.len();
    let mut i = 0;
    time("cell_at", 2_000_000, || {
        i = (i + 1) % n;
        db.cell_at(black_box(points[i])).map_or(0, |c| c.index())
    });
    let mut cursor = db.cursor();
    time("cell_at + visible set, random cells", 200_000, || {
        i = (i + 1) % n;
        match db.cell_at(black_box(points[i])) {
            Some(c) => cursor.visible(&db, c).fold(0, |a, o| a ^ o as usize),
            None => 0,
        }
    });
    time("cell_at + visible set, camera walk", 400_000, || {
        i = (i + 1) % n;
        match db.cell_at(black_box(walk[i])) {
            Some(c) => cursor.visible(&db, c).fold(0, |a, o| a ^ o as usize),
            None => 0,
        }
    });
    time("cell_at + cursor move only, camera walk", 1_000_000, || {
        i = (i + 1) % n;
        match db.cell_at(black_box(walk[i])) {
            Some(c) => {
                cursor.move_to(&db, c);
                c.index()
            }
            None => 0,
        }
    });
    let objects = s.objects.max(1) as u64;
    time("is_visible, random cell and object", 1_000_000, || {
        i = (i + 1) % n;
        let c = CellId((i % s.cells) as u32);
        db.is_visible(c, (rng.next() % objects) as u32) as usize
    });
    Ok(())
}
