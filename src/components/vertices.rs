use crate::sampling::SampleKey;
use glam::{Vec2, Vec3};

/// One subpath vertex as a `PathVertices` store keeps it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathVertex {
    pub p: Vec3,
    /// Per-axis bound on the floating-point error of `p` (for spawning rays).
    pub p_error: Vec3,
    /// Unit geometric normal as the triangle winds it (the camera's forward axis at a
    /// camera vertex).
    pub ng: Vec3,
    /// Unit shading normal.
    pub ns: Vec3,
    /// Throughput of the subpath up to and including this vertex's sampling density.
    pub beta: Vec3,
    /// The triangle the vertex lies on (its material and emitter follow from it);
    /// `CAMERA_VERTEX` at a camera vertex.
    pub triangle: u32,
    /// Density (area measure) of sampling this vertex from the previous one of its subpath.
    pub pdf_fwd: f32,
    /// Density (area measure) of sampling this vertex from the next one, were the subpath
    /// generated in the opposite direction.
    pub pdf_rev: f32,
    /// The subpath scattered here by a delta lobe.
    pub delta: bool,
}

/// Vertices of bidirectional subpaths at one depth: slot `k` is vertex `depth` of subpath
/// `k` (camera subpaths first, then light subpaths). Stored depth by depth, so a bounce of
/// the subpath walk writes one contiguous store.
///
/// Unlike the other stores, an array of whole vertices rather than one column per field:
/// connections read every field of a few vertices of one subpath from every depth, and as
/// columns that is nine memory streams per depth (on door_ajar the column gathers were 14% of
/// BDPT's time, `perf`); a whole vertex is one or two cache lines.
#[derive(Clone, Debug, Default)]
pub struct PathVertices {
    pub items: Vec<PathVertex>,
}

/// A mutable view of one range of slots of a `PathVertices` store (indexed from 0).
pub struct PathVerticesChunk<'a> {
    /// Slot of the chunk's first item.
    pub start: usize,
    pub items: &'a mut [PathVertex],
}

/// A read-only view of a range of slots of a `PathVertices` store, indexed from 0.
#[derive(Clone, Copy)]
pub struct PathVerticesView<'a> {
    pub items: &'a [PathVertex],
}

impl PathVerticesChunk<'_> {
    pub fn len(&self) -> usize {
        self.items.len()
    }
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
    #[inline]
    pub fn view(&self) -> PathVerticesView<'_> {
        PathVerticesView { items: self.items }
    }
    #[inline]
    pub fn get(&self, i: usize) -> PathVertex {
        self.items[i]
    }
    #[inline]
    pub fn set(&mut self, i: usize, item: PathVertex) {
        self.items[i] = item;
    }
}

impl PathVerticesView<'_> {
    #[inline]
    pub fn get(&self, i: usize) -> PathVertex {
        self.items[i]
    }
}

impl PathVertices {
    /// A store of `capacity` default vertices, written in parallel: a BDPT wave allocates one
    /// store of two vertices per sample for each depth it reaches first, and filling those
    /// serially kept one core busy while the other waited.
    pub fn new(capacity: usize) -> PathVertices {
        use rayon::prelude::*;
        let mut items = Vec::with_capacity(capacity);
        items.par_extend(rayon::iter::repeat_n(PathVertex::default(), capacity));
        PathVertices { items }
    }

    pub fn capacity(&self) -> usize {
        self.items.len()
    }

    pub fn bytes_per_item() -> usize {
        std::mem::size_of::<PathVertex>()
    }

    #[inline]
    pub fn get(&self, slot: usize) -> PathVertex {
        self.items[slot]
    }

    #[inline]
    pub fn set(&mut self, slot: usize, item: PathVertex) {
        self.items[slot] = item;
    }

    /// Views of the slots in `range`, `CHUNK` slots each.
    pub fn chunks_mut(&mut self, range: std::ops::Range<usize>) -> Vec<PathVerticesChunk<'_>> {
        let start = range.start;
        self.items[range]
            .chunks_mut(crate::components::CHUNK)
            .enumerate()
            .map(|(c, items)| PathVerticesChunk {
                start: start + c * crate::components::CHUNK,
                items,
            })
            .collect()
    }

    /// Mutable views of consecutive ranges: view k covers `starts[k]..starts[k + 1]` (the
    /// last one ends at `end`), as the column stores' `split_mut`.
    pub fn split_mut(&mut self, starts: &[usize], end: usize) -> Vec<PathVerticesChunk<'_>> {
        crate::components::split_ranges(&mut self.items, starts, end)
            .into_iter()
            .zip(starts)
            .map(|(items, &start)| PathVerticesChunk { start, items })
            .collect()
    }

    /// A read-only view of the slots in `range`.
    #[inline]
    pub fn view(&self, range: std::ops::Range<usize>) -> PathVerticesView<'_> {
        PathVerticesView {
            items: &self.items[range],
        }
    }
}

/// `PathVertices::triangle` of a camera vertex.
pub const CAMERA_VERTEX: u32 = u32::MAX;

crate::soa! {
    /// Subpaths being extended, one per slot, compacted as they end.
    pub struct Walkers, WalkersChunk, WalkersView, Walker {
        /// The subpath this walker extends (index into the vertex stores).
        subpath: u32,
        key: SampleKey,
        /// Throughput of the ray being traced.
        beta: Vec3,
        /// Solid-angle density of the ray's direction (0 after a delta lobe).
        pdf_dir: f32,
        /// Russian roulette compares `beta` against this (the throughput the walk started
        /// with), so that a light subpath's emitted power does not make it immortal.
        roulette_scale: f32,
        alive: bool,
    }
}

crate::soa! {
    /// Which film position each connection of a wave feeds, slot for slot with its shadow ray.
    pub struct Connections, ConnectionsChunk, ConnectionsView, Connection {
        /// The sample (index in the wave) whose subpaths the connection joins.
        sample: u32,
        /// Pixel the contribution lands in: the sample's own, or for light tracing (t = 1)
        /// the pixel the light vertex projects to.
        pixel: u32,
        /// For light tracing (t = 1), where in `pixel` the light vertex projects (raster
        /// position, pixels of the rendered image): a filter wider than a pixel spreads the
        /// splat from there. NaN for the other strategies (they land with their sample).
        raster: Vec2,
        /// Light subpath vertices used (s).
        s: u16,
        /// Camera subpath vertices used (t).
        t: u16,
    }
}
