//! glTF 2.0 import (`.gltf` with external or `data:` buffers, `.glb`): owns the glTF
//! object-numbering contract.
//!
//! # Objects
//! The scene traversed is the document's `scene`, else scene 0, else the root nodes (nodes
//! that are nobody's child) in index order. Nodes are visited depth-first, pre-order,
//! children in listed order; every visited node with a mesh is one object, so a mesh used by
//! two nodes gives two objects, and a node whose mesh has no triangles still gets an id (with
//! an empty triangle range and [`Aabb::EMPTY`] bounds). The name is the node's name (when not
//! empty), else `node<INDEX>`.
//!
//! # Geometry
//! All triangle primitives of the node's mesh (modes triangles, strip, fan) in world space
//! (node transforms applied; with a negative determinant the winding is flipped so that
//! front faces stay counter-clockwise). Points and lines are ignored with one warning per
//! kind. Positions of any component type (float, or normalized/unnormalized integers as
//! `KHR_mesh_quantization` allows) and sparse accessors are decoded here. Nodes with
//! `EXT_mesh_gpu_instancing` contribute every instance to their one object.
//! Meshopt compression (`EXT_meshopt_compression`, `KHR_meshopt_compression`: files straight
//! out of gltfpack or glTF-Transform) is decoded ([`super::meshopt`]); Draco
//! (`KHR_draco_mesh_compression`) is refused when required.
//!
//! # Opacity and alpha-tested cards
//! Triangles whose material has `alphaMode` `MASK` or `BLEND` are not opaque. `MASK`
//! triangles are also alpha-tested cards ([`super::alpha`]): import keeps their material's
//! `alphaCutoff` (default 0.5), the alpha of `baseColorFactor`, the alpha plane of the
//! `baseColorTexture` (PNG with palette and `tRNS` too, JPEG, WebP; `KHR_texture_basisu` and
//! `EXT_texture_webp` sources are preferred when present) with its sampler's wrap modes, the
//! texture coordinates of the set the texture names (with `KHR_texture_transform`) and the
//! alpha of `COLOR_0`. A `MASK` material's image that cannot be read or decoded is an error
//! naming the file and the image, unless [`LoadOptions::alpha_missing`] is
//! [`AlphaMissing::Transparent`] (its cards then never occlude; the summary counts them).
//! Images of other materials are not decoded; a missing image file is a warning.

use super::alpha::{AlphaCards, AlphaMaterial, AlphaTexture, CardTriangle, NO_CARD, Wrap};
use super::{AlphaMissing, LoadOptions, Scene, SceneError, SceneObject};
use crate::geom::Aabb;
use ::gltf::accessor::{Accessor, DataType};
use ::gltf::json;
use ::gltf::mesh::Mode;
use glam::{DMat4, DQuat, DVec3, Mat3, Vec2, Vec3};
use std::collections::HashMap;
use std::path::Path;
use std::rc::Rc;
use std::sync::Arc;

/// Compression extensions whose data this importer cannot decode.
const COMPRESSION_EXTENSIONS: &[&str] = &["KHR_draco_mesh_compression"];

/// Buffer-view compression decoded here ([`super::meshopt`]).
const MESHOPT_EXTENSIONS: &[&str] = &["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// Required extensions known not to change the geometry we read (or read here).
const HARMLESS_EXTENSIONS: &[&str] = &[
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "KHR_mesh_quantization",
    "EXT_mesh_gpu_instancing",
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
    "KHR_lights_punctual",
    "KHR_materials_unlit",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_specular",
    "KHR_materials_transmission",
    "KHR_materials_volume",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_iridescence",
    "KHR_materials_anisotropy",
    "KHR_materials_dispersion",
    "KHR_materials_variants",
    "KHR_materials_pbrSpecularGlossiness",
];

/// Upper bound on node visits, against hierarchies that share subtrees exponentially.
const MAX_VISITS: usize = 50_000_000;

const INSTANCING: &str = "EXT_mesh_gpu_instancing";

/// Loads a `.gltf` or `.glb` file into a [`Scene`]. External buffers are read relative to
/// the file.
///
/// The scene is not validated here; [`super::load`] does that.
///
/// # Errors
/// [`SceneError::Io`] when the file cannot be read; [`SceneError::Invalid`] naming the file
/// for malformed glTF, a required compression extension, missing or short buffers,
/// out-of-range indices or a cyclic node hierarchy.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    load_with(path, &LoadOptions::default())
}

/// [`load`] with import options.
///
/// # Errors
/// As [`load`], and [`SceneError::Invalid`] for a `MASK` material's unreadable image unless
/// `options.alpha_missing` is [`AlphaMissing::Transparent`].
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_with(&bytes, path, options)
}

/// Parses glTF JSON or GLB bytes; `path` names the file in messages and anchors external
/// buffer URIs.
///
/// # Errors
/// As [`load`], except for reading the file itself.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Scene, SceneError> {
    parse_with(bytes, path, &LoadOptions::default())
}

