//! The frame loop: camera → renderer → feedback → cache manager → producers → pools → renderer.
//!
//! GigaVoxels' two display modes ([R08] §6 multi-pass, [P09] §5 "second display mode"):
//! - **converged**: render, serve every request, repeat until the rays ask for nothing: the exact image;
//! - **interactive**: one pass per frame with whatever is resident (coarser ancestors stand in), then a bounded
//!   number of requests served, so the frame time stays bounded and detail arrives over the next frames.
//!
//! In converged mode, only the rays that reported a miss are traced again in the next pass ([R08]'s "interrupt and
//! resume"); a ray that missed nothing already used exactly the data it needs. Converged frames also let the cache
//! manager produce the children of each node it subdivides at once, into free brick slots only
//! ([`LoopLimits::prefetch_new_children`], [`voxstream_core::ServeOptions`]): about one pass per tree level instead
//! of two, for a little over-production. Interactive frames never do, so their per-frame work stays bounded.

//!
//! The renderer is any [`FrameRenderer`]: [`CpuRenderer`] by default, a GPU backend later.

use std::ops::ControlFlow;
use std::time::Instant;

use voxstream_core::{CacheManager, ProduceError, Producer, Residency, ServeReport};
use voxstream_render::{Camera, Image, PassInputs, ProgressiveImage, RenderSettings, TransferFunction, TransferLut};

use crate::error::EngineError;
use crate::frame_renderer::{CpuRenderer, FrameRenderer};
use crate::level_pace::level_rate;
pub use crate::pass_policy::{LoopLimits, Mode, CONVERGED_REQUESTS_PER_RAY, GATHER_STRIDE};
use crate::pass_policy::{NextPass, PassPolicy};

type Result<T> = std::result::Result<T, EngineError>;

/// The outcome of one output frame.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// The final image.
    pub image: Image,
    /// Render passes (1 in interactive mode).
    pub passes: u32,
    /// Wall time of the frame, rendering and production, milliseconds.
    pub elapsed_ms: f64,
    /// Wall time spent rendering, milliseconds.
    pub render_ms: f64,
    /// Rays traced over all passes.
    pub rays: u64,
    /// Samples taken over all passes.
    pub samples: u64,
    /// Distinct requests over all passes.
    pub requests: u64,
    /// Bricks produced.
    pub bricks_produced: u64,
    /// Of `bricks_produced`, those produced for new children before any ray asked for them.
    pub bricks_prefetched: u64,
    /// Of the requests served, the forced steps that kept the working set restricted
    /// ([`LoopLimits::restrict_working_set`]).
    pub forced_steps: u64,
    /// Evictions that broke the restriction because the memory budget needed them
    /// ([`voxstream_core::ServeReport::restriction_yielded`]).
    pub restriction_yielded: u64,
    /// Requests still pending after the last pass: 0 = the image is exact.
    pub pending: usize,
    /// Requests served over all passes (0 with some pending: the budget cannot hold what the view needs, or the
    /// producer fails).
    pub served: u64,
    /// Whether the frame blended some brick towards its parent (a fade-in, or a finer neighbour still missing):
    /// the next frames still change the image.
    pub blended: bool,
    /// Levels per frame by which the camera changed the wanted level since the previous interactive frame
    /// ([`crate::level_rate`]): the pace the fades kept ([`LoopLimits::pace_fades_to_camera`]). 0 for a converged
    /// frame, the first interactive frame after one, and with the pace off.
    pub level_rate: f64,
    /// Producer failures met in this frame.
    pub failures: Vec<ProduceError>,
    /// Whether [`Session::render_interruptible`]'s observer stopped the frame early (then it is not converged,
    /// whatever `pending` says: some pixels may never have been traced).
    pub interrupted: bool,
    /// Per pixel, row by row: whether its ray missed data in the last pass (coarser data stood in, or, in a
    /// converged frame that gave up, nothing better could be loaded).
    pub missing: Vec<bool>,
}

impl FrameResult {
    /// Counts what serving one pass's requests did.
    fn add_report(&mut self, report: &ServeReport) {
        self.requests += report.requests as u64;
        self.bricks_produced += report.bricks_produced as u64;
        self.bricks_prefetched += report.bricks_prefetched as u64;
        self.forced_steps += report.forced as u64;
        self.restriction_yielded += report.restriction_yielded as u64;
        self.pending = report.pending;
        self.served += report.served as u64;
        self.failures.extend(report.failures.iter().cloned());
    }
}

