//! Ends the camera chains that stopped this bounce: each writes its gather point (or none)
//! and the emission it met to its pixel's slot of `visible`; the live chains move to the
//! front, in slot order.

use crate::components::{gather_column, live_slots};
use crate::integrators::camera_walk::CameraWalk;
use crate::pipeline::Flow;

pub struct CompactCameraChains;

crate::system! {
    CompactCameraChains = "compact_camera_chains";
    on CameraWalk {
        write chains, rays, active, visible, order, scratch_chains, scratch_rays;
    }
    run {
        use std::mem::swap;
        let n = *active;
        let (c, v) = (&*chains, visible);
        // Each pixel has one chain: ended chains write disjoint slots.
        for i in (0..n).filter(|&i| !c.alive[i]) {
            let pixel = c.pixel[i] as usize;
            v.p[pixel] = c.p[i];
            v.p_error[pixel] = c.p_error[i];
            v.ng[pixel] = c.ng[i];
            v.ns[pixel] = c.ns[i];
            v.wo[pixel] = c.wo[i];
            v.triangle[pixel] = c.triangle[i];
            v.beta[pixel] = c.beta[i];
            v.emitted[pixel] = c.emitted[i];
        }
        live_slots(&c.alive[..n], order);
        scratch_chains.gather_from(chains, order);
        gather_column(&mut scratch_rays.origin, &rays.origin, order);
        gather_column(&mut scratch_rays.dir, &rays.dir, order);
        swap(chains, scratch_chains);
        swap(rays, scratch_rays);
        *active = order.len();
        Flow::new(n, *active)
    }
}