/// [`parse`] with import options.
///
/// # Errors
/// As [`load_with`], except for reading the file itself.
pub fn parse_with(bytes: &[u8], path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
    let invalid = |message: String| SceneError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let gltf = ::gltf::Gltf::from_slice_without_validation(bytes)
        .map_err(|e| invalid(format!("not a valid glTF 2.0 file: {e}")))?;
    let root = gltf.document.as_json();
    let mut warnings = Vec::new();

    for ext in &root.extensions_required {
        if COMPRESSION_EXTENSIONS.contains(&ext.as_str()) {
            return Err(invalid(format!(
                "requires the {ext} extension (compressed geometry), which is not supported; \
                 decompress the file first (e.g. `gltf-transform copy` without compression)"
            )));
        }
    }
    validate(root).map_err(&invalid)?;
    for ext in &root.extensions_required {
        if !HARMLESS_EXTENSIONS.contains(&ext.as_str()) {
            warnings.push(format!(
                "{}: required extension {ext} is not interpreted; geometry is read without it",
                path.display()
            ));
        }
    }
    let compression_used = root
        .extensions_used
        .iter()
        .find(|e| COMPRESSION_EXTENSIONS.contains(&e.as_str()))
        .cloned();

    let doc = &gltf.document;
    let visits = traverse(doc).map_err(&invalid)?;

    let buffers = load_buffers(doc, gltf.blob.as_deref(), &visits, path).map_err(|m| {
        invalid(match &compression_used {
            Some(ext) => format!("{m} (the file uses {ext}, which is not supported)"),
            None => m,
        })
    })?;

    let mut b = Builder {
        doc,
        buffers: &buffers,
        prims: HashMap::new(),
        scene: Scene {
            source: path.to_path_buf(),
            ..Default::default()
        },
        points: 0,
        lines: 0,
        path,
        options,
        cards: AlphaCards::default(),
        card_materials: HashMap::new(),
        card_textures: HashMap::new(),
        any_card: false,
    };
    warnings.extend(missing_image_warnings(doc, path));
    for v in &visits {
        b.object(v).map_err(|m| {
            invalid(match &compression_used {
                Some(ext) => format!("{m} (the file uses {ext}, which is not supported)"),
                None => m,
            })
        })?;
    }
    let mut scene = b.scene;
    if b.any_card {
        scene.alpha = Some(b.cards);
    }
    if let Some(a) = &scene.alpha
        && a.missing_transparent > 0
    {
        warnings.push(format!(
            "{}: {} alpha-tested triangle(s) whose image is missing are left transparent \
             (--alpha-missing transparent)",
            path.display(),
            a.missing_transparent
        ));
    }
    if b.points > 0 {
        warnings.push(format!(
            "{}: ignored {} point primitive(s)",
            path.display(),
            b.points
        ));
    }
    if b.lines > 0 {
        warnings.push(format!(
            "{}: ignored {} line primitive(s)",
            path.display(),
            b.lines
        ));
    }
    scene.warnings.extend(warnings);
    Ok(scene)
}

/// Runs the gltf crate's validation, tolerating unknown required extensions (handled above).
fn validate(root: &json::Root) -> Result<(), String> {
    use json::validation::{Error, Validate};
    // The gltf crate's own validation indexes the POSITION accessor before checking it
    // exists (a panic found by fuzzing): check every primitive's accessors first.
    let n_acc = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let attrs = prim.attributes.values().map(|a| a.value());
            for a in attrs.chain(prim.indices.iter().map(|i| i.value())) {
                if a >= n_acc {
                    return Err(format!(
                        "invalid glTF: meshes[{m}].primitives[{p}] uses accessor {a}, but the \
                         file has {n_acc} accessors"
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        root.validate(root, json::Path::new, &mut |path, error| {
            let path = path().to_string();
            // A texture may name its image only through an extension (KHR_texture_basisu,
            // EXT_texture_webp): its plain `source` is then absent, which is valid.
            let extension_source = error == Error::Missing
                && path
                    .strip_prefix("textures[")
                    .and_then(|r| r.strip_suffix("].source"))
                    .and_then(|i| i.parse::<usize>().ok())
                    .and_then(|i| root.textures.get(i))
                    .and_then(|t| t.extensions.as_ref())
                    .is_some_and(|e| {
                        ["KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif"]
                            .iter()
                            .any(|k| e.others.contains_key(*k))
                    });
            if error != Error::Unsupported && !extension_source {
                errors.push(format!("{path}: {error}"));
            }
        });
    }));
    if ran.is_err() {
        return Err(
            "invalid glTF: the glTF validator failed on this file (it is malformed)".into(),
        );
    }
    if errors.is_empty() {
        return Ok(());
    }
    let n = errors.len();
    errors.truncate(5);
    Err(format!(
        "invalid glTF: {}{}",
        errors.join("; "),
        if n > 5 {
            format!(" (and {} more)", n - 5)
        } else {
            String::new()
        }
    ))
}

/// One visited node with a mesh: the node index and its world transform.
struct Visit {
    node: usize,
    world: DMat4,
}

/// The nodes with a mesh in traversal order (see the module documentation).
fn traverse(doc: &::gltf::Document) -> Result<Vec<Visit>, String> {
    let roots: Vec<usize> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().map(|n| n.index()).collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            (0..is_child.len()).filter(|&i| !is_child[i]).collect()
        }
    };
    let nodes: Vec<::gltf::Node> = doc.nodes().collect();
    let mut out = Vec::new();
    // Explicit stack (deep hierarchies must not overflow the call stack); `path` holds the
    // nodes from the root to the current one to detect cycles.
    let mut stack: Vec<(usize, DMat4, usize)> = roots
        .iter()
        .rev()
        .map(|&r| (r, DMat4::IDENTITY, 0))
        .collect();
    let mut path: Vec<usize> = Vec::new();
    let mut on_path = vec![false; nodes.len()];
    let mut visits = 0usize;
    while let Some((i, parent, depth)) = stack.pop() {
        for p in path.drain(depth..) {
            on_path[p] = false;
        }
        if on_path[i] {
            return Err(format!("the node hierarchy has a cycle through node {i}"));
        }
        visits += 1;
        if visits > MAX_VISITS {
            return Err(format!("more than {MAX_VISITS} node visits"));
        }
        on_path[i] = true;
        path.push(i);
        let node = &nodes[i];
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if node.mesh().is_some() {
            out.push(Visit { node: i, world });
        }
        let children: Vec<usize> = node.children().map(|c| c.index()).collect();
        for &c in children.iter().rev() {
            stack.push((c, world, depth + 1));
        }
    }
    Ok(out)
}

