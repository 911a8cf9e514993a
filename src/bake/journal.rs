//! The bake journal (`bake --resume`): every finished cell's result appended to a file next
//! to the output and flushed to disk before the next one is reported, so that a bake killed
//! at any moment (Ctrl-C, `kill -9`, power loss) continues from its last finished cell. Also
//! the hash of a bake's inputs ([`inputs_hash`]) that journals and shards are checked
//! against.
//!
//! Format (text, one record per line):
//! ```text
//! umbrasweep-journal 1 <inputs: 64 hex digits>
//! <crc32 of the JSON: 8 hex digits> {"cell": 17, "result": {…CellResult…}}
//! …
//! ```
//! A record counts only when its line is complete (ends in a newline), its checksum matches
//! and its JSON parses; reading stops at the first record that does not (the torn tail of an
//! interrupted write), and the file is cut back to the records before it when it is reopened
//! for appending.

use super::{BakeSettings, CellResult};
use crate::geom::Aabb;
use crate::scene::Scene;
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The first word of a journal's header line.
pub const JOURNAL_MAGIC: &str = "umbrasweep-journal";
/// The journal format's version.
pub const JOURNAL_VERSION: u32 = 1;

/// Journal failures: the path and what went wrong.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// The file cannot be read, written or flushed.
    #[error("{path}: {source}")]
    Io {
        /// The journal.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a journal (no valid header).
    #[error("{path}: not an umbrasweep bake journal ({reason}); delete it to start over")]
    NotAJournal {
        /// The journal.
        path: PathBuf,
        /// What was found instead.
        reason: String,
    },
    /// The journal was written by a bake of other inputs or settings.
    #[error(
        "{path}: this journal belongs to another bake (its scene, cells, settings, backend or \
         shard differ: inputs {found}, this bake's {expected}); run the same command as the \
         interrupted bake, or delete the journal to start over"
    )]
    OtherInputs {
        /// The journal.
        path: PathBuf,
        /// The hash in the journal.
        found: String,
        /// This bake's hash.
        expected: String,
    },
}

