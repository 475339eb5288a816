//! A fluid time step ready to render: its bins, the bricks made so far under a memory budget, and the frame loop
//! that makes the bricks rays ask for (Reichl §6.4.1: "the GPU detects the visible leaf bricks and signals the CPU
//! to create our renderable binary voxel representation").
//!
//! A frame is cast in passes: each pass casts every pixel into the resident bricks, the bricks rays asked for are
//! made in parallel from the bins, and the next pass sees them; a frame is complete when a pass asks for nothing.
//! Bricks are evicted least recently used first when the budget is exceeded, never one used by the current pass.
//! The depth image is then smoothed in screen space and shaded ([`crate::shading`]).

use rustc_hash::FxHashMap as HashMap;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rayon::prelude::*;
use voxstream_render::{Camera, Image};

use crate::binning::FluidBins;
use crate::bit_brick::{BitBrick, BrickSettings, FOAM_REACH};
use crate::grid::BrickKey;
use crate::screen_space::{smooth_bilateral, smooth_rof, DepthImage, RofSettings};
use crate::shading::{shade, view_depth};
use crate::sphere_caster::{level_radius, Bricks, CastSettings, RaySample, SphereCaster};
use crate::FluidError;

/// Most passes a frame takes before it is shown incomplete (a budget too small for what the view needs).
pub const MAX_PASSES: u32 = 64;

/// The default ROF strength over [`RofSettings::for_radius`]'s estimate (calibrated on regular carpets of spheres).
/// Measured on a ball of jittered particles drawn by this caster (`tests/fluid_ball.rs`, the `sweep` there): the
/// normals from depth are 45° off the sphere's bare, 29° at strength 1, 19° at 4, 14° at 8, 11° at 32, while the
/// spread of the surface's distance from the centre is least at 4–8 (0.0127–0.0123 against 0.0219 bare) and grows
/// beyond; more iterations than the thesis' 75 make both worse (TV's terraces). 4 keeps spray droplets round.
pub const DEFAULT_ROF_STRENGTH: f32 = 4.0;

/// How the depth image is smoothed before shading (Reichl §6.5.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Smoothing {
    /// None: the spheres as they are, lit by their own normals (Fig. 6.7 top row).
    None,
    /// Rudin–Osher–Fatemi total variation with depth-dependent strength: `iterations` of Chambolle's scheme,
    /// `strength` scaling λ₀ (1: the thesis' estimate from the sphere's screen radius).
    Rof {
        /// Iterations (the thesis: 75).
        iterations: u32,
        /// Multiplies the estimated λ₀.
        strength: f32,
    },
    /// A depth-aware bilateral filter of about a sphere's screen radius (the comparator).
    Bilateral,
}

/// How a fluid is rendered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluidRenderSettings {
    /// Largest footprint of a cell in pixels (finer levels where a cell would be smaller).
    pub lod_error: f64,
    /// A cell is foam when its neighbourhood holds less than this fraction of what the fluid's interior holds
    /// (the thesis: 20 %); 0 disables foam.
    pub foam_fraction: f64,
    /// Foam opacity per sphere radius of a fully foamed block.
    pub foam_extinction: f64,
    /// Screen-space smoothing.
    pub smoothing: Smoothing,
    /// Time step (seeds the jitter).
    pub time_step: u32,
}

impl Default for FluidRenderSettings {
    fn default() -> Self {
        FluidRenderSettings {
            lod_error: 1.0,
            foam_fraction: 0.2,
            foam_extinction: 0.5,
            smoothing: Smoothing::Rof { iterations: 75, strength: DEFAULT_ROF_STRENGTH },
            time_step: 0,
        }
    }
}

/// What a frame took.
#[derive(Clone, Debug, Default)]
pub struct FrameStatistics {
    /// Casting passes.
    pub passes: u32,
    /// Whether the last pass asked for nothing.
    pub complete: bool,
    /// Whether the bricks this view needs exceed the budget (the frame stopped incomplete).
    pub over_budget: bool,
    /// Bricks made for this frame (those rays asked for and the neighbours they read).
    pub bricks_made: usize,
    /// Time casting, all passes.
    pub cast: Duration,
    /// Time making bricks.
    pub build: Duration,
    /// Time smoothing and shading.
    pub shade: Duration,
    /// Pixels that hit the surface.
    pub surface_pixels: usize,
    /// Bricks resident after the frame, and their bytes.
    pub resident_bricks: usize,
    /// Bytes of the resident bricks.
    pub resident_bytes: u64,
}

/// A rendered fluid frame.
pub struct FluidFrame {
    /// The shaded image.
    pub image: Image,
    /// View depth per pixel after smoothing (`f32::INFINITY`: no surface).
    pub depth: Vec<f32>,
    /// View depth per pixel as cast.
    pub raw_depth: Vec<f32>,
    /// What it took.
    pub statistics: FrameStatistics,
}