/// Reads the buffers the visited meshes need (others stay `None`): the GLB chunk, `data:`
/// URIs or files relative to `path`.
fn load_buffers(
    doc: &::gltf::Document,
    blob: Option<&[u8]>,
    visits: &[Visit],
    path: &Path,
) -> Result<Vec<Option<Vec<u8>>>, String> {
    let mut needed = vec![false; doc.buffers().len()];
    // Buffers whose views are meshopt-compressed: made from the decoded views.
    let mut synthesized = vec![false; doc.buffers().len()];
    let mut mark_view = |v: &::gltf::buffer::View| match meshopt_source(v) {
        Some(src) => {
            if let Some(n) = needed.get_mut(src) {
                *n = true;
            }
            synthesized[v.buffer().index()] = true;
        }
        None => needed[v.buffer().index()] = true,
    };
    let mut mark = |a: &Accessor| {
        if let Some(v) = a.view() {
            mark_view(&v);
        }
        if let Some(s) = a.sparse() {
            mark_view(&s.indices().view());
            mark_view(&s.values().view());
        }
    };
    let accessors: Vec<Accessor> = doc.accessors().collect();
    let mut meshes_seen = vec![false; doc.meshes().len()];
    let nodes: Vec<::gltf::Node> = doc.nodes().collect();
    for v in visits {
        let node = &nodes[v.node];
        if let Some(mesh) = node.mesh()
            && !std::mem::replace(&mut meshes_seen[mesh.index()], true)
        {
            for p in mesh.primitives() {
                if let Some(a) = p.get(&::gltf::Semantic::Positions) {
                    mark(&a);
                }
                if let Some(a) = p.indices() {
                    mark(&a);
                }
                if p.material().alpha_mode() == ::gltf::material::AlphaMode::Mask {
                    for (sem, a) in p.attributes() {
                        if matches!(
                            sem,
                            ::gltf::Semantic::TexCoords(_) | ::gltf::Semantic::Colors(0)
                        ) {
                            mark(&a);
                        }
                    }
                }
            }
        }
        for a in instancing_accessors(node) {
            if let Some(a) = a.and_then(|i| accessors.get(i)) {
                mark(a);
            }
        }
    }
    // Images stored in buffer views (GLB) of MASK materials' textures.
    let views = &doc.as_json().buffer_views;
    for m in doc.materials() {
        if m.alpha_mode() != ::gltf::material::AlphaMode::Mask {
            continue;
        }
        if let Some(info) = m.pbr_metallic_roughness().base_color_texture() {
            for img in texture_images(doc, info.texture().index()) {
                if let Some(v) = doc.as_json().images.get(img).and_then(|i| i.buffer_view)
                    && let Some(view) = views.get(v.value())
                    && let Some(n) = needed.get_mut(view.buffer.value())
                {
                    *n = true;
                }
            }
        }
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut out = Vec::with_capacity(needed.len());
    for buffer in doc.buffers() {
        let i = buffer.index();
        if !needed[i] {
            out.push(None);
            continue;
        }
        let data = match buffer.source() {
            ::gltf::buffer::Source::Bin => match blob {
                Some(b) if i == 0 => b.to_vec(),
                _ => {
                    return Err(format!(
                        "buffer {i} has no uri and there is no GLB binary chunk"
                    ));
                }
            },
            ::gltf::buffer::Source::Uri(uri) => {
                read_uri(uri, dir).map_err(|m| format!("buffer {i}: {m}"))?
            }
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {i} holds {} bytes, less than its byteLength {}",
                data.len(),
                buffer.length()
            ));
        }
        out.push(Some(data));
    }
    // Decode the meshopt views into their (fallback) buffers.
    for view in doc.views() {
        let i = view.buffer().index();
        if !synthesized[i] || meshopt_source(&view).is_none() {
            continue;
        }
        let ext = MESHOPT_EXTENSIONS
            .iter()
            .find_map(|e| view.extension_value(e))
            .expect("a meshopt view");
        let decoded = super::meshopt::decode_view(ext, &out)
            .map_err(|m| format!("buffer view {}: meshopt: {m}", view.index()))?;
        let len = view.buffer().length();
        let target = out[i].get_or_insert_with(Vec::new);
        if target.len() < len {
            if len > (1 << 31) {
                return Err(format!(
                    "buffer {i}: byteLength {len} is too large to decode into"
                ));
            }
            target.resize(len, 0);
        }
        let dest = target
            .get_mut(view.offset()..view.offset() + decoded.len())
            .ok_or_else(|| {
                format!(
                    "buffer view {}: its decoded {} bytes do not fit buffer {i}",
                    view.index(),
                    decoded.len()
                )
            })?;
        dest.copy_from_slice(&decoded);
    }
    Ok(out)
}

