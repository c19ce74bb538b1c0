//! BDPT's and VCM's MIS weights in constant time per technique.
//!
//! `PathContext::vcm_weight` walks the whole path for every connection and merge: O(s + t)
//! per technique, O(n^2) per sample, and for a merge it needs the light subpath's vertices,
//! scattered over the stores. Only the densities next to a technique's joint depend on the
//! technique (two vertices on either side of a connection; for a merge, two on the camera
//! side and one on the light side); every term further out reads densities the subpaths
//! stored. Each of those far terms is h(ratio) times something fixed by the subpath, and h
//! (power or balance) is multiplicative, so a subpath's far terms sum once into a
//! `WeightTail` per prefix, and a technique's weight is its near terms plus h(ratio) times the
//! tail. Georgiev et al.'s technical report on VCM derives the same recursion (its dVCM, dVC
//! and dVM); this is derived from our walk and tested against it on random paths of every
//! scene (tests/it/vcm.rs), so the two stay one definition.

use crate::path::{MisHeuristic, PathContext, Techniques, Vertex, remap0, to_area, towards};

/// The ratio walk's terms over a subpath's first vertices, in units of the ratio with which
/// the walk arrives there. Merge terms are without their factor h(pi r^2 N), which changes
/// from pass to pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WeightTail {
    pub merges: f32,
    /// Connections other than the one that reaches the emitter.
    pub connections: f32,
    /// The camera subpath reaching the emitter (s = 0; on the light side only).
    pub emitter: f32,
}

/// Which subpath a tail is of: the walk steps past every light vertex, but never past the
/// camera's own vertex, and only the light side holds the emitter strategy (s = 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Camera,
    Light,
}

#[inline]
fn h(heuristic: MisHeuristic, r: f32) -> f32 {
    match heuristic {
        MisHeuristic::Power => r * r,
        MisHeuristic::Balance => r,
    }
}

impl WeightTail {
    /// The tail over the first i + 1 vertices of a subpath from the tail over its first i;
    /// `v` is vertex i, `prev_delta` whether vertex i - 1 is delta (false at i = 0). The walk
    /// never steps past the camera's own vertex.
    #[inline]
    fn extend(
        self,
        v: &Vertex,
        i: usize,
        prev_delta: bool,
        side: Side,
        heuristic: MisHeuristic,
    ) -> WeightTail {
        if side == Side::Camera && i == 0 {
            return self;
        }
        let rev = remap0(v.pdf_rev);
        let step = h(heuristic, rev / remap0(v.pdf_fwd));
        let mut next = WeightTail {
            merges: self.merges * step,
            connections: self.connections * step,
            emitter: self.emitter * step,
        };
        if i >= 1 && !v.delta {
            next.merges += h(heuristic, rev);
        }
        if !v.delta && !prev_delta {
            if side == Side::Light && i == 0 {
                // No camera path hits a point light.
                if !v.is_point_light() {
                    next.emitter += step;
                }
            } else {
                next.connections += step;
            }
        }
        next
    }
}

/// `out[k]`: the tail over the first k vertices of `vertices` (k = 0 ..= len).
pub fn weight_tails(
    vertices: &[Vertex],
    side: Side,
    heuristic: MisHeuristic,
    out: &mut Vec<WeightTail>,
) {
    out.clear();
    append_weight_tails(vertices, side, heuristic, out);
}

/// `weight_tails`, appended to `out`.
pub fn append_weight_tails(
    vertices: &[Vertex],
    side: Side,
    heuristic: MisHeuristic,
    out: &mut Vec<WeightTail>,
) {
    let mut tail = WeightTail::default();
    out.push(tail);
    for (i, v) in vertices.iter().enumerate() {
        let prev_delta = i > 0 && vertices[i - 1].delta;
        tail = tail.extend(v, i, prev_delta, side, heuristic);
        out.push(tail);
    }
}

/// One vertex next to a technique's joint: its reverse density as the technique makes it,
/// and whether a merge there and the connection that steps past it are techniques.
#[derive(Clone, Copy, Default)]
struct Near {
    rev: f32,
    fwd: f32,
    merge: bool,
    connect: bool,
}

/// One side's share of a weight's denominator: the near vertices outward from the joint, then
/// the tail beyond them. `eta_h` is h(pi r^2 N) (0: no merging).
#[inline]
fn side_sum(
    near: &[Near],
    tail: WeightTail,
    heuristic: MisHeuristic,
    eta_h: f32,
    connect: bool,
) -> f32 {
    let (mut ratio, mut sum) = (1.0f32, 0.0f32);
    for v in near {
        if v.merge {
            sum += h(heuristic, ratio * remap0(v.rev)) * eta_h;
        }
        ratio *= remap0(v.rev) / remap0(v.fwd);
        if v.connect {
            sum += h(heuristic, ratio);
        }
    }
    let connections = if connect { tail.connections } else { 0.0 };
    sum + h(heuristic, ratio) * (eta_h * tail.merges + connections + tail.emitter)
}

