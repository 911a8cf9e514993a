//! Tables a bake keeps on the device, each element written when work first names it, from
//! that work's own values:
//! [`ResidentTable`], the occludee boxes of the box tests ([`super::hdm::ResidentBoxes`]) and
//! the scene's occluder parts' points of the counted projections ([`ResidentParts`]).

use super::device::ErrorScopes;
use crate::backend::BackendError;
use std::sync::{Arc, Mutex};

/// A table of `f64` elements (`stride` `f64`s each) kept on the device: work then names an
/// element by its index instead of sending it, and each element goes up the first time work
/// names it, from the values that work has at hand ([`ResidentTable::send_given`]), so a bake
/// uploads at most what it uses, once, and keeps no copy of the table on the CPU.
#[derive(Clone, Debug)]
pub(super) struct ResidentTable {
    /// Which table this is: work naming another sends its data whole.
    pub generation: u64,
    /// The device's table, each element written before the first submission that reads it.
    pub buffer: Arc<wgpu::Buffer>,
    /// What the elements must be, where kept to check work against (debug builds).
    check: Option<Arc<[f64]>>,
    /// Elements in the table.
    len: usize,
    /// `f64`s per element.
    stride: usize,
    /// One bit per element: written to `buffer` already.
    sent: Arc<Mutex<Vec<u64>>>,
}

/// The device's buffer of `f64s` `f64`s (zeros), mapped at creation.
///
/// Mapped at creation, so that wgpu knows it initialised from the start: a buffer it thinks
/// uninitialised is zeroed where a submission binds it, and that clear could land after
/// another thread's first write of an element in the same submission, leaving the element
/// zero (work on the wrong data: for boxes a false cull, seen on lavapipe as 5–19 objects of a
/// cell culled by some runs).
fn mapped_table(
    device: &wgpu::Device,
    label: &str,
    f64s: usize,
) -> Result<wgpu::Buffer, BackendError> {
    let scope = ErrorScopes::push(device);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (f64s as u64 * 8).max(8),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: true,
    });
    buffer.unmap();
    scope.check()?;
    Ok(buffer)
}

impl ResidentTable {
    /// A table of `len` elements of `stride` `f64`s (zeros) that keeps nothing on the CPU:
    /// work that names an element for the first time gives its values
    /// ([`ResidentTable::send_given`]). `check`, where given (debug builds), holds what the
    /// elements must be, for [`ResidentTable::element`].
    ///
    /// # Errors
    /// [`BackendError`] when the device fails to make the buffer.
    pub fn given(
        device: &wgpu::Device,
        label: &str,
        (len, stride): (usize, usize),
        generation: u64,
        check: Option<Arc<[f64]>>,
    ) -> Result<Self, BackendError> {
        let buffer = mapped_table(device, label, len * stride)?;
        Ok(ResidentTable {
            generation,
            buffer: Arc::new(buffer),
            check,
            len,
            stride,
            sent: Arc::new(Mutex::new(vec![0; len.div_ceil(64)])),
        })
    }

    /// Elements in the table.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Bytes of the device's table.
    pub fn bytes(&self) -> u64 {
        (self.len * self.stride) as u64 * 8
    }

    /// What element `i` must be, where the table keeps that to check (panics when
    /// `i >= len()`).
    pub fn element(&self, i: usize) -> Option<&[f64]> {
        let d = self.check.as_ref()?;
        Some(&d[i * self.stride..(i + 1) * self.stride])
    }

