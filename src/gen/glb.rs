//! glTF binary (`.glb`) output of the generators, for forests of textured tree models
//! (`gen forest --tree-model TREE.gltf -o forest.glb`): one node and mesh per object in
//! object order (so ids match the OBJ output's), its alpha-tested cards as `MASK` primitives
//! with their cutoff, factor, texture coordinates (`KHR_texture_transform` already applied),
//! `COLOR_0` alpha and sampler wrap modes, and each card texture's alpha plane as a PNG
//! (grey colour: visibility needs only alpha). Other non-opaque faces get a `BLEND`
//! material, so re-importing keeps them occludee-only. One file, written atomically.

use super::{GenError, Generated, NO_VERTEX};
use crate::scene::alpha::{NO_CARD, Wrap};
use serde_json::{Value, json};
use std::io::Write;
use std::path::Path;

/// glTF's component type and target constants used here.
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

/// Appends `bytes` to `bin` as a buffer view (4-byte aligned) and an accessor over it;
/// returns the accessor's index.
fn accessor(
    bin: &mut Vec<u8>,
    views: &mut Vec<Value>,
    accessors: &mut Vec<Value>,
    bytes: &[u8],
    count: usize,
    ty: &str,
    component: u32,
) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len()}));
    accessors.push(json!({
        "bufferView": views.len() - 1,
        "componentType": component,
        "count": count,
        "type": ty,
    }));
    bin.extend_from_slice(bytes);
    accessors.len() - 1
}

fn f32_bytes(v: impl IntoIterator<Item = f32>) -> Vec<u8> {
    v.into_iter().flat_map(f32::to_le_bytes).collect()
}

fn gl_wrap(w: Wrap) -> u32 {
    match w {
        Wrap::Repeat => 10497,
        Wrap::MirroredRepeat => 33648,
        Wrap::ClampToEdge => 33071,
    }
}