struct Resident {
    brick: Arc<BitBrick>,
    /// Pass counter when a ray last used it.
    used: AtomicU32,
}

/// A fluid time step and its bricks.
pub struct FluidScene {
    bins: FluidBins,
    bricks: HashMap<BrickKey, Resident>,
    resident_bytes: u64,
    budget_bytes: u64,
    pass: u32,
    /// Foam threshold in occupied cells of a neighbourhood.
    foam_below: u32,
    settings: FluidRenderSettings,
}

/// The resident bricks as the caster sees them (marking each use with the pass).
struct View<'a> {
    scene: &'a FluidScene,
}

impl Bricks for View<'_> {
    fn get(&self, key: BrickKey) -> Option<&BitBrick> {
        self.scene.bricks.get(&key).map(|r| {
            // Written once per pass: a store on every lookup would bounce the line between the cores.
            if r.used.load(Ordering::Relaxed) != self.scene.pass {
                r.used.store(self.scene.pass, Ordering::Relaxed);
            }
            &*r.brick
        })
    }

    fn is_occupied(&self, key: BrickKey) -> bool {
        self.scene.bins.is_occupied(key)
    }

    fn is_reached(&self, key: BrickKey) -> bool {
        self.scene.bins.is_reached(key)
    }
}

impl FluidScene {
    /// A scene over `bins` holding at most `budget_bytes` of bricks.
    pub fn new(bins: FluidBins, budget_bytes: u64, settings: FluidRenderSettings) -> Result<FluidScene, FluidError> {
        if !(settings.foam_fraction.is_finite() && (0.0..1.0).contains(&settings.foam_fraction)) {
            return Err(FluidError::Settings(format!(
                "--foam {} is out of range: give the fraction of the fluid's neighbourhood in [0, 1) below which a \
                 particle is foam (0: no foam)",
                settings.foam_fraction
            )));
        }
        if !(settings.lod_error.is_finite() && settings.lod_error > 0.0) {
            return Err(FluidError::Settings(format!("the pixel error must be positive, got {}", settings.lod_error)));
        }
        // What the interior holds: a neighbourhood of `FOAM_REACH` cells at the particles' fill of cells.
        let full = f64::from((2 * FOAM_REACH + 1).pow(3) as u32);
        let fill = interior_fill(&bins);
        let foam_below = (settings.foam_fraction * full * fill).round() as u32;
        let foam_below = if settings.foam_fraction > 0.0 { foam_below.max(1) } else { 0 };
        Ok(FluidScene {
            bins,
            bricks: HashMap::default(),
            resident_bytes: 0,
            budget_bytes,
            pass: 0,
            foam_below,
            settings,
        })
    }

    /// The bins.
    pub fn bins(&self) -> &FluidBins {
        &self.bins
    }

    /// Renders a frame, making the bricks it needs.
    pub fn render(&mut self, camera: &Camera, width: u32, height: u32) -> Result<FluidFrame, FluidError> {
        let frame = camera.frame(width, height)?;
        let mut statistics = FrameStatistics::default();
        let cast_settings = CastSettings {
            grid: self.bins.grid,
            radius: self.bins.radius,
            lod_error: self.settings.lod_error,
            time_step: self.settings.time_step,
            foam_extinction: self.settings.foam_extinction / self.bins.radius,
        };
        let mut samples = vec![RaySample::MISS; width as usize * height as usize];
        loop {
            self.pass = self.pass.wrapping_add(1);
            statistics.passes += 1;
            let started = Instant::now();
            let view = View { scene: self };
            let caster = SphereCaster::new(cast_settings, &view);
            let mut requests: Vec<BrickKey> = samples
                .par_chunks_mut(width as usize)
                .enumerate()
                .flat_map_iter(|(y, row)| {
                    let mut requests = Vec::new();
                    for (x, sample) in row.iter_mut().enumerate() {
                        let dir = frame.direction(x as u32, y as u32, width, height);
                        *sample = caster.cast(frame.eye, dir, frame.pixel_spread, &mut requests);
                    }
                    // A row's rays ask for the same few bricks.
                    requests.sort_unstable();
                    requests.dedup();
                    requests
                })
                .collect();
            statistics.cast += started.elapsed();
            requests.sort_unstable();
            requests.dedup();
            requests.retain(|k| !self.bricks.contains_key(k));
            if requests.is_empty() {
                statistics.complete = true;
                break;
            }
            if statistics.passes >= MAX_PASSES {
                break;
            }
            let started = Instant::now();
            let (made, within_budget) = self.make(&requests);
            statistics.bricks_made += made;
            statistics.build += started.elapsed();
            if !within_budget {
                // What this view needs does not fit: drawn with what is made, and said incomplete.
                statistics.over_budget = true;
                break;
            }
        }
        let started = Instant::now();
        let raw_depth = view_depth(&samples, &frame, width, height);
        let radius_px = |z: f32| self.bins.radius / (f64::from(z) * frame.pixel_spread);
        let depth = match self.settings.smoothing {
            Smoothing::None => raw_depth.clone(),
            Smoothing::Rof { iterations, strength } => {
                let image = DepthImage { width: width as usize, height: height as usize, depth: raw_depth.clone() };
                let mut rof = RofSettings::for_radius(self.bins.radius as f32, (1.0 / frame.pixel_spread) as f32);
                rof.iterations = iterations;
                rof.lambda0 *= strength;
                smooth_rof(&image, &rof).depth
            }
            Smoothing::Bilateral => {
                let image = DepthImage { width: width as usize, height: height as usize, depth: raw_depth.clone() };
                // About a sphere's radius on screen at the median depth, and its radius in depth.
                let mut finite: Vec<f32> = raw_depth.iter().copied().filter(|z| z.is_finite()).collect();
                let sigma = if finite.is_empty() {
                    1.0
                } else {
                    let mid = finite.len() / 2;
                    let (_, median, _) = finite.select_nth_unstable_by(mid, f32::total_cmp);
                    radius_px(*median).clamp(0.5, 8.0) as f32
                };
                smooth_bilateral(&image, sigma, self.bins.radius as f32).depth
            }
        };
        let sphere_normals = self.settings.smoothing == Smoothing::None;
        let image = shade(&samples, &depth, &frame, width, height, sphere_normals);
        statistics.shade = started.elapsed();
        statistics.surface_pixels = raw_depth.iter().filter(|z| z.is_finite()).count();
        statistics.resident_bricks = self.bricks.len();
        statistics.resident_bytes = self.resident_bytes;
        Ok(FluidFrame { image, depth, raw_depth, statistics })
    }

