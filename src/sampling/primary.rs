//! Primary-sample vectors: per slot, a vector of numbers in [0, 1) that a later system reads
//! instead of drawing them. Metropolis chains in primary sample space mutate these vectors;
//! the evaluation systems read them through `Sampler::Primary`.

/// Per-slot vectors of `dims` numbers, stored dimension-major (all slots' dimension 0, then
/// all slots' dimension 1, ...), so a system that writes one dimension of every slot writes
/// one contiguous column.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrimarySamples {
    slots: usize,
    dims: u32,
    values: Vec<f32>,
}

impl PrimarySamples {
    /// `slots` vectors of `dims` numbers, all 0.
    pub fn new(slots: usize, dims: u32) -> PrimarySamples {
        PrimarySamples {
            slots,
            dims,
            values: vec![0.0; slots * dims as usize],
        }
    }

    pub fn slots(&self) -> usize {
        self.slots
    }

    pub fn dims(&self) -> u32 {
        self.dims
    }

    /// Number `dim` of slot `slot`.
    #[inline]
    pub fn get(&self, slot: usize, dim: u32) -> f32 {
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
}
