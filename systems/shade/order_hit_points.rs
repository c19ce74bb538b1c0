//! After PPM's ray tree is traced: orders its hit points by pixel (each pixel's in the order
//! its branches ended), numbers each among its pixel's (`branch`, which keeps their light
//! samples apart), and gives each its own progressive statistics at the initial radius.

use crate::components::ShadowRays;
use crate::components::photon_mapping::ProgressiveSettings;
use crate::components::{CHUNK, PixelEstimates, VisiblePoints};
use crate::pipeline::Flow;
use crate::scene::SceneData;
use rayon::prelude::*;
use std::sync::Arc;

pub struct OrderHitPoints;

crate::system! {
    OrderHitPoints = "order_hit_points";
    read data: Arc<SceneData>, settings: ProgressiveSettings, tree: bool, starts: usize,
        points: usize;
    write visible: VisiblePoints, estimates: PixelEstimates, shadow: ShadowRays;
    run {
        let n = *points;
        if !*tree || *starts == 0 {
            return Flow::new(0, 0);
        }
        // In parallel (a stable sort, so the same order for any thread count): serial, this
        // once-per-render system was a serial stretch of PPM's first pass.
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.par_sort_by_key(|&i| visible.pixel[i as usize]);
        let mut sorted = VisiblePoints::new(n);
        sorted.gather_from(visible, &order);
        // Each point's branch: its run's first point's plus its rank in the run.
        let pixel = &sorted.pixel;
        let first_branch = &visible.branch;
        sorted
            .branch
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, branch)| {
                let mut run_start = c * CHUNK;
                while run_start > 0 && pixel[run_start - 1] == pixel[c * CHUNK] {
                    run_start -= 1;
                }
                for (j, b) in branch.iter_mut().enumerate() {
                    let i = c * CHUNK + j;
                    if pixel[i] != pixel[run_start] {
                        run_start = i;
                    }
                    *b = first_branch[order[run_start] as usize] + (i - run_start) as u32;
                }
            });
        *visible = sorted;
        *estimates = PixelEstimates::new(n);
        let radius = settings.radius_in(data);
        estimates.radius.par_iter_mut().for_each(|r| *r = radius);
        shadow.reserve_slots(n);
        Flow::new(n, n)
    }
}