    /// Makes `keys` and the neighbours their rays read (in parallel) and evicts what the budget cannot hold, least
    /// recently used first. Returns the bricks made, and false when the bricks this pass used and made alone
    /// exceed the budget.
    fn make(&mut self, keys: &[BrickKey]) -> (usize, bool) {
        let bins = &self.bins;
        let foam_below = self.foam_below;
        let build = |keys: &[BrickKey]| -> Vec<BitBrick> {
            keys.par_iter()
                .map(|&key| {
                    let (_, reach) = level_radius(&bins.grid, bins.radius, key.level);
                    BitBrick::build(bins, key, BrickSettings { reach, foam_below })
                })
                .collect()
        };
        let mut made = build(keys);
        // The neighbours whose bits the new bricks' rays read: made now, not a pass later.
        let mut neighbours: Vec<BrickKey> = made
            .iter()
            .flat_map(|brick| {
                let key = brick.key;
                let bricks = bins.grid.bricks(key.level);
                (0..27u32).filter(move |o| brick.neighbours_read >> o & 1 == 1).filter_map(move |o| {
                    let d = [(o % 3) as i64 - 1, (o / 3 % 3) as i64 - 1, (o / 9) as i64 - 1];
                    let at: [i64; 3] = std::array::from_fn(|a| i64::from(key.at[a]) + d[a]);
                    (0..3)
                        .all(|a| at[a] >= 0 && at[a] < i64::from(bricks[a]))
                        .then(|| BrickKey { level: key.level, at: at.map(|c| c as u32) })
                })
            })
            .filter(|k| bins.is_occupied(*k) && !self.bricks.contains_key(k))
            .collect();
        neighbours.sort_unstable();
        neighbours.dedup();
        neighbours.retain(|k| keys.binary_search(k).is_err());
        made.extend(build(&neighbours));
        let count = made.len();
        for brick in made {
            self.resident_bytes += brick.heap_bytes();
            self.bricks.insert(brick.key, Resident { brick: Arc::new(brick), used: AtomicU32::new(self.pass) });
        }
        if self.resident_bytes <= self.budget_bytes {
            return (count, true);
        }
        // Least recently used first; bricks of this pass stay.
        let mut by_use: Vec<(u32, BrickKey)> =
            self.bricks.iter().map(|(k, r)| (r.used.load(Ordering::Relaxed), *k)).collect();
        by_use.sort_unstable();
        for (used, key) in by_use {
            if self.resident_bytes <= self.budget_bytes || used >= self.pass {
                break;
            }
            if let Some(r) = self.bricks.remove(&key) {
                self.resident_bytes -= r.brick.heap_bytes();
            }
        }
        (count, self.resident_bytes <= self.budget_bytes)
    }

    /// Bytes of the resident bricks.
    pub fn resident_bytes(&self) -> u64 {
        self.resident_bytes
    }
}

/// The fraction of level-0 cells occupied inside the fluid: one particle per `spacing³` of the particles'
/// estimated spacing, at most 1.
fn interior_fill(bins: &FluidBins) -> f64 {
    if bins.spacing > 0.0 {
        (bins.grid.cell / bins.spacing).powi(3).clamp(1e-3, 1.0)
    } else {
        1.0
    }
}
