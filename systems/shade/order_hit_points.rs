//! After PPM's ray tree is traced: orders its hit points by pixel (each pixel's in the order
//! its branches ended), numbers each among its pixel's (`branch`, which keeps their light
//! samples apart), and gives each its own progressive statistics at the initial radius.

use crate::components::{PixelEstimates, VisiblePoints};
use crate::integrators::sppm::ProgressiveState;
use crate::pipeline::Flow;

pub struct OrderHitPoints;

crate::system! {
    OrderHitPoints = "order_hit_points";
    on ProgressiveState {
        read data, settings, tree = camera_walk.tree, starts = camera_walk.starts, points = camera_walk.points;
        write visible = camera_walk.visible, estimates, shadow;
    }
    run {
        let n = *points;
        if !*tree || *starts == 0 {
            return Flow::new(0, 0);
        }
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.sort_by_key(|&i| visible.pixel[i as usize]);
        let mut sorted = VisiblePoints::new(n);
        sorted.gather_from(visible, &order);
        for i in 1..n {
            if sorted.pixel[i] == sorted.pixel[i - 1] {
                sorted.branch[i] = sorted.branch[i - 1] + 1;
            }
        }
        *visible = sorted;
        *estimates = PixelEstimates::new(n);
        estimates.radius.fill(settings.radius_in(data));
        shadow.reserve_slots(n);
        Flow::new(n, n)
    }
}