/// The buffer holding a meshopt-compressed view's data, when the view is compressed.
fn meshopt_source(view: &::gltf::buffer::View) -> Option<usize> {
    MESHOPT_EXTENSIONS
        .iter()
        .find_map(|e| view.extension_value(e))
        .and_then(|ext| ext.get("buffer"))
        .and_then(|b| b.as_u64())
        .map(|b| b as usize)
}

/// The accessor indices of a node's `EXT_mesh_gpu_instancing` (translation, rotation, scale).
fn instancing_accessors(node: &::gltf::Node) -> [Option<usize>; 3] {
    let Some(attrs) = node
        .extension_value(INSTANCING)
        .and_then(|v| v.get("attributes"))
    else {
        return [None; 3];
    };
    let get = |k: &str| attrs.get(k).and_then(|v| v.as_u64()).map(|v| v as usize);
    [get("TRANSLATION"), get("ROTATION"), get("SCALE")]
}

/// A primitive decoded once (meshes used by several nodes are decoded once).
struct Prim {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    opaque: bool,
    /// For alpha-tested cards: the material (index into [`AlphaCards::materials`]), each
    /// vertex's transformed texture coordinates and `COLOR_0` alpha.
    card: Option<PrimCard>,
    /// A `MASK` primitive whose image is missing, kept transparent.
    missing: bool,
}

/// The per-vertex data of a `MASK` primitive.
struct PrimCard {
    material: u32,
    uv: Vec<Vec2>,
    alpha: Vec<f32>,
}

struct Builder<'a> {
    doc: &'a ::gltf::Document,
    buffers: &'a [Option<Vec<u8>>],
    /// (mesh, primitive) → decoded triangles; `None` for points and lines.
    prims: HashMap<(usize, usize), Option<Rc<Prim>>>,
    scene: Scene,
    points: usize,
    lines: usize,
    path: &'a Path,
    options: &'a LoadOptions,
    cards: AlphaCards,
    /// glTF material → card material (`None`: its image is missing, left transparent).
    card_materials: HashMap<usize, Option<u32>>,
    /// (image, wrap s, wrap t) → index into `cards.textures`.
    card_textures: HashMap<(usize, u32, u32), u32>,
    any_card: bool,
}

