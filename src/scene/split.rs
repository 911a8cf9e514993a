//! Splitting objects too big to cull (`bake --split-objects SIZE`): every object larger than
//! `SIZE` along some axis becomes spatial clusters — its connected components, grouped or cut
//! by a median split along the longest axis until each cluster fits in `SIZE` — with a stable
//! mapping back to the object of the file ([`SplitMap`]).
//!
//! Real files number objects badly for a PVS: the Cube 2 levels group triangles by texture
//! (84–206 objects that each span the level), city files have one ground object, foliage files
//! one mesh per tree. An object is visible when any of its triangles is, so one that spans the
//! level is visible from everywhere; its clusters are culled one by one.
//!
//! # The rule
//! 1. Objects whose bounds fit in `SIZE` on every axis stay whole (one cluster).
//! 2. Larger ones are cut into connected components: triangles sharing a vertex position
//!    (positions compared exactly, so that welded and unwelded meshes split alike).
//! 3. The components are split recursively: a set of components whose common bounds fit stays
//!    one cluster; otherwise the set is cut in two at the median of the components' centres
//!    along the longest axis of the set's bounds; a single component too large is cut the same
//!    way triangle by triangle (by the triangles' centroids). A single triangle is a cluster
//!    whatever its size.
//! 4. Clusters keep the order of their objects, and within an object the order of that
//!    recursion (lower half first): the same file and `SIZE` always give the same clusters and
//!    ids. Cluster `k` of object `name` is named `name#k`; an object left whole keeps its name.
//!
//! # Why it is conservative
//! Splitting changes what a PVS lists, not what is visible: an original object is visible from
//! a cell exactly when one of its clusters is, and the PVS keeps every cluster it cannot prove
//! hidden ([`PvsSplit::source_visible`](crate::pvs::PvsSplit::source_visible) gives the
//! original objects). Occlusion can only get
//! weaker: a closed object cut into open pieces stops occluding as a solid (each cluster is
//! tested for closedness again), which loses culling, never correctness.

use super::{Scene, SceneObject};
use crate::geom::Aabb;
use glam::Vec3;
use std::collections::HashMap;

/// The mapping from a split scene's objects (clusters) back to the objects of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct SplitMap {
    /// The `SIZE` the scene was split with, in scene units.
    pub size: f32,
    /// The objects of the file, in their id order.
    pub sources: Vec<SourceObject>,
}

/// One object of the file and the clusters it became.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceObject {
    /// Its name in the file.
    pub name: String,
    /// Its triangle count.
    pub triangles: u32,
    /// Its bounds.
    pub bounds: Aabb,
    /// Its clusters: a range of the split scene's object ids (contiguous; may be empty for an
    /// object without triangles only when it had none, then it keeps one empty cluster).
    pub clusters: std::ops::Range<u32>,
}

impl SplitMap {
    /// The PVS document's form of the mapping (`split` in the document and the `.pvs` file),
    /// where [`PvsSplit::source_of`](crate::pvs::PvsSplit::source_of) and
    /// [`PvsSplit::source_visible`](crate::pvs::PvsSplit::source_visible) answer lookups.
    pub fn to_pvs(&self) -> crate::pvs::PvsSplit {
        crate::pvs::PvsSplit {
            size: self.size,
            sources: (self.sources.iter().enumerate())
                .map(|(i, s)| crate::pvs::PvsSource {
                    id: i as u32,
                    name: s.name.clone(),
                    triangles: s.triangles,
                    min: s.bounds.min.to_array(),
                    max: s.bounds.max.to_array(),
                    first: s.clusters.start,
                    count: s.clusters.len() as u32,
                })
                .collect(),
        }
    }
}

/// Errors of [`split_objects`].
#[derive(Debug, thiserror::Error)]
pub enum SplitError {
    /// `SIZE` is not a positive finite number.
    #[error("--split-objects {0}: the cluster size must be a positive number of scene units")]
    BadSize(f32),
    /// The scene was already split.
    #[error("the scene is already split (--split-objects given twice?)")]
    AlreadySplit,
    /// A PVS baked with `--split-objects` does not match this scene split the same way.
    #[error(
        "the PVS was baked with --split-objects {size}, but this scene split so gives {what}: \
         not the scene file the PVS was baked from"
    )]
    Mismatch {
        /// The size recorded in the PVS.
        size: f32,
        /// What differs.
        what: String,
    },
}