    /// Writes to the device the elements of each `(first, values)` not written yet: the
    /// elements from `first` on that `values` fills (`stride` per element; work names a run
    /// of elements together, and all of a run are new or none are). Runs that meet go up as
    /// one write. Returns the bytes written. The bits are set and the elements written under
    /// one lock, so a submission made after this returns — on any thread, once it has seen an
    /// element's bit set — reads the element.
    ///
    /// # Panics
    /// When a run reaches beyond the table.
    pub fn send_given(&self, queue: &wgpu::Queue, runs: Vec<(u32, &[f64])>) -> u64 {
        let mut sent = self.sent.lock().unwrap_or_else(|e| e.into_inner());
        let mut new: Vec<(u32, &[f64])> = runs
            .into_iter()
            .filter(|&(first, values)| {
                let fresh = sent[first as usize / 64] & 1u64 << (first % 64) == 0;
                for id in first..first + (values.len() / self.stride) as u32 {
                    sent[id as usize / 64] |= 1u64 << (id % 64);
                }
                fresh
            })
            .collect();
        new.sort_unstable_by_key(|r| r.0);
        let mut written = 0u64;
        let mut k = 0;
        let mut bytes: Vec<f64> = Vec::new();
        while k < new.len() {
            let start = new[k].0;
            let mut end = start;
            bytes.clear();
            while k < new.len() && new[k].0 == end {
                bytes.extend_from_slice(new[k].1);
                end += (new[k].1.len() / self.stride) as u32;
                k += 1;
            }
            queue.write_buffer(
                &self.buffer,
                u64::from(start) * self.stride as u64 * 8,
                bytemuck::cast_slice(&bytes),
            );
            written += bytes.len() as u64 * 8;
        }
        written
    }
}

/// The scene's occluder parts' points kept on the device for the counted projections
/// ([`crate::backend::RasterBackend::upload_occluder_parts`]): the table's elements are
/// points (three `f64`), part `k` is `spans[k]` of them, each part written the first time a
/// counted occluder names it, from that occluder's own points, which are the part's bit for bit
/// (a scene's points can be hundreds of megabytes, of which no second copy stays on the CPU
/// but in debug builds, which check each named occluder against its part).
/// A counted occluder that is a scene part unchanged then sends 16 bytes (its record) instead
/// of 16 plus 24 per point.
#[derive(Clone, Debug)]
pub(super) struct ResidentParts {
    /// The points.
    pub points: ResidentTable,
    /// Per part, its points' range in the table.
    pub spans: Arc<[(u32, u32)]>,
}

impl ResidentParts {
    /// The range of part `part`'s points in the table when `job_table` (the job's
    /// [`crate::plane::OccluderSet::table`]) names this table, the part is in it and has
    /// `n` points; `None` sends the occluder's points whole.
    pub fn span(&self, job_table: Option<u64>, part: Option<u32>, n: usize) -> Option<(u32, u32)> {
        if job_table != Some(self.points.generation) {
            return None;
        }
        let s = *self.spans.get(part? as usize)?;
        (s.1.checked_sub(s.0)? as usize == n && s.1 as usize <= self.points.len()).then_some(s)
    }
}

/// How many of the parts `spans` (each part's range of `points` points, in order) a table of
/// at most `binding` bytes (24 a point) keeps, from the first, and the points it then holds.
pub(super) fn parts_that_fit(spans: &[(u32, u32)], points: usize, binding: u64) -> (usize, usize) {
    let fit = (binding / 24).min(points as u64);
    let kept = spans.partition_point(|&(_, end)| u64::from(end) <= fit);
    let end = kept.checked_sub(1).map_or(0, |k| spans[k].1 as usize);
    (kept, end)
}

#[cfg(test)]
mod tests {
    use super::parts_that_fit;

    /// A table beyond one binding keeps the whole parts that fit, from the first; none when
    /// even the first does not fit.
    #[test]
    fn a_table_keeps_the_whole_parts_that_fit_one_binding() {
        let spans = [(0, 3), (3, 7), (7, 10), (10, 18)];
        assert_eq!(parts_that_fit(&spans, 18, 24 * 18), (4, 18));
        assert_eq!(parts_that_fit(&spans, 18, u64::MAX), (4, 18));
        assert_eq!(parts_that_fit(&spans, 18, 24 * 17), (3, 10));
        assert_eq!(parts_that_fit(&spans, 18, 24 * 10 + 23), (3, 10));
        assert_eq!(parts_that_fit(&spans, 18, 24 * 9), (2, 7));
        assert_eq!(parts_that_fit(&spans, 18, 24 * 2), (0, 0));
        assert_eq!(parts_that_fit(&[], 0, 1 << 30), (0, 0));
    }
}
