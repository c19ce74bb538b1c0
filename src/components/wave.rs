//! The samples a wave of a sample-based integrator renders.

/// The samples a wave renders: global sample ids `first..first + len`, where global sample id
/// g is pixel `g % pixels` at sample index `g / pixels`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Wave {
    pub first: u64,
    pub len: usize,
}
