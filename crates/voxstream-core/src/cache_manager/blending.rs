//! The level-blending switches of the cache (Thiele et al.'s temporal and spatial blending, [`crate::level_blending`]):
//! on or off, the camera's pace, settling; and the tests of what the view's caps show frame by frame.

use crate::level_blending::LevelBlending;
use crate::producer::Producer;

use super::CacheManager;

impl<P: Producer> CacheManager<P> {
    /// Turns level blending on with a fade-in of `fade_frames` frames (see [`crate::level_blending`]), or off with
    /// `None`. Off, the view carries no caps and frames are as without blending.
    pub fn set_blending(&mut self, fade_frames: Option<u32>) {
        self.blending = fade_frames.map(LevelBlending::new);
    }

    /// With blending on: how many levels per frame the camera's motion changes the wanted level by, for the next
    /// [`CacheManager::begin_frame`] (see [`LevelBlending::set_level_rate`]). Without blending it does nothing.
    pub fn set_blending_level_rate(&mut self, levels_per_frame: f64) {
        if let Some(blending) = &mut self.blending {
            blending.set_level_rate(levels_per_frame as f32);
        }
    }

    /// Ends any blending in progress: the next frame shows what is resident as it is (after an exact frame).
    pub fn settle_blending(&mut self) {
        if let Some(blending) = &mut self.blending {
            blending.settle();
        }
    }