/// The camera side of a technique at camera vertex z_{t-1} (t >= 2) whose reverse densities
/// there and at z_{t-2} are `z_rev`; `merge_last` whether a merge at z_{t-1} counts.
#[inline]
fn camera_side(
    camera: &[Vertex],
    camera_tails: &[WeightTail],
    t: usize,
    z_rev: [f32; 2],
    merge_last: bool,
    heuristic: MisHeuristic,
    (eta_h, connect): (f32, bool),
) -> f32 {
    let mut near = [Near::default(); 2];
    // A camera ray that sees the light at infinity directly has no (1, 1) alternative.
    let seen_at_infinity = t == 2 && camera[1].is_at_infinity();
    near[0] = Near {
        rev: z_rev[0],
        fwd: camera[t - 1].pdf_fwd,
        merge: merge_last,
        connect: connect && !camera[t - 2].delta && !seen_at_infinity,
    };
    let count = if t >= 3 {
        near[1] = Near {
            rev: z_rev[1],
            fwd: camera[t - 2].pdf_fwd,
            merge: !camera[t - 2].delta,
            connect: connect && !camera[t - 2].delta && !camera[t - 3].delta,
        };
        2
    } else {
        1
    };
    side_sum(
        &near[..count],
        camera_tails[t - 2],
        heuristic,
        eta_h,
        connect,
    )
}

/// The area densities next to connection (s, t)'s joint as the connection makes them: at the
/// camera subpath's z_{t-1} and z_{t-2} (`z_rev`, for t >= 2 and t >= 3) and at the light
/// subpath's y_{s-1} and y_{s-2} (`y_rev`, for s >= 1 and s >= 2); zero where not read.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointDensities {
    pub z_rev: [f32; 2],
    pub y_rev: [f32; 2],
}

/// `PathContext::connection_weight_from_tails` from the connection's joint densities.
pub fn connection_weight_from_densities(
    (camera, camera_tails): (&[Vertex], &[WeightTail]),
    (light, light_tails): (&[Vertex], &[WeightTail]),
    (s, t): (usize, usize),
    densities: JointDensities,
    heuristic: MisHeuristic,
    techniques: Techniques,
) -> f32 {
    debug_assert_eq!(techniques.connection_count, 1.0);
    if s == 1 && t == 1 && light[0].is_at_infinity() {
        // As `vcm_weight`: no such technique.
        return 0.0;
    }
    let eta_h = h(heuristic, techniques.merge_count);
    let connect = techniques.connect;
    let y_last = (s >= 1).then(|| &light[s - 1]);
    let y_before = (s >= 2).then(|| &light[s - 2]);
    let mut sum = 1.0;
    if t >= 2 {
        let merge_last = s != 0;
        sum += camera_side(
            camera,
            camera_tails,
            t,
            densities.z_rev,
            merge_last,
            heuristic,
            (eta_h, connect),
        );
    }
    if let Some(y) = y_last {
        let mut near = [Near::default(); 2];
        near[0] = Near {
            rev: densities.y_rev[0],
            fwd: y.pdf_fwd,
            merge: s >= 2,
            // Past a point light (s = 1) lies no strategy: no camera path hits it.
            connect: (connect || s == 1) && !(s >= 2 && light[s - 2].delta) && !y.is_point_light(),
        };
        let count = if let Some(y_prev) = y_before {
            near[1] = Near {
                rev: densities.y_rev[1],
                fwd: y_prev.pdf_fwd,
                merge: s >= 3 && !y_prev.delta,
                connect: (connect || s == 2)
                    && !y_prev.delta
                    && !(s >= 3 && light[s - 3].delta)
                    && !y_prev.is_point_light(),
            };
            2
        } else {
            1
        };
        let tail = if s >= 2 {
            light_tails[s - 2]
        } else {
            WeightTail::default()
        };
        sum += side_sum(&near[..count], tail, heuristic, eta_h, connect);
    }
    1.0 / sum
}

/// A light vertex y_s (s >= 1) as a merge with it is weighed: what the weight reads of y_s and
/// of the subpath before it, kept beside the vertex so a merge does not visit the subpath.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MergedLight {
    /// s: the vertex's depth on its light subpath.
    pub depth: u32,
    /// y_s's forward area density.
    pub pdf_fwd: f32,
    /// |cos| at y_{s-1} over the squared distance, per unit distance: a direction density at
    /// y_s times this is the area density at y_{s-1}.
    pub prev_geometry: f32,
    pub prev_pdf_fwd: f32,
    pub prev_delta: bool,
    /// Whether y_{s-1} is a point light (s = 1), which no camera path reaches.
    pub prev_point_light: bool,
    /// Whether y_{s-2} is delta (false for s = 1).
    pub before_prev_delta: bool,
    /// The tail over y_0 .. y_{s-2}.
    pub tail: WeightTail,
}