impl Builder<'_> {
    /// Appends the object of one visited node.
    fn object(&mut self, v: &Visit) -> Result<(), String> {
        let node = self.doc.nodes().nth(v.node).expect("validated node index");
        let mesh = node.mesh().expect("visits have meshes");
        let name = match node.name() {
            Some(n) if !n.is_empty() => n.to_string(),
            _ => format!("node{}", v.node),
        };
        let instances = self.instances(&node)?;
        let start = self.scene.triangles.len();
        let mut prims = Vec::new();
        for p in mesh.primitives() {
            let key = (mesh.index(), p.index());
            let prim = match self.prims.get(&key) {
                Some(d) => d.clone(),
                None => {
                    let d = match p.mode() {
                        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan => {
                            Some(Rc::new(self.decode(&p).map_err(|m| {
                                format!("mesh {} primitive {}: {m}", mesh.index(), p.index())
                            })?))
                        }
                        _ => None,
                    };
                    self.prims.insert(key, d.clone());
                    d
                }
            };
            match (prim, p.mode()) {
                (Some(d), _) => prims.push(d),
                (None, Mode::Points) => self.points += instances.len(),
                (None, _) => self.lines += instances.len(),
            }
        }
        let s = &mut self.scene;
        let mut bounds = Aabb::EMPTY;
        for inst in &instances {
            let m = v.world * *inst;
            let flip = m.determinant() < 0.0;
            for d in &prims {
                if d.triangles.is_empty() {
                    continue;
                }
                let base = s.vertices.len();
                if base + d.positions.len() > u32::MAX as usize {
                    return Err("more than 2^32 vertices".into());
                }
                s.vertices.extend(
                    d.positions
                        .iter()
                        .map(|p| m.transform_point3(p.as_dvec3()).as_vec3()),
                );
                let base = base as u32;
                for &[a, b, c] in &d.triangles {
                    let (b, c) = if flip { (c, b) } else { (b, c) };
                    let t = [a + base, b + base, c + base];
                    for &i in &t {
                        bounds.grow(s.vertices[i as usize]);
                    }
                    s.triangles.push(t);
                }
                s.opaque
                    .extend(std::iter::repeat_n(d.opaque, d.triangles.len()));
                let cards = &mut self.cards;
                match &d.card {
                    Some(c) => {
                        self.any_card = true;
                        for &[a, b, cc] in &d.triangles {
                            let (b, cc) = if flip { (cc, b) } else { (b, cc) };
                            let ix = [a as usize, b as usize, cc as usize];
                            cards.card_of.push(cards.cards.len() as u32);
                            cards.cards.push(CardTriangle {
                                material: c.material,
                                uv: ix.map(|i| c.uv[i]),
                                vertex_alpha: ix.map(|i| c.alpha[i]),
                            });
                        }
                    }
                    None => {
                        if d.missing {
                            self.any_card = true;
                            cards.missing_transparent += d.triangles.len();
                        }
                        cards
                            .card_of
                            .extend(std::iter::repeat_n(NO_CARD, d.triangles.len()))
                    }
                }
            }
        }
        if s.triangles.len() > u32::MAX as usize {
            return Err("more than 2^32 triangles".into());
        }
        s.objects.push(SceneObject {
            name,
            triangles: start as u32..s.triangles.len() as u32,
            bounds,
            closed: false,
        });
        Ok(())
    }

    /// Instance transforms of `EXT_mesh_gpu_instancing` (just the identity without it).
    fn instances(&self, node: &::gltf::Node) -> Result<Vec<DMat4>, String> {
        let [t, r, s] = instancing_accessors(node);
        if t.is_none() && r.is_none() && s.is_none() {
            return Ok(vec![DMat4::IDENTITY]);
        }
        let read = |i: Option<usize>, n: usize| -> Result<Option<Vec<f64>>, String> {
            let Some(i) = i else { return Ok(None) };
            let a =
                self.doc.accessors().nth(i).ok_or_else(|| {
                    format!("node {}: {INSTANCING}: no accessor {i}", node.index())
                })?;
            if a.dimensions().multiplicity() != n {
                return Err(format!(
                    "node {}: {INSTANCING}: accessor {i} has the wrong type",
                    node.index()
                ));
            }
            read_accessor(&a, self.buffers)
                .map(Some)
                .map_err(|m| format!("node {}: {INSTANCING}: {m}", node.index()))
        };
        let (t, r, s) = (read(t, 3)?, read(r, 4)?, read(s, 3)?);
        let count = [
            t.as_ref().map(|v| v.len() / 3),
            r.as_ref().map(|v| v.len() / 4),
            s.as_ref().map(|v| v.len() / 3),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(0);
        Ok((0..count)
            .map(|k| {
                let tr = t
                    .as_ref()
                    .map_or(DVec3::ZERO, |v| DVec3::from_slice(&v[3 * k..]));
                let rot = r.as_ref().map_or(DQuat::IDENTITY, |v| {
                    DQuat::from_slice(&v[4 * k..]).normalize()
                });
                let sc = s
                    .as_ref()
                    .map_or(DVec3::ONE, |v| DVec3::from_slice(&v[3 * k..]));
                DMat4::from_scale_rotation_translation(sc, rot, tr)
            })
            .collect())
    }

    /// Decodes a triangle primitive in local space.
    fn decode(&mut self, p: &::gltf::Primitive) -> Result<Prim, String> {
        let opaque = p.material().alpha_mode() == ::gltf::material::AlphaMode::Opaque;
        let Some(pos) = p.get(&::gltf::Semantic::Positions) else {
            return Ok(Prim {
                positions: Vec::new(),
                triangles: Vec::new(),
                opaque,
                card: None,
                missing: false,
            });
        };
        if pos.dimensions().multiplicity() != 3 {
            return Err(format!("POSITION accessor {} is not a VEC3", pos.index()));
        }
        let positions: Vec<Vec3> = read_accessor(&pos, self.buffers)?
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32))
            .collect();
        let nv = positions.len();
        let indices: Vec<u32> = match p.indices() {
            Some(a) => {
                if a.dimensions().multiplicity() != 1 {
                    return Err(format!("indices accessor {} is not a SCALAR", a.index()));
                }
                let raw = read_accessor(&a, self.buffers)?;
                let mut out = Vec::with_capacity(raw.len());
                for x in raw {
                    if !(x >= 0.0 && (x as usize) < nv) || x.fract() != 0.0 {
                        return Err(format!(
                            "index {x} out of range ({nv} vertices) in accessor {}",
                            a.index()
                        ));
                    }
                    out.push(x as u32);
                }
                out
            }
            None => (0..nv as u32).collect(),
        };
        let n = indices.len();
        let triangles: Vec<[u32; 3]> = match p.mode() {
            Mode::Triangles => indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
            // glTF: p_i = {v_i, v_{i+(1+i%2)}, v_{i+(2-i%2)}}.
            Mode::TriangleStrip => (0..n.saturating_sub(2))
                .map(|i| {
                    if i % 2 == 0 {
                        [indices[i], indices[i + 1], indices[i + 2]]
                    } else {
                        [indices[i], indices[i + 2], indices[i + 1]]
                    }
                })
                .collect(),
            // glTF: p_i = {v_{i+1}, v_{i+2}, v_0}.
            Mode::TriangleFan => (0..n.saturating_sub(2))
                .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
                .collect(),
            _ => Vec::new(),
        };
        let mask = p.material().alpha_mode() == ::gltf::material::AlphaMode::Mask;
        let card = if mask { self.prim_card(p, nv)? } else { None };
        Ok(Prim {
            positions,
            triangles,
            opaque,
            missing: mask && card.is_none(),
            card,
        })
    }

    /// The card data of a `MASK` primitive with `nv` vertices (`None` when its image is
    /// missing and left transparent).
    fn prim_card(&mut self, p: &::gltf::Primitive, nv: usize) -> Result<Option<PrimCard>, String> {
        let m = p.material();
        let Some(material) = self.card_material(&m)? else {
            return Ok(None);
        };
        let mut uv = vec![Vec2::ZERO; nv];
        if let Some(info) = m.pbr_metallic_roughness().base_color_texture() {
            let transform = info.extension_value("KHR_texture_transform");
            let set = transform
                .and_then(|t| t.get("texCoord"))
                .and_then(|v| v.as_u64())
                .map_or(info.tex_coord(), |v| v as u32);
            let Some(a) = p.get(&::gltf::Semantic::TexCoords(set)) else {
                return Err(format!(
                    "alpha-tested material {} samples TEXCOORD_{set}, which the primitive lacks",
                    material_name(&m)
                ));
            };
            if a.dimensions().multiplicity() != 2 {
                return Err(format!(
                    "TEXCOORD_{set} accessor {} is not a VEC2",
                    a.index()
                ));
            }
            let raw = read_accessor(&a, self.buffers)?;
            if raw.len() / 2 < nv {
                return Err(format!(
                    "TEXCOORD_{set} accessor {} has fewer elements than POSITION",
                    a.index()
                ));
            }
            let t = texture_transform(transform);
            for (i, u) in uv.iter_mut().enumerate() {
                let v = Vec2::new(raw[2 * i] as f32, raw[2 * i + 1] as f32);
                *u = t.transform_point2(v);
            }
        }
        let mut alpha = vec![1f32; nv];
        if let Some(a) = p.get(&::gltf::Semantic::Colors(0))
            && a.dimensions().multiplicity() == 4
        {
            let raw = read_accessor(&a, self.buffers)?;
            for (i, x) in alpha.iter_mut().enumerate() {
                *x = raw.get(4 * i + 3).map_or(1.0, |&v| v as f32);
            }
        }
        Ok(Some(PrimCard {
            material,
            uv,
            alpha,
        }))
    }

    /// The card material of a `MASK` glTF material, its texture decoded once.
    fn card_material(&mut self, m: &::gltf::Material) -> Result<Option<u32>, String> {
        let key = m.index().unwrap_or(usize::MAX);
        if let Some(&done) = self.card_materials.get(&key) {
            return Ok(done);
        }
        let pbr = m.pbr_metallic_roughness();
        let texture = match pbr.base_color_texture() {
            None => Some(None),
            Some(info) => {
                let tex = info.texture();
                let sampler = tex.sampler();
                let wrap = [sampler.wrap_s().as_gl_enum(), sampler.wrap_t().as_gl_enum()];
                match self.card_texture(tex.index(), wrap) {
                    Ok(t) => Some(Some(t)),
                    Err(e) if self.options.alpha_missing == AlphaMissing::Transparent => {
                        self.scene.warnings.push(format!(
                            "{}: alpha-tested material {}: {e}; its cards are left transparent",
                            self.path.display(),
                            material_name(m)
                        ));
                        None
                    }
                    Err(e) => {
                        return Err(format!(
                            "alpha-tested material {}: {e} (pass --alpha-missing transparent to \
                             keep its cards as non-occluders)",
                            material_name(m)
                        ));
                    }
                }
            }
        };
        let out = texture.map(|texture| {
            self.cards.materials.push(AlphaMaterial {
                name: material_name(m),
                cutoff: m.alpha_cutoff().unwrap_or(0.5),
                factor: pbr.base_color_factor()[3],
                texture,
            });
            (self.cards.materials.len() - 1) as u32
        });
        self.card_materials.insert(key, out);
        Ok(out)
    }

    /// Decodes glTF texture `index` with wrap modes `wrap` once.
    fn card_texture(&mut self, index: usize, wrap: [u32; 2]) -> Result<u32, String> {
        let candidates = texture_images(self.doc, index);
        let Some(&image) = candidates.first() else {
            return Err(format!("texture {index} has no image"));
        };
        if let Some(&t) = self.card_textures.get(&(image, wrap[0], wrap[1])) {
            return Ok(t);
        }
        let mut last = String::new();
        let mut decoded = None;
        // Extension sources first (KTX2, WebP), then the plain one.
        for &img in &candidates {
            match self.image_alpha(img) {
                Ok(d) => {
                    decoded = Some((img, d));
                    break;
                }
                Err(e) => last = e,
            }
        }
        let Some((img, (width, height, alpha))) = decoded else {
            return Err(last);
        };
        self.cards.textures.push(AlphaTexture {
            label: image_label(self.doc, img),
            width,
            height,
            alpha: Arc::new(alpha),
            wrap: [Wrap::from_gl(wrap[0]), Wrap::from_gl(wrap[1])],
        });
        let t = (self.cards.textures.len() - 1) as u32;
        self.card_textures.insert((image, wrap[0], wrap[1]), t);
        Ok(t)
    }

    /// The alpha plane of glTF image `index`.
    fn image_alpha(&self, index: usize) -> Result<(u32, u32, Vec<u8>), String> {
        let label = image_label(self.doc, index);
        let json = self
            .doc
            .as_json()
            .images
            .get(index)
            .ok_or_else(|| format!("no image {index}"))?;
        let bytes: Vec<u8> = if let Some(v) = json.buffer_view {
            let view = self
                .doc
                .views()
                .nth(v.value())
                .ok_or_else(|| format!("{label}: no buffer view {}", v.value()))?;
            view_bytes(&view, self.buffers)
                .map_err(|e| format!("{label}: {e}"))?
                .to_vec()
        } else if let Some(uri) = &json.uri {
            read_uri(uri, self.path.parent().unwrap_or(Path::new("")))
                .map_err(|m| format!("{label}: {m}"))?
        } else {
            return Err(format!("{label} has neither a uri nor a buffer view"));
        };
        super::image::decode_alpha(&bytes).map_err(|e| format!("{label}: {e}"))
    }
}

