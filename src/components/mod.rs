//! Structure-of-arrays components: one `Vec` per field, indexed by slot.
//!
//! Every store is sized once to the wavefront and reused across bounces and passes. Live items
//! are kept contiguous (slots `0..len`): compaction and sorting gather them into a scratch store
//! of the same shape and swap, so systems run over plain slices split into fixed-size chunks,
//! which rayon processes in parallel without any shared mutable state.

pub mod camera_walk;
pub mod metropolis;
pub mod path_tracing;
mod paths;
pub mod photon_mapping;
mod photons;
pub mod ray_record;
mod rays;
mod shadow;
pub mod subpaths;
mod surfaces;
mod vertices;
mod visible_points;
pub mod wave;

pub use paths::*;
pub use photons::*;
pub use rays::*;
pub use shadow::*;
pub use surfaces::*;
pub use vertices::*;
pub use visible_points::*;
pub use wave::Wave;

/// Items per chunk of parallel work. Fixed, so the work split never depends on thread count.
pub const CHUNK: usize = 1024;

/// Items from which `filled` writes in parallel.
const PARALLEL_FILL: usize = 1 << 16;

/// `len` default values, written in parallel when many: PPM's stores of a million hit points
/// were filled serially while the other core waited.
pub fn filled<T: Default + Clone + Send + Sync>(len: usize) -> Vec<T> {
    use rayon::prelude::*;
    if len < PARALLEL_FILL {
        return vec![T::default(); len];
    }
    let mut items = Vec::with_capacity(len);
    items.par_extend(rayon::iter::repeat_n(T::default(), len));
    items
}

/// Lengthens `items` to `len` with default values, written in parallel when many (as
/// `filled`: PPM's hit-point stores grow to a million slots during its first pass).
pub fn grow<T: Default + Clone + Send + Sync>(items: &mut Vec<T>, len: usize) {
    use rayon::prelude::*;
    let more = len.saturating_sub(items.len());
    if more < PARALLEL_FILL {
        items.resize(items.len() + more, T::default());
        return;
    }
    items.reserve_exact(more);
    items.par_extend(rayon::iter::repeat_n(T::default(), more));
}

/// `dst[i] = src[order[i]]` for `i < order.len()`, in parallel over fixed-size chunks.
pub fn gather_column<T: Copy + Send + Sync>(dst: &mut [T], src: &[T], order: &[u32]) {
    use rayon::prelude::*;
    dst[..order.len()]
        .par_chunks_mut(CHUNK)
        .zip(order.par_chunks(CHUNK))
        .for_each(|(dst, idx)| {
            for (d, &i) in dst.iter_mut().zip(idx) {
                *d = src[i as usize];
            }
        });
}

/// Fills `order` with the slots whose `alive` flag is set, in slot order: the gather order of a
/// stable compaction. In parallel over fixed-size chunks (each chunk's live slots counted, then
/// written from where the chunks before it end): one serial pass per bounce was the largest
/// serial stretch of the compaction systems.
pub fn live_slots(alive: &[bool], order: &mut Vec<u32>) {
    use rayon::prelude::*;
    let counts: Vec<usize> = alive
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|&&a| a).count())
        .collect();
    let mut starts = Vec::with_capacity(counts.len());
    let mut total = 0;
    for count in counts {
        starts.push(total);
        total += count;
    }
    order.clear();
    order.resize(total, 0);
    split_ranges(order, &starts, total)
        .into_par_iter()
        .zip(alive.par_chunks(CHUNK))
        .enumerate()
        .for_each(|(c, (out, alive))| {
            let live = (0..alive.len()).filter(|&i| alive[i]);
            for (o, i) in out.iter_mut().zip(live) {
                *o = (c * CHUNK + i) as u32;
            }
        });
}

/// Splits `slice[..end]` into consecutive pieces: piece k is `starts[k]..starts[k + 1]` (the
/// last one ends at `end`). Panics if `starts` decreases or passes `end`.
pub fn split_ranges<'a, T>(slice: &'a mut [T], starts: &[usize], end: usize) -> Vec<&'a mut [T]> {
    let mut rest = &mut slice[..end];
    let mut at = 0;
    let mut out = Vec::with_capacity(starts.len());
    for (k, &start) in starts.iter().enumerate() {
        let stop = starts.get(k + 1).copied().unwrap_or(end);
        assert!(
            at <= start && start <= stop,
            "split_ranges: ranges out of order"
        );
        let (_, tail) = std::mem::take(&mut rest).split_at_mut(start - at);
        let (piece, tail) = tail.split_at_mut(stop - start);
        rest = tail;
        at = stop;
        out.push(piece);
    }
    out
}