/// Writes `g` as one `.glb` file at `path`.
///
/// # Errors
/// [`GenError::Write`] for I/O errors (no file is left behind); [`GenError::Options`] when
/// the scene does not fit glTF's 32-bit sizes.
pub fn write_glb(path: &Path, g: &Generated) -> Result<(), GenError> {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let cards = g.alpha.as_ref();
    let card_materials = cards.map_or(0, |c| c.materials.len());
    for o in &g.objects {
        let mut prims = Vec::new();
        // Plain faces, opaque and not, each as one indexed primitive.
        for opaque in [true, false] {
            let mut idx: Vec<u32> = Vec::new();
            for (f, face) in o.faces.iter().enumerate() {
                // Cards are written below (a quad never is one: model faces are triangles).
                let card = o.cards.get(f).copied().unwrap_or(NO_CARD);
                if o.opaque[f] != opaque || (card != NO_CARD && face[3] == NO_VERTEX) {
                    continue;
                }
                idx.extend([face[0], face[1], face[2]]);
                if face[3] != NO_VERTEX {
                    idx.extend([face[0], face[2], face[3]]);
                }
            }
            if idx.is_empty() {
                continue;
            }
            let p = accessor(
                &mut bin,
                &mut views,
                &mut accessors,
                &f32_bytes(o.vertices.iter().flat_map(|v| v.to_array())),
                o.vertices.len(),
                "VEC3",
                FLOAT,
            );
            let b = o.bounds();
            accessors[p]["min"] = json!(b.min.to_array());
            accessors[p]["max"] = json!(b.max.to_array());
            let i = accessor(
                &mut bin,
                &mut views,
                &mut accessors,
                &idx.iter()
                    .flat_map(|x| x.to_le_bytes())
                    .collect::<Vec<u8>>(),
                idx.len(),
                "SCALAR",
                UNSIGNED_INT,
            );
            prims.push(json!({
                "attributes": {"POSITION": p},
                "indices": i,
                "material": if opaque { 0 } else { 1 },
            }));
        }
        // Cards, one primitive per material, unwelded (texture coordinates are per corner).
        if let Some(c) = cards {
            for m in 0..card_materials {
                let (mut pos, mut uv, mut alpha) = (Vec::new(), Vec::new(), Vec::new());
                for (f, face) in o.faces.iter().enumerate() {
                    let card = o.cards.get(f).copied().unwrap_or(NO_CARD);
                    let Some(t) = (card != NO_CARD).then(|| &c.cards[card as usize]) else {
                        continue;
                    };
                    if t.material as usize != m || face[3] != NO_VERTEX {
                        continue;
                    }
                    for (k, &v) in face[..3].iter().enumerate() {
                        pos.extend(o.vertices[v as usize].to_array());
                        uv.extend(t.uv[k].to_array());
                        alpha.extend([1.0, 1.0, 1.0, t.vertex_alpha[k]]);
                    }
                }
                if pos.is_empty() {
                    continue;
                }
                let n = pos.len() / 3;
                let p = accessor(
                    &mut bin,
                    &mut views,
                    &mut accessors,
                    &f32_bytes(pos.iter().copied()),
                    n,
                    "VEC3",
                    FLOAT,
                );
                let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
                for (k, x) in pos.iter().enumerate() {
                    lo[k % 3] = lo[k % 3].min(*x);
                    hi[k % 3] = hi[k % 3].max(*x);
                }
                accessors[p]["min"] = json!(lo);
                accessors[p]["max"] = json!(hi);
                let t = accessor(
                    &mut bin,
                    &mut views,
                    &mut accessors,
                    &f32_bytes(uv),
                    n,
                    "VEC2",
                    FLOAT,
                );
                let mut attributes = json!({"POSITION": p, "TEXCOORD_0": t});
                if alpha.chunks(4).any(|a| a[3] != 1.0) {
                    let a = accessor(
                        &mut bin,
                        &mut views,
                        &mut accessors,
                        &f32_bytes(alpha),
                        n,
                        "VEC4",
                        FLOAT,
                    );
                    attributes["COLOR_0"] = json!(a);
                }
                prims.push(json!({"attributes": attributes, "material": 2 + m}));
            }
        }
        meshes.push(json!({ "primitives": prims }));
        nodes.push(json!({"name": o.name, "mesh": meshes.len() - 1}));
    }
    // Materials: opaque, translucent (blend), then the cards'.
    let mut materials = vec![
        json!({"name": "opaque"}),
        json!({"name": "translucent", "alphaMode": "BLEND",
               "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.5]}}),
    ];
    let (mut textures, mut images, mut samplers) = (Vec::new(), Vec::new(), Vec::new());
    if let Some(c) = cards {
        for (k, t) in c.textures.iter().enumerate() {
            let mut rgba = image::RgbaImage::new(t.width, t.height);
            for (p, &a) in rgba.pixels_mut().zip(t.alpha.iter()) {
                *p = image::Rgba([96, 128, 64, a]);
            }
            let mut png = Vec::new();
            rgba.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .map_err(|e| GenError::Options(format!("texture {k}: cannot encode PNG: {e}")))?;
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": png.len()}));
            bin.extend_from_slice(&png);
            images.push(
                json!({"bufferView": views.len() - 1, "mimeType": "image/png",
                               "name": t.label}),
            );
            samplers.push(json!({"wrapS": gl_wrap(t.wrap[0]), "wrapT": gl_wrap(t.wrap[1])}));
            textures.push(json!({"source": k, "sampler": k}));
        }
        for m in &c.materials {
            let mut pbr = json!({"baseColorFactor": [1.0, 1.0, 1.0, m.factor]});
            if let Some(t) = m.texture {
                pbr["baseColorTexture"] = json!({"index": t});
            }
            materials.push(json!({
                "name": m.name, "alphaMode": "MASK", "alphaCutoff": m.cutoff,
                "doubleSided": true, "pbrMetallicRoughness": pbr,
            }));
        }
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": format!("umbrasweep gen: {}", g.comment)},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": views,
        "accessors": accessors,
    });
    if !images.is_empty() {
        doc["images"] = json!(images);
        doc["textures"] = json!(textures);
        doc["samplers"] = json!(samplers);
    }
    let mut text = serde_json::to_vec(&doc)
        .map_err(|e| GenError::Options(format!("cannot encode the glTF JSON: {e}")))?;
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let total = u32::try_from(total).map_err(|_| {
        GenError::Options(format!(
            "-o {}: the scene needs {total} bytes, over glTF binary's 4 GiB; write .obj instead",
            path.display()
        ))
    })?;
    crate::util::write_atomic_with(path, |w| {
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&total.to_le_bytes())?;
        w.write_all(&(text.len() as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        w.write_all(&text)?;
        w.write_all(&(bin.len() as u32).to_le_bytes())?;
        w.write_all(b"BIN\0")?;
        w.write_all(&bin)
    })
    .map_err(|e| GenError::Write(e.to_string()))
}
