//! A balanced kd-tree over points for k-nearest-neighbour queries (the PM density estimate):
//! the points are reordered so that every subtree is a contiguous range with its median in
//! the middle, split along the axis of the range's largest extent. Built in parallel by
//! median selection; the result depends only on the input order.

use glam::Vec3;

pub struct KdTree {
    /// Point indices in tree order.
    order: Vec<u32>,
    points: Vec<Vec3>,
    /// Split axis of the node whose median sits at each position.
    axis: Vec<u8>,
}

/// Ranges below this size are built on one thread.
const PARALLEL_BUILD: usize = 4096;

fn build(points: &mut [(Vec3, u32)], axis: &mut [u8]) {
    if points.len() <= 1 {
        return;
    }
    let (lo, hi) = points
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
    let extent = hi - lo;
    let a = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = points.len() / 2;
    points.select_nth_unstable_by(mid, |p, q| p.0[a].total_cmp(&q.0[a]).then(p.1.cmp(&q.1)));
    axis[mid] = a as u8;
    let (left, rest) = points.split_at_mut(mid);
    let right = &mut rest[1..];
    let (axis_left, axis_rest) = axis.split_at_mut(mid);
    let axis_right = &mut axis_rest[1..];
    if left.len() > PARALLEL_BUILD {
        rayon::join(|| build(left, axis_left), || build(right, axis_right));
    } else {
        build(left, axis_left);
        build(right, axis_right);
    }
}

/// The k nearest found so far, as (squared distance, index): a max-heap on (distance, index)
/// once full, so the farthest is `found[0]` and each better point costs O(log k).
pub struct Nearest {
    pub found: Vec<(f32, u32)>,
    k: usize,
    max_d2: f32,
}

#[inline]
fn farther(a: (f32, u32), b: (f32, u32)) -> bool {
    a.0 > b.0 || (a.0 == b.0 && a.1 > b.1)
}

impl Nearest {
    pub fn new(k: usize, max_radius: f32) -> Nearest {
        Nearest {
            found: Vec::with_capacity(k),
            k,
            max_d2: max_radius * max_radius,
        }
    }

    /// The search radius now: the k-th distance once k are found, else the maximum.
    #[inline]
    fn bound(&self) -> f32 {
        if self.found.len() == self.k {
            self.found[0].0
        } else {
            self.max_d2
        }
    }

    /// Offers a candidate at squared distance `d2`: kept if within the maximum radius and
    /// nearer than the farthest of k already found.
    #[inline]
    pub fn offer(&mut self, d2: f32, i: u32) {
        if d2 > self.bound() {
            return;
        }
        let h = &mut self.found;
        if h.len() < self.k {
            // Sift up.
            h.push((d2, i));
            let mut c = h.len() - 1;
            while c > 0 {
                let parent = (c - 1) / 2;
                if !farther(h[c], h[parent]) {
                    break;
                }
                h.swap(c, parent);
                c = parent;
            }
        } else {
            if !farther(h[0], (d2, i)) {
                return;
            }
            // Replace the farthest and sift down.
            h[0] = (d2, i);
            let mut p = 0;
            loop {
                let (l, r) = (2 * p + 1, 2 * p + 2);
                let mut big = p;
                if l < h.len() && farther(h[l], h[big]) {
                    big = l;
                }
                if r < h.len() && farther(h[r], h[big]) {
                    big = r;
                }
                if big == p {
                    break;
                }
                h.swap(p, big);
                p = big;
            }
        }
    }

    /// How many neighbours a query keeps.
    pub fn k(&self) -> usize {
        self.k
    }

    /// The largest search radius.
    pub fn max_radius(&self) -> f32 {
        self.max_d2.sqrt()
    }

    /// Squared distance of the farthest of the neighbours found.
    pub fn radius2(&self) -> f32 {
        self.found.first().map_or(0.0, |f| f.0)
    }
}

impl KdTree {
    pub fn build(points: &[Vec3]) -> KdTree {
        let mut tagged: Vec<(Vec3, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| (*p, i as u32))
            .collect();
        let mut axis = vec![0u8; points.len()];
        build(&mut tagged, &mut axis);
        KdTree {
            order: tagged.iter().map(|p| p.1).collect(),
            points: tagged.iter().map(|p| p.0).collect(),
            axis,
        }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Bytes the tree holds.
    pub fn bytes(&self) -> usize {
        self.points.len() * (std::mem::size_of::<Vec3>() + std::mem::size_of::<u32>() + 1)
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The (at most) `k` points nearest to `q` within `max_radius`, as (squared distance,
    /// original index), the farthest first (the rest in heap order).
    pub fn nearest(&self, q: Vec3, k: usize, max_radius: f32, out: &mut Nearest) {
        *out = Nearest {
            found: std::mem::take(&mut out.found),
            k,
            max_d2: max_radius * max_radius,
        };
        out.found.clear();
        if k > 0 {
            self.search(0, self.points.len(), q, out);
        }
    }

    /// Calls `f(original index)` for every point within `radius` of `q` (the fixed-radius
    /// query of the PPM/SPPM gather, for comparison with `HashGrid`).
    pub fn for_each_within(&self, q: Vec3, radius: f32, mut f: impl FnMut(u32)) {
        self.within(0, self.points.len(), q, radius * radius, &mut f);
    }

    fn within(&self, lo: usize, hi: usize, q: Vec3, r2: f32, f: &mut impl FnMut(u32)) {
        if lo >= hi {
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let p = self.points[mid];
        let a = self.axis[mid] as usize;
        let d = q[a] - p[a];
        if p.distance_squared(q) <= r2 {
            f(self.order[mid]);
        }
        if d <= 0.0 || d * d <= r2 {
            self.within(lo, mid, q, r2, f);
        }
        if d > 0.0 || d * d <= r2 {
            self.within(mid + 1, hi, q, r2, f);
        }
    }

    fn search(&self, lo: usize, hi: usize, q: Vec3, out: &mut Nearest) {
        if lo >= hi {
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let p = self.points[mid];
        let a = self.axis[mid] as usize;
        let d = q[a] - p[a];
        let (near, far) = if d <= 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.search(near.0, near.1, q, out);
        out.offer(p.distance_squared(q), self.order[mid]);
        if d * d <= out.bound() {
            self.search(far.0, far.1, q, out);
        }
    }
}