impl FrameResult {
    /// Whether no ray of the final pass missed anything (and the frame was not interrupted).
    pub fn is_converged(&self) -> bool {
        self.pending == 0 && !self.interrupted
    }

    /// Whether the image is final: converged, and no brick blended towards its parent.
    pub fn is_final(&self) -> bool {
        self.is_converged() && !self.blended
    }
}

/// Where a frame stands after one of its passes, for progress displays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassProgress {
    /// Passes done in this frame (1 after the first).
    pub pass: u32,
    /// Pixels whose rays still miss data (they are traced again in the next pass; 0 = the frame is complete).
    pub pixels_pending: usize,
    /// Pixels of the image.
    pub pixels: usize,
    /// Bricks produced so far in this frame.
    pub bricks_produced: u64,
}

/// A producer, its cache, the renderer, and the render state shared by consecutive frames.
pub struct Session<P: Producer, R: FrameRenderer = CpuRenderer> {
    cache: CacheManager<P>,
    renderer: R,
    lut: TransferLut,
    settings: RenderSettings,
    limits: LoopLimits,
    /// Data values the normalised voxel values 0 and 1 stand for (the transfer function is written in data values).
    value_range: [f64; 2],
    /// World length of one finest voxel: the transfer function's default unit distance.
    finest_voxel: f64,
    peak_resident_bytes: u64,
    /// Whether the next converged frame starts with sparse passes: yes unless the last one needed no data (a warm
    /// view, where the sparse pass would only add a pass).
    gather_sparsely_next: bool,
    /// The camera of the last interactive frame since the last converged one: where the camera came from, for the
    /// pace of the fades ([`LoopLimits::pace_fades_to_camera`]).
    previous_interactive_camera: Option<Camera>,
}

impl<P: Producer> Session<P, CpuRenderer> {
    /// A session within `budget_bytes` on a producer whose values span `[0, 1]`. The transfer function's unit
    /// distance defaults to one finest voxel.
    pub fn new(
        producer: P,
        transfer_function: &TransferFunction,
        settings: RenderSettings,
        budget_bytes: u64,
        limits: LoopLimits,
    ) -> Result<Session<P>> {
        Session::with_value_range(producer, transfer_function, settings, budget_bytes, limits, [0.0, 1.0])
    }

    /// A session on a producer whose normalised values stand for data values `value_range` (the transfer function
    /// is written in data values).
    pub fn with_value_range(
        producer: P,
        transfer_function: &TransferFunction,
        settings: RenderSettings,
        budget_bytes: u64,
        limits: LoopLimits,
        value_range: [f64; 2],
    ) -> Result<Session<P>> {
        Session::with_renderer(CpuRenderer, producer, transfer_function, settings, budget_bytes, limits, value_range)
    }
}

impl<P: Producer, R: FrameRenderer> Session<P, R> {
    /// A session drawn by `renderer` (see [`Session::with_value_range`] for the other arguments).
    pub fn with_renderer(
        renderer: R,
        producer: P,
        transfer_function: &TransferFunction,
        settings: RenderSettings,
        budget_bytes: u64,
        limits: LoopLimits,
        value_range: [f64; 2],
    ) -> Result<Session<P, R>> {
        settings.validate()?;
        let shape = producer.shape();
        let finest_voxel = settings.placement.mean_scale() * shape.voxel_size(shape.max_level);
        let lut = TransferLut::new(transfer_function, value_range[0] as f32, value_range[1] as f32, finest_voxel);
        let mut cache = if renderer.needs_sixteen_bit_bricks() {
            CacheManager::with_sixteen_bit_bricks(producer, budget_bytes)?
        } else {
            CacheManager::new(producer, budget_bytes)?
        };
        cache.set_blending(limits.blending_fade_frames);
        Ok(Session {
            cache,
            renderer,
            lut,
            settings,
            limits,
            value_range,
            finest_voxel,
            peak_resident_bytes: 0,
            gather_sparsely_next: true,
            previous_interactive_camera: None,
        })
    }

    /// The cache.
    pub fn cache(&self) -> &CacheManager<P> {
        &self.cache
    }

    /// The renderer that draws the passes.
    pub fn renderer(&self) -> &R {
        &self.renderer
    }

