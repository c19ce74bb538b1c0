//! Builds PM's photon maps from the photons just traced: a kd-tree over every stored photon
//! (the global map) and, where the scene has specular surfaces, one over the caustic photons.

use crate::components::PhotonFlags;
use crate::photons::PhotonTracing;
use crate::photons::{KdTree, PhotonMaps};
use crate::pipeline::Flow;

pub struct BuildPhotonMaps;

crate::system! {
    BuildPhotonMaps = "build_photon_maps";
    read caustics: bool;
    write tracing: PhotonTracing, maps: Option<PhotonMaps>;
    run {
        let t = tracing;
        let stored = t.stored;
        let photons = std::mem::take(&mut t.photons);
        t.stored = 0;
        let global = KdTree::build(&photons.p[..stored]);
        let caustic = caustics.then(|| {
            let index: Vec<u32> = (0..stored as u32)
                .filter(|&i| photons.flags[i as usize].has(PhotonFlags::CAUSTIC))
                .collect();
            let points: Vec<_> = index.iter().map(|&i| photons.p[i as usize]).collect();
            (KdTree::build(&points), index)
        });
        let in_maps = stored + caustic.as_ref().map_or(0, |c| c.1.len());
        *maps = Some(PhotonMaps {
            photons,
            global,
            caustic,
            emitted: t.emitted,
        });
        Flow::new(stored, in_maps)
    }
}