    /// Whether the current frame's view blends some brick towards its parent (some brick is still in transition:
    /// fading in, or capped beside a region waiting for data): the image is not final yet.
    pub fn is_blending(&self) -> bool {
        self.blending.as_ref().is_some_and(LevelBlending::is_active)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{caps_of, request, root_children, Ramp};
    use super::*;
    use crate::feedback::{Request, RequestKind};
    use crate::node::NodeId;
    use crate::ServeOptions;

    #[test]
    fn fades_keep_pace_with_a_camera_that_approaches() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let [first, second] = [root_children(&cache)[1], root_children(&cache)[2]];
        // The root is in at once: nothing blends.
        assert!(!cache.is_blending());
        // At rest: a quarter per frame.
        request(&mut cache, first, RequestKind::Produce, false);
        cache.set_blending_level_rate(0.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, first).fade, 0.25);
        cache.end_frame(ServeOptions::ALL);
        // The camera now wants a level finer every 16 frames: eight fades in 16 frames, half a fade per frame.
        cache.set_blending_level_rate(1.0 / 16.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, first).fade, 0.75);
        cache.end_frame(ServeOptions::ALL);
        // Slower than the fade-in itself asks for: the fade-in's own pace; nonsense rates count as rest.
        request(&mut cache, second, RequestKind::Produce, false);
        for rate in [0.01, f64::NAN, -1.0] {
            cache.set_blending_level_rate(rate);
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        assert_eq!(caps_of(&cache, second).fade, 0.75, "{:?}", caps_of(&cache, second));
        // An infinite pace ends the fade at once.
        let third = root_children(&cache)[3];
        request(&mut cache, third, RequestKind::Produce, false);
        cache.set_blending_level_rate(f64::INFINITY);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, third).fade, 1.0);
        cache.end_frame(ServeOptions::ALL);
        // Without blending the rate does nothing.
        cache.set_blending(None);
        cache.set_blending_level_rate(1.0);
        cache.begin_frame();
        assert!(cache.view().brick_blends.is_empty());
    }

    #[test]
    fn the_root_is_in_at_once_and_its_children_fade_in_from_the_next_frame() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        // The next frame's caps: the root has no parent brick to fade from, so nothing blends.
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        assert!(cache.view().brick_blends.is_empty());
        assert!(!cache.is_blending());
        let child = root_children(&cache)[1];
        request(&mut cache, child, RequestKind::Produce, false);
        // The next frame draws the child a quarter in: it does not wait for the root.
        cache.begin_frame();
        assert_eq!(caps_of(&cache, child).fade, 0.25);
        assert_eq!(caps_of(&cache, NodeId::ROOT), crate::BrickBlend::FULL);
        cache.end_frame(ServeOptions::ALL);
    }

    #[test]
    fn an_arriving_brick_fades_in_to_1_its_children_wait_for_it_and_speed_it_up() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let parent = root_children(&cache)[1];
        request(&mut cache, parent, RequestKind::Produce, false);
        request(&mut cache, parent, RequestKind::Subdivide, false);
        assert_eq!(caps_of(&cache, parent).fade, 0.25, "a quarter per frame");
        let tile = cache.node_pool().node(parent).child_tile().unwrap();
        let child = NodeId::new(tile, 1, 8);
        // The child arrives while its parent is at 0.5.
        request(&mut cache, child, RequestKind::Produce, false);
        let mut parent_fades = Vec::new();
        let mut child_fades = Vec::new();
        for _ in 0..7 {
            cache.begin_frame();
            parent_fades.push(caps_of(&cache, parent).fade);
            child_fades.push(caps_of(&cache, child).fade);
            cache.end_frame(ServeOptions::ALL);
        }
        // With a generation waiting below it, the parent rises by two quarters: in at once.
        assert_eq!(parent_fades, [1.0; 7]);
        // The child waited at 0 while its parent was below 1, then rises by a quarter per frame to 1.
        assert_eq!(child_fades[..5], [0.0, 0.25, 0.5, 0.75, 1.0]);
        assert!(!cache.is_blending(), "all in: the view carries no caps");
        assert!(cache.view().brick_blends.is_empty());
    }

    #[test]
    fn a_brick_drawn_in_full_is_never_taken_back_by_an_arriving_neighbour() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let children = root_children(&cache);
        request(&mut cache, children[1], RequestKind::Produce, false);
        for _ in 0..6 {
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        assert!(!cache.is_blending());
        // Child 3 is child 1's neighbour along y: it arrives, and child 1 (drawn in full) keeps its caps at 1.
        request(&mut cache, children[3], RequestKind::Produce, false);
        cache.begin_frame();
        assert!(caps_of(&cache, children[1]).is_full() && caps_of(&cache, children[1]).is_in());
        let arriving = caps_of(&cache, children[3]);
        assert_eq!((arriving.fade, arriving.corners()), (0.25, [0.25; 8]));
        cache.end_frame(ServeOptions::ALL);
    }

    #[test]
    fn corners_touching_a_region_still_waiting_for_data_stay_at_0_unless_the_camera_outpaces_the_fades() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(2));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        for _ in 0..3 {
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        let children = root_children(&cache);
        // Child 1 (x = 1, y = 0, z = 0) and child 3 (x = 1, y = 1, z = 0) share a face; both are asked for in a
        // frame that serves one request: the other waits, and the served one's corners on that face stay at 0.
        cache.begin_frame();
        cache.feedback().push_requests(&[
            Request { node: children[1], kind: RequestKind::Produce, deficit: 1 },
            Request { node: children[3], kind: RequestKind::Produce, deficit: 1 },
        ]);
        cache.end_frame(ServeOptions { limit: Some(1), prefetch_new_children: false, wait_for_data: true });
        let first_served = cache.node_pool().node(children[1]).brick().is_some();
        let (served, waiting) = if first_served { (children[1], children[3]) } else { (children[3], children[1]) };
        // Corner c has y = (c >> 1) & 1; the shared face is y = 1 of child 1, y = 0 of child 3.
        let touches = |c: usize| ((c >> 1) & 1 == 1) == first_served;
        for _ in 0..3 {
            cache.begin_frame();
            let corners = caps_of(&cache, served).corners();
            for c in (0..8).filter(|&c| touches(c)) {
                assert_eq!(corners[c], 0.0, "corner {c}");
            }
            // The other child is still wanted: asked for again, served never.
            cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
            cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        }
        let corners = caps_of(&cache, served).corners();
        assert!((0..8).filter(|&c| !touches(c)).all(|c| corners[c] == 1.0), "the other corners are in: {corners:?}");
        assert!(cache.is_blending(), "the served brick is not drawn in full while its neighbour waits");
        // A camera that approaches a hair slower than a fade per frame: the waiting region still caps the corners.
        let outpacing = 1.0 / crate::level_blending::FADES_PER_LEVEL as f64;
        cache.set_blending_level_rate(outpacing * 0.99);
        cache.begin_frame();
        assert!((0..8).filter(|&c| touches(c)).all(|c| caps_of(&cache, served).corners()[c] == 0.0));
        cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
        cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        // One so fast that a fade ends within the frame (FADES_PER_LEVEL fades in the frames it takes to want the
        // next level): the region still waiting caps nothing, and the served brick is drawn in full.
        cache.set_blending_level_rate(outpacing);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, served), crate::BrickBlend::FULL);
        cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
        cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        // At rest again the waiting region does not take it back (it left the transitions, drawn in full).
        cache.set_blending_level_rate(0.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, served), crate::BrickBlend::FULL);
        cache.end_frame(ServeOptions::ALL);
    }
}
