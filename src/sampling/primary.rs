//! Primary-sample vectors: per slot, a vector of numbers in [0, 1) that a later system reads
//! instead of drawing them. Metropolis chains in primary sample space mutate these vectors;
//! the evaluation systems read them through `Sampler::Primary`.

/// Per-slot vectors of up to `dims` numbers, stored dimension-major (all slots' dimension 0,
/// then all slots' dimension 1, ...), so a system that reads one dimension of a run of slots
/// reads contiguous memory.
///
/// Each slot has its own length, `used(slot)` <= `dims`: the numbers its evaluation can read
/// (in MMLT, those of a path of the chain's depth). Mutations and copies stop there, so a
/// chain of depth 1 costs 24 numbers per step rather than the 294 of depth 16; reading past
/// a slot's length is a bug, checked in debug builds.
///
/// A vector is infinite: past its stored numbers, number d of a slot is the hash of the slot's
/// `tail` seed and d (`Sampler::Primary`), so a path may be of any depth. A mutation gives the
/// proposal a fresh tail seed every step (an independent uniform proposal for the unstored
/// numbers: symmetric, so acceptance needs no correction), and an accepted proposal's seed
/// becomes the chain's, so the current state's whole vector is known and replayable.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrimarySamples {
    slots: usize,
    dims: u32,
    values: Vec<f32>,
    used: Vec<u32>,
    tails: Vec<u64>,
}

impl PrimarySamples {
    /// `slots` vectors of `dims` numbers, all 0, every slot using all `dims`.
    pub fn new(slots: usize, dims: u32) -> PrimarySamples {
        PrimarySamples {
            slots,
            dims,
            values: vec![0.0; slots * dims as usize],
            used: vec![dims; slots],
            tails: vec![0; slots],
        }
    }

    /// The seed of slot `slot`'s numbers past the stored ones.
    #[inline]
    pub fn tail(&self, slot: usize) -> u64 {
        self.tails[slot]
    }

    /// Every slot's tail seed.
    pub fn tails(&self) -> &[u64] {
        &self.tails
    }

    /// Every slot's tail seed, to write.
    pub fn tails_mut(&mut self) -> &mut [u64] {
        &mut self.tails
    }

    pub fn slots(&self) -> usize {
        self.slots
    }

    pub fn dims(&self) -> u32 {
        self.dims
    }

    /// The numbers slot `slot` uses.
    #[inline]
    pub fn used(&self, slot: usize) -> u32 {
        self.used[slot]
    }

    /// Sets slot `slot`'s length (at most `dims`).
    pub fn set_used(&mut self, slot: usize, used: u32) {
        assert!(
            used <= self.dims,
            "a slot uses at most {} numbers",
            self.dims
        );
        self.used[slot] = used;
    }

    /// Becomes a copy of `other`, in parallel (a store is up to hundreds of megabytes: one
    /// serial copy was a serial stretch of MLT's seeding).
    pub fn copy_from(&mut self, other: &PrimarySamples) {
        use rayon::prelude::*;
        const PIECE: usize = 1 << 16;
        self.slots = other.slots;
        self.dims = other.dims;
        self.values.resize(other.values.len(), 0.0);
        self.values
            .par_chunks_mut(PIECE)
            .zip(other.values.par_chunks(PIECE))
            .for_each(|(to, from)| to.copy_from_slice(from));
        self.used.clone_from(&other.used);
        self.tails.clone_from(&other.tails);
    }

    /// Number `dim` of slot `slot`.
    #[inline]
    pub fn get(&self, slot: usize, dim: u32) -> f32 {
        debug_assert!(
            dim < self.used[slot],
            "slot {slot} read number {dim} of its {}",
            self.used[slot]
        );
        self.values[dim as usize * self.slots + slot]
    }

    #[inline]
    pub fn set(&mut self, slot: usize, dim: u32, value: f32) {
        self.values[dim as usize * self.slots + slot] = value;
    }

    /// Dimension `dim` of every slot.
    pub fn column(&self, dim: u32) -> &[f32] {
        let start = dim as usize * self.slots;
        &self.values[start..start + self.slots]
    }

    pub fn column_mut(&mut self, dim: u32) -> &mut [f32] {
        let start = dim as usize * self.slots;
        &mut self.values[start..start + self.slots]
    }

    /// The store cut into blocks of `block` slots (the last may be shorter), each block as
    /// its slots' lengths and its columns: `columns[d]` is dimension d of the block's slots,
    /// for d below the longest length in the block. Lets one parallel loop over blocks write
    /// every dimension a block uses.
    pub fn blocks_mut(&mut self, block: usize) -> Vec<SampleBlock<'_>> {
        let slots = self.slots;
        let mut blocks: Vec<SampleBlock> = self
            .used
            .chunks(block)
            .enumerate()
            .map(|(b, used)| SampleBlock {
                first: b * block,
                used,
                columns: Vec::new(),
            })
            .collect();
        let longest: Vec<usize> = blocks
            .iter()
            .map(|b| b.used.iter().copied().max().unwrap_or(0) as usize)
            .collect();
        if slots == 0 {
            return blocks;
        }
        for column in self.values.chunks_mut(slots) {
            for ((b, &longest), part) in blocks
                .iter_mut()
                .zip(&longest)
                .zip(column.chunks_mut(block))
            {
                if b.columns.len() < longest {
                    b.columns.push(part);
                }
            }
        }
        blocks
    }
}

/// A block of consecutive slots of a [`PrimarySamples`] (see `blocks_mut`).
pub struct SampleBlock<'a> {
    /// The block's first slot.
    pub first: usize,
    /// Its slots' lengths.
    pub used: &'a [u32],
    /// Its columns, up to the longest length among its slots.
    pub columns: Vec<&'a mut [f32]>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parallel_copy_equals_a_clone() {
        let mut from = PrimarySamples::new(70_001, 3);
        for slot in 0..from.slots() {
            from.set_used(slot, (slot % 4) as u32);
            for dim in 0..from.used(slot) {
                from.set(slot, dim, (slot * 3 + dim as usize) as f32);
            }
        }
        for mut to in [PrimarySamples::new(5, 4), PrimarySamples::new(80_000, 3)] {
            to.copy_from(&from);
            assert_eq!(to, from);
        }
    }

    #[test]
    fn blocks_hold_the_columns_their_slots_use() {
        let mut s = PrimarySamples::new(5, 4);
        s.set_used(0, 1);
        s.set_used(1, 2);
        s.set_used(2, 1);
        s.set_used(3, 0);
        s.set_used(4, 3);
        for block in s.blocks_mut(2) {
            for (d, column) in block.columns.into_iter().enumerate() {
                for (i, x) in column.iter_mut().enumerate() {
                    *x = (10 * (block.first + i) + d) as f32;
                }
            }
        }
        // Block 0 (slots 0, 1) has 2 columns, block 1 (2, 3) one, block 2 (4) three.
        assert_eq!(s.get(1, 1), 11.0);
        assert_eq!(s.get(2, 0), 20.0);
        assert_eq!(s.column(1)[3], 0.0);
        assert_eq!(s.get(4, 2), 42.0);
        assert_eq!(s.column(3)[4], 0.0);
    }
}
