//! Closed-manifold detection: owns [`SceneObject::closed`](super::SceneObject::closed).
//!
//! An object is closed when its triangles, ignoring degenerate (zero-area) ones and after
//! welding vertices with bit-identical positions (`-0.0` and `0.0` count as equal), form
//! closed 2-manifold surfaces: every undirected edge is used by exactly two triangles, with
//! opposite orientation. An object without any non-degenerate triangle is not closed.
//!
//! Welding uses a hash map on the coordinates' bit patterns; the edge test sorts packed edge
//! keys. Objects are checked in parallel.

use super::{Scene, is_degenerate};
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};

/// Sets [`SceneObject::closed`](super::SceneObject::closed) for every object of `scene`.
pub fn mark_closed_objects(scene: &mut Scene) {
    let s: &Scene = scene;
    let closed: Vec<bool> = s
        .objects
        .par_iter()
        .with_min_len(16)
        .map_init(Scratch::default, |scratch, o| {
            let tris = &s.triangles[o.triangles.start as usize..o.triangles.end as usize];
            scratch.closed(tris.iter().map(|&[a, b, c]| {
                [
                    s.vertices[a as usize],
                    s.vertices[b as usize],
                    s.vertices[c as usize],
                ]
            }))
        })
        .collect();
    for (o, c) in scene.objects.iter_mut().zip(closed) {
        o.closed = c;
    }
}

/// True when `tris` form closed 2-manifold surfaces (see the module documentation).
pub fn is_closed(tris: &[[Vec3; 3]]) -> bool {
    Scratch::default().closed(tris.iter().copied())
}

/// Position key: the coordinates' bit patterns, `-0.0` folded onto `0.0`.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Key([u32; 3]);

impl Key {
    fn of(p: Vec3) -> Key {
        let bits = |x: f32| if x == 0.0 { 0 } else { x.to_bits() };
        Key([bits(p.x), bits(p.y), bits(p.z)])
    }
}

impl Hash for Key {
    #[inline]
    fn hash<H: Hasher>(&self, state: &mut H) {
        let [x, y, z] = self.0;
        let mut h = (x as u64 | (y as u64) << 32).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (z as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        h ^= h >> 31;
        h = h.wrapping_mul(0x1656_67B1_9E37_79F9);
        h ^= h >> 29;
        state.write_u64(h);
    }
}

/// Passes a pre-mixed `u64` through.
#[derive(Default)]
struct PassHasher(u64);

impl Hasher for PassHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = v;
    }
}

/// Buffers reused between objects.
#[derive(Default)]
struct Scratch {
    weld: HashMap<Key, u32, BuildHasherDefault<PassHasher>>,
    edges: Vec<u64>,
}

impl Scratch {
    fn closed(&mut self, tris: impl Iterator<Item = [Vec3; 3]>) -> bool {
        self.weld.clear();
        self.edges.clear();
        for t in tris {
            if is_degenerate(t) {
                continue;
            }
            let mut id = [0u32; 3];
            for (k, &p) in t.iter().enumerate() {
                let next = self.weld.len() as u32;
                id[k] = *self.weld.entry(Key::of(p)).or_insert(next);
            }
            if self.weld.len() >= 1 << 31 {
                return false; // Cannot pack the edge keys; far beyond any real object.
            }
            for k in 0..3 {
                let (a, b) = (id[k] as u64, id[(k + 1) % 3] as u64);
                // Undirected edge (min, max) in the high bits, direction in bit 0.
                let (lo, hi, dir) = if a < b { (a, b, 0) } else { (b, a, 1) };
                self.edges.push(lo << 33 | hi << 1 | dir);
            }
        }
        if self.edges.is_empty() || !self.edges.len().is_multiple_of(2) {
            return false;
        }
        self.edges.sort_unstable();
        // Sorted, every edge must appear exactly as the pair (key|0, key|1): used twice, once
        // in each direction. A third use or a repeated direction breaks the pairing.
        self.edges
            .chunks_exact(2)
            .all(|p| p[0] & 1 == 0 && p[1] == p[0] | 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> Vec<[Vec3; 3]> {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        vec![
            [p[0], p[2], p[1]],
            [p[0], p[1], p[3]],
            [p[0], p[3], p[2]],
            [p[1], p[2], p[3]],
        ]
    }

    #[test]
    fn tetrahedron_closed_and_open() {
        let t = tetra();
        assert!(is_closed(&t));
        assert!(!is_closed(&t[..3]));
        let mut flipped = t.clone();
        flipped[0].swap(1, 2);
        assert!(!is_closed(&flipped));
        assert!(!is_closed(&[]));
    }

    #[test]
    fn negative_zero_welds_and_degenerates_are_ignored() {
        let mut t = tetra();
        t[1][0] = Vec3::new(-0.0, 0.0, -0.0);
        t.push([Vec3::X, Vec3::X, Vec3::Y]);
        assert!(is_closed(&t));
    }
}