/// Images of glTF texture `index`, extension sources (`KHR_texture_basisu`,
/// `EXT_texture_webp`) first.
fn texture_images(doc: &::gltf::Document, index: usize) -> Vec<usize> {
    let Some(t) = doc.as_json().textures.get(index) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    if let Some(ext) = &t.extensions {
        for name in ["KHR_texture_basisu", "EXT_texture_webp"] {
            if let Some(src) = ext.others.get(name).and_then(|e| e.get("source"))
                && let Some(i) = src.as_u64()
            {
                out.push(i as usize);
            }
        }
    }
    let plain = t.source.value();
    if plain < doc.as_json().images.len() {
        out.push(plain);
    }
    out.retain(|&i| i < doc.as_json().images.len());
    out
}

/// "image I (URI or name)".
fn image_label(doc: &::gltf::Document, index: usize) -> String {
    let img = &doc.as_json().images[index];
    match (&img.uri, &img.name) {
        (Some(u), _) if !u.starts_with("data:") => format!("image {index} ({u})"),
        (_, Some(n)) => format!("image {index} ({n})"),
        _ => format!("image {index}"),
    }
}

fn material_name(m: &::gltf::Material) -> String {
    match (m.name(), m.index()) {
        (Some(n), _) if !n.is_empty() => n.to_string(),
        (_, Some(i)) => format!("material{i}"),
        _ => "default material".into(),
    }
}