    /// The render settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Replaces the transfer function for the next frames (an editor's change). The cache is kept: bricks hold
    /// data, not colours.
    pub fn set_transfer_function(&mut self, transfer_function: &TransferFunction) {
        self.lut = TransferLut::new(
            transfer_function,
            self.value_range[0] as f32,
            self.value_range[1] as f32,
            self.finest_voxel,
        );
        // What was needed under the old function says nothing about the new one.
        self.gather_sparsely_next = true;
    }

    /// Replaces the render settings for the next frames (image size, shading, level-of-detail bias, …), after
    /// validating them. The placement must stay the session's: the transfer function's unit distance was derived
    /// from it.
    pub fn set_settings(&mut self, settings: RenderSettings) -> Result<()> {
        settings.validate()?;
        if settings.placement != self.settings.placement {
            return Err(EngineError::PlacementChanged);
        }
        self.settings = settings;
        self.gather_sparsely_next = true;
        Ok(())
    }

    /// The loop's limits.
    pub fn limits(&self) -> &LoopLimits {
        &self.limits
    }

    /// Changes how many requests interactive frames serve (at least 1), e.g. more while the view rests.
    pub fn set_requests_per_frame(&mut self, requests: usize) {
        self.limits.requests_per_frame = requests.max(1);
    }

    /// The data values the voxel values 0 and 1 stand for.
    pub fn value_range(&self) -> [f64; 2] {
        self.value_range
    }

    /// Moves the pools to `budget_bytes` ([`CacheManager::set_budget`]: they start empty and fill again as rays
    /// ask); a budget too small for the tree is refused and changes nothing. The peak resident bytes start again.
    pub fn set_pool_budget(&mut self, budget_bytes: u64) -> Result<()> {
        self.cache.set_budget(budget_bytes)?;
        self.peak_resident_bytes = 0;
        self.gather_sparsely_next = true;
        Ok(())
    }

    /// Highest resident pool bytes seen.
    pub fn peak_resident_bytes(&self) -> u64 {
        self.peak_resident_bytes
    }

    /// Residency now.
    pub fn residency(&self) -> Residency {
        self.cache.residency()
    }

    /// Renders one output frame from `camera`.
    pub fn render(&mut self, camera: &Camera, mode: Mode) -> Result<FrameResult> {
        self.render_observed(camera, mode, &mut |_| {})
    }

    /// Renders one output frame from `camera`, telling `observe` where the frame stands after each pass.
    pub fn render_observed(
        &mut self,
        camera: &Camera,
        mode: Mode,
        observe: &mut dyn FnMut(&PassProgress),
    ) -> Result<FrameResult> {
        self.render_interruptible(camera, mode, &mut |progress| {
            observe(progress);
            ControlFlow::Continue(())
        })
    }

