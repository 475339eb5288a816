//! Windowed fusion (seed 004 §8.3): frames enter a ring buffer of `2n`; each frame allocates the bricks its samples
//! fall near (§8.4.2) and gives the bricks no window has processed yet a quick, non-confident update from the last
//! `n̂` frames (the sub-cache, §8.3.3); every `n/2` frames the last `n` frames are processed together (§8.3.2),
//! each brick they saw projected into all of them at once. Consecutive windows share half their frames, which
//! smooths out tracking drift. After a window, bricks left with nothing behind the surface are removed and, over
//! the memory budget, far chunks are streamed to disk (§8.6). Memory is the ring (fixed) plus two bits per voxel of
//! the bricks near the surface.

use std::collections::VecDeque;
use std::path::PathBuf;

use glam::{DVec3, IVec3};
use rayon::prelude::*;
use rustc_hash::FxHashSet;

use crate::brick::BRICK;
use crate::brick_map::BrickMap;
use crate::camera::Pose;
use crate::frame::RgbdFrame;
use crate::integrate::{integrate_brick, CachedFrame, IntegrationSettings, Pass};
use crate::FusionError;

/// The fusion's choices.
#[derive(Clone, Debug, PartialEq)]
pub struct FusionSettings {
    pub integration: IntegrationSettings,
    /// Frames per window (`n`); windows start every `n/2` frames and the ring holds `2n`.
    pub window: usize,
    /// Frames of the sub-cache (`n̂`).
    pub sub_cache: usize,
    /// Depths outside this range (metres) are ignored.
    pub depth_range: [f32; 2],
    /// Samples used for allocation: every `stride`-th pixel along both axes (bricks span tens of pixels).
    pub allocation_stride: u32,
    /// Bytes the resident bricks may hold before far chunks are streamed out.
    pub memory_budget: usize,
    /// Chunks within this distance (metres) of the camera are never streamed out.
    pub keep_radius: f64,
    /// Where streamed-out chunks go; `None`: nowhere (going over the budget is then an error).
    pub spill_dir: Option<PathBuf>,
}

impl Default for FusionSettings {
    fn default() -> Self {
        FusionSettings {
            integration: IntegrationSettings {
                voxel: 0.01,
                sigma_factor: 3.0,
                min_band_voxels: 3.0,
                confidence_weight: 3.0,
                prior_weight: 4.0,
                surface_offsets: true,
            },
            window: 16,
            sub_cache: 2,
            depth_range: [0.3, 5.0],
            allocation_stride: 4,
            memory_budget: 1 << 30,
            keep_radius: 3.0,
            spill_dir: None,
        }
    }
}

impl FusionSettings {
    /// Checks the settings; the message names the flag.
    pub fn validate(&self) -> Result<(), FusionError> {
        let voxel = self.integration.voxel;
        if !(voxel.is_finite() && (1e-4..=1.0).contains(&voxel)) {
            return Err(FusionError::Settings(format!("--voxel {voxel}: give an edge between 0.0001 and 1 metre")));
        }
        if !(2..=240).contains(&self.window) || !self.window.is_multiple_of(2) {
            return Err(FusionError::Settings(format!(
                "--window {}: give an even number of frames from 2 to 240",
                self.window
            )));
        }
        if self.sub_cache == 0 || self.sub_cache > self.window {
            return Err(FusionError::Settings(format!(
                "--sub-cache {}: give 1 to --window ({}) frames",
                self.sub_cache, self.window
            )));
        }
        let t = self.integration.min_band_voxels;
        if !(t.is_finite() && (1.0..=32.0).contains(&t)) {
            return Err(FusionError::Settings(format!("--truncation {t}: give 1 to 32 voxels")));
        }
        let c = self.integration.confidence_weight;
        if !(c.is_finite() && c > 0.0 && c <= self.window as f32) {
            return Err(FusionError::Settings(format!(
                "--confidence {c}: give a weight above 0 and at most --window ({})",
                self.window
            )));
        }
        Ok(())
    }
}

/// What the fusion has done so far.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FusionStats {
    pub frames: usize,
    pub windows: usize,
    pub bricks_integrated: u64,
    pub bricks_sub_cache: u64,
    pub bricks_removed: u64,
    /// The most bytes the resident bricks held after any window.
    pub peak_brick_bytes: usize,
    /// Bytes of the frame ring when full.
    pub ring_bytes: usize,
    /// After every window: the frames fused so far and the bytes of the resident bricks.
    pub memory_trace: Vec<(usize, usize)>,
}

/// An online fusion of RGB-D frames into binary bricks.
pub struct Fusion {
    settings: FusionSettings,
    map: BrickMap,
    ring: VecDeque<CachedFrame>,
    since_window: usize,
    last_camera: DVec3,
    pub stats: FusionStats,
}

impl Fusion {
    pub fn new(settings: FusionSettings) -> Result<Fusion, FusionError> {
        settings.validate()?;
        if let Some(dir) = &settings.spill_dir {
            std::fs::create_dir_all(dir)
                .map_err(|e| FusionError::File { path: dir.clone(), message: e.to_string() })?;
        }
        let map = BrickMap::new(settings.integration.voxel, settings.spill_dir.clone());
        Ok(Fusion {
            settings,
            map,
            ring: VecDeque::new(),
            since_window: 0,
            last_camera: DVec3::ZERO,
            stats: FusionStats::default(),
        })
    }

    pub fn settings(&self) -> &FusionSettings {
        &self.settings
    }

    pub fn map(&self) -> &BrickMap {
        &self.map
    }