/// `KHR_texture_transform` as a matrix: translation · rotation · scale.
fn texture_transform(t: Option<&json::Value>) -> Mat3 {
    let Some(t) = t else { return Mat3::IDENTITY };
    let pair = |k: &str, d: f32| -> Vec2 {
        t.get(k)
            .and_then(|v| v.as_array())
            .filter(|a| a.len() == 2)
            .map_or(Vec2::splat(d), |a| {
                Vec2::new(
                    a[0].as_f64().unwrap_or(d as f64) as f32,
                    a[1].as_f64().unwrap_or(d as f64) as f32,
                )
            })
    };
    let offset = pair("offset", 0.0);
    let scale = pair("scale", 1.0);
    let r = t.get("rotation").and_then(|v| v.as_f64()).unwrap_or(0.0) as f32;
    let (sin, cos) = r.sin_cos();
    // The extension's GLSL: mat3(cos, sin, 0, -sin, cos, 0, 0, 0, 1), column-major.
    let rotation = Mat3::from_cols(
        glam::Vec3::new(cos, sin, 0.0),
        glam::Vec3::new(-sin, cos, 0.0),
        glam::Vec3::Z,
    );
    Mat3::from_translation(offset) * rotation * Mat3::from_scale(scale)
}

/// Warnings for image files that materials other than `MASK` name but that are missing
/// (visibility does not need them).
fn missing_image_warnings(doc: &::gltf::Document, path: &Path) -> Vec<String> {
    let dir = path.parent().unwrap_or(Path::new(""));
    // Images of MASK materials are read, and refused or warned about, where they are decoded.
    let mut masked = vec![false; doc.as_json().images.len()];
    for m in doc.materials() {
        if m.alpha_mode() == ::gltf::material::AlphaMode::Mask
            && let Some(info) = m.pbr_metallic_roughness().base_color_texture()
        {
            for i in texture_images(doc, info.texture().index()) {
                masked[i] = true;
            }
        }
    }
    let mut out = Vec::new();
    for (i, img) in doc.as_json().images.iter().enumerate() {
        if masked[i] {
            continue;
        }
        if let Some(uri) = &img.uri
            && !uri.starts_with("data:")
            && !uri.contains("://")
        {
            let file = dir.join(percent_decode(uri));
            if !file.exists() {
                out.push(format!(
                    "{}: image {i} ({uri}) is missing; only an alpha-tested material needs it",
                    path.display()
                ));
            }
        }
    }
    out
}

/// The bytes of a buffer view.
fn view_bytes<'b>(
    view: &::gltf::buffer::View,
    buffers: &'b [Option<Vec<u8>>],
) -> Result<&'b [u8], String> {
    let bi = view.buffer().index();
    let data = buffers
        .get(bi)
        .and_then(|b| b.as_deref())
        .ok_or_else(|| format!("buffer {bi} has no data"))?;
    data.get(view.offset()..view.offset() + view.length())
        .ok_or_else(|| format!("buffer view {} lies outside buffer {bi}", view.index()))
}

/// Decodes `count` elements of `n` components starting at `start` with `stride` into `out`
/// (as f64, which holds every component type exactly; normalized integers mapped to [0, 1]
/// or [-1, 1]).
#[expect(
    clippy::too_many_arguments,
    reason = "mirrors the glTF accessor fields (offset, count, components, stride, type, normalization); a struct would just rename them"
)]
fn decode_elements(
    src: &[u8],
    start: usize,
    stride: usize,
    count: usize,
    n: usize,
    ty: DataType,
    normalized: bool,
    out: &mut Vec<f64>,
) {
    macro_rules! run {
        ($t:ty, $norm:expr) => {{
            const S: usize = std::mem::size_of::<$t>();
            for e in 0..count {
                let base = start + e * stride;
                for c in 0..n {
                    let o = base + c * S;
                    let v = <$t>::from_le_bytes(src[o..o + S].try_into().unwrap());
                    let f = v as f64;
                    out.push(if normalized { $norm(f) } else { f });
                }
            }
        }};
    }
    match ty {
        DataType::F32 => run!(f32, |f: f64| f),
        DataType::U32 => run!(u32, |f: f64| f / u32::MAX as f64),
        DataType::U16 => run!(u16, |f: f64| f / 65535.0),
        DataType::I16 => run!(i16, |f: f64| (f / 32767.0).max(-1.0)),
        DataType::U8 => run!(u8, |f: f64| f / 255.0),
        DataType::I8 => run!(i8, |f: f64| (f / 127.0).max(-1.0)),
    }
}