    /// [`Session::render_observed`], where `observe` may stop a converged frame after any pass
    /// (`ControlFlow::Break`): the frame then returns what it has, with requests still pending (not converged). A
    /// viewer refines a view at rest this way and still answers the next input within one pass.
    pub fn render_interruptible(
        &mut self,
        camera: &Camera,
        mode: Mode,
        observe: &mut dyn FnMut(&PassProgress) -> ControlFlow<()>,
    ) -> Result<FrameResult> {
        let start = Instant::now();
        let mut result = FrameResult {
            image: Image::new(0, 0),
            passes: 0,
            elapsed_ms: 0.0,
            render_ms: 0.0,
            rays: 0,
            samples: 0,
            requests: 0,
            bricks_produced: 0,
            bricks_prefetched: 0,
            forced_steps: 0,
            restriction_yielded: 0,
            pending: 0,
            served: 0,
            blended: false,
            level_rate: 0.0,
            failures: Vec::new(),
            interrupted: false,
            missing: Vec::new(),
        };
        let mut progressive = ProgressiveImage::new(self.settings.width, self.settings.height);
        let mut policy = PassPolicy::new(mode, self.limits, self.settings.pixel_stride, self.gather_sparsely_next);
        let mut settings = self.settings.clone();
        settings.max_requests_per_ray = policy.max_requests_per_ray(settings.max_requests_per_ray);
        // Interactive frames with level blending step stand-ins as the data they stand in for (see
        // `RenderSettings::steps_ignore_stand_ins`): arriving data then changes values, never sample positions.
        settings.steps_ignore_stand_ins = mode == Mode::Interactive && self.limits.blending_fade_frames.is_some();
        // Interactive frames keep the working set restricted; a converged frame draws every ray at its own level, so
        // nothing of it pops, and the eviction veto would only cost (a quarter of a frame that evicts much).
        self.cache.set_restricted(
            mode == Mode::Interactive && self.limits.blending_fade_frames.is_some() && self.limits.restrict_working_set,
        );
        // How fast the camera changes the wanted level since the last interactive frame: the fades keep that pace.
        let pace = match (mode, &self.previous_interactive_camera) {
            (Mode::Interactive, Some(previous)) if self.limits.pace_fades_to_camera => level_rate(previous, camera),
            _ => 0.0,
        };
        self.cache.set_blending_level_rate(pace);
        result.level_rate = pace;
        self.previous_interactive_camera = (mode == Mode::Interactive).then_some(*camera);
        if let Some(options) = policy.serve_root_first() {
            if let Some(report) = self.cache.serve_root(options) {
                result.add_report(&report);
            }
        }
        loop {
            if !policy.blends() {
                // Converged frames never blend: no transitions to track between their passes.
                self.cache.settle_blending();
            }
            settings.pixel_stride = policy.pixel_stride();
            self.cache.begin_frame();
            let render_start = Instant::now();
            let mut view = self.cache.view();
            if !policy.blends() {
                view.brick_blends = &[];
            }
            result.blended = !view.brick_blends.is_empty();
            let inputs =
                PassInputs { view, feedback: self.cache.feedback(), camera, lut: &self.lut, settings: &settings };
            let (stats, _) = self.renderer.render_pass(inputs, &mut progressive)?;
            result.render_ms += render_start.elapsed().as_secs_f64() * 1e3;
            let report = self.cache.end_frame(policy.serve_options());
            self.peak_resident_bytes = self.peak_resident_bytes.max(self.cache.residency().bytes);
            result.passes += 1;
            result.rays += stats.rays;
            result.samples += stats.samples;
            result.add_report(&report);
            let flow = observe(&PassProgress {
                pass: result.passes,
                pixels_pending: progressive.pending_count(),
                pixels: progressive.pending.len(),
                bricks_produced: result.bricks_produced,
            });
            if flow.is_break() {
                result.interrupted = true;
                break;
            }
            if policy.after_pass(&report) == NextPass::Stop {
                break;
            }
        }
        if mode == Mode::Converged {
            self.gather_sparsely_next = result.requests > 0;
            self.cache.settle_blending();
        }
        result.image = progressive.image;
        result.missing = progressive.pending;
        result.elapsed_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(result)
    }