/// The scene as a PVS document saw it: split again as its `split` table records (the same
/// file and size give the same clusters), or unchanged when the PVS has none. For checking
/// and drawing a PVS against the scene file (`validate`, `report`).
///
/// # Errors
/// [`SplitError::Mismatch`] when the clusters do not match the table (another scene file),
/// [`SplitError::BadSize`] for a recorded size that is not positive.
pub fn as_baked(scene: Scene, split: Option<&crate::pvs::PvsSplit>) -> Result<Scene, SplitError> {
    let Some(table) = split else {
        return Ok(scene);
    };
    let out = split_objects(&scene, table.size)?;
    let map = out.split.as_ref().expect("just split");
    let mismatch = |what: String| SplitError::Mismatch {
        size: table.size,
        what,
    };
    if map.sources.len() != table.sources.len() {
        return Err(mismatch(format!(
            "{} objects where the PVS lists {}",
            map.sources.len(),
            table.sources.len()
        )));
    }
    if let Some((i, (a, b))) = (map.sources.iter().zip(&table.sources))
        .enumerate()
        .find(|(_, (a, b))| a.clusters.start != b.first || a.clusters.len() as u32 != b.count)
    {
        return Err(mismatch(format!(
            "object {i} ({:?}) in {} clusters where the PVS has {}",
            a.name,
            a.clusters.len(),
            b.count
        )));
    }
    Ok(out)
}

/// Splits every object of `scene` larger than `size` along some axis into clusters (the rule
/// in the module docs) and returns the new scene, whose [`Scene::split`] maps clusters back.
/// Vertices are shared with the input; triangles are reordered so that each cluster's are
/// contiguous, as [`Scene`] requires.
///
/// # Errors
/// [`SplitError::BadSize`] for a `size` that is not positive and finite;
/// [`SplitError::AlreadySplit`] for a scene that already has a [`SplitMap`].
pub fn split_objects(scene: &Scene, size: f32) -> Result<Scene, SplitError> {
    if !(size.is_finite() && size > 0.0) {
        return Err(SplitError::BadSize(size));
    }
    if scene.split.is_some() {
        return Err(SplitError::AlreadySplit);
    }
    let mut out = Scene {
        source: scene.source.clone(),
        vertices: scene.vertices.clone(),
        warnings: scene.warnings.clone(),
        ..Default::default()
    };
    let mut sources = Vec::with_capacity(scene.objects.len());
    let mut order: Vec<u32> = Vec::new();
    for o in &scene.objects {
        let first = out.objects.len() as u32;
        let fits = o.bounds.is_empty() || (o.bounds.max - o.bounds.min).max_element() <= size;
        let clusters = if fits {
            vec![(o.triangles.clone()).collect::<Vec<u32>>()]
        } else {
            object_clusters(scene, o, size)
        };
        let whole = clusters.len() == 1;
        for (k, tris) in clusters.into_iter().enumerate() {
            let start = out.triangles.len() as u32;
            let mut bounds = Aabb::EMPTY;
            for &t in &tris {
                let tri = scene.triangles[t as usize];
                for &v in &tri {
                    bounds.grow(scene.vertices[v as usize]);
                }
                out.triangles.push(tri);
                out.opaque.push(scene.opaque[t as usize]);
                order.push(t);
            }
            out.objects.push(SceneObject {
                name: if whole {
                    o.name.clone()
                } else {
                    format!("{}#{k}", o.name)
                },
                triangles: start..out.triangles.len() as u32,
                bounds,
                closed: false,
            });
        }
        sources.push(SourceObject {
            name: o.name.clone(),
            triangles: o.triangles.len() as u32,
            bounds: o.bounds,
            clusters: first..out.objects.len() as u32,
        });
    }
    out.alpha = scene.alpha.as_ref().map(|a| a.reorder(&order));
    super::closed::mark_closed_objects(&mut out);
    out.split = Some(SplitMap { size, sources });
    Ok(out)
}

