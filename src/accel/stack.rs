//! The traversal stack: a fixed array on the call stack that spills to the heap, so that a
//! pathologically deep tree costs an allocation rather than a wrong answer.

pub(crate) struct TraversalStack<T: Copy + Default, const N: usize> {
    inline: [T; N],
    len: usize,
    spill: Vec<T>,
}

impl<T: Copy + Default, const N: usize> TraversalStack<T, N> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        TraversalStack {
            inline: [T::default(); N],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, v: T) {
        if self.len < N {
            self.inline[self.len] = v;
            self.len += 1;
        } else {
            self.spill.push(v);
        }
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if !self.spill.is_empty() {
            return self.spill.pop();
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }
}