impl MergedLight {
    /// The last vertex of `light` (y_0 .. y_s, s >= 1), with `tails` of `light` (or of a longer
    /// subpath it begins).
    pub fn new(light: &[Vertex], tails: &[WeightTail]) -> MergedLight {
        let s = light.len() - 1;
        let (y_s, y) = (&light[s], &light[s - 1]);
        let d = y.p - y_s.p;
        let dist2 = d.length_squared();
        // At infinity densities stay in solid angle.
        let prev_geometry = if y.is_at_infinity() {
            1.0
        } else if dist2 > 0.0 {
            y.ng.dot(d).abs() / (dist2 * dist2.sqrt())
        } else {
            0.0
        };
        MergedLight {
            depth: s as u32,
            pdf_fwd: y_s.pdf_fwd,
            prev_geometry,
            prev_pdf_fwd: y.pdf_fwd,
            prev_delta: y.delta,
            prev_point_light: y.is_point_light(),
            before_prev_delta: s >= 2 && light[s - 2].delta,
            tail: tails[s - 1],
        }
    }
}

impl PathContext<'_> {
    /// `vcm_weight` of connection (s, t) in constant time, from the two subpaths' tails
    /// (`weight_tails` of `camera` and of `light`; `light_tails` may be empty for s <= 1).
    /// Connection strategies must be sampled as often as the others (no light-vertex cache).
    pub fn connection_weight_from_tails(
        &self,
        (camera, camera_tails): (&[Vertex], &[WeightTail]),
        (light, light_tails): (&[Vertex], &[WeightTail]),
        (s, t): (usize, usize),
        heuristic: MisHeuristic,
        techniques: Techniques,
    ) -> f32 {
        let densities = self.joint_densities(camera, light, (s, t));
        connection_weight_from_densities(
            (camera, camera_tails),
            (light, light_tails),
            (s, t),
            densities,
            heuristic,
            techniques,
        )
    }

    /// The densities next to connection (s, t)'s joint that its weight reads.
    #[inline]
    pub fn joint_densities(
        &self,
        camera: &[Vertex],
        light: &[Vertex],
        (s, t): (usize, usize),
    ) -> JointDensities {
        let z = &camera[t - 1];
        let y_last = (s >= 1).then(|| &light[s - 1]);
        let y_before = (s >= 2).then(|| &light[s - 2]);
        let mut densities = JointDensities::default();
        if t >= 2 {
            densities.z_rev = [
                match y_last {
                    Some(y) => self.pdf_area(y, y_before, z),
                    None => self.pdf_light_origin(z),
                },
                // Read only for t >= 3.
                match y_last {
                    _ if t < 3 => 0.0,
                    Some(y) => self.pdf_area(z, Some(y), &camera[t - 2]),
                    None => self.pdf_light_dir(z, &camera[t - 2]),
                },
            ];
        }
        if let Some(y) = y_last {
            let z_prev = (t >= 2).then(|| &camera[t - 2]);
            densities.y_rev[0] = self.pdf_area(z, z_prev, y);
            if let Some(y_prev) = y_before {
                densities.y_rev[1] = self.pdf_area(y, Some(z), y_prev);
            }
        }
        densities
    }

    /// `vcm_weight` of the merge of camera vertex z_{t-1} (t >= 2) with light vertex y_s
    /// (`light`), reached from direction `w_light` (unit, towards y_{s-1}), in constant time.
    pub fn merge_weight_from_tails(
        &self,
        (camera, camera_tails): (&[Vertex], &[WeightTail]),
        t: usize,
        light: &MergedLight,
        w_light: glam::Vec3,
        heuristic: MisHeuristic,
        techniques: Techniques,
    ) -> f32 {
        let eta_h = h(heuristic, techniques.merge_count);
        let connect = techniques.connect;
        let z = &camera[t - 1];
        let w_camera = towards(z, &camera[t - 2]);
        let z_rev = [
            light.pdf_fwd,
            to_area(self.pdf_dir(z, w_light, w_camera), z, &camera[t - 2]),
        ];
        let y_rev = self.pdf_dir(z, w_camera, w_light) * light.prev_geometry;
        let own = h(heuristic, remap0(z_rev[0])) * eta_h;
        let s = light.depth as usize;
        let mut sum = if connect && !light.prev_delta {
            1.0
        } else {
            0.0
        };
        sum += camera_side(
            camera,
            camera_tails,
            t,
            z_rev,
            true,
            heuristic,
            (eta_h, connect),
        );
        let near = [Near {
            rev: y_rev,
            fwd: light.prev_pdf_fwd,
            merge: s >= 2 && !light.prev_delta,
            connect: (connect || s == 1)
                && !light.prev_delta
                && !(s >= 2 && light.before_prev_delta)
                && !light.prev_point_light,
        }];
        sum += side_sum(&near, light.tail, heuristic, eta_h, connect);
        own / sum
    }
}