/// A component or a triangle as the recursion sees it: its triangles, bounds and centre.
struct Unit {
    tris: Vec<u32>,
    bounds: Aabb,
    centre: Vec3,
}

/// The clusters of one object too large to stay whole, each a list of scene triangles.
fn object_clusters(scene: &Scene, o: &SceneObject, size: f32) -> Vec<Vec<u32>> {
    let mut units: Vec<Unit> = components(scene, o)
        .into_iter()
        .map(|tris| unit(scene, tris))
        .collect();
    let mut out = Vec::new();
    split_units(scene, &mut units, size, &mut out);
    out
}

fn unit(scene: &Scene, tris: Vec<u32>) -> Unit {
    let mut bounds = Aabb::EMPTY;
    for &t in &tris {
        for p in scene.triangle(t as usize) {
            bounds.grow(p);
        }
    }
    Unit {
        centre: bounds.center(),
        tris,
        bounds,
    }
}

fn fits(b: &Aabb, size: f32) -> bool {
    (b.max - b.min).max_element() <= size
}

/// Splits `units` into clusters (module docs, step 3), appending them to `out` in order.
fn split_units(scene: &Scene, units: &mut [Unit], size: f32, out: &mut Vec<Vec<u32>>) {
    let bounds = units.iter().fold(Aabb::EMPTY, |b, u| b.union(&u.bounds));
    if fits(&bounds, size) {
        let mut tris: Vec<u32> = units.iter().flat_map(|u| u.tris.iter().copied()).collect();
        tris.sort_unstable();
        out.push(tris);
        return;
    }
    if units.len() == 1 {
        let tris = std::mem::take(&mut units[0].tris);
        if tris.len() == 1 {
            out.push(tris);
            return;
        }
        let mut singles: Vec<Unit> = tris.into_iter().map(|t| unit(scene, vec![t])).collect();
        split_units(scene, &mut singles, size, out);
        return;
    }
    // The longest axis of the units' centres (of the bounds when the centres coincide).
    let centres = units.iter().fold(Aabb::EMPTY, |mut b, u| {
        b.grow(u.centre);
        b
    });
    let spread = centres.max - centres.min;
    let axis = if spread.max_element() > 0.0 {
        spread.max_position()
    } else {
        (bounds.max - bounds.min).max_position()
    };
    // A stable order: by centre on the axis, ties by first triangle.
    units.sort_by(|a, b| {
        a.centre[axis]
            .total_cmp(&b.centre[axis])
            .then(a.tris.first().cmp(&b.tris.first()))
    });
    let mid = units.len() / 2;
    let (lo, hi) = units.split_at_mut(mid);
    split_units(scene, lo, size, out);
    split_units(scene, hi, size, out);
}