/// The most components a sparse accessor without a buffer view may have (its zeros are made
/// from its count alone, so a count claiming billions is refused: 512 MiB of `f64`).
const MAX_SPARSE_COMPONENTS: usize = 1 << 26;

/// Reads all components of an accessor, sparse substitution included.
fn read_accessor(a: &Accessor, buffers: &[Option<Vec<u8>>]) -> Result<Vec<f64>, String> {
    let count = a.count();
    let n = a.dimensions().multiplicity();
    let ty = a.data_type();
    let elem = ty.size() * n;
    // No allocation from a count before the data is known to be there: a hostile file may
    // claim billions of elements.
    let mut out = Vec::new();
    match a.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(format!(
                    "accessor {}: byteStride {stride} is smaller than an element ({elem} bytes)",
                    a.index()
                ));
            }
            let src = view_bytes(&view, buffers)?;
            let end = stride
                .checked_mul(count.saturating_sub(1))
                .and_then(|x| x.checked_add(a.offset()))
                .and_then(|x| x.checked_add(elem));
            if count > 0 && end.is_none_or(|e| e > src.len()) {
                return Err(format!("accessor {} reads past its buffer view", a.index()));
            }
            out.reserve(count * n);
            decode_elements(
                src,
                a.offset(),
                stride,
                count,
                n,
                ty,
                a.normalized(),
                &mut out,
            );
        }
        None if a.sparse().is_some() => {
            if count.saturating_mul(n) > MAX_SPARSE_COMPONENTS {
                return Err(format!(
                    "accessor {}: a sparse accessor of {count} elements without a buffer view \
                     (over the reader's limit of {MAX_SPARSE_COMPONENTS} components)",
                    a.index()
                ));
            }
            out.resize(count * n, 0.0)
        }
        None => return Err(format!("accessor {} has no data", a.index())),
    }
    if let Some(sparse) = a.sparse() {
        let k = sparse.count();
        let iv = sparse.indices();
        let ity = match iv.index_type() {
            ::gltf::accessor::sparse::IndexType::U8 => DataType::U8,
            ::gltf::accessor::sparse::IndexType::U16 => DataType::U16,
            ::gltf::accessor::sparse::IndexType::U32 => DataType::U32,
        };
        let isrc = view_bytes(&iv.view(), buffers)?;
        let vv = sparse.values();
        let vsrc = view_bytes(&vv.view(), buffers)?;
        if iv.offset() + k * ity.size() > isrc.len() || vv.offset() + k * elem > vsrc.len() {
            return Err(format!(
                "accessor {}: sparse data outside its views",
                a.index()
            ));
        }
        let mut idx = Vec::with_capacity(k);
        decode_elements(isrc, iv.offset(), ity.size(), k, 1, ity, false, &mut idx);
        let mut vals = Vec::with_capacity(k * n);
        decode_elements(vsrc, vv.offset(), elem, k, n, ty, a.normalized(), &mut vals);
        for (j, &i) in idx.iter().enumerate() {
            let i = i as usize;
            if i >= count {
                return Err(format!(
                    "accessor {}: sparse index {i} out of range",
                    a.index()
                ));
            }
            out[i * n..(i + 1) * n].copy_from_slice(&vals[j * n..(j + 1) * n]);
        }
    }
    Ok(out)
}

/// The bytes a buffer's or image's URI names: a `data:` URI, or a file relative to `dir`
/// (external URLs are refused).
fn read_uri(uri: &str, dir: &Path) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        decode_data_uri(rest).map_err(|m| format!("bad data URI: {m}"))
    } else if uri.contains("://") {
        Err(format!("external URL {uri} is not supported"))
    } else {
        let file = dir.join(percent_decode(uri));
        std::fs::read(&file).map_err(|e| format!("cannot read {}: {e}", file.display()))
    }
}

/// Decodes the part of a `data:` URI after `data:`.
fn decode_data_uri(rest: &str) -> Result<Vec<u8>, String> {
    let comma = rest.find(',').ok_or("no comma")?;
    let (header, payload) = (&rest[..comma], &rest[comma + 1..]);
    if header.ends_with(";base64") {
        base64_decode(payload)
    } else {
        Ok(percent_decode_bytes(payload))
    }
}

/// Standard base64 (padding optional, white space ignored; `-`/`_` accepted too).
fn base64_decode(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0;
    for &c in s.as_bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\t' | b'\r' | b'\n' => continue,
            _ => return Err(format!("invalid base64 character {:?}", c as char)),
        };
        acc = acc << 6 | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

fn percent_decode_bytes(s: &str) -> Vec<u8> {
    let hex = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2]))
        {
            out.push(h << 4 | l);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    out
}

/// Percent-decodes a relative URI into a path string.
fn percent_decode(s: &str) -> String {
    String::from_utf8_lossy(&percent_decode_bytes(s)).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_roundtrip_known() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("AAEC/w==").unwrap(), [0, 1, 2, 255]);
        assert!(base64_decode("a*b").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("my%20file.bin"), "my file.bin");
        assert_eq!(percent_decode("a%2"), "a%2");
        assert_eq!(percent_decode("100%"), "100%");
    }
}
