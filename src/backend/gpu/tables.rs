//! Reprojection sources kept on the device across `render` calls: each source Depth Map's
//! summed-area table (`R32Uint` texture) and its umbra's bounding box, keyed by the source's
//! allocation ([`TableCache`]). In an occlusion sweep a plane's map is the source of the next
//! plane and of planes 2, 4, 8… further on (the bake's skip list), so without the cache the
//! same table was built and uploaded once per reprojection; with it, once per source.
//!
//! # Why a key cannot be confused
//!
//! A source is an `Arc<DepthMap>`; the key is its pointer and the entry holds a
//! [`Weak`] to it. While the `Weak` exists the allocation is not freed, so no other `Arc` can
//! have that address; and a `DepthMap` behind an `Arc` cannot change while a `Weak` to it exists
//! (`Arc::get_mut` refuses, `Arc::make_mut` copies). An entry whose source has no strong
//! reference left is evicted at the next call ([`TableCache::evict`]); its texture goes to a
//! free list of its size for reuse (a `queue.write_texture` runs after every earlier
//! submission, so reusing a texture cannot race a draw that read it).

use crate::plane::DepthMap;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, Weak};

/// Free textures kept per size: beyond this they are dropped.
const FREE_PER_SIZE: usize = 64;

/// One source's summed-area table on the device.
#[derive(Debug)]
pub(super) struct SweepTable {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    /// `(width, height)` of the source (and the texture).
    pub size: (u32, u32),
}

/// The umbra's bounding box `[x0, x1, y0, y1]` (inclusive) in the source's pixels, `None`
/// without umbra.
pub(super) type UmbraBox = Option<[u32; 4]>;

/// What the cache knows of a source.
#[derive(Clone, Debug)]
pub(super) struct Cached {
    /// Its table on the device (`None` without umbra: nothing to draw).
    pub table: Option<Arc<SweepTable>>,
    /// Its umbra's bounding box.
    pub umbra: UmbraBox,
}

struct Entry {
    source: Weak<DepthMap>,
    cached: Cached,
}

/// The cache, shared by every call of a backend (see the module docs).
#[derive(Default)]
pub(super) struct TableCache {
    inner: Mutex<Inner>,
}

#[derive(Default)]
struct Inner {
    live: HashMap<usize, Entry>,
    free: HashMap<(u32, u32), Vec<SweepTable>>,
}

impl TableCache {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What is cached for `source`, if anything.
    pub fn get(&self, source: &Arc<DepthMap>) -> Option<Cached> {
        // The key is the address, which the entry's Weak keeps taken (module docs).
        self.lock().live.get(&key(source)).map(|e| e.cached.clone())
    }

    /// Records `cached` for `source` (a later call finds it with [`Self::get`]).
    pub fn insert(&self, source: &Arc<DepthMap>, cached: Cached) {
        self.lock().live.insert(
            key(source),
            Entry {
                source: Arc::downgrade(source),
                cached,
            },
        );
    }

    /// Puts a texture no source uses on the free list of its size (at most
    /// [`FREE_PER_SIZE`] per size).
    pub fn give_back(&self, table: SweepTable) {
        let mut inner = self.lock();
        let list = inner.free.entry(table.size).or_default();
        if list.len() < FREE_PER_SIZE {
            list.push(table);
        }
    }

    /// A free texture of `size`, if one was evicted.
    pub fn take_free(&self, size: (u32, u32)) -> Option<SweepTable> {
        self.lock().free.get_mut(&size)?.pop()
    }

    /// Evicts the entries whose source is gone; their textures go to the free lists (at most
    /// [`FREE_PER_SIZE`] per size).
    pub fn evict(&self) {
        let mut inner = self.lock();
        let dead: Vec<usize> = inner
            .live
            .iter()
            .filter(|(_, e)| e.source.strong_count() == 0)
            .map(|(&k, _)| k)
            .collect();
        for k in dead {
            let Some(e) = inner.live.remove(&k) else {
                continue;
            };
            // Another call of this backend may still hold the Arc (its draws in flight): then
            // the texture is simply dropped (wgpu keeps it alive for those draws).
            if let Some(t) = e.cached.table.and_then(|t| Arc::try_unwrap(t).ok()) {
                let list = inner.free.entry(t.size).or_default();
                if list.len() < FREE_PER_SIZE {
                    list.push(t);
                }
            }
        }
    }
}

/// The cache key of a source: its allocation's address.
fn key(source: &Arc<DepthMap>) -> usize {
    Arc::as_ptr(source) as usize
}