    /// Renders interactive frames from `camera` until one is final ([`FrameResult::is_final`]) or `max_frames` were
    /// rendered; returns how many and the last.
    pub fn render_until_converged_interactively(
        &mut self,
        camera: &Camera,
        max_frames: u32,
    ) -> Result<(u32, FrameResult)> {
        if max_frames == 0 {
            return Err(EngineError::NoFrames);
        }
        let mut frames = 0;
        loop {
            let result = self.render(camera, Mode::Interactive)?;
            frames += 1;
            if result.is_final() || frames >= max_frames {
                return Ok((frames, result));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, TreeShape};
    use voxstream_render::RayStats;

    use super::*;

    /// A sphere of density 1 around the cube's centre, 0 elsewhere.
    struct Ball;
    impl Producer for Ball {
        fn shape(&self) -> TreeShape {
            TreeShape::new(2, 8, 3).unwrap()
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> std::result::Result<Produced, ProduceError> {
            let shape = self.shape();
            let ([x0, y0, z0], size) = key.bounds(&shape);
            let b = shape.stored_brick_size() as usize;
            let voxel = size / shape.brick_size as f64;
            for (index, v) in voxels.iter_mut().enumerate() {
                let (i, j, k) = (index % b, index / b % b, index / (b * b));
                let p = [i, j, k].map(|c| (c as f64 - 0.5) * voxel);
                let (x, y, z) = (x0 + p[0] - 0.5, y0 + p[1] - 0.5, z0 + p[2] - 0.5);
                *v = if x * x + y * y + z * z < 0.09 { u16::MAX } else { 0 };
            }
            Ok(Produced { content: NodeContent::Brick, is_terminal: key.level == shape.max_level })
        }
    }

    /// The CPU renderer, counting its passes.
    #[derive(Default)]
    struct CountingRenderer {
        passes: u32,
    }
    impl FrameRenderer for CountingRenderer {
        fn render_pass(
            &mut self,
            inputs: PassInputs<'_>,
            progressive: &mut ProgressiveImage,
        ) -> std::result::Result<(RayStats, usize), voxstream_render::RenderError> {
            self.passes += 1;
            CpuRenderer.render_pass(inputs, progressive)
        }

        fn describe(&self) -> String {
            "counting cpu".to_string()
        }
    }

    fn parts() -> (TransferFunction, RenderSettings, Camera) {
        let tf = TransferFunction::new(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 0.5, 0.2, 0.9]], None).unwrap();
        let settings = RenderSettings { width: 24, height: 24, ..RenderSettings::default() };
        let camera = Camera { eye: [0.5, 0.5, 3.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
        (tf, settings, camera)
    }

    #[test]
    fn interactive_frames_measure_the_pace_of_the_camera_and_converged_frames_reset_it() {
        let (tf, settings, camera) = parts();
        let closer = Camera { eye: [0.5, 0.5, 1.75], ..camera };
        for pace in [true, false] {
            let limits = LoopLimits { pace_fades_to_camera: pace, ..LoopLimits::default() };
            let mut session = Session::new(Ball, &tf, settings.clone(), 16 << 20, limits).unwrap();
            // The first interactive frame has no previous camera.
            assert_eq!(session.render(&camera, Mode::Interactive).unwrap().level_rate, 0.0);
            // Half the distance to the target: a level finer.
            let rate = session.render(&closer, Mode::Interactive).unwrap().level_rate;
            let expected = if pace { 1.0 } else { 0.0 };
            assert!((rate - expected).abs() < 1e-12, "pace {pace}: {rate}");
            // A converged frame forgets where the camera came from.
            assert_eq!(session.render(&camera, Mode::Converged).unwrap().level_rate, 0.0);
            assert_eq!(session.render(&closer, Mode::Interactive).unwrap().level_rate, 0.0);
        }
    }

    #[test]
    fn the_loop_drives_the_renderer_it_is_given_and_matches_the_cpu_session() {
        let (tf, settings, camera) = parts();
        let budget = 16 << 20;
        let mut counted = Session::with_renderer(
            CountingRenderer::default(),
            Ball,
            &tf,
            settings.clone(),
            budget,
            LoopLimits::default(),
            [0.0, 1.0],
        )
        .unwrap();
        let frame = counted.render(&camera, Mode::Converged).unwrap();
        assert!(frame.is_converged());
        assert!(frame.passes > 1, "the ball needs bricks, so more than one pass");
        assert_eq!(counted.renderer().passes, frame.passes);

        let mut cpu = Session::new(Ball, &tf, settings, budget, LoopLimits::default()).unwrap();
        let reference = cpu.render(&camera, Mode::Converged).unwrap();
        assert_eq!(frame.image.pixels, reference.image.pixels);
        assert!(reference.image.pixels.iter().any(|&p| p != reference.image.pixels[0]), "the ball is visible");
    }

    #[test]
    fn a_converged_frame_stops_at_its_pass_limit_plus_the_pass_that_traces_every_pixel() {
        let (tf, mut settings, camera) = parts();
        (settings.width, settings.height) = (64, 64);
        settings.background = [0.2, 0.3, 0.4];
        for max_passes in 1..4 {
            let limits = LoopLimits { max_passes, ..LoopLimits::default() };
            let mut session = Session::new(Ball, &tf, settings.clone(), 64 << 20, limits).unwrap();
            let frame = session.render(&camera, Mode::Converged).unwrap();
            assert!(!frame.is_converged(), "{max_passes} passes cannot converge the cold ball");
            assert!(frame.passes <= max_passes + 1, "{} passes with a limit of {max_passes}", frame.passes);
            let untraced = frame.image.pixels.iter().filter(|p| **p == [0.0; 4]).count();
            assert_eq!(untraced, 0, "{untraced} pixels were never traced");
        }
    }

    #[test]
    fn a_view_larger_than_the_budget_still_traces_every_pixel() {
        // The smallest budget the tree accepts cannot hold the ball's finest bricks at this size: the converged
        // frame stalls with coarser data standing in, and must still have traced every pixel (its sparse
        // gathering passes trace one pixel in 4×4 until the pools can serve no more).
        let (tf, mut settings, camera) = parts();
        (settings.width, settings.height) = (64, 64);
        settings.background = [0.2, 0.3, 0.4];
        let minimum = match voxstream_core::PoolCapacities::plan(&Ball.shape(), 0) {
            Err(voxstream_core::CoreError::BudgetTooSmall { minimum_bytes, .. }) => minimum_bytes,
            other => panic!("a zero budget must be too small: {other:?}"),
        };
        let mut session = Session::new(Ball, &tf, settings, 2 * minimum, LoopLimits::default()).unwrap();
        let frame = session.render(&camera, Mode::Converged).unwrap();
        assert!(!frame.is_converged() && frame.pending > 0, "the budget is too small for the view");
        assert!(frame.rays >= 64 * 64, "{} rays for {} pixels", frame.rays, 64 * 64);
        // An untraced pixel keeps the image's initial value; a traced one holds at least the background.
        let untraced = frame.image.pixels.iter().filter(|p| **p == [0.0; 4]).count();
        assert_eq!(untraced, 0, "{untraced} pixels were never traced");
    }

    /// The ball, whose finest bricks cannot be read.
    struct BallWithoutItsFinestLevel;
    impl Producer for BallWithoutItsFinestLevel {
        fn shape(&self) -> TreeShape {
            Ball.shape()
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> std::result::Result<Produced, ProduceError> {
            if key.level == self.shape().max_level {
                return Err(ProduceError { level: key.level, ijk: key.ijk, message: "unreadable".into() });
            }
            Ball.produce(key, voxels)
        }
    }

    #[test]
    fn a_view_whose_bricks_fail_to_load_still_traces_every_pixel() {
        let (tf, mut settings, camera) = parts();
        (settings.width, settings.height) = (64, 64);
        settings.background = [0.2, 0.3, 0.4];
        let mut session =
            Session::new(BallWithoutItsFinestLevel, &tf, settings, 16 << 20, LoopLimits::default()).unwrap();
        let frame = session.render(&camera, Mode::Converged).unwrap();
        assert!(!frame.failures.is_empty(), "the finest bricks fail");
        assert!(frame.rays >= 64 * 64, "{} rays for {} pixels", frame.rays, 64 * 64);
        let untraced = frame.image.pixels.iter().filter(|p| **p == [0.0; 4]).count();
        assert_eq!(untraced, 0, "{untraced} pixels were never traced");
    }

    #[test]
    fn an_interrupted_converged_frame_is_incomplete_and_the_next_one_exact() {
        let (tf, settings, camera) = parts();
        let mut session = Session::new(Ball, &tf, settings.clone(), 16 << 20, LoopLimits::default()).unwrap();
        let mut passes = 0;
        let interrupted = session
            .render_interruptible(&camera, Mode::Converged, &mut |_| {
                passes += 1;
                ControlFlow::Break(())
            })
            .unwrap();
        assert_eq!((passes, interrupted.passes), (1, 1));
        assert!(interrupted.interrupted && !interrupted.is_converged(), "stopped after one pass");
        let resumed = session.render(&camera, Mode::Converged).unwrap();
        let mut fresh = Session::new(Ball, &tf, settings, 16 << 20, LoopLimits::default()).unwrap();
        assert_eq!(resumed.image.pixels, fresh.render(&camera, Mode::Converged).unwrap().image.pixels);
    }

    #[test]
    fn a_new_pool_budget_refills_the_pools_within_it_and_gives_the_same_image() {
        let (tf, settings, camera) = parts();
        let mut session = Session::new(Ball, &tf, settings.clone(), 16 << 20, LoopLimits::default()).unwrap();
        let before = session.render(&camera, Mode::Converged).unwrap();
        assert!(session.residency().bricks > 0);
        let smaller = 4 << 20;
        session.set_pool_budget(smaller).unwrap();
        let residency = session.residency();
        assert_eq!(residency.budget_bytes, smaller);
        assert_eq!((residency.bricks, residency.tiles), (0, 1), "the pools start again from the root's tile");
        let after = session.render(&camera, Mode::Converged).unwrap();
        assert!(after.is_converged());
        assert_eq!(after.image.pixels, before.image.pixels, "the budget changes what is resident, not the image");
        let residency = session.residency();
        assert!(residency.bricks > 0 && residency.bytes <= smaller, "{residency:?}");
        assert!(session.peak_resident_bytes() <= smaller);
        // Too small for the tree: refused, and the cache keeps its budget and contents.
        assert!(session.set_pool_budget(1).is_err());
        assert_eq!(session.residency(), residency);
    }

    #[test]
    fn zero_interactive_frames_is_an_error() {
        let (tf, settings, camera) = parts();
        let mut session = Session::new(Ball, &tf, settings, 16 << 20, LoopLimits::default()).unwrap();
        assert!(matches!(session.render_until_converged_interactively(&camera, 0), Err(EngineError::NoFrames)));
    }
}