/// The SHA-256 (hex) of everything a bake's result depends on: the scene's geometry and
/// objects, the cells (as baked, in `f32`), the settings and `extra` (the backend choice, the
/// shard…). Two bakes with the same hash compute the same PVS.
pub fn inputs_hash(scene: &Scene, cells: &[Aabb], settings: &BakeSettings, extra: &str) -> String {
    let mut h = Sha256::new();
    h.update(b"umbrasweep-inputs 2\0");
    h.update((scene.vertices.len() as u64).to_le_bytes());
    for v in &scene.vertices {
        for c in v.to_array() {
            h.update(c.to_bits().to_le_bytes());
        }
    }
    h.update((scene.triangles.len() as u64).to_le_bytes());
    for t in &scene.triangles {
        for i in t {
            h.update(i.to_le_bytes());
        }
    }
    h.update(scene.opaque.iter().map(|&o| o as u8).collect::<Vec<u8>>());
    h.update((scene.objects.len() as u64).to_le_bytes());
    for o in &scene.objects {
        h.update((o.name.len() as u64).to_le_bytes());
        h.update(o.name.as_bytes());
        h.update(o.triangles.start.to_le_bytes());
        h.update(o.triangles.end.to_le_bytes());
        h.update([o.closed as u8]);
    }
    // Alpha-tested cards: what decides where a card occludes (materials, texture alpha and
    // wrap modes, texture coordinates, vertex alpha), so that a changed texture is a new bake.
    match &scene.alpha {
        None => h.update([0u8]),
        Some(a) => {
            h.update([1u8]);
            h.update((a.materials.len() as u64).to_le_bytes());
            for m in &a.materials {
                h.update(m.cutoff.to_bits().to_le_bytes());
                h.update(m.factor.to_bits().to_le_bytes());
                h.update(m.texture.map_or(u32::MAX, |t| t).to_le_bytes());
            }
            h.update((a.textures.len() as u64).to_le_bytes());
            for t in &a.textures {
                h.update(t.width.to_le_bytes());
                h.update(t.height.to_le_bytes());
                h.update(t.wrap.map(|w| w as u8));
                h.update(t.alpha.as_slice());
            }
            h.update((a.card_of.len() as u64).to_le_bytes());
            for c in &a.card_of {
                h.update(c.to_le_bytes());
            }
            h.update((a.cards.len() as u64).to_le_bytes());
            for c in &a.cards {
                h.update(c.material.to_le_bytes());
                for x in c.uv.iter().flat_map(|v| v.to_array()).chain(c.vertex_alpha) {
                    h.update(x.to_bits().to_le_bytes());
                }
            }
            h.update((a.missing_transparent as u64).to_le_bytes());
        }
    }
    h.update((cells.len() as u64).to_le_bytes());
    for c in cells {
        for v in [c.min, c.max] {
            for x in v.to_array() {
                h.update(x.to_bits().to_le_bytes());
            }
        }
    }
    let s = serde_json::to_string(settings).expect("settings serialise");
    h.update((s.len() as u64).to_le_bytes());
    h.update(s.as_bytes());
    h.update((extra.len() as u64).to_le_bytes());
    h.update(extra.as_bytes());
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// The journal path for an output: `OUT.journal` beside it.
pub fn journal_path(output: &Path) -> PathBuf {
    let mut s = output.as_os_str().to_owned();
    s.push(".journal");
    PathBuf::from(s)
}

#[derive(serde::Serialize, serde::Deserialize)]
struct Record {
    cell: usize,
    result: CellResult,
}

/// An open journal, appending records.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> JournalError + '_ {
    move |source| JournalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl Journal {
    /// Starts a new journal at `path` for inputs `inputs` (replacing any file there), its
    /// header flushed to disk.
    ///
    /// # Errors
    /// The file cannot be created or written.
    pub fn create(path: &Path, inputs: &str) -> Result<Journal, JournalError> {
        let mut file = File::create(path).map_err(io(path))?;
        writeln!(file, "{JOURNAL_MAGIC} {JOURNAL_VERSION} {inputs}").map_err(io(path))?;
        file.sync_all().map_err(io(path))?;
        Ok(Journal {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Opens the journal at `path` to continue it: checks that it was written for `inputs`,
    /// returns its finished cells (by cell index; a later record of a cell wins) and cuts off
    /// a torn last record.
    ///
    /// # Errors
    /// The file cannot be read or written, is not a journal, or belongs to other inputs.
    pub fn resume(
        path: &Path,
        inputs: &str,
    ) -> Result<(Journal, BTreeMap<usize, CellResult>), JournalError> {
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(io(path))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io(path))?;
        let (done, valid) = parse(path, &bytes, inputs)?;
        file.set_len(valid as u64).map_err(io(path))?;
        file.seek(SeekFrom::End(0)).map_err(io(path))?;
        file.sync_all().map_err(io(path))?;
        Ok((
            Journal {
                path: path.to_path_buf(),
                file,
            },
            done,
        ))
    }

    /// Appends cell `cell`'s result and flushes it to disk.
    ///
    /// # Errors
    /// The write or the flush failed.
    pub fn append(&mut self, cell: usize, result: &CellResult) -> Result<(), JournalError> {
        let json = serde_json::to_string(&Record {
            cell,
            result: result.clone(),
        })
        .expect("cell results serialise");
        let crc = crc32fast::hash(json.as_bytes());
        let line = format!("{crc:08x} {json}\n");
        self.file
            .write_all(line.as_bytes())
            .map_err(io(&self.path))?;
        self.file.sync_data().map_err(io(&self.path))
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Parses a journal: its finished cells and the length of its valid prefix.
fn parse(
    path: &Path,
    bytes: &[u8],
    inputs: &str,
) -> Result<(BTreeMap<usize, CellResult>, usize), JournalError> {
    let not = |reason: String| JournalError::NotAJournal {
        path: path.to_path_buf(),
        reason,
    };
    let Some(nl) = bytes.iter().position(|&b| b == b'\n') else {
        return Err(not("no complete header line".into()));
    };
    let header =
        std::str::from_utf8(&bytes[..nl]).map_err(|_| not("a header that is not text".into()))?;
    let words: Vec<&str> = header.split(' ').collect();
    if words.len() != 3 || words[0] != JOURNAL_MAGIC {
        return Err(not(format!(
            "header {:?}",
            header.chars().take(60).collect::<String>()
        )));
    }
    if words[1] != JOURNAL_VERSION.to_string() {
        return Err(not(format!(
            "journal version {} (this build writes {JOURNAL_VERSION})",
            words[1]
        )));
    }
    if words[2] != inputs {
        return Err(JournalError::OtherInputs {
            path: path.to_path_buf(),
            found: words[2].to_string(),
            expected: inputs.to_string(),
        });
    }
    let mut done = BTreeMap::new();
    let mut at = nl + 1;
    while at < bytes.len() {
        let Some(len) = bytes[at..].iter().position(|&b| b == b'\n') else {
            break;
        };
        let Some(rec) = record(&bytes[at..at + len]) else {
            break;
        };
        done.insert(rec.cell, rec.result);
        at += len + 1;
    }
    Ok((done, at))
}

fn record(line: &[u8]) -> Option<Record> {
    let line = std::str::from_utf8(line).ok()?;
    let (crc, json) = line.split_once(' ')?;
    let crc = u32::from_str_radix(crc, 16).ok()?;
    if crc32fast::hash(json.as_bytes()) != crc {
        return None;
    }
    serde_json::from_str(json).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{CullerStats, CullerWork};

    fn result(k: u32) -> CellResult {
        CellResult {
            visible: vec![0, k, k + 5],
            ms: 1.0 / 3.0 + f64::from(k),
            planes: 7,
            occluders_projected: 11,
            cullers: vec![CullerStats {
                hidden: k,
                only: 1,
                ms: 0.1,
                work: CullerWork {
                    planes: 3,
                    occluders_projected: 4,
                    points: 5,
                    polygons: 6,
                    finest_eps: Some(0.0123),
                    levels: vec![crate::pvs::SamplingLevel {
                        eps: 0.5,
                        resolution: 512,
                        points: 5,
                        seconds: 0.25,
                        hidden: k,
                        probe_only: k.is_multiple_of(2),
                        probe_hidden: k.is_multiple_of(2).then_some(0.25),
                        probe_cell_hidden: k.is_multiple_of(2).then_some(k),
                        probe_objects: k.is_multiple_of(2).then_some(100),
                        probe_rects: k.is_multiple_of(2).then_some(7),
                        probe_cost: k.is_multiple_of(2).then_some(3.5),
                        pilot_saving: k.is_multiple_of(4).then_some(1.25),
                    }],
                    cpu_fallback: k
                        .is_multiple_of(3)
                        .then(|| "512 px: GPU error: plane size 4096 × 4096".to_string()),
                    // Not recorded: already in `ms`.
                    resumed_ms: 0.0,
                },
            }],
            // A subdivided cell's halves travel with it.
            children: if k % 2 == 1 {
                vec![crate::bake::ChildCell {
                    min: [0.0, 0.5, 1.0],
                    max: [2.0, 2.5, 3.0],
                    result: result(k - 1),
                }]
            } else {
                Vec::new()
            },
        }
    }

    #[test]
    fn a_changed_card_texture_changes_the_inputs_hash() {
        use crate::scene::alpha::{AlphaCards, AlphaMaterial, AlphaTexture, CardTriangle, Wrap};
        use glam::{Vec2, Vec3};
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut scene = Scene::from_objects(
            std::path::Path::new("t.obj"),
            vec![("a".into(), vec![tri], true)],
        );
        let cells = [Aabb::new(Vec3::splat(2.0), Vec3::splat(3.0))];
        let settings = BakeSettings::default();
        let plain = inputs_hash(&scene, &cells, &settings, "");
        let cards = |alpha: u8| AlphaCards {
            materials: vec![AlphaMaterial {
                name: "leaf".into(),
                cutoff: 0.5,
                factor: 1.0,
                texture: Some(0),
            }],
            textures: vec![AlphaTexture {
                label: "leaf.png".into(),
                width: 2,
                height: 1,
                alpha: std::sync::Arc::new(vec![255, alpha]),
                wrap: [Wrap::Repeat; 2],
            }],
            card_of: vec![0],
            cards: vec![CardTriangle {
                material: 0,
                uv: [Vec2::ZERO, Vec2::X, Vec2::Y],
                vertex_alpha: [1.0; 3],
            }],
            missing_transparent: 0,
        };
        scene.alpha = Some(cards(0));
        let with_cards = inputs_hash(&scene, &cells, &settings, "");
        scene.alpha = Some(cards(255));
        let other_texture = inputs_hash(&scene, &cells, &settings, "");
        assert_ne!(plain, with_cards);
        assert_ne!(with_cards, other_texture, "one texel changed");
        scene.alpha = Some(cards(0));
        assert_eq!(with_cards, inputs_hash(&scene, &cells, &settings, ""));
    }

    #[test]
    fn records_round_trip_and_a_torn_tail_is_cut() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.json.journal");
        let mut j = Journal::create(&p, "abc").unwrap();
        j.append(3, &result(3)).unwrap();
        j.append(0, &result(0)).unwrap();
        drop(j);
        // A torn record: half a line.
        let full = std::fs::read(&p).unwrap();
        let mut f = OpenOptions::new().append(true).open(&p).unwrap();
        f.write_all(b"1234abcd {\"cell\": 9, \"res").unwrap();
        drop(f);
        let (mut j, done) = Journal::resume(&p, "abc").unwrap();
        assert_eq!(done.len(), 2);
        assert_eq!(done[&3], result(3));
        assert_eq!(done[&0], result(0));
        assert_eq!(std::fs::read(&p).unwrap(), full, "the torn tail is cut off");
        j.append(9, &result(9)).unwrap();
        drop(j);
        let (_, done) = Journal::resume(&p, "abc").unwrap();
        assert_eq!(done.keys().copied().collect::<Vec<_>>(), vec![0, 3, 9]);
    }

    #[test]
    fn a_bad_checksum_ends_the_journal_and_other_inputs_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("j");
        let mut j = Journal::create(&p, "abc").unwrap();
        j.append(1, &result(1)).unwrap();
        j.append(2, &result(2)).unwrap();
        drop(j);
        let text = std::fs::read_to_string(&p).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // Flip one digit of the second record's JSON.
        let bad = lines[2].replacen("\"cell\":2", "\"cell\":4", 1);
        assert_ne!(bad, lines[2]);
        std::fs::write(&p, format!("{}\n{}\n{bad}\n", lines[0], lines[1])).unwrap();
        let (_, done) = Journal::resume(&p, "abc").unwrap();
        assert_eq!(done.keys().copied().collect::<Vec<_>>(), vec![1]);
        let e = Journal::resume(&p, "xyz").unwrap_err();
        assert!(matches!(e, JournalError::OtherInputs { .. }), "{e}");
        assert!(e.to_string().contains("delete the journal"), "{e}");
        std::fs::write(&p, "hello\n").unwrap();
        let e = Journal::resume(&p, "abc").unwrap_err();
        assert!(matches!(e, JournalError::NotAJournal { .. }), "{e}");
    }
}