/// Declares a structure-of-arrays store and its chunk view.
///
/// `soa! { pub struct Rays, RaysChunk, RaysView, Ray { origin: Vec3, dir: Vec3 } }` makes `Rays` with
/// one `Vec` per field, `RaysChunk<'a>` with one `&'a mut [T]` per field plus the chunk's first
/// slot, `RaysView<'a>` with one `&'a [T]` per field, and the methods: `view(range)`, `new(capacity)`, `capacity()`, `chunks_mut(range)` (views over
/// the slots of `range` in `CHUNK`-sized pieces), `gather_from(source, order)` (slot i takes
/// source's slot `order[i]`, in parallel per column), and `bytes_per_item()`.
#[macro_export]
macro_rules! soa {
    ($(#[$meta:meta])* pub struct $name:ident, $chunk:ident, $view:ident, $item:ident { $($(#[$fmeta:meta])* $field:ident : $ty:ty),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Clone, Debug, Default)]
        pub struct $name {
            $($(#[$fmeta])* pub $field: Vec<$ty>,)+
        }

        /// One item of the store, every field.
        #[derive(Clone, Copy, Debug)]
        pub struct $item {
            $($(#[$fmeta])* pub $field: $ty,)+
        }

        /// A mutable view of one chunk of slots.
        pub struct $chunk<'a> {
            /// Slot of the chunk's first item.
            pub start: usize,
            $(pub $field: &'a mut [$ty],)+
        }

        /// A read-only view of a range of slots, indexed from 0. Systems take one per chunk so
        /// that indexing inside the chunk's loop needs no bounds checks.
        pub struct $view<'a> {
            $(pub $field: &'a [$ty],)+
        }

        impl $chunk<'_> {
            pub fn len(&self) -> usize {
                let lens = [$(self.$field.len()),+];
                lens[0]
            }
            pub fn is_empty(&self) -> bool {
                self.len() == 0
            }
            /// A read-only view of the chunk (indexed from 0, like the chunk).
            #[inline]
            pub fn view(&self) -> $view<'_> {
                $view { $($field: &*self.$field,)+ }
            }
            /// Item `i` of the chunk.
            #[inline(always)]
            pub fn get(&self, i: usize) -> $item {
                $item { $($field: self.$field[i],)+ }
            }
            /// Writes every field of item `i` of the chunk.
            #[inline(always)]
            pub fn set(&mut self, i: usize, item: $item) {
                $(self.$field[i] = item.$field;)+
            }
        }

        impl $view<'_> {
            /// Item `i` of the view.
            #[inline(always)]
            pub fn get(&self, i: usize) -> $item {
                $item { $($field: self.$field[i],)+ }
            }
        }

        impl $name {
            pub fn new(capacity: usize) -> Self {
                Self { $($field: $crate::components::filled(capacity),)+ }
            }

            pub fn capacity(&self) -> usize {
                let lens = [$(self.$field.len()),+];
                lens[0]
            }

            /// Grows the store to at least `capacity` slots (doubling, so that appending one
            /// item at a time stays linear), keeping its items.
            pub fn reserve_slots(&mut self, capacity: usize) {
                if self.capacity() < capacity {
                    let grown = capacity.max(2 * self.capacity());
                    $($crate::components::grow(&mut self.$field, grown);)+
                }
            }

            pub fn bytes_per_item() -> usize {
                0 $(+ std::mem::size_of::<$ty>())+
            }

            /// The item in `slot`.
            #[inline(always)]
            pub fn get(&self, slot: usize) -> $item {
                $item { $($field: self.$field[slot],)+ }
            }

            /// Writes every field of the item in `slot`.
            #[inline(always)]
            pub fn set(&mut self, slot: usize, item: $item) {
                $(self.$field[slot] = item.$field;)+
            }

            /// Views of the slots in `range`, `CHUNK` slots each.
            pub fn chunks_mut(&mut self, range: std::ops::Range<usize>) -> Vec<$chunk<'_>> {
                let n_chunks = range.len().div_ceil($crate::components::CHUNK);
                let mut views = Vec::with_capacity(n_chunks);
                $(let mut $field = self.$field[range.clone()].chunks_mut($crate::components::CHUNK);)+
                for c in 0..n_chunks {
                    views.push($chunk {
                        start: range.start + c * $crate::components::CHUNK,
                        $($field: $field.next().expect("one slice per chunk"),)+
                    });
                }
                views
            }

            /// Mutable views of consecutive ranges: view k covers `starts[k]..starts[k + 1]`
            /// (the last one ends at `end`). `starts` must be non-decreasing and end at most at
            /// `end`. For work split by something other than fixed chunks (each chunk of a
            /// queue owning the slots of the items it holds).
            pub fn split_mut(&mut self, starts: &[usize], end: usize) -> Vec<$chunk<'_>> {
                $(let mut $field = $crate::components::split_ranges(&mut self.$field, starts, end).into_iter();)+
                starts
                    .iter()
                    .map(|&start| $chunk {
                        start,
                        $($field: $field.next().expect("one slice per range"),)+
                    })
                    .collect()
            }

            /// A read-only view of the slots in `range`.
            #[inline]
            pub fn view(&self, range: std::ops::Range<usize>) -> $view<'_> {
                $view { $($field: &self.$field[range.clone()],)+ }
            }

            /// Slot `i` takes `source`'s slot `order[i]`, for `i < order.len()`. One parallel
            /// loop over fixed chunks, each gathering every column (one loop per column
            /// spent more on starting loops than on copying when few items were left).
            pub fn gather_from(&mut self, source: &Self, order: &[u32]) {
                use rayon::prelude::*;
                self.chunks_mut(0..order.len()).into_par_iter().for_each(|c| {
                    let order = &order[c.start..c.start + c.len()];
                    $(for (d, &i) in c.$field.iter_mut().zip(order) {
                        *d = source.$field[i as usize];
                    })+
                });
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn live_slots_are_the_set_flags_in_order() {
        for len in [0, 1, CHUNK - 1, CHUNK, 3 * CHUNK + 17] {
            for pattern in [0u32, 1, 7, 1 << 20] {
                // A mix of runs and scattered flags: hash-like bits of (slot, pattern).
                let alive: Vec<bool> = (0..len as u32)
                    .map(|i| (i.wrapping_mul(2654435761) ^ pattern) % 3 == 0 || pattern == 0)
                    .collect();
                let mut order = vec![99; 5];
                live_slots(&alive, &mut order);
                let expected: Vec<u32> = (0..len as u32).filter(|&i| alive[i as usize]).collect();
                assert_eq!(order, expected, "len {len}, pattern {pattern}");
            }
        }
    }
}