/// The connected components of an object's triangles (sharing a vertex position), each
/// ascending, ordered by their first triangle.
fn components(scene: &Scene, o: &SceneObject) -> Vec<Vec<u32>> {
    let n = o.triangles.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    let mut first_at: HashMap<[u32; 3], u32> = HashMap::new();
    for (k, t) in o.triangles.clone().enumerate() {
        for v in scene.triangles[t as usize] {
            let key = scene.vertices[v as usize].to_array().map(f32::to_bits);
            let other = *first_at.entry(key).or_insert(k as u32);
            let (a, b) = (find(&mut parent, k as u32), find(&mut parent, other));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut index: HashMap<u32, usize> = HashMap::new();
    let mut out: Vec<Vec<u32>> = Vec::new();
    for k in 0..n as u32 {
        let root = find(&mut parent, k);
        let i = *index.entry(root).or_insert_with(|| {
            out.push(Vec::new());
            out.len() - 1
        });
        out[i].push(o.triangles.start + k);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn quad(x: f32, z: f32, s: f32) -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            Vec3::new(x, 0.0, z),
            Vec3::new(x + s, 0.0, z),
            Vec3::new(x + s, 0.0, z + s),
            Vec3::new(x, 0.0, z + s),
        );
        vec![[a, b, c], [a, c, d]]
    }

    #[test]
    fn small_objects_stay_whole_and_keep_their_names() {
        let s = Scene::from_objects(
            Path::new("t"),
            vec![("a".into(), quad(0.0, 0.0, 1.0), true)],
        );
        let t = split_objects(&s, 2.0).unwrap();
        assert_eq!(t.objects.len(), 1);
        assert_eq!(t.objects[0].name, "a");
        let m = t.split.as_ref().unwrap();
        assert_eq!(m.sources[0].clusters, 0..1);
        t.validate().unwrap();
    }

    #[test]
    fn a_spread_object_becomes_clusters_that_fit_and_map_back() {
        // 16 separate unit quads on a line 0..32: one object spanning 32 units.
        let tris: Vec<_> = (0..16)
            .flat_map(|i| quad(2.0 * i as f32, 0.0, 1.0))
            .collect();
        let s = Scene::from_objects(
            Path::new("t"),
            vec![
                ("small".into(), quad(0.0, 5.0, 1.0), true),
                ("row".into(), tris, true),
            ],
        );
        let t = split_objects(&s, 4.0).unwrap();
        t.validate().unwrap();
        let m = t.split.as_ref().unwrap();
        let table = m.to_pvs();
        assert_eq!(m.sources.len(), 2);
        assert_eq!(m.sources[0].clusters, 0..1);
        let c = m.sources[1].clusters.clone();
        assert!(c.len() >= 8, "{} clusters", c.len());
        let mut total = 0;
        for o in c.clone() {
            let b = t.objects[o as usize].bounds;
            assert!((b.max - b.min).max_element() <= 4.0, "{b:?}");
            assert!(t.objects[o as usize].name.starts_with("row#"));
            assert_eq!(table.source_of(o), 1);
            total += t.objects[o as usize].triangles.len();
        }
        assert_eq!(total, 32);
        assert_eq!(table.source_of(0), 0);
        assert_eq!(table.source_visible(&[0, c.start, c.start + 1]), vec![0, 1]);
        // Stable: the same input gives the same clusters.
        let again = split_objects(&s, 4.0).unwrap();
        assert_eq!(again.triangles, t.triangles);
        assert_eq!(again.split, t.split);
    }

    #[test]
    fn a_connected_mesh_larger_than_the_size_is_cut_by_triangles() {
        // One 8×8 grid of unit quads, all connected: 8 units wide.
        let tris: Vec<_> = (0..64)
            .flat_map(|i| quad((i % 8) as f32, (i / 8) as f32, 1.0))
            .collect();
        let s = Scene::from_objects(Path::new("t"), vec![("ground".into(), tris, true)]);
        let t = split_objects(&s, 2.0).unwrap();
        t.validate().unwrap();
        assert!(t.objects.len() >= 16, "{}", t.objects.len());
        for o in &t.objects {
            assert!((o.bounds.max - o.bounds.min).max_element() <= 2.0, "{o:?}");
        }
    }

    #[test]
    fn a_closed_box_smaller_than_the_size_stays_closed() {
        let b = crate::geom::box_triangles(Vec3::ZERO, Vec3::ONE);
        let s = Scene::from_objects(Path::new("t"), vec![("box".into(), b, true)]);
        assert!(s.objects[0].closed);
        let t = split_objects(&s, 1.5).unwrap();
        assert!(t.objects[0].closed);
        let t = split_objects(&s, 0.5).unwrap();
        assert!(t.objects.len() > 1);
        assert!(t.objects.iter().all(|o| !o.closed));
    }

    #[test]
    fn bad_sizes_and_double_splits_are_refused() {
        let s = Scene::from_objects(
            Path::new("t"),
            vec![("a".into(), quad(0.0, 0.0, 1.0), true)],
        );
        assert!(matches!(
            split_objects(&s, 0.0),
            Err(SplitError::BadSize(_))
        ));
        assert!(matches!(
            split_objects(&s, f32::NAN),
            Err(SplitError::BadSize(_))
        ));
        let t = split_objects(&s, 1.0).unwrap();
        assert!(matches!(
            split_objects(&t, 1.0),
            Err(SplitError::AlreadySplit)
        ));
    }
}