    pub fn map_mut(&mut self) -> &mut BrickMap {
        &mut self.map
    }

    /// Adds a frame taken at `pose`: allocates its bricks, updates new bricks from the sub-cache, and processes a
    /// window when one is due.
    pub fn add_frame(&mut self, frame: &RgbdFrame, pose: Pose) -> Result<(), FusionError> {
        let [near, far] = self.settings.depth_range;
        let depth: Vec<f32> = frame.depth.iter().map(|&d| if d >= near && d <= far { d } else { 0.0 }).collect();
        let mut cached = CachedFrame::new(frame.intrinsics, &depth, frame.colour.clone(), pose);
        let keys = self.allocation_keys(&cached);
        self.map.allocate(&keys)?;
        cached.bricks = keys.into_iter().collect();
        self.last_camera = pose.translation;
        if self.ring.len() == 2 * self.settings.window {
            self.ring.pop_front();
        }
        self.ring.push_back(cached);
        self.stats.frames += 1;
        self.stats.ring_bytes = self.stats.ring_bytes.max(self.ring.iter().map(CachedFrame::bytes).sum());

        // Sub-cache: every brick of this frame no window has processed yet.
        let recent: Vec<&CachedFrame> = self.ring.iter().rev().take(self.settings.sub_cache).collect();
        let fresh: Vec<IVec3> = self
            .ring
            .back()
            .expect("just pushed")
            .bricks
            .iter()
            .copied()
            .filter(|k| self.map.brick(*k).is_some_and(|b| !b.integrated))
            .collect();
        let updated = self.process(&fresh, &recent, Pass::SubCache);
        self.stats.bricks_sub_cache += updated.len() as u64;
        for (key, brick) in updated {
            self.map.put(key, brick);
        }

        self.since_window += 1;
        let n = self.settings.window;
        if self.ring.len() >= n && (self.since_window >= n / 2 || self.stats.windows == 0) {
            self.window()?;
        }
        Ok(())
    }

    /// Processes the last window over whatever frames have not been in one yet; call after the last frame.
    pub fn finish(&mut self) -> Result<(), FusionError> {
        if self.since_window > 0 && !self.ring.is_empty() {
            self.window()?;
        }
        Ok(())
    }

    /// Processes the last `n` frames of the ring.
    fn window(&mut self) -> Result<(), FusionError> {
        let n = self.settings.window.min(self.ring.len());
        let frames: Vec<&CachedFrame> = self.ring.iter().skip(self.ring.len() - n).collect();
        let mut keys: FxHashSet<IVec3> = FxHashSet::default();
        for frame in &frames {
            keys.extend(frame.bricks.iter().copied());
        }
        // Bricks streamed out since a frame touched them come back first.
        self.map.allocate(&keys)?;
        let keys: Vec<IVec3> = keys.into_iter().collect();
        let updated = self.process(&keys, &frames, Pass::Window);
        self.stats.bricks_integrated += updated.len() as u64;
        for (key, brick) in updated {
            self.map.put(key, brick);
        }
        self.stats.bricks_removed += self.map.remove_empty(&keys) as u64;
        self.stats.windows += 1;
        self.since_window = 0;
        self.map.stream_out(self.last_camera, self.settings.keep_radius, self.settings.memory_budget)?;
        self.map.recount();
        self.stats.peak_brick_bytes = self.stats.peak_brick_bytes.max(self.map.resident_bytes());
        self.stats.memory_trace.push((self.stats.frames, self.map.resident_bytes()));
        Ok(())
    }

    fn process(&self, keys: &[IVec3], frames: &[&CachedFrame], pass: Pass) -> Vec<(IVec3, crate::brick::BinaryBrick)> {
        let settings = &self.settings.integration;
        let map = &self.map;
        keys.par_iter().map(|&key| (key, integrate_brick(map, key, frames, settings, pass))).collect()
    }

    /// The bricks within the band of the frame's samples (every `allocation_stride`-th pixel): walked along each
    /// sample's ray from `σ` in front to `σ` behind in half-brick steps.
    fn allocation_keys(&self, frame: &CachedFrame) -> FxHashSet<IVec3> {
        let k = frame.intrinsics;
        let stride = self.settings.allocation_stride.max(1) as usize;
        let voxel = self.settings.integration.voxel;
        let half_brick = voxel * f64::from(BRICK) * 0.5;
        let settings = &self.settings.integration;
        let rows: Vec<usize> = (0..k.height as usize).step_by(stride).collect();
        rows.par_iter()
            .fold(FxHashSet::default, |mut set, &v| {
                for u in (0..k.width as usize).step_by(stride) {
                    let d = frame.depth[v * k.width as usize + u];
                    if d == 0 {
                        continue;
                    }
                    let d = f32::from(d) * crate::integrate::DEPTH_UNIT;
                    let band = f64::from(settings.band(d));
                    let z0 = (f64::from(d) - band).max(1e-3);
                    let z1 = f64::from(d) + band;
                    let steps = ((z1 - z0) / half_brick).ceil().max(1.0) as usize;
                    for s in 0..=steps {
                        let z = z0 + (z1 - z0) * s as f64 / steps as f64;
                        let p = frame.pose.transform_point3(k.unproject(u as f64, v as f64, z));
                        let voxel_index = (p / voxel).floor().as_ivec3();
                        set.insert(BrickMap::split(voxel_index).0);
                    }
                }
                set
            })
            .reduce(FxHashSet::default, |mut a, b| {
                a.extend(b);
                a
            })
    }
}
