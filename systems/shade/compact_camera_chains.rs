//! Ends the camera chains that stopped this bounce: each writes its gather point (or none)
//! and the emission it met to its pixel's visible point; the live chains move to the front,
//! in slot order.

use crate::components::{gather_column, live_slots};
use crate::pipeline::{Flow, System};
use crate::systems::shade::extend_camera_chains::CameraChainQueue;

pub struct CompactCameraChains;

impl<S: CameraChainQueue + Send> System<S> for CompactCameraChains {
    fn name(&self) -> &'static str {
        "compact_camera_chains"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["camera_chains"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["camera_chains", "rays", "visible_points"]
    }
    fn run(&self, state: &mut S) -> Flow {
        use std::mem::swap;
        let q = state.camera_chain_queue();
        let w = q.wave;
        let n = w.active;
        let (c, v) = (&w.chains, q.visible);
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
        live_slots(&c.alive[..n], &mut w.order);
        w.scratch_chains.gather_from(&w.chains, &w.order);
        gather_column(&mut w.scratch_rays.origin, &w.rays.origin, &w.order);
        gather_column(&mut w.scratch_rays.dir, &w.rays.dir, &w.order);
        swap(&mut w.chains, &mut w.scratch_chains);
        swap(&mut w.rays, &mut w.scratch_rays);
        w.active = w.order.len();
        Flow::new(n, w.active)
    }
}
