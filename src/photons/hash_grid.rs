//! A hashed uniform grid over points for fixed-radius queries (the PPM/SPPM gather): cells
//! of the query radius, so a query visits the 27 cells around it. Built by sorting point
//! indices by cell hash (in parallel; ties keep index order, so the layout never depends on
//! the thread count).

use super::Nearest;
use glam::{IVec3, Vec3};
use rayon::prelude::*;

pub struct HashGrid {
    cell: f32,
    inv_cell: f32,
    /// Table size minus one (a power of two).
    mask: u32,
    /// Points of bucket b: `indices[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    indices: Vec<u32>,
}

#[inline]
fn hash(c: IVec3) -> u32 {
    // Three large primes (Teschner et al. 2003), wrapped.
    (c.x.wrapping_mul(73_856_093) ^ c.y.wrapping_mul(19_349_663) ^ c.z.wrapping_mul(83_492_791))
        as u32
}

impl HashGrid {
    /// A grid over `points` for queries of radius at most `radius` (> 0).
    pub fn build(points: &[Vec3], radius: f32) -> HashGrid {
        let n = points.len();
        let size = (2 * n).next_power_of_two().max(16);
        let mask = (size - 1) as u32;
        let cell = radius;
        let inv_cell = 1.0 / cell;
        let mut keyed: Vec<(u32, u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| (hash((*p * inv_cell).floor().as_ivec3()) & mask, i as u32))
            .collect();
        keyed.par_sort_unstable();
        let mut start = vec![0u32; size + 1];
        for &(b, _) in &keyed {
            start[b as usize + 1] += 1;
        }
        for b in 0..size {
            start[b + 1] += start[b];
        }
        let indices = keyed.into_iter().map(|(_, i)| i).collect();
        HashGrid {
            cell,
            inv_cell,
            mask,
            start,
            indices,
        }
    }

    /// A grid over `points` for `for_each_within_octants` queries of radius at most
    /// `radius`: cells twice the radius, so a query's ball lies in the 2 x 2 x 2 cells around
    /// the corner nearest it. With sparse points (VCM's light vertices: most cells empty) the
    /// eight bucket lookups cost less than the 27 of `build`'s cells.
    pub fn build_for_octants(points: &[Vec3], radius: f32) -> HashGrid {
        HashGrid::build(points, 2.0 * radius)
    }

    /// The largest radius a query may use.
    pub fn radius(&self) -> f32 {
        self.cell
    }

    /// `for_each_within` over the 2 x 2 x 2 cells around the cell corner nearest `q`, for a
    /// grid of `build_for_octants` (`radius` at most half a cell).
    #[inline]
    pub fn for_each_within_octants(
        &self,
        points: &[Vec3],
        q: Vec3,
        radius: f32,
        f: impl FnMut(u32),
    ) {
        debug_assert!(2.0 * radius <= self.cell);
        let r2 = radius * radius;
        let scaled = q * self.inv_cell;
        let c = scaled.floor();
        // Per axis, this cell and its neighbour on the side of q's half of it.
        let frac = (scaled - c).to_array();
        let step = frac.map(|x| if x < 0.5 { -1 } else { 1 });
        let c = c.as_ivec3();
        let mut buckets = [0u32; 8];
        let mut count = 0;
        for corner in 0..8 {
            let offset = IVec3::new(
                if corner & 1 != 0 { step[0] } else { 0 },
                if corner & 2 != 0 { step[1] } else { 0 },
                if corner & 4 != 0 { step[2] } else { 0 },
            );
            let b = hash(c + offset) & self.mask;
            if !buckets[..count].contains(&b) {
                buckets[count] = b;
                count += 1;
            }
        }
        self.scan_buckets(&buckets[..count], points, q, r2, f);
    }

    /// Calls `f(index)` for every point of the distinct `buckets` within squared distance `r2`
    /// of `q`, bucket by bucket.
    #[inline]
    fn scan_buckets(
        &self,
        buckets: &[u32],
        points: &[Vec3],
        q: Vec3,
        r2: f32,
        mut f: impl FnMut(u32),
    ) {
        for &b in buckets {
            let range = self.start[b as usize] as usize..self.start[b as usize + 1] as usize;
            for &i in &self.indices[range] {
                if points[i as usize].distance_squared(q) <= r2 {
                    f(i);
                }
            }
        }
    }

    /// Calls `f(index)` for every point within `radius` (<= the build radius) of `q`, each
    /// once, in a fixed order.
    #[inline]
    pub fn for_each_within(&self, points: &[Vec3], q: Vec3, radius: f32, f: impl FnMut(u32)) {
        debug_assert!(radius <= self.cell);
        let r2 = radius * radius;
        let c = (q * self.inv_cell).floor().as_ivec3();
        // Distinct buckets only: two cells may hash to the same bucket.
        let mut buckets = [0u32; 27];
        let mut count = 0;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let b = hash(c + IVec3::new(dx, dy, dz)) & self.mask;
                    if !buckets[..count].contains(&b) {
                        buckets[count] = b;
                        count += 1;
                    }
                }
            }
        }
        self.scan_buckets(&buckets[..count], points, q, r2, f);
    }

    /// The (at most) `k` points nearest to `q` within `max_radius` (<= the build radius): the
    /// k-nearest query of PM, for comparison with `KdTree` (it visits every point of the 27
    /// cells, so it suits a `max_radius` close to the k-th distance).
    pub fn nearest(&self, points: &[Vec3], q: Vec3, k: usize, max_radius: f32, out: &mut Nearest) {
        *out = Nearest::new(k, max_radius);
        if k == 0 {
            return;
        }
        self.for_each_within(points, q, max_radius, |i| {
            out.offer(points[i as usize].distance_squared(q), i)
        });
    }
}
